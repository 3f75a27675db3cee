"""DBSCAN for dense scans: scikit-learn's labels, without its per-point neighbour lists.

scikit-learn's ``DBSCAN`` stores every point's eps-neighbourhood (hundreds of indices per
point on a dense scan). Here:

1. **Core points** by counting: every point of a grid cell of side ``eps / sqrt(3)``
   (diagonal ``eps``) holding at least ``min_samples`` points is core; the others ask a
   k-d tree whether their ``min_samples``-th nearest neighbour lies within ``eps``.
2. **Clusters** are the connected components of the core points' eps-graph. The core
   points of one cell are all mutually connected, so the graph is built on cells: two
   cells (at most 2 cells apart on each axis) are joined when some pair of their core
   points lies within ``eps``. Offsets are tried nearest first and a pair of cells is only
   tested while the union-find still holds them apart, so on dense data most tests are
   skipped.
3. **Border points** (non-core with a core point within ``eps``) take the lowest cluster
   label among their core neighbours.

The labels equal ``sklearn.cluster.DBSCAN(eps, min_samples=min_samples).fit(xyz).labels_``
exactly, border points included (see :func:`dbscan_labels`).
"""

from __future__ import annotations

import math
from collections.abc import Iterable

import numpy as np
import numpy.typing as npt
from scipy.spatial import cKDTree

from hollowtree.arrays import FloatArray, IntArray
from hollowtree.columns import column_min
from hollowtree.errors import ConfigError
from hollowtree.params import check_args
from hollowtree.primitives._validation import as_xyz as _as_xyz
from hollowtree.primitives.coarse_params import DBSCAN_ARGS
from hollowtree.primitives.stitch import UnionFind
from hollowtree.threads import task_threads

__all__ = ["dbscan_labels", "dbscan_segments", "default_eps", "sparse_points", "spacing_quantile",
           "window_distances", "window_spacing"]

# Point pairs tested at once (bounds the temporary arrays: about 100 bytes per pair).
_PAIR_BUDGET = 1 << 19
# Cell pairs are first tested on this many points of each cell; pairs with more than
# _BIG_PAIR point pairs left are then tested with a k-d tree of one cell.
_BIG_PAIR = 4096
_SUBSAMPLE = 4
# Neighbour entries per k-d tree query chunk (about 50 bytes each with temporaries).
_QUERY_BUDGET = 1 << 20

# -- public kernels ------------------------------------------------------------------------


