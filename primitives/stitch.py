"""Join per-tile segments across tile borders with a union-find.

Each tile is segmented on its core plus buffer points, so a point near a border has one
copy per tile that holds it. Two tile-local segments that share enough of those points
(and are compatible, e.g. the same primitive type with close parameters) are the same
global segment. Every point then takes the global id of its *core* copy: only the tile
that owns a point decides its label.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from hollowtree.errors import ConfigError

__all__ = ["StitchResult", "UnionFind", "csr_by_segment", "stitch_segments"]

SegmentKey = tuple[int, int]


class UnionFind:
    """Array-based disjoint sets with path compression and union by rank.

    Parameters
    ----------
    n : int
        Number of elements, labelled ``0 .. n-1``; each starts in its own set.

    Notes
    -----
    Memory: two int64 arrays of length ``n`` (16 bytes per element). :meth:`union_pairs`
    and :meth:`find` are vectorised: they loop in NumPy over rounds (a handful in
    practice), never in Python over elements.

    Examples
    --------
    >>> uf = UnionFind(6)
    >>> uf.union_pairs([0, 2, 4], [1, 3, 3])
    >>> uf.find([0, 1, 2, 3, 4, 5]).tolist()
    [0, 0, 2, 2, 2, 5]
    >>> uf.labels().tolist()
    [0, 0, 1, 1, 1, 2]
    """

    def __init__(self, n: int) -> None:
        if not isinstance(n, (int, np.integer)) or isinstance(n, bool) or n < 0:
            raise ConfigError(
                f"The 'n' parameter of UnionFind must be an int in the range [0, inf). "
                f"Got {n!r} instead."
            )
        self.parent = np.arange(int(n), dtype=np.int64)
        self.rank = np.zeros(int(n), dtype=np.int64)

    def __len__(self) -> int:
        return len(self.parent)

    def find(self, x: npt.ArrayLike) -> npt.NDArray[np.int64]:
        """Roots of the elements ``x`` (array), compressing the paths walked."""
        arr = np.asarray(x, dtype=np.int64)
        flat = arr.ravel()
        parent = self.parent
        root = parent[flat]
        while True:
            up = parent[root]
            if np.array_equal(up, root):
                break
            root = up
        out = root.reshape(arr.shape)
        # Path compression: point every element walked directly at its root.
        node = flat
        while node.size:
            nxt = parent[node]
            moving = nxt != node
            parent[node[moving]] = root[moving]
            node, root = nxt[moving], root[moving]
        return out

    def union_pairs(self, a: npt.ArrayLike, b: npt.ArrayLike) -> None:
        """Merge the sets of ``a[i]`` and ``b[i]`` for every ``i`` (vectorised).

        Each round links every root that needs it under the higher-ranked root of one of
        its pairs (ties: the lower index wins and gains a rank); pairs whose roots a round
        could not link (a root may only get one parent per round) are retried.
        """
        xa = np.asarray(a, dtype=np.int64).ravel()
        xb = np.asarray(b, dtype=np.int64).ravel()
        if xa.shape != xb.shape:
            raise ConfigError(
                f"The 'a' and 'b' parameters of UnionFind.union_pairs must have the same "
                f"length. Got {xa.size} and {xb.size} instead."
            )
        n = len(self.parent)
        while xa.size:
            ra, rb = self.find(xa), self.find(xb)
            keep = ra != rb
            ra, rb = ra[keep], rb[keep]
            xa, xb = xa[keep], xb[keep]
            if not ra.size:
                break
            # Total order on roots: (rank, -index). The smaller root becomes the child.
            a_low = (self.rank[ra] < self.rank[rb]) | (
                (self.rank[ra] == self.rank[rb]) & (ra > rb)
            )
            child = np.where(a_low, ra, rb)
            par = np.where(a_low, rb, ra)
            # One parent per child root: the greatest in the order (lexsort: last key first).
            order = np.lexsort((-par, self.rank[par], child))
            child, par = child[order], par[order]
            last = np.r_[child[1:] != child[:-1], True]
            child, par = child[last], par[last]
            tie = self.rank[child] == self.rank[par]
            self.parent[child] = par
            bump = np.zeros(n, dtype=bool)
            bump[par[tie]] = True
            self.rank[bump] += 1

    def labels(self) -> npt.NDArray[np.int64]:
        """Dense set ids ``0 .. n_sets-1`` per element, in order of each set's lowest element."""
        roots = self.find(np.arange(len(self.parent)))
        _, first, inverse = np.unique(roots, return_index=True, return_inverse=True)
        rank_of = np.empty(len(first), dtype=np.int64)
        rank_of[np.argsort(first, kind="stable")] = np.arange(len(first))
        return rank_of[inverse]


