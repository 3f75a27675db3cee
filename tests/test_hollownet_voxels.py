"""Hollow voxels: values, aspect ratio, z up, invariances, batches, bad input."""

from __future__ import annotations

import numpy as np
import pytest

from hollowtree.errors import PipelineError
from hollowtree.hollownet.voxels import (
    EMPTY,
    OCCUPIED,
    DegenerateSegmentError,
    canonical_angle,
    voxelize,
    voxelize_batch,
)


def _box_surface(rng, n, size=(2.0, 1.0, 1.0)) -> np.ndarray:
    """Points on the six faces of an axis-aligned box from the origin to ``size``."""
    p = rng.random((n, 3)) * size
    axis = rng.integers(0, 3, n)
    side = rng.integers(0, 2, n)
    p[np.arange(n), axis] = side * np.asarray(size)[axis]
    return p


def test_values_shape_and_map():
    rng = np.random.default_rng(0)
    pts = _box_surface(rng, 5000)
    before = pts.copy()
    grid, voxel = voxelize(pts)
    assert grid.shape == (30, 30, 30)
    assert grid.dtype == np.int8
    assert set(np.unique(grid).tolist()) == {EMPTY, OCCUPIED}
    assert voxel.shape == (5000,)
    assert voxel.dtype == np.int64
    assert (grid.reshape(-1)[voxel] == OCCUPIED).all()
    assert (grid == OCCUPIED).sum() == len(np.unique(voxel))
    np.testing.assert_array_equal(pts, before)  # input left unmodified
    # hollow: the inside of the box is empty
    assert (grid[3:27, 10:20, 10:20] == EMPTY).all()


def test_aspect_ratio_is_kept_and_z_is_up():
    rng = np.random.default_rng(1)
    grid, _ = voxelize(_box_surface(rng, 20000, size=(4.0, 2.0, 1.0)))
    occ = np.argwhere(grid == OCCUPIED)
    span = occ.max(axis=0) - occ.min(axis=0) + 1
    # 4 : 2 : 1 -> 30 : 15 : 7.5 voxels, give or take the voxel a centred side straddles
    assert span[0] == 30
    assert abs(span[1] - 15) <= 1
    assert abs(span[2] - 7.5) <= 1
    centre = (occ.max(axis=0) + occ.min(axis=0)) / 2
    assert np.abs(centre - 14.5).max() <= 0.5  # centred in every axis
    # a point cloud that is taller at high x: occupied k grows with i
    x = np.linspace(0, 1, 200)
    ramp = np.c_[x, np.zeros_like(x), x]
    g, v = voxelize(ramp, size=10)
    ijk = np.c_[v // 100, (v // 10) % 10, v % 10]
    assert (np.diff(ijk[:, 2]) >= 0).all()
    assert ijk[-1, 2] == 9
    assert ijk[0, 2] == 0


def test_translation_and_uniform_scale_do_not_matter():
    rng = np.random.default_rng(2)
    pts = _box_surface(rng, 3000, size=(3.0, 1.3, 2.1))
    g1, v1 = voxelize(pts)
    g2, v2 = voxelize(pts * 7.5 + [512_000.25, 3_400_000.5, 210.0])
    np.testing.assert_array_equal(g1, g2)
    assert (v1 != v2).mean() < 0.002  # only float rounding at voxel borders


def test_canonical_yaw_removes_the_heading():
    rng = np.random.default_rng(3)
    pts = _box_surface(rng, 20000, size=(4.0, 1.5, 1.0))
    base, _ = voxelize(pts, canonical_yaw=True)
    for deg in (17.0, 90.0, 133.0):
        a = np.radians(deg)
        rot = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
        g, _ = voxelize(pts @ rot.T, canonical_yaw=True)
        # equal up to the sign of the principal axis (flips in x and y)
        best = max(np.mean(g == np.flip(base, axes)) for axes in [(), (0,), (1,), (0, 1)])
        assert best > 0.995, deg
        plain, _ = voxelize(pts @ rot.T)
        if deg != 90.0:
            assert np.mean(plain == base) < best
    assert abs(abs(np.degrees(canonical_angle(pts @ rot.T))) - 47.0) < 1.0


@pytest.mark.parametrize("canonical_yaw", [False, True])
def test_batch_equals_one_by_one(canonical_yaw):
    rng = np.random.default_rng(4)
    parts = [_box_surface(rng, n, size=rng.uniform(0.5, 3, 3)) + rng.normal(0, 100, 3) for n in (7, 300, 1, 2000)]
    offsets = np.r_[0, np.cumsum([len(p) for p in parts])]
    grids, voxel = voxelize_batch(np.concatenate(parts), offsets, canonical_yaw=canonical_yaw)
    assert grids.shape == (4, 30, 30, 30)
    for s, p in enumerate(parts):
        g, v = voxelize(p, canonical_yaw=canonical_yaw)
        np.testing.assert_array_equal(grids[s], g)
        np.testing.assert_array_equal(voxel[offsets[s]:offsets[s + 1]], v)


def test_degenerate_segments():
    with pytest.raises(DegenerateSegmentError, match="no points"):
        voxelize(np.zeros((0, 3)))
    bad = np.ones((5, 3))
    bad[2, 1] = np.nan
    with pytest.raises(DegenerateSegmentError, match="NaN"):
        voxelize(bad)
    bad[2, 1] = np.inf
    with pytest.raises(PipelineError, match="NaN or infinite"):
        voxelize(bad)
    with pytest.raises(DegenerateSegmentError, match="segment 1 has no points"):
        voxelize_batch(np.ones((4, 3)), [0, 4, 4])
    with pytest.raises(DegenerateSegmentError, match="shape"):
        voxelize(np.ones((4, 2)))
    with pytest.raises(ValueError, match="'size' parameter"):
        voxelize(np.ones((4, 3)), size=1)
    # one point, or all points at one spot: the centre voxel, no error
    for pts in (np.array([[1.0, 2.0, 3.0]]), np.full((10, 3), 7.0)):
        g, v = voxelize(pts, canonical_yaw=True)
        assert (g == OCCUPIED).sum() == 1
        assert g[15, 15, 15] == OCCUPIED
        assert (v == (15 * 30 + 15) * 30 + 15).all()
