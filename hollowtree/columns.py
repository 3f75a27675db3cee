"""Per-column extremes of narrow point arrays, the same values as NumPy's axis-0 reductions.

NumPy reduces a C-ordered ``(n, k)`` array along axis 0 one row at a time, a ``k``-wide
inner loop per row. For the ``(n, 3)`` and ``(n, 2)`` arrays every kernel here holds,
``a.min(axis=0)`` is 4x (``k = 3``) to 17x (``k = 2``) slower than reducing each column
in turn, and ``np.ptp(a, axis=0)`` 9x (2 M points: 60 against 15 ms, 64 against 3.8 ms,
133 against 14 ms; docs/decisions/speed-and-memory.md, "Less CPU for the same labels").
Minimum and maximum are exact, so the values are those of the axis-0 reductions (NaN
propagates alike, an empty array raises alike); only the sign of a zero extreme may
differ where ``-0.0`` and ``0.0`` tie.

Pure NumPy, on the ground floor (``hollowtree/`` itself): every package may import it.

Examples
--------
>>> a = np.array([[3.0, -1.0], [2.0, 5.0]])
>>> column_min(a).tolist(), column_max(a).tolist(), column_span(a).tolist()
([2.0, -1.0], [3.0, 5.0], [1.0, 6.0])
>>> column_max(np.array([[3, -1], [2, 5]])).tolist()  # the array's dtype
[3, 5]
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar

import numpy as np
import numpy.typing as npt

__all__ = ["column_max", "column_min", "column_span"]

_S = TypeVar("_S", bound=np.generic)


def _by_column(a: npt.NDArray[_S], reduce: Callable[[npt.NDArray[_S]], Any]) -> npt.NDArray[_S]:
    """``reduce`` of each column of the 2-D array ``a`` in turn, as an array of ``a``'s dtype."""
    return np.array([reduce(a[:, j]) for j in range(a.shape[1])], dtype=a.dtype)


def column_min(a: npt.NDArray[_S]) -> npt.NDArray[_S]:
    """``a.min(axis=0)`` of a 2-D array, one column at a time."""
    return _by_column(a, np.ndarray.min)


def column_max(a: npt.NDArray[_S]) -> npt.NDArray[_S]:
    """``a.max(axis=0)`` of a 2-D array, one column at a time."""
    return _by_column(a, np.ndarray.max)


def column_span(a: npt.NDArray[_S]) -> npt.NDArray[_S]:
    """``np.ptp(a, axis=0)`` (maximum minus minimum) of a 2-D array, one column at a time."""
    return _by_column(a, lambda c: c.max() - c.min())
