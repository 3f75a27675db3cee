"""Blocks of bounded size inside a tile: a k-d split of the x-y plane by point count.

Tiles are laid out on a regular grid sized for the scan's *average* density; near a
scanner station a tile can hold several times that many points. The coarse stage splits
such a tile into blocks of at most ``max_points`` points, segments each block with a
margin of context around it, and joins the blocks' segments over the context points as
the stage joins tiles (``pipeline/coarse.py``). Memory per task then follows the block,
not the densest spot of the scan.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from hollowtree.errors import ConfigError

__all__ = ["split_blocks", "block_context"]


def split_blocks(xy: npt.ArrayLike, max_points: int, scale: npt.ArrayLike | None = None
                 ) -> tuple[npt.NDArray[np.int32], npt.NDArray[np.float64]]:
    """Split points into x-y rectangles of at most ``max_points`` points each.

    Each rectangle holding more points is cut at the median of its longer side (the
    lower half keeps the points strictly below the median value, so equal coordinates
    stay together), recursively.

    Parameters
    ----------
    xy : array-like of shape (n_points, 2) (further columns are ignored)
        Coordinates, or a store's integer coordinates with their ``scale``: integers are
        split as they are (4 or 8 bytes a point, not a float copy of 16), and the blocks
        are those of ``xy * scale`` in float64, to the bit.
    max_points : int
        Largest block wanted, ``>= 1``. A block of identical x-y values cannot be cut and
        may stay larger.
    scale : array-like of 2 floats > 0, optional
        The size of one unit of ``xy`` along x and y (default 1).

    Returns
    -------
    block_of : ndarray of shape (n_points,), int32
        The block of every point, ``0 .. n_blocks-1``.
    rects : ndarray of shape (n_blocks, 4)
        ``[xmin, ymin, xmax, ymax]`` of each block's points, times ``scale``.

    Examples
    --------
    >>> xy = np.array([[0, 0], [1, 0], [2, 0], [3, 0], [3, 1.0]])
    >>> block_of, rects = split_blocks(xy, 2)
    >>> block_of.tolist()
    [0, 0, 1, 2, 2]
    >>> rects.tolist()
    [[0.0, 0.0, 1.0, 0.0], [2.0, 0.0, 2.0, 0.0], [3.0, 0.0, 3.0, 1.0]]
    >>> split_blocks(np.array([[0, 0], [1000, 0], [2000, 0]]), 2, scale=[0.001, 0.001])[1].tolist()
    [[0.0, 0.0, 0.0, 0.0], [1.0, 0.0, 2.0, 0.0]]
    """
    a = np.asarray(xy)
    if a.dtype.kind not in "iu":
        a = np.asarray(a, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] < 2:
        raise ConfigError(f"The 'xy' parameter of split_blocks must have shape (n_points, 2). Got {a.shape} instead.")
    if isinstance(max_points, bool) or not isinstance(max_points, (int, np.integer)) or max_points < 1:
        raise ConfigError(f"The 'max_points' parameter of split_blocks must be an int >= 1. Got {max_points!r} instead.")
    sx, sy = (1.0, 1.0) if scale is None else (float(v) for v in np.asarray(scale, dtype=np.float64)[:2])
    if not (sx > 0 and sy > 0):
        raise ConfigError(f"The 'scale' parameter of split_blocks must be 2 numbers > 0. Got {scale!r} instead.")
    # Columns as views, not copies; one coordinate of a rectangle's points at a time, and
    # the median taken in that gather itself: the split holds about 17 bytes per point
    # besides its input (int32 indices and blocks).
    x, y = a[:, 0], a[:, 1]
    n = len(a)
    itype = np.int32 if n < 2**31 else np.int64
    block_of = np.zeros(n, dtype=np.int32)
    rects: list[list[float]] = []
    stack = [np.arange(n, dtype=itype)]
    done: list[np.ndarray] = []
    while stack:
        idx = stack.pop()
        if len(idx) <= max_points:
            done.append(idx)
            continue
        # The extent in the units of xy * scale, as np.ptp of the scaled points gives it.
        ext_x = float(x[idx].max()) * sx - float(x[idx].min()) * sx
        ext_y = float(y[idx].max()) * sy - float(y[idx].min()) * sy
        first, second = (x, y) if ext_x >= ext_y else (y, x)
        low = _below_median(first, idx)
        if low.all():  # all equal along this axis: try the other one
            low = _below_median(second, idx)
            if low.all():  # identical x-y: cannot be cut
                done.append(idx)
                continue
        stack.append(idx[~low])
        stack.append(idx[low])
    # Blocks in order of their lowest point index: the same input gives the same blocks.
    done.sort(key=lambda i: int(i[0]) if len(i) else -1)
    for b, idx in enumerate(done):
        block_of[idx] = b
        if len(idx):
            rects.append([float(x[idx].min()) * sx, float(y[idx].min()) * sy,
                          float(x[idx].max()) * sx, float(y[idx].max()) * sy])
        else:
            rects.append([np.nan] * 4)
    return block_of, np.asarray(rects, dtype=np.float64).reshape(-1, 4)


def _below_median(c: npt.NDArray, idx: npt.NDArray) -> npt.NDArray[np.bool_]:
    """The points ``idx`` strictly below the median of ``c[idx]``; those at or below it when
    half or more of them sit on the minimum (all of them when every value is equal).

    Integer coordinates give the answer of the float64 ones times a scale > 0: the median
    of integers is one of them, or the mean of two neighbours, and the cut falls between
    the same points either way."""
    med = float(np.median(c[idx], overwrite_input=True))  # the gather is a temporary: partition it in place
    low = c[idx] < med
    if not low.any():  # half or more of the points sit on the minimum: cut above it
        low = c[idx] <= med
    return low


def block_context(xy: npt.ArrayLike, rect: npt.ArrayLike, margin: float) -> npt.NDArray[np.int64]:
    """Indices of the points within ``margin`` of a block's rectangle (its own included).

    Examples
    --------
    >>> xy = np.array([[0, 0], [1, 0], [2, 0], [3, 0.0]])
    >>> block_context(xy, [0, 0, 1, 0], 1.0).tolist()
    [0, 1, 2]
    """
    a = np.asarray(xy, dtype=np.float64)
    r = np.asarray(rect, dtype=np.float64)
    inside = (a[:, 0] >= r[0] - margin) & (a[:, 0] <= r[2] + margin)
    inside &= (a[:, 1] >= r[1] - margin) & (a[:, 1] <= r[3] + margin)
    return np.flatnonzero(inside)
