"""Ground or roof: a horizontal planar part is told apart by its height above the ground.

HollowNet sees a segment scaled to fit its grid, so a flat horizontal patch looks the
same at ground level and on a roof (its main confusion, docs/benchmarks.md "HollowNet").
The height above the local ground decides instead: the ground level of a place is the
lowest point of any coarse segment near it (walls, pillars and the ground itself reach
down to it), taken over a coarse grid from the segments' bounding boxes alone, so it
needs no pass over the points.

Pure NumPy.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from hollowtree.classes import ClassId

__all__ = ["ground_levels", "ground_or_roof"]


def ground_levels(bbox: npt.ArrayLike, *, cell: float = 10.0, min_points: npt.ArrayLike | None = None,
                  n_points: npt.ArrayLike | None = None) -> npt.NDArray[np.float64]:
    """The local ground level under each segment.

    Parameters
    ----------
    bbox : array (g, 6)
        Segment bounding boxes ``xmin, ymin, zmin, xmax, ymax, zmax``.
    cell : float
        Grid cell size in metres. A cell's ground is the lowest ``zmin`` of the
        segments whose footprint touches it; a segment's ground is the lowest of the
        cells its footprint touches, widened by one cell.
    n_points, min_points : arrays or None
        When both are given, segments with fewer points than ``min_points`` do not set
        the ground (stray clutter below the terrain).

    Returns
    -------
    float64 (g,)

    >>> b = np.array([[0, 0, 100.0, 50, 50, 100.02],   # ground
    ...               [10, 10, 108.0, 20, 20, 108.0],  # a roof
    ...               [60, 0, 103.0, 70, 5, 103.0]])   # a terrace far off, on its own
    >>> ground_levels(b, cell=10.0).tolist()
    [100.0, 100.0, 100.0]
    >>> ground_levels(b, cell=5.0).tolist()
    [100.0, 100.0, 103.0]
    """
    b = np.asarray(bbox, dtype=np.float64).reshape(-1, 6)
    g = len(b)
    if g == 0:
        return np.zeros(0)
    setter = np.ones(g, bool)
    if n_points is not None and min_points is not None:
        setter = np.asarray(n_points) >= np.asarray(min_points)
        if not setter.any():
            setter[:] = True
    x0, y0 = b[:, 0].min(), b[:, 1].min()
    i0 = np.floor((b[:, 0] - x0) / cell).astype(np.int64)
    j0 = np.floor((b[:, 1] - y0) / cell).astype(np.int64)
    i1 = np.floor((b[:, 3] - x0) / cell).astype(np.int64)
    j1 = np.floor((b[:, 4] - y0) / cell).astype(np.int64)
    ni, nj = int(i1.max()) + 3, int(j1.max()) + 3
    grid = np.full((ni, nj), np.inf)
    for s in np.flatnonzero(setter).tolist():  # one slice per segment, not per point
        blk = grid[i0[s] + 1:i1[s] + 2, j0[s] + 1:j1[s] + 2]
        np.minimum(blk, b[s, 2], out=blk)
    out = np.empty(g)
    for s in range(g):  # widened by one cell (the grid is padded by one on each side)
        v = grid[i0[s]:i1[s] + 3, j0[s]:j1[s] + 3].min()
        out[s] = v if np.isfinite(v) else b[s, 2]
    return out


def ground_or_roof(class_id: npt.NDArray[np.uint8], z: npt.NDArray[np.floating], leaf: npt.NDArray[np.integer],
                   ground: float, min_height: float) -> npt.NDArray[np.uint8]:
    """Per point, ground and roof decided by height: a leaf classed ground or roof is
    roof when its median height above ``ground`` is at least ``min_height``, else ground.
    Other classes are kept.

    >>> c = np.array([1, 1, 3, 3, 2], np.uint8)
    >>> z = np.array([0.0, 0.1, 0.0, 0.05, 5.0])
    >>> ground_or_roof(c, z, np.array([0, 0, 1, 1, 2]), 0.0, 1.5).tolist()
    [1, 1, 1, 1, 2]
    >>> ground_or_roof(c, z + 6, np.array([0, 0, 1, 1, 2]), 0.0, 1.5).tolist()
    [3, 3, 3, 3, 2]
    """
    out = np.asarray(class_id, dtype=np.uint8).copy()
    sel = np.flatnonzero((out == ClassId.GROUND) | (out == ClassId.ROOF))
    if len(sel) == 0:
        return out
    leaves, inv = np.unique(np.asarray(leaf)[sel], return_inverse=True)
    zs = np.asarray(z, dtype=np.float64)[sel]
    order = np.lexsort((zs, inv))
    counts = np.bincount(inv, minlength=len(leaves))
    starts = np.r_[0, np.cumsum(counts)[:-1]]
    median = zs[order][starts + counts // 2]
    roof = (median - ground) >= min_height
    out[sel] = np.where(roof[inv], np.uint8(ClassId.ROOF), np.uint8(ClassId.GROUND))
    return out
