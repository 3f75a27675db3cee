"""Ground points of a sparse (airborne) scan: the Simple Morphological Filter (SMRF).

Pingel, Clarke and McBride (2013), "An improved simple morphological filter for the
terrain classification of airborne LIDAR data", ISPRS J. 77, 21-30, as PDAL's
``filters.smrf`` implements it, with PDAL's defaults:

1. the lowest z per ``cell`` of a grid over the points (empty cells take their nearest
   cell's value);
2. a progressive opening with windows of radius 1, 2, ... cells up to ``window`` metres:
   a cell that the opening of radius r lowers by more than ``slope * r * cell`` is an
   object (a building, a tree), not terrain;
3. the terrain model: the minimum surface without the object cells, filled from the
   nearest terrain cell;
4. a point is ground when it lies within ``threshold + scalar * s`` of the terrain
   model, ``s`` being the model's slope (rise over run) under the point.

Two deviations, both for speed on large tiles: the opening windows are squares (a
separable minimum and maximum filter, linear in the window) where the paper and PDAL use
disks, and the cell grows where the grid would hold more than ``MAX_CELLS_PER_POINT``
cells per point (a few points over square kilometres), so the grid stays linear in the
points.

hollowtree's own method labels ground as a planar part of a terrestrial scan; a scan
whose points are far apart (``pipeline.coarse.MAX_SPACING``) takes its ground from here
instead (docs/method.md, "Sparse scans").

Pure NumPy/SciPy.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from scipy import ndimage

__all__ = ["MAX_CELLS_PER_POINT", "smrf_ground"]

#: The grid holds at most this many cells per point: a larger ``cell`` where it would not.
MAX_CELLS_PER_POINT = 4.0


def _fill_nearest(grid: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """NaN cells take the value of the nearest finite cell (all NaN stays NaN)."""
    missing = ~np.isfinite(grid)
    if not missing.any() or missing.all():
        return grid
    _, (ii, jj) = ndimage.distance_transform_edt(missing, return_indices=True)
    return grid[ii, jj]


def smrf_ground(xyz: npt.ArrayLike, *, cell: float = 1.0, slope: float = 0.15, window: float = 18.0,
                threshold: float = 0.5, scalar: float = 1.25) -> npt.NDArray[np.bool_]:
    """True for the ground points of ``xyz`` (n, 3), in metres.

    Parameters
    ----------
    cell : float
        Grid cell of the minimum surface, m.
    slope : float
        Terrain slope (rise over run) above which a cell lowered by the opening is an object.
    window : float
        Largest opening radius, m: about the half-size of the largest building.
    threshold, scalar : float
        A point is ground within ``threshold + scalar * slope of the terrain`` metres of it.

    >>> rng = np.random.default_rng(0)
    >>> ground = np.c_[rng.uniform(0, 60, (3000, 2)), rng.normal(0, 0.05, 3000)]
    >>> roof = np.c_[rng.uniform(20, 35, (600, 2)), 8 + rng.normal(0, 0.05, 600)]
    >>> g = smrf_ground(np.r_[ground, roof])
    >>> bool(g[:3000].mean() > 0.99), bool(g[3000:].any())
    (True, False)
    """
    p = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
    out = np.zeros(len(p), bool)
    finite = np.isfinite(p).all(axis=1)
    if finite.sum() == 0:
        return out
    q = p[finite]
    lo = q[:, :2].min(axis=0)
    span = np.maximum(q[:, :2].max(axis=0) - lo, cell)
    cell = max(cell, float(np.sqrt(span[0] * span[1] / (MAX_CELLS_PER_POINT * len(q)))))
    ij = np.floor((q[:, :2] - lo) / cell).astype(np.int64)
    shape = tuple(int(v) for v in ij.max(axis=0) + 1)
    zmin = np.full(shape, np.inf)
    np.minimum.at(zmin, (ij[:, 0], ij[:, 1]), q[:, 2])
    zmin[~np.isfinite(zmin)] = np.nan
    surface = _fill_nearest(zmin)
    obj = np.zeros(shape, bool)
    last = surface
    for radius in range(1, max(1, int(np.ceil(window / cell))) + 1):
        size = 2 * radius + 1
        opened = ndimage.maximum_filter(ndimage.minimum_filter(last, size=size, mode="nearest"), size=size,
                                        mode="nearest")
        obj |= (last - opened) > slope * radius * cell
        last = opened
    terrain = np.where(obj | np.isnan(zmin), np.nan, zmin)
    terrain = _fill_nearest(terrain) if np.isfinite(terrain).any() else surface
    grade = np.zeros(shape)
    for axis in range(2):
        if shape[axis] > 1:
            grade += np.gradient(terrain, cell, axis=axis) ** 2
    grade = np.sqrt(grade)
    # Bilinear heights and slopes under each point (cell centres at (i + 0.5) * cell).
    f = (q[:, :2] - lo) / cell - 0.5
    coords = [f[:, 0], f[:, 1]]
    zt = ndimage.map_coordinates(terrain, coords, order=1, mode="nearest")
    st = ndimage.map_coordinates(grade, coords, order=1, mode="nearest")
    out[np.flatnonzero(finite)] = np.abs(q[:, 2] - zt) <= threshold + scalar * st
    return out