def dbscan_labels(xyz: npt.ArrayLike, *, eps: float, min_samples: int) -> IntArray:
    """Cluster points with DBSCAN (Euclidean), equal to scikit-learn's labels.

    Parameters
    ----------
    xyz : ndarray of shape (n_points, 3)
        Point coordinates (not modified).
    eps : float
        Neighbourhood radius; a neighbour at distance exactly ``eps`` counts.
    min_samples : int
        Points within ``eps`` of a point, itself included, for it to be a core point.

    Returns
    -------
    labels : ndarray of shape (n_points,)
        int64 cluster labels, -1 for noise.

    Raises
    ------
    ConfigError
        If ``eps`` or ``min_samples`` breaks its rule or ``xyz`` is not finite (n, 3).

    Notes
    -----
    Numbering follows scikit-learn: clusters are numbered 0, 1, ... in order of their
    lowest-index *core* point, and a border point within ``eps`` of several clusters
    joins the one with the lowest label (the first to reach it in scikit-learn's search).
    So the labels equal ``DBSCAN(eps=eps, min_samples=min_samples).fit(xyz).labels_``
    element for element, up to floating-point ties at distance exactly ``eps``.

    Memory: O(n_points): the k-d tree, a few int64 arrays, and temporaries bounded by
    ``_PAIR_BUDGET`` point pairs and ``_QUERY_BUDGET`` neighbours (tens of MB), however
    many neighbours each point has. scikit-learn holds every neighbourhood at once
    (``n_points * mean neighbours * 8`` bytes).

    Examples
    --------
    >>> import numpy as np
    >>> xyz = np.array([[0., 0, 0], [0.5, 0, 0], [1, 0, 0], [5, 0, 0], [5.5, 0, 0], [9, 0, 0]])
    >>> dbscan_labels(xyz, eps=0.6, min_samples=2).tolist()
    [0, 0, 0, 1, 1, -1]
    """
    func = "dbscan_labels"
    check_args(DBSCAN_ARGS, func, eps=eps, min_samples=min_samples)
    pts = _as_xyz(xyz, func)
    eps, min_samples = float(eps), int(min_samples)
    n = len(pts)
    labels = np.full(n, -1, dtype=np.int64)
    if n < min_samples:
        return labels

    cell, ijk, uxy, dims = _cells(pts, eps / math.sqrt(3.0) * (1.0 - 1e-9))
    tree = cKDTree(pts, balanced_tree=False)  # sliding midpoint: faster build and queries
    core = _core_points(pts, tree, cell, eps, min_samples)
    if not core.any():
        return labels

    # Core points grouped by cell (a pseudo-random order inside a cell, for subsamples).
    core_idx = np.flatnonzero(core)
    shuffle = np.random.default_rng(0).permutation(len(core_idx))
    # np.lexsort((shuffle, cell[core_idx])) as one stable sort: the points in shuffle
    # order (its inverse permutation), then stably by cell; the same order, 2.4x faster.
    by_shuffle = np.empty(len(core_idx), dtype=np.int64)
    by_shuffle[shuffle] = np.arange(len(core_idx))
    order = by_shuffle[np.argsort(cell[core_idx][by_shuffle], kind="stable")]
    core_idx = core_idx[order]
    ccell, start, count = np.unique(cell[core_idx], return_index=True, return_counts=True)
    cxyz = pts[core_idx]
    cell_ijk = ijk[core_idx[start]]
    uf = UnionFind(len(ccell))
    every = np.arange(len(ccell))
    for off in _OFFSETS:
        a, b = _neighbour_cells(ccell, cell_ijk, uxy, dims, off)
        _join_cells(uf, a, b, start, count, cxyz, eps)
        if (uf.find(every) == uf.find(0)).all():
            break  # one cluster already

    # Number clusters by their lowest core point, like scikit-learn's search.
    root = uf.find(np.arange(len(ccell)))
    root_of_point = np.empty(n, dtype=np.int64)
    root_of_point[core_idx] = np.repeat(root, count)
    by_index = np.flatnonzero(core)
    roots, first = np.unique(root_of_point[by_index], return_index=True)
    label_of_root = np.empty(len(ccell), dtype=np.int64)
    label_of_root[roots[np.argsort(first, kind="stable")]] = np.arange(len(roots))
    labels[by_index] = label_of_root[root_of_point[by_index]]

    _label_border(pts, tree, core, labels, eps, min_samples)
    return labels