@dataclass(frozen=True, kw_only=True)
class StitchResult:
    """Global segment ids after stitching.

    Parameters
    ----------
    labels : ndarray of shape (n_points,)
        Global segment id of each original point (int64): ``1 .. n_segments`` in order of
        each segment's lowest original index, 0 for unsegmented points and for points
        without a core copy.
    keys : ndarray of shape (n_keys, 2)
        The (tile, local label) pairs of all tile-local segments (local label > 0), sorted.
    key_global : ndarray of shape (n_keys,)
        Global id of each key; 0 for a segment none of whose points were kept (a segment
        that only exists in buffers and joined nothing with core points).
    n_segments : int
        Number of global segments ``G``.
    """

    labels: npt.NDArray[np.int64]
    keys: npt.NDArray[np.int64]
    key_global: npt.NDArray[np.int64]
    n_segments: int

    def mapping(self) -> dict[SegmentKey, int]:
        """``{(tile, local): global}`` for every tile-local segment."""
        return {
            (int(t), int(s)): int(g)
            for (t, s), g in zip(self.keys.tolist(), self.key_global.tolist(), strict=True)
        }

    def to_dict(self) -> dict[str, Any]:
        """Plain-list form."""
        return {
            "labels": self.labels.tolist(),
            "keys": self.keys.tolist(),
            "key_global": self.key_global.tolist(),
            "n_segments": self.n_segments,
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> StitchResult:
        """Inverse of :meth:`to_dict`."""
        return cls(
            labels=np.asarray(d["labels"], dtype=np.int64),
            keys=np.asarray(d["keys"], dtype=np.int64).reshape(-1, 2),
            key_global=np.asarray(d["key_global"], dtype=np.int64),
            n_segments=int(d["n_segments"]),
        )


def _int_rows(value: npt.ArrayLike, name: str, m: int | None) -> npt.NDArray[np.int64]:
    arr = np.asarray(value)
    if arr.ndim != 1 or not (np.issubdtype(arr.dtype, np.integer) or arr.size == 0):
        raise ConfigError(
            f"The '{name}' parameter of stitch_segments must be a 1-d int array. "
            f"Got {arr.dtype} of shape {arr.shape} instead."
        )
    if m is not None and len(arr) != m:
        raise ConfigError(
            f"The '{name}' parameter of stitch_segments must have one entry per row ({m}). "
            f"Got {len(arr)} instead."
        )
    return arr.astype(np.int64)


def stitch_segments(
    tile_of_row: npt.ArrayLike,
    local_label_of_row: npt.ArrayLike,
    original_index_of_row: npt.ArrayLike,
    *,
    is_core: npt.ArrayLike,
    compatible: Callable[[SegmentKey, SegmentKey], bool] | None = None,
    min_shared: int = 3,
    n_points: int | None = None,
) -> StitchResult:
    """Join tile-local segments that share points into global segments.

    Parameters
    ----------
    tile_of_row : ndarray of shape (n_rows,)
        Tile id of each point copy (every copy of every point in every tile, buffer
        copies included).
    local_label_of_row : ndarray of shape (n_rows,)
        The copy's segment label within its tile; 0 or -1 means unsegmented, which never
        joins anything.
    original_index_of_row : ndarray of shape (n_rows,)
        Original (global) index of the point the row is a copy of, ``>= 0``.
    is_core : ndarray of shape (n_rows,) of bool
        True for the one copy of each point that lies in its tile's core.
    compatible : callable or None, default=None
        ``compatible((tile_a, local_a), (tile_b, local_b)) -> bool`` vetoes a join (e.g.
        different primitive types). Called once per candidate pair of segments. None
        accepts every pair.
    min_shared : int, default=3
        Least number of shared original points for two segments to join.
    n_points : int or None, default=None
        Length of the output ``labels``; default ``max(original_index_of_row) + 1``.

    Returns
    -------
    StitchResult

    Raises
    ------
    ConfigError
        If the arrays do not match, ``min_shared < 1``, or a point has two core copies.

    Notes
    -----
    Joining is transitive (a chain of tiles joins end to end). Memory: a few int64 arrays
    of length ``n_rows`` (about 100 bytes per row) plus the candidate pairs of copies of
    the same point (one per pair of tiles holding it: at most 6 per point for 4 tiles).

    Examples
    --------
    Tile 0 holds points 0-3 (core 0-1), tile 1 holds points 1-4 (core 2-4); both call the
    shared points segment 1, so they join:

    >>> res = stitch_segments(
    ...     [0, 0, 0, 0, 1, 1, 1, 1],
    ...     [1, 1, 1, 1, 1, 1, 1, 2],
    ...     [0, 1, 2, 3, 1, 2, 3, 4],
    ...     is_core=[True, True, False, False, False, True, True, True],
    ... )
    >>> res.labels.tolist(), res.mapping()
    ([1, 1, 1, 1, 2], {(0, 1): 1, (1, 1): 1, (1, 2): 2})
    """
    tile = _int_rows(tile_of_row, "tile_of_row", None)
    m = len(tile)
    local = _int_rows(local_label_of_row, "local_label_of_row", m)
    orig = _int_rows(original_index_of_row, "original_index_of_row", m)
    core = np.asarray(is_core)
    if core.shape != (m,) or core.dtype != bool:
        raise ConfigError(
            f"The 'is_core' parameter of stitch_segments must be a bool array of shape ({m},). "
            f"Got {core.dtype} of shape {core.shape} instead."
        )
    if not isinstance(min_shared, (int, np.integer)) or isinstance(min_shared, bool) or min_shared < 1:
        raise ConfigError(
            f"The 'min_shared' parameter of stitch_segments must be an int in the range "
            f"[1, inf). Got {min_shared!r} instead."
        )
    if m and orig.min() < 0:
        raise ConfigError(
            "The 'original_index_of_row' parameter of stitch_segments must be >= 0. "
            f"Got {orig.min()} instead."
        )
    size = (int(orig.max()) + 1 if m else 0) if n_points is None else int(n_points)
    if m and size <= orig.max():
        raise ConfigError(
            f"The 'n_points' parameter of stitch_segments must exceed every original index "
            f"({orig.max()}). Got {n_points!r} instead."
        )
    cores_per_point = np.bincount(orig[core], minlength=size)
    if (cores_per_point > 1).any():
        bad = int(np.argmax(cores_per_point > 1))
        raise ConfigError(
            "The 'is_core' parameter of stitch_segments must mark at most one copy of each "
            f"point as core. Got {cores_per_point[bad]} core copies of point {bad} instead."
        )

    # Tile-local segments -> key ids 0..K-1.
    seg = local > 0
    t0 = int(tile[seg].min()) if seg.any() else 0
    span = int(local[seg].max()) + 1 if seg.any() else 1
    packed, key_of_seg = np.unique((tile[seg] - t0) * span + local[seg], return_inverse=True)
    keys = np.stack([packed // span + t0, packed % span], axis=1)
    key_of_row = np.full(m, -1, dtype=np.int64)
    key_of_row[seg] = key_of_seg.ravel()
    n_keys = len(keys)

    # Candidate joins: pairs of segmented copies of the same original point.
    rows = np.flatnonzero(seg)
    rows = rows[np.lexsort((key_of_row[rows], orig[rows]))]
    o, kr = orig[rows], key_of_row[rows]
    pa: list[npt.NDArray[np.int64]] = []
    pb: list[npt.NDArray[np.int64]] = []
    d = 1
    while d < len(rows):
        same = o[d:] == o[:-d]
        if not same.any():
            break
        pa.append(kr[:-d][same])
        pb.append(kr[d:][same])
        d += 1
    uf = UnionFind(n_keys)
    if pa:
        a, b = np.concatenate(pa), np.concatenate(pb)
        differ = a != b
        pair = a[differ] * n_keys + b[differ]
        uniq, count = np.unique(pair, return_counts=True)
        uniq = uniq[count >= min_shared]
        ka, kb = uniq // n_keys, uniq % n_keys
        if compatible is not None:
            ok = np.array(
                [
                    bool(compatible((int(keys[i, 0]), int(keys[i, 1])), (int(keys[j, 0]), int(keys[j, 1]))))
                    for i, j in zip(ka.tolist(), kb.tolist(), strict=True)
                ],
                dtype=bool,
            )
            ka, kb = ka[ok], kb[ok]
        uf.union_pairs(ka, kb)
    root = uf.find(np.arange(n_keys))

    # Per point, from its core copy; then dense ids by lowest original index.
    labels = np.zeros(size, dtype=np.int64)
    kept = core & seg
    point_root = np.full(size, -1, dtype=np.int64)
    point_root[orig[kept]] = root[key_of_row[kept]]
    has = np.flatnonzero(point_root >= 0)  # ascending original index
    roots_in_order, first = np.unique(point_root[has], return_index=True)
    by_first = np.argsort(first, kind="stable")
    global_of_root = np.zeros(n_keys, dtype=np.int64)
    global_of_root[roots_in_order[by_first]] = np.arange(1, len(first) + 1)
    labels[has] = global_of_root[point_root[has]]
    return StitchResult(
        labels=labels,
        keys=keys.astype(np.int64),
        key_global=global_of_root[root],
        n_segments=len(first),
    )


def csr_by_segment(
    global_id_per_point: npt.ArrayLike, original_index: npt.ArrayLike | None = None
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """Gather each segment's original indices contiguously (CSR layout).

    Parameters
    ----------
    global_id_per_point : ndarray of shape (n_points,)
        Segment id ``>= 0`` of each point (0 = unsegmented, gathered as segment 0).
    original_index : ndarray of shape (n_points,) or None
        Original index of each point; None means ``arange(n_points)``.

    Returns
    -------
    indices : ndarray of shape (n_points,)
        Original indices grouped by segment, ascending within a segment when
        ``original_index`` is ascending.
    offsets : ndarray of shape (n_segments + 1,)
        Segment ``g``'s points are ``indices[offsets[g]:offsets[g + 1]]``, for
        ``g = 0 .. max(global_id_per_point)``.

    Notes
    -----
    Memory: two int64 arrays of length ``n_points`` plus the offsets.

    Examples
    --------
    >>> indices, offsets = csr_by_segment([2, 0, 1, 2, 1, 0])
    >>> indices.tolist(), offsets.tolist()
    ([1, 5, 2, 4, 0, 3], [0, 2, 4, 6])
    >>> indices[offsets[2]:offsets[3]].tolist()
    [0, 3]
    """
    gid = np.asarray(global_id_per_point)
    if gid.ndim != 1 or not (np.issubdtype(gid.dtype, np.integer) or gid.size == 0) or (gid.size and gid.min() < 0):
        raise ConfigError(
            "The 'global_id_per_point' parameter of csr_by_segment must be a 1-d array of "
            f"ints >= 0. Got {gid.dtype} of shape {gid.shape} instead."
        )
    gid = gid.astype(np.int64)
    if original_index is None:
        orig = np.arange(len(gid), dtype=np.int64)
    else:
        orig = np.asarray(original_index, dtype=np.int64)
        if orig.shape != gid.shape:
            raise ConfigError(
                "The 'original_index' parameter of csr_by_segment must have the shape of "
                f"'global_id_per_point' {gid.shape}. Got {orig.shape} instead."
            )
    order = np.argsort(gid, kind="stable")
    counts = np.bincount(gid, minlength=int(gid.max()) + 1 if gid.size else 1)
    offsets = np.zeros(len(counts) + 1, dtype=np.int64)
    np.cumsum(counts, out=offsets[1:])
    return orig[order], offsets
