"""hollowtree/columns.py: per-column extremes equal NumPy's axis-0 reductions."""

from __future__ import annotations

import numpy as np
import pytest

from hollowtree.columns import column_max, column_min, column_span


@pytest.mark.parametrize("k", [1, 2, 3, 5])
@pytest.mark.parametrize("dtype", [np.float64, np.float32, np.int64, np.int32])
def test_equal_to_axis0_reductions(k: int, dtype: type) -> None:
    rng = np.random.default_rng(k)
    a = (rng.normal(size=(1001, k)) * 1e3).astype(dtype)
    for got, want in ((column_min(a), a.min(axis=0)), (column_max(a), a.max(axis=0)),
                      (column_span(a), np.ptp(a, axis=0))):
        assert got.dtype == want.dtype
        assert got.shape == (k,)
        np.testing.assert_array_equal(got, want)


def test_strided_views_and_nan() -> None:
    a = np.arange(24, dtype=np.float64).reshape(6, 4)[:, :3]  # not C-contiguous
    np.testing.assert_array_equal(column_min(a), a.min(axis=0))
    np.testing.assert_array_equal(column_span(a), np.ptp(a, axis=0))
    a = a.copy()
    a[2, 1] = np.nan
    np.testing.assert_array_equal(column_min(a), a.min(axis=0))  # NaN propagates alike
    np.testing.assert_array_equal(column_max(a), a.max(axis=0))
    np.testing.assert_array_equal(column_span(a), np.ptp(a, axis=0))


def test_empty_raises_like_numpy() -> None:
    a = np.zeros((0, 3))
    with pytest.raises(ValueError, match="zero-size"):
        a.min(axis=0)
    for f in (column_min, column_max, column_span):
        with pytest.raises(ValueError, match="zero-size"):
            f(a)