def default_eps(xyz: npt.ArrayLike, *, k: int = 8, factor: float = 3.0) -> float:
    """An ``eps`` for :func:`dbscan_labels` from the local point spacing.

    Parameters
    ----------
    xyz : ndarray of shape (n_points, 3)
        Point coordinates, at least ``k + 1`` points.
    k : int, default=8
        The spacing is the distance to the k-th nearest other point.
    factor : float, default=3.0
        ``eps = factor * median spacing``.

    Returns
    -------
    eps : float

    Raises
    ------
    ConfigError
        If a parameter breaks its rule, there are ``k`` points or fewer, or the median
        spacing is 0 (mostly duplicate points): set ``eps`` by hand then.

    Notes
    -----
    The median is taken over at most 200 000 evenly strided query points (all points
    serve as neighbours). Memory: the k-d tree plus ``k`` distances per query point.

    Examples
    --------
    >>> import numpy as np
    >>> xyz = np.array([[0., 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0], [4, 0, 0], [5, 0, 0]])
    >>> default_eps(xyz, k=2, factor=3.0)
    3.0
    """
    func = "default_eps"
    check_args(DBSCAN_ARGS, func, k=k, factor=factor)
    pts = _as_xyz(xyz, func)
    k = int(k)
    if len(pts) <= k:
        raise ConfigError(
            f"The 'xyz' parameter of {func} must hold more than k={k} points. "
            f"Got {len(pts)} instead."
        )
    tree = cKDTree(pts, balanced_tree=False)
    queries = pts[:: max(1, len(pts) // 200_000)]
    dist, _ = tree.query(queries, k=[k + 1], workers=task_threads(rows=len(queries)))
    spacing = float(np.median(dist))
    if spacing <= 0:
        raise ConfigError(
            f"The 'xyz' parameter of {func} must have distinct neighbours: the median "
            f"distance to the {k}-th neighbour is 0. Set eps explicitly instead."
        )
    return float(factor) * spacing


def dbscan_segments(
    xyz: npt.ArrayLike, primitive_labels: npt.ArrayLike, *, eps: float, min_samples: int
) -> IntArray:
    """Split each primitive's inliers into spatially connected segments.

    Parameters
    ----------
    xyz : ndarray of shape (n_points, 3)
        Point coordinates.
    primitive_labels : ndarray of shape (n_points,)
        Primitive (e.g. RANSAC shape) of each point; negative means none.
    eps, min_samples
        As in :func:`dbscan_labels`, applied to each primitive's points separately.

    Returns
    -------
    segments : ndarray of shape (n_points,)
        int64 segment ids ``1 ..`` unique across primitives (primitives in ascending label
        order, clusters in DBSCAN order within each), 0 for points without a primitive
        and DBSCAN noise.

    Notes
    -----
    DBSCAN runs once per primitive, never on all points at once. Memory: that of
    :func:`dbscan_labels` on the largest primitive, plus the output.

    Examples
    --------
    >>> import numpy as np
    >>> xyz = np.array([[0., 0, 0], [0.1, 0, 0], [3, 0, 0], [3.1, 0, 0], [0, 0.1, 0], [9, 9, 9]])
    >>> dbscan_segments(xyz, [0, 0, 0, 0, 1, -1], eps=0.5, min_samples=2).tolist()
    [1, 1, 2, 2, 0, 0]
    """
    func = "dbscan_segments"
    check_args(DBSCAN_ARGS, func, eps=eps, min_samples=min_samples)
    pts = _as_xyz(xyz, func)
    prim = np.asarray(primitive_labels)
    if prim.shape != (len(pts),) or not (np.issubdtype(prim.dtype, np.integer) or prim.size == 0):
        raise ConfigError(
            f"The 'primitive_labels' parameter of {func} must be an int array of shape "
            f"({len(pts)},). Got {prim.dtype} of shape {prim.shape} instead."
        )
    prim = prim.astype(np.int64)
    segments = np.zeros(len(pts), dtype=np.int64)
    order = np.argsort(prim, kind="stable")
    values, starts = np.unique(prim[order], return_index=True)
    bounds = np.r_[starts, len(order)]
    next_id = 1
    for i, value in enumerate(values.tolist()):
        if value < 0:
            continue
        idx = order[bounds[i] : bounds[i + 1]]
        lab = dbscan_labels(pts[idx], eps=eps, min_samples=min_samples)
        hit = lab >= 0
        segments[idx[hit]] = lab[hit] + next_id
        next_id += int(lab.max()) + 1 if hit.any() else 0
    return segments


# -- helpers -------------------------------------------------------------------------------


def _cells(
    pts: FloatArray, side: float
) -> tuple[IntArray, IntArray, IntArray | None, tuple[int, int]]:
    """Grid cell of each point.

    Returns the cell key per point, the integer cell coordinates per point (with 2 cells
    of padding on each side), the sorted distinct (x, y) column keys or None, and the
    (y, z) dimensions. Keys are ``(ix * ny + iy) * nz + iz`` when that fits in int64.
    Otherwise each axis is compressed (gaps wider than 2 cells become 3, which keeps
    neighbour relations within +-2) and the key is ``rank(ix * ny + iy) * nz + iz``.
    """
    raw = np.floor((pts - column_min(pts)) / side).astype(np.int64)
    dims = [int(raw[:, axis].max()) + 5 for axis in range(3)]
    if math.prod(dims) < 2**62:
        ijk = raw + 2
        return (ijk[:, 0] * dims[1] + ijk[:, 1]) * dims[2] + ijk[:, 2], ijk, None, (dims[1], dims[2])
    ijk = np.empty_like(raw)
    for axis in range(3):
        u, inv = np.unique(raw[:, axis], return_inverse=True)
        packed = 2 + np.r_[0, np.cumsum(np.minimum(np.diff(u), 3))]
        ijk[:, axis] = packed[inv.ravel()]
        dims[axis] = int(packed[-1]) + 3
    xy = ijk[:, 0] * dims[1] + ijk[:, 1]
    uxy, col = np.unique(xy, return_inverse=True)
    key = col.ravel() * dims[2] + ijk[:, 2]
    return key, ijk, uxy, (dims[1], dims[2])


def _offsets() -> list[tuple[int, int, int]]:
    """Half of the cell offsets within reach of eps (the other half is symmetric),
    nearest first."""
    out = []
    for dx in range(-2, 3):
        for dy in range(-2, 3):
            for dz in range(-2, 3):
                if (dx, dy, dz) > (0, 0, 0):
                    gap = sum(max(abs(d) - 1, 0) ** 2 for d in (dx, dy, dz))
                    out.append((gap, dx * dx + dy * dy + dz * dz, (dx, dy, dz)))
    return [o for _, _, o in sorted(out)]


# Side eps/sqrt(3): the closest points of cells (dx, dy, dz) apart are
# side * sqrt(sum(max(|d| - 1, 0)^2)) <= side * sqrt(3) < eps, so all 62 half-offsets
# in [-2, 2]^3 can hold neighbours, and none beyond.
_OFFSETS = _offsets()


def _neighbour_cells(
    cells: IntArray,
    cell_ijk: IntArray,
    uxy: IntArray | None,
    dims: tuple[int, int],
    off: tuple[int, int, int],
) -> tuple[IntArray, IntArray]:
    """Pairs (a, b) of positions in the sorted ``cells`` with b = a + off."""
    dy_dim, dz_dim = dims
    if uxy is None:
        key = cells + ((off[0] * dy_dim + off[1]) * dz_dim + off[2])
        found = np.ones(len(cells), dtype=bool)
    else:
        xy = (cell_ijk[:, 0] + off[0]) * dy_dim + (cell_ijk[:, 1] + off[1])
        col = np.searchsorted(uxy, xy)
        found = col < len(uxy)
        found[found] = uxy[col[found]] == xy[found]
        key = col * dz_dim + cell_ijk[:, 2] + off[2]
    pos = np.searchsorted(cells, key)
    found &= pos < len(cells)
    found[found] = cells[pos[found]] == key[found]
    a = np.flatnonzero(found)
    return a, pos[a]


def _core_points(
    pts: FloatArray,
    tree: cKDTree,
    cell: IntArray,
    eps: float,
    min_samples: int,
) -> npt.NDArray[np.bool_]:
    """Whether each point has at least ``min_samples`` points (itself included) within eps."""
    _, inv, per_cell = np.unique(cell, return_inverse=True, return_counts=True)
    core = per_cell[inv.ravel()] >= min_samples  # a cell's diagonal is < eps
    rest = np.flatnonzero(~core)
    if rest.size and min_samples > 1:
        rest = _tree_order(tree, rest)
        chunk = max(1, _QUERY_BUDGET // min_samples)
        for s in range(0, len(rest), chunk):
            q = rest[s : s + chunk]
            dist, _ = tree.query(
                pts[q], k=[min_samples], distance_upper_bound=eps * (1 + 1e-9), workers=task_threads(rows=len(q))
            )
            core[q] = dist[:, 0] <= eps
    return core


def _tree_order(tree: cKDTree, idx: IntArray) -> IntArray:
    """``idx`` sorted in the tree's leaf order: queries 3-4x faster than input order."""
    rank = np.empty(tree.n, dtype=np.int64)
    rank[tree.indices] = np.arange(tree.n)
    return idx[np.argsort(rank[idx], kind="stable")]


def _join_cells(uf: UnionFind, a: IntArray, b: IntArray, start: IntArray, count: IntArray, cxyz: FloatArray,
                eps: float) -> None:
    """Union the cell pairs (a, b) that hold core points within eps of each other."""
    if not a.size:
        return
    work = count[a] * count[b]
    capped = np.minimum(work, _BIG_PAIR)
    cum = np.cumsum(capped)
    cuts = np.searchsorted(cum, np.arange(_PAIR_BUDGET, int(cum[-1]), _PAIR_BUDGET), side="right")
    for lo, hi in zip(np.r_[0, cuts], np.r_[cuts, len(a)], strict=True):
        if lo >= hi:
            continue
        pa, pb = a[lo:hi], b[lo:hi]
        apart = uf.find(pa) != uf.find(pb)  # skip pairs already joined
        pa, pb = pa[apart], pb[apart]
        if not pa.size:
            continue
        # Stage 1: a few points of each cell (in pseudo-random order) usually find a
        # close pair on dense data.
        sub = np.minimum(count, _SUBSAMPLE)
        hit = _any_within(start[pa], sub[pa], start[pb], sub[pb], cxyz, eps)
        uf.union_pairs(pa[hit], pb[hit])
        # Stage 2: every pair of points, for the cell pairs still apart.
        rest = ~hit & (sub[pa] * sub[pb] < count[pa] * count[pb])
        pa, pb = pa[rest], pb[rest]
        apart = uf.find(pa) != uf.find(pb)
        pa, pb = pa[apart], pb[apart]
        big = count[pa] * count[pb] > _BIG_PAIR
        small = ~big
        hit = _any_within(start[pa[small]], count[pa[small]], start[pb[small]],
                          count[pb[small]], cxyz, eps)
        uf.union_pairs(pa[small][hit], pb[small][hit])
        for ca, cb in zip(pa[big].tolist(), pb[big].tolist(), strict=True):
            if uf.find(ca) == uf.find(cb):
                continue
            sa = cxyz[start[ca] : start[ca] + count[ca]]
            sb = cxyz[start[cb] : start[cb] + count[cb]]
            if len(sa) < len(sb):
                sa, sb = sb, sa
            d, _ = cKDTree(sb).query(sa, k=1, distance_upper_bound=eps * (1 + 1e-9))
            if (d <= eps).any():
                uf.union_pairs([ca], [cb])


def _any_within(start_a: IntArray, count_a: IntArray, start_b: IntArray, count_b: IntArray, cxyz: FloatArray,
                eps: float) -> npt.NDArray[np.bool_]:
    """For each pair of point runs, whether any point of run a is within eps of run b."""
    work = count_a * count_b
    total = int(work.sum())
    if total == 0:
        return np.zeros(len(work), dtype=bool)
    pid = np.repeat(np.arange(len(work)), work)
    t = np.arange(total) - np.repeat(np.cumsum(work) - work, work)
    i = start_a[pid] + t // count_b[pid]
    j = start_b[pid] + t % count_b[pid]
    diff = cxyz[i] - cxyz[j]
    close = np.einsum("ij,ij->i", diff, diff) <= eps * eps
    hit = np.zeros(len(work), dtype=bool)
    hit[pid[close]] = True
    return hit


def _label_border(
    pts: FloatArray,
    tree: cKDTree,
    core: npt.NDArray[np.bool_],
    labels: IntArray,
    eps: float,
    min_samples: int,
) -> None:
    """Give each non-core point within eps of a core point the lowest such cluster label.

    A non-core point has fewer than ``min_samples`` points within eps, itself included,
    so its ``min_samples`` nearest neighbours hold all of them.
    """
    rest = np.flatnonzero(~core)
    if not rest.size:
        return
    rest = _tree_order(tree, rest)
    k = min(min_samples, tree.n)
    chunk = max(1, _QUERY_BUDGET // k)
    big = np.iinfo(np.int64).max
    for s in range(0, len(rest), chunk):
        q = rest[s : s + chunk]
        dist, idx = tree.query(pts[q], k=k, distance_upper_bound=eps * (1 + 1e-9),
                               workers=task_threads(rows=len(q)))
        dist, idx = dist.reshape(len(q), k), idx.reshape(len(q), k)
        near = dist <= eps
        idx = np.where(near, idx, 0)
        cand = np.where(near & core[idx], labels[idx], big)
        best = cand.min(axis=1)
        has = best != big
        labels[q[has]] = best[has]


def window_spacing(windows: Iterable[tuple[npt.ArrayLike, npt.ArrayLike]], *, k: int = 8,
                   quantile: float = 0.25) -> float:
    """A quantile of the local point spacing, measured on compact windows of a scan.

    Each window is a spatially compact piece of the scan (a run of Morton-sorted rows of
    a tile) with a mask of the rows to measure; a measured row's spacing is the distance
    to its ``k``-th nearest other point of its window. All measured rows of all windows
    are pooled and the ``quantile`` of their spacings is returned.

    Neighbours come from the full window, not from a random sample of the scan, so the
    value is the scan's own spacing and does not grow with a tile's point count. A low
    quantile follows the densest, well-covered surfaces: on a terrestrial scan whose
    spacings are bimodal (near and far surfaces) it stays with the near mode, where the
    median can jump from one mode to the other (docs/method.md, "The DBSCAN eps").

    Parameters
    ----------
    windows : iterable of (xyz, mask)
        ``xyz`` of shape (n, 3) and a bool ``mask`` of shape (n,) (the rows measured; the
        others, a tile's buffer, serve as neighbours only). Windows of ``k`` points or
        fewer are skipped.
    k : int, default=8
    quantile : float in (0, 1], default=0.25

    Returns
    -------
    spacing : float

    Raises
    ------
    ConfigError
        If a parameter breaks its rule, a window's arrays do not match, no window holds a
        measured row with ``k`` neighbours, or every measured row has ``k`` exact
        duplicates (zero spacings are left out of the quantile).

    Examples
    --------
    >>> line = np.c_[np.arange(20) * 0.5, np.zeros(20), np.zeros(20)]
    >>> window_spacing([(line, np.ones(20, bool))], k=3, quantile=0.5)
    1.0
    """
    check_args(DBSCAN_ARGS, "window_spacing", k=k, quantile=quantile)
    return spacing_quantile([_distances(windows, int(k), "window_spacing")], k=k, quantile=quantile)


def window_distances(windows: Iterable[tuple[npt.ArrayLike, npt.ArrayLike]], *, k: int = 8) -> FloatArray:
    """The ``k``-th nearest neighbour distance of every measured row of ``windows``
    (:func:`window_spacing`), pooled in window order; windows of ``k`` points or fewer,
    or without a measured row, give none. Pieces of one scan's windows measured apart
    (tasks) and pooled give :func:`window_spacing`'s answer through :func:`spacing_quantile`.

    >>> line = np.c_[np.arange(6) * 0.5, np.zeros(6), np.zeros(6)]
    >>> window_distances([(line, np.ones(6, bool))], k=2).tolist()
    [1.0, 0.5, 0.5, 0.5, 0.5, 1.0]
    """
    check_args(DBSCAN_ARGS, "window_distances", k=k)
    return _distances(windows, int(k), "window_distances")


def _distances(windows: Iterable[tuple[npt.ArrayLike, npt.ArrayLike]], k: int, func: str) -> FloatArray:
    found = [np.zeros(0)]
    for xyz, mask in windows:
        pts = _as_xyz(xyz, func)
        m = np.asarray(mask, dtype=bool).reshape(-1)
        if len(m) != len(pts):
            raise ConfigError(f"The 'windows' parameter of {func} must pair each window with a mask of one "
                              f"entry per point ({len(pts)}). Got {len(m)} instead.")
        if len(pts) <= k or not m.any():
            continue
        found.append(cKDTree(pts, balanced_tree=False).query(pts[m], k=[k + 1],
                                                            workers=task_threads(rows=int(m.sum())))[0][:, 0])
    return np.concatenate(found)


def spacing_quantile(distances: Iterable[npt.ArrayLike], *, k: int = 8, quantile: float = 0.25) -> float:
    """The ``quantile`` of pooled :func:`window_distances` (one array or several), zero
    distances (a point with ``k`` exact duplicates) left out.

    Raises
    ------
    ConfigError
        If ``quantile`` breaks its rule, no distance was measured, or every one is zero.
    """
    func = "window_spacing"
    check_args(DBSCAN_ARGS, func, k=k, quantile=quantile)
    pooled = np.concatenate([np.asarray(d, dtype=np.float64).reshape(-1) for d in distances] or [np.zeros(0)])
    if not len(pooled):
        raise ConfigError(f"The 'windows' parameter of {func} must hold a measured point with {k} neighbours. "
                          "Got none instead.")
    # A zero spacing is a point with k exact duplicates: it says nothing about the spacing.
    pooled = pooled[pooled > 0]
    if not len(pooled):
        raise ConfigError(f"The 'windows' parameter of {func} must have distinct neighbours: every measured "
                          f"point has {k} exact duplicates. Set eps explicitly instead.")
    return float(np.quantile(pooled, quantile))


def sparse_points(xyz: npt.ArrayLike, mask: npt.ArrayLike, spacing: float, factor: float, *, k: int = 8
                  ) -> tuple[IntArray, float]:
    """Rows of ``mask`` whose local spacing is at least ``factor`` x ``spacing``.

    The local spacing of a point is the distance to its ``k``-th nearest neighbour among
    *all* points, so the stray edge points of a dense surface are not sparse. Used for
    the coarse stage's sparse pass: far surfaces of a terrestrial scan, several times
    sparser than the ground that sets ``eps``, are left unsegmented by the first pass.

    Returns
    -------
    rows : ndarray of int64
        The sparse rows, ascending.
    median : float
        Their median local spacing (0.0 when there are none).

    Examples
    --------
    >>> dense = np.c_[np.arange(100) * 0.1, np.zeros(100), np.zeros(100)]
    >>> sparse = np.c_[np.arange(20) * 1.0 + 50, np.zeros(20), np.zeros(20)]
    >>> rows, med = sparse_points(np.r_[dense, sparse], np.arange(120) % 2 == 0, 0.1, 3.0, k=2)
    >>> rows.min(), len(rows), med
    (np.int64(100), 10, 1.0)
    """
    p = _as_xyz(xyz, "sparse_points")
    rows = np.flatnonzero(np.asarray(mask, dtype=bool).reshape(-1))
    if len(rows) == 0 or len(p) <= k:
        return rows[:0].astype(np.int64), 0.0
    # A bounded query first: a dense point stops at the bound, and only the sparse
    # points (a minority) need their exact spacing, for the median.
    tree = cKDTree(p, balanced_tree=False)
    bound = factor * spacing
    d = tree.query(p[rows], k=k + 1, distance_upper_bound=bound, workers=task_threads(rows=len(rows)))[0][:, k]
    keep = ~(d < bound)
    if not keep.any():
        return rows[:0].astype(np.int64), 0.0
    d_sparse = tree.query(p[rows[keep]], k=k + 1, workers=task_threads(rows=int(keep.sum())))[0][:, k]
    return rows[keep].astype(np.int64), float(np.median(d_sparse))
