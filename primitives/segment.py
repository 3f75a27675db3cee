"""The coarse segmentation of one set of points (paper step 1) and its parameters.

:class:`CoarseParams` holds every parameter of the coarse stage. :func:`segment_points`
runs PCA normals, Efficient RANSAC and DBSCAN on one set of points, and once more at a
coarser scale on the sparse points the first pass left unsegmented; :func:`segment_tile`
runs it on a tile, cut into x-y blocks (:func:`block_inputs`, :func:`segment_block`,
:func:`join_blocks`) when the tile holds more than ``block_points`` points.
:func:`same_primitive` tells whether two segments' fits are one primitive (the stitch
across tiles and blocks). ``pipeline/coarse.py`` runs these per tile as Dask tasks.

Pure NumPy/SciPy and the numba kernels of this package.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Iterator
from dataclasses import replace
from typing import Any

import numpy as np

from hollowtree.primitives.blocks import block_context, split_blocks
from hollowtree.primitives.coarse_params import CoarseParams
from hollowtree.primitives.dbscan import dbscan_segments, sparse_points
from hollowtree.primitives.group import segment_contacts
from hollowtree.primitives.normals import estimate_normals
from hollowtree.primitives.ransac import efficient_ransac
from hollowtree.primitives.stitch import UnionFind

__all__ = ["CONTEXT_FACTOR", "PRIMITIVE_CODES", "CoarseParams", "block_inputs", "join_blocks", "join_passes",
           "same_primitive", "segment_block", "segment_points", "segment_tile"]

#: Primitive type codes stored per point (0 = no primitive).
PRIMITIVE_CODES = {"plane": 1, "sphere": 2, "cylinder": 3, "cone": 4, "torus": 5}


#: The cell, metres, in which ``free_min_cells`` counts the extent of a small free cluster
#: (the tree's occupancy cell).
FREE_CELL = 0.1


def segment_points(xyz: np.ndarray, params: CoarseParams, eps: float, rng: np.random.Generator,
                    *, sparse_pass: bool = True, normals: tuple[np.ndarray, np.ndarray] | None = None,
                    ) -> tuple[np.ndarray, list[dict[str, Any]], np.ndarray]:
    """Normals, Efficient RANSAC and DBSCAN on one set of points, then (``sparse_factor``)
    once more, at a coarser scale, on the sparse points the first pass left unsegmented.

    ``normals``: the points' normals and which have one, computed before
    (:func:`~hollowtree.primitives.normals.estimate_normals` with ``k``, in parts as
    ``pipeline/coarse.py`` does); None computes them here.

    Returns the segment of every point (``1..S``, 0 = unsegmented), the fit of every
    segment (``fits[s - 1]``: ``kind``, ``params`` as a JSON list, ``rms``; kind
    ``"free"`` for a cluster of points no primitive explains) and which points have no
    normal.
    """
    n = len(xyz)
    labels: np.ndarray | None = None  # made after the search where it found nothing to label
    prims: tuple[Any, ...] = ()
    no_normal = np.zeros(n, dtype=bool)
    if n:
        if normals is None:
            nr = estimate_normals(xyz, k=params.k)
            nrm, valid = nr.normals, nr.valid
            del nr  # the curvature is not used here: 8 bytes a point less during the search
        else:
            nrm, valid = normals
            normals = None  # held once, as nrm
        no_normal = ~valid
        if valid.sum() >= params.ransac.min_support:
            # A point without a normal has a zero normal, which efficient_ransac leaves
            # unassigned: the whole arrays give the labels xyz[valid] would, without two
            # copies of the points (48 bytes a point) held through the search.
            res = efficient_ransac(xyz, nrm, **params.ransac.to_dict(), rng=rng)
            labels = res.labels
            prims = res.primitives
        del nrm
    if labels is None:
        labels = np.full(n, -1, dtype=np.int64)
    free = len(prims)  # the group of points no primitive explains
    groups = np.where(labels < 0, free if params.free_segments else -1, labels)
    segment = dbscan_segments(xyz, groups, eps=eps, min_samples=params.min_samples) if n else np.zeros(0, np.int64)
    segment = segment.astype(np.int64, copy=False)
    if params.free_segments and n:
        in_free = (groups == free) & (segment > 0)
        small = small_free_clusters(xyz, segment, in_free, params)
        segment[in_free & small[segment]] = 0
    # Dense ids 1..S (DBSCAN may leave gaps after the free filter).
    has = segment > 0
    ids, segment[has] = np.unique(segment[has], return_inverse=True)
    segment[has] += 1
    seg_group = np.zeros(len(ids), dtype=np.int64)
    seg_group[segment[has] - 1] = groups[has]
    fits = [{"kind": "free", "params": "[]", "rms": float("nan")} if g == free else
            {"kind": prims[g].kind, "params": json.dumps(list(prims[g].params)), "rms": float(prims[g].rms)}
            for g in seg_group.tolist()]
    if sparse_pass and params.sparse_factor > 0 and n:
        # Far surfaces of a terrestrial scan are several times sparser than the ground
        # near a station, which sets eps and the bitmap cell: there a second pass with
        # every distance scaled up (docs/method.md, "Sparse second pass").
        spacing = eps / 3.0
        rows, _ = sparse_points(xyz, segment == 0, spacing, params.sparse_factor)
        if len(rows) >= params.free_min_points:
            # One scale for every tile (not the tile's own sparse spacing): tiles of one
            # scan must fit with the same parameters for the stitching to join them.
            f = 2.0 * params.sparse_factor
            r = params.ransac
            sub = replace(params, epsilon=r.epsilon * f, cluster_epsilon=r.cluster_epsilon * f,
                          min_support=max(params.free_min_points, int(r.min_support / f**2)))
            seg2, fits2, _ = segment_points(xyz[rows], sub, eps * f, rng, sparse_pass=False)
            got = seg2 > 0
            n1 = len(fits)
            segment[rows[got]] = seg2[got] + n1
            fits = fits + fits2
            if fits2:
                segment, fits = join_passes(xyz, segment, fits, n1, eps * f, params)
    return segment, fits, no_normal


def small_free_clusters(xyz: np.ndarray, segment: np.ndarray, in_free: np.ndarray,
                        params: CoarseParams) -> np.ndarray:
    """Which DBSCAN clusters of free points (``segment`` ids, ``in_free`` marking their
    points) stay unsegmented: those under ``free_min_points`` points that also span fewer
    than ``free_min_cells`` cells of :data:`FREE_CELL` metres. A count alone says little
    across densities: 100 points are a shred of wall where a scan is dense and a whole
    pillar where it is sparse; the cells they span tell the two apart.

    >>> xyz = np.c_[np.arange(60) * 0.2, np.zeros(60), np.zeros(60)]  # 12 m, one point a cell
    >>> small_free_clusters(xyz, np.ones(60, np.int64), np.ones(60, bool),
    ...                     CoarseParams(free_min_points=200, free_min_cells=50)).tolist()
    [True, False]
    >>> small_free_clusters(xyz * 0.1, np.ones(60, np.int64), np.ones(60, bool),  # 1.2 m: 12 cells
    ...                     CoarseParams(free_min_points=200, free_min_cells=50)).tolist()
    [True, True]
    """
    sizes = np.bincount(segment[in_free], minlength=int(segment.max(initial=0)) + 1)
    small = sizes < params.free_min_points
    small[0] = True
    rows = np.flatnonzero(in_free & small[segment])
    if params.free_min_cells > 0 and len(rows):
        cells = np.floor(xyz[rows] / FREE_CELL).astype(np.int64)
        spans = np.unique(np.column_stack([segment[rows], cells]), axis=0)[:, 0]
        small &= np.bincount(spans, minlength=len(small)) < params.free_min_cells
        small[0] = True
    return small


def join_passes(xyz: np.ndarray, segment: np.ndarray, fits: list[dict[str, Any]], n1: int, gap: float,
                 params: CoarseParams) -> tuple[np.ndarray, list[dict[str, Any]]]:
    """Join each sparse-pass segment (ids > ``n1``) to the first-pass segments it touches
    (within ``gap``) that are the same primitive: the far, sparse part of a ground plane
    is that plane. Without this, two tiles' stitching would join them where one tile saw
    the part dense and the other sparse, and the answer would depend on the tile size."""
    a, b, _ = segment_contacts(xyz, segment, gap, min_contacts=3)
    cross = (a <= n1) & (b > n1)
    a, b = a[cross], b[cross]
    keep = np.array([same_primitive(fits[i - 1], fits[j - 1], params) for i, j in zip(a.tolist(), b.tolist(),
                                                                                        strict=True)], dtype=bool)
    if not keep.any():
        return segment, fits
    uf = UnionFind(len(fits) + 1)
    uf.union_pairs(a[keep], b[keep])
    root = uf.find(np.arange(len(fits) + 1))
    # Each joined set takes the id and fit of its lowest member (a first-pass segment).
    low = np.full(len(fits) + 1, len(fits) + 1, dtype=np.int64)
    np.minimum.at(low, root, np.arange(len(fits) + 1))
    new_id = low[root]
    live = np.unique(new_id[1:])
    dense = np.zeros(len(fits) + 2, dtype=np.int64)
    dense[live] = np.arange(1, len(live) + 1)
    segment = np.where(segment > 0, dense[new_id[segment]], 0)
    return segment, [fits[i - 1] for i in live.tolist()]


def segment_block(xyz: np.ndarray, rows: np.ndarray, mine: np.ndarray, b: int, params: CoarseParams,
                   eps: float, tile: int, normals: tuple[np.ndarray, np.ndarray] | None = None) -> dict[str, Any]:
    """Segment block ``b`` of a tile with the points within its margin as context.

    ``xyz`` are the context's points (store-local metres), ``rows`` their tile rows and
    ``mine`` which of them block ``b`` owns (:func:`block_inputs`). Returns what the join
    needs (:func:`join_blocks`): the block's own rows and their segments, the segmented
    context rows of other blocks and their segments, the fits and the block's points
    without a normal. ``normals``: as :func:`segment_points` takes them.
    """
    rng = np.random.default_rng(np.random.SeedSequence([params.seed, tile, b]))
    seg, fits, no_normal = segment_points(xyz, params, eps, rng, normals=normals)
    other = ~mine & (seg > 0)
    return {"own_rows": rows[mine], "own_seg": seg[mine], "other_rows": rows[other], "other_seg": seg[other],
            "fits": fits, "n_invalid": int(no_normal[mine].sum())}


#: A block whose context (its own points and those within the margin) holds more than
#: this many times ``block_points`` is cut again (:func:`block_inputs`): a block task's
#: memory follows its context. The 10 M- and 100 M-point benchmarks' largest contexts are
#: 0.98 ``block_points``; at 200 M one block of 2.09 M own points had 2.71 M (1.23).
CONTEXT_FACTOR = 1.2
#: Rows of a tile taken at a time when a block's context is found (a float copy of this many).
PIECE_ROWS = 1 << 20


def block_inputs(xy: np.ndarray, cap: int, margin: float, scale: np.ndarray | None = None
                  ) -> tuple[int, Iterator[tuple[np.ndarray, np.ndarray]]]:
    """The blocks of a tile (:func:`primitives.blocks.split_blocks`) and, for each, its
    context: the tile rows within ``margin`` of the block's rectangle and which of them
    the block owns. ``xy`` are metres, or the store's integer coordinates with their
    ``scale`` (the same blocks and contexts, to the bit). Returns the number of blocks and
    ``(rows, mine)`` per block, each made when it is taken.

    A block whose context holds more than ``CONTEXT_FACTOR * cap`` points (a dense spot
    just outside it) has its own points split again in halves, the first half keeping
    its number and the others numbered after the last block, while it still owns more
    than ``cap / 4`` points.
    """
    block_of, rects = split_blocks(xy, cap, scale)
    s = np.ones(2) if scale is None else np.asarray(scale, dtype=np.float64)[:2]

    def context(rect: np.ndarray) -> np.ndarray:
        # In metres a piece at a time, as xy * scale: no float copy of the tile.
        return np.concatenate([block_context(xy[a:a + PIECE_ROWS, :2].astype(np.float64) * s, rect, margin) + a
                               for a in range(0, len(xy), PIECE_ROWS)] or [np.zeros(0, np.int64)])

    rect_list = list(rects)
    b = 0
    while b < len(rect_list):
        if len(context(rect_list[b])) > CONTEXT_FACTOR * cap:
            own = np.flatnonzero(block_of == b)
            if 4 * len(own) > cap:
                sub_of, sub_rects = split_blocks(xy[own], (len(own) + 1) // 2, scale)
                if len(sub_rects) > 1:
                    for j in range(1, len(sub_rects)):
                        block_of[own[sub_of == j]] = len(rect_list)
                        rect_list.append(sub_rects[j])
                    rect_list[b] = sub_rects[0]
                    continue  # the first half again
        b += 1

    def contexts() -> Iterator[tuple[np.ndarray, np.ndarray]]:
        for b, rect in enumerate(rect_list):
            ctx = context(rect)
            yield ctx, block_of[ctx] == b

    return len(rect_list), contexts()


def join_blocks(n: int, results: Iterable[dict[str, Any]], params: CoarseParams
                 ) -> tuple[np.ndarray, list[dict[str, Any]], int]:
    """Join the blocks' segments over their context points, as tiles are joined over their
    buffers (at least 3 shared points and the same primitive within the tolerances).

    ``results`` are the blocks' results in block order (:func:`segment_block`), taken one
    at a time (a store-backed run reads each when it is needed), so memory follows one
    block and a few bytes per point of the tile. Returns segment per point of the tile
    (int32), fits per segment and points without a normal.
    """
    own_key = np.full(n, -1, dtype=np.int32)  # each point's key: block b's segment s -> base_b + s - 1
    all_fits: list[dict[str, Any]] = []
    shared: list[tuple[np.ndarray, np.ndarray]] = []  # (context key, owner's point index)
    owned_parts: list[np.ndarray] = []  # points owned per key
    first_parts: list[np.ndarray] = []  # lowest owned point per key
    n_invalid = 0
    base = 0
    for r in results:
        n_fits = len(r["fits"])
        rows = np.asarray(r["own_rows"], dtype=np.int64)
        seg = np.asarray(r["own_seg"], dtype=np.int64)
        ok = seg > 0
        rows, local = rows[ok], seg[ok] - 1
        own_key[rows] = base + local
        owned_parts.append(np.bincount(local, minlength=n_fits))
        first = np.full(n_fits, n, dtype=np.int64)
        np.minimum.at(first, local, rows)
        first_parts.append(first)
        shared.append((base + np.asarray(r["other_seg"], dtype=np.int64) - 1,
                       np.asarray(r["other_rows"], dtype=np.int64)))
        all_fits.extend(r["fits"])
        n_invalid += int(r["n_invalid"])
        base += n_fits
    n_keys = base
    uf = UnionFind(n_keys)
    pairs: dict[tuple[int, int], int] = {}
    for ka, pts in shared:
        kb = own_key[pts].astype(np.int64)
        ok = kb >= 0
        lo, hi = np.minimum(ka[ok], kb[ok]), np.maximum(ka[ok], kb[ok])
        u, cnt = np.unique(lo * n_keys + hi, return_counts=True)
        for c_, k_ in zip(u.tolist(), cnt.tolist(), strict=True):
            pr = (c_ // n_keys, c_ % n_keys)
            pairs[pr] = pairs.get(pr, 0) + k_
    sel = [pr for pr, k_ in sorted(pairs.items())
           if k_ >= 3 and same_primitive(all_fits[pr[0]], all_fits[pr[1]], params)]
    if sel:
        arr = np.asarray(sel, dtype=np.int64)
        uf.union_pairs(arr[:, 0], arr[:, 1])
    # Tile segments 1..S: the roots that own points, in order of their lowest point; the
    # fit of each is that of its member with the most owned points.
    root = uf.find(np.arange(n_keys)) if n_keys else np.zeros(0, np.int64)
    owned = np.concatenate(owned_parts) if owned_parts else np.zeros(0, np.int64)
    first = np.full(n_keys, n, dtype=np.int64)
    if n_keys:
        np.minimum.at(first, root, np.concatenate(first_parts))
    live = np.flatnonzero(first < n)
    live = live[np.argsort(first[live], kind="stable")]
    seg_of_root = np.zeros(n_keys, dtype=np.int64)
    seg_of_root[live] = np.arange(1, len(live) + 1)
    seg_of_key = seg_of_root[root].astype(np.int32)
    segment = np.zeros(n, dtype=np.int32)
    has = own_key >= 0
    segment[has] = seg_of_key[own_key[has]]
    best = np.full(n_keys, -1, dtype=np.int64)
    for k in np.argsort(owned, kind="stable").tolist():  # ascending: the largest wins last
        if owned[k]:
            best[root[k]] = k
    fits = [all_fits[int(best[r])] for r in live.tolist()]
    return segment, fits, n_invalid


def segment_tile(xyz: np.ndarray, params: CoarseParams, eps: float, tile: int, margin: float,
                 normals: tuple[np.ndarray, np.ndarray] | None = None,
                 ) -> tuple[np.ndarray, list[dict[str, Any]], int, int]:
    """Segment a tile whole, or block by block when it holds more than ``block_points``.

    A dense tile (near a scanner station it can hold several times the average) is cut
    into x-y blocks of at most ``block_points`` points (:func:`primitives.blocks.split_blocks`),
    each segmented with its context (:func:`segment_block`) and joined
    (:func:`join_blocks`). :func:`run_coarse` runs the blocks of such a tile as tasks of
    their own (:func:`coarse_block`); this in-process loop gives the same answer. Returns
    segment per point, fits per segment, points without a normal and the number of blocks.
    ``normals`` (a tile segmented whole only): as :func:`segment_points` takes them.
    """
    n = len(xyz)
    cap = params.block_points
    if not cap or n <= cap:
        rng = np.random.default_rng(np.random.SeedSequence([params.seed, tile]))
        seg, fits, no_normal = segment_points(xyz, params, eps, rng, normals=normals)
        return seg, fits, int(no_normal.sum()), 1
    n_blocks, inputs = block_inputs(xyz[:, :2], cap, margin)
    results = (segment_block(xyz[rows], rows, mine, b, params, eps, tile) for b, (rows, mine) in enumerate(inputs))
    segment, fits, n_invalid = join_blocks(n, results, params)
    return segment, fits, n_invalid, n_blocks


def same_primitive(a: dict[str, Any], b: dict[str, Any], p: CoarseParams) -> bool:
    """Whether two tiles' fits describe the same primitive (within the tolerances)."""
    if a["kind"] != b["kind"]:
        return False
    if a["kind"] == "free":  # no parameters to compare: shared points decide
        return True
    pa_, pb = np.asarray(json.loads(a["params"])), np.asarray(json.loads(b["params"]))
    cos_tol = math.cos(math.radians(p.angle_tol_deg))
    if a["kind"] == "plane":
        if abs(float(pa_[:3] @ pb[:3])) < cos_tol:
            return False
        sign = 1.0 if float(pa_[:3] @ pb[:3]) > 0 else -1.0
        return abs(pa_[3] - sign * pb[3]) <= p.distance_tol
    if a["kind"] == "sphere":
        return (np.linalg.norm(pa_[:3] - pb[:3]) <= p.distance_tol + p.radius_tol * pa_[3]
                and abs(pa_[3] - pb[3]) <= p.radius_tol * max(pa_[3], pb[3]))
    if a["kind"] == "cylinder":
        axis_a, axis_b = pa_[3:6], pb[3:6]
        if abs(float(axis_a @ axis_b)) < cos_tol:
            return False
        d = pb[:3] - pa_[:3]
        off_axis = np.linalg.norm(d - (d @ axis_a) * axis_a)
        return off_axis <= p.distance_tol + p.radius_tol * pa_[6] and abs(pa_[6] - pb[6]) <= p.radius_tol * max(pa_[6], pb[6])
    if a["kind"] == "torus":  # centre (3), axis (3), major R, minor r
        if abs(float(pa_[3:6] @ pb[3:6])) < cos_tol:
            return False
        return (np.linalg.norm(pa_[:3] - pb[:3]) <= p.distance_tol + p.radius_tol * pa_[6]
                and abs(pa_[6] - pb[6]) <= p.radius_tol * max(pa_[6], pb[6])
                and abs(pa_[7] - pb[7]) <= p.radius_tol * max(pa_[7], pb[7]) + p.distance_tol)
    if a["kind"] == "cone":
        if abs(float(pa_[3:6] @ pb[3:6])) < cos_tol:
            return False
        return np.linalg.norm(pa_[:3] - pb[:3]) <= 5 * p.distance_tol and abs(pa_[6] - pb[6]) <= math.radians(p.angle_tol_deg)
    return False
