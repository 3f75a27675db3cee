"""Contacts between segments: which segments touch, for grouping them into elements.

An architectural element is rarely one primitive: RANSAC cuts an onion dome into sphere
patches and a free cluster, a minaret into cylinder and cone stages and the balconies
between them. :func:`segment_contacts` finds the pairs of segments whose points come
within ``gap`` of each other (counted on a voxel subsample, so a dense scan costs little
more than a sparse one); the coarse stage joins the touching segments that are not large
planes into one element group, the unit the hierarchical tree then splits
(docs/method.md, "Element groups").
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.spatial import cKDTree

from hollowtree.columns import column_max, column_min
from hollowtree.errors import ConfigError
from hollowtree.primitives._validation import as_xyz
from hollowtree.primitives.stitch import UnionFind

__all__ = ["OUTLINE_DIRECTIONS", "SET_IN_MAX_NZ", "STRIP_FACTOR", "box_plane_distance", "join_stacked",
           "large_segments", "outline_add", "outline_plane_distance", "segment_contacts", "segment_contacts_chunked",
           "set_in_plane", "set_in_walls", "stacked_pairs"]

#: A segment's outline in plan (``coarse/tables``' ``outline``): the least and the greatest of
#: ``x cos t + y sin t`` over its points for ``t = k pi / OUTLINE_DIRECTIONS``, a polygon of
#: ``2 x OUTLINE_DIRECTIONS`` sides around them. Unlike the bounding box it turns with the
#: scan: an arch's intrados in a wall at 30 degrees to the axes is as far from the wall as
#: in one along them.
OUTLINE_DIRECTIONS = 16


def _first_per_voxel(v: npt.NDArray[np.int64], segment: npt.NDArray[np.int64]) -> npt.NDArray[np.int64]:
    """Row of the first point of each (voxel, segment) pair, ascending; ``v`` are integer
    voxel coordinates ``(n, 3)``."""
    v = v - column_min(v)
    dims = column_max(v) + 1
    n_seg = int(segment.max()) + 1
    if float(np.prod(dims.astype(np.float64))) * n_seg < 2.0**62:
        key = ((v[:, 0] * dims[1] + v[:, 1]) * dims[2] + v[:, 2]) * n_seg + segment
        _, first = np.unique(key, return_index=True)
    else:  # an extent too large for one int64 key: unique rows (slower, same answer)
        _, first = np.unique(np.c_[v, segment], axis=0, return_index=True)
    return np.sort(first)


def _voxel_representatives(xyz: npt.NDArray[np.float64], segment: npt.NDArray[np.int64], size: float
                           ) -> npt.NDArray[np.int64]:
    """Row of one point (the first) per (voxel of edge ``size``, segment) pair."""
    return _first_per_voxel(np.floor(xyz / size).astype(np.int64), segment)


def _check_gap(gap: float, func: str) -> None:
    if not (np.isfinite(gap) and gap > 0):
        raise ConfigError(f"The 'gap' parameter of {func} must be a float in the range (0.0, inf). "
                          f"Got {gap!r} instead.")


def _contacts(q: npt.NDArray[np.float64], s: npt.NDArray[np.int64], gap: float, min_contacts: int
              ) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """The contacts between representatives ``q`` of segments ``s``."""
    empty = np.zeros(0, dtype=np.int64)
    pairs = cKDTree(q).query_pairs(gap, output_type="ndarray")
    if not len(pairs):
        return empty, empty, empty
    sa, sb = s[pairs[:, 0]], s[pairs[:, 1]]
    other = sa != sb
    lo, hi = np.minimum(sa[other], sb[other]), np.maximum(sa[other], sb[other])
    n_seg = int(s.max()) + 1
    code, count = np.unique(lo * n_seg + hi, return_counts=True)
    keep = count >= min_contacts
    code, count = code[keep], count[keep]
    return code // n_seg, code % n_seg, count.astype(np.int64)


def segment_contacts(
    xyz: npt.ArrayLike, segment: npt.ArrayLike, gap: float, *, min_contacts: int = 3
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """Pairs of segments that touch: points of both within ``gap`` of each other.

    The points of each segment are thinned to one per voxel of edge ``gap / 2`` first;
    a pair of representatives of two segments within ``gap`` is one contact.

    Parameters
    ----------
    xyz : array-like of shape (n, 3)
        Point coordinates (metres).
    segment : array-like of int, shape (n,)
        Segment of each point; 0 = none (ignored).
    gap : float
        Largest distance between two points of touching segments, metres (> 0).
    min_contacts : int
        Pairs with fewer contacts are dropped (a stray point is not a contact).

    Returns
    -------
    a, b, count : ndarrays of int64
        Segment pairs with ``a < b`` in ascending order, and their contact counts.

    Examples
    --------
    >>> x = np.c_[np.linspace(0, 1, 11), np.zeros(11), np.zeros(11)]
    >>> pts = np.r_[x, x + [1.1, 0, 0], x + [5, 0, 0]]
    >>> a, b, n = segment_contacts(pts, np.repeat([1, 2, 3], 11), 0.3, min_contacts=1)
    >>> a.tolist(), b.tolist()
    ([1], [2])
    """
    p = as_xyz(xyz, "segment_contacts")
    seg = np.asarray(segment, dtype=np.int64).reshape(-1)
    if len(seg) != len(p):
        raise ConfigError(f"The 'segment' parameter of segment_contacts must have one entry per point "
                         f"({len(p)}). Got {len(seg)} instead.")
    _check_gap(gap, "segment_contacts")
    empty = np.zeros(0, dtype=np.int64)
    has = np.flatnonzero(seg > 0)
    if len(np.unique(seg[has])) < 2:
        return empty, empty, empty
    p, seg = p[has], seg[has]
    rep = _voxel_representatives(p, seg, gap / 2.0)
    return _contacts(p[rep], seg[rep], gap, min_contacts)


def segment_contacts_chunked(
    chunks: Iterable[tuple[npt.ArrayLike, npt.ArrayLike]], gap: float, *, min_contacts: int = 3
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """:func:`segment_contacts` of the points of ``chunks`` (``(xyz, segment)`` pairs, in
    order) taken together, holding one chunk at a time.

    Each chunk is thinned to its first point per (voxel, segment) pair; the first of those
    over all chunks is the first over all points, so the representatives, their order and
    the answer are those of :func:`segment_contacts` on the concatenated points. Memory
    follows one chunk and the representatives (one per voxel of edge ``gap / 2`` and
    segment), not the number of points.

    Examples
    --------
    >>> x = np.c_[np.linspace(0, 1, 11), np.zeros(11), np.zeros(11)]
    >>> pts, seg = np.r_[x, x + [1.1, 0, 0], x + [5, 0, 0]], np.repeat([1, 2, 3], 11)
    >>> a, b, n = segment_contacts_chunked([(pts[:15], seg[:15]), (pts[15:], seg[15:])], 0.3, min_contacts=1)
    >>> a.tolist(), b.tolist()
    ([1], [2])
    """
    _check_gap(gap, "segment_contacts_chunked")
    size = gap / 2.0
    vs, ss, ps = [], [], []
    for xyz, segment in chunks:
        p = as_xyz(xyz, "segment_contacts_chunked")
        seg = np.asarray(segment, dtype=np.int64).reshape(-1)
        if len(seg) != len(p):
            raise ConfigError(f"The 'segment' parameter of segment_contacts_chunked must have one entry per "
                              f"point of its chunk ({len(p)}). Got {len(seg)} instead.")
        has = np.flatnonzero(seg > 0)
        if not len(has):
            continue
        p, seg = p[has], seg[has]
        v = np.floor(p / size).astype(np.int64)
        first = _first_per_voxel(v, seg)
        vs.append(v[first])
        ss.append(seg[first])
        ps.append(p[first])
    empty = np.zeros(0, dtype=np.int64)
    if not ss or len(np.unique(np.concatenate(ss))) < 2:
        return empty, empty, empty
    v, s, q = np.concatenate(vs), np.concatenate(ss), np.concatenate(ps)
    first = _first_per_voxel(v, s)
    return _contacts(q[first], s[first], gap, min_contacts)


def _unit_normal(normal: npt.ArrayLike, fn: str) -> tuple[np.ndarray, float]:
    """``normal`` as a unit vector, and its length; a clear error naming ``fn`` for a zero one."""
    n = np.asarray(normal, dtype=np.float64).reshape(3)
    norm = float(np.linalg.norm(n))
    if not (np.isfinite(norm) and norm > 0):
        raise ConfigError(f"The 'normal' parameter of {fn} must be a non-zero vector. Got {n.tolist()} instead.")
    return n / norm, norm


def box_plane_distance(boxes: npt.ArrayLike, normal: npt.ArrayLike, d: float) -> npt.NDArray[np.float64]:
    """Largest distance of each axis-aligned box to the plane ``normal . x + d = 0``.

    The distance is linear over a box, so its largest value is at a corner:
    ``|n . c + d| + |n| . h`` for the box's centre ``c`` and half-extents ``h``.

    Parameters
    ----------
    boxes : array-like of shape (m, 6)
        ``xmin, ymin, zmin, xmax, ymax, zmax`` per box.
    normal : array-like of shape (3,)
        The plane's normal (normalised here).
    d : float
        The plane's offset, in the boxes' frame.

    Examples
    --------
    >>> box_plane_distance([[0, 0, 0, 1, 1, 1], [2, 0, 0, 3, 1, 1]], [1, 0, 0], -1.0).tolist()
    [1.0, 2.0]
    """
    b = np.asarray(boxes, dtype=np.float64).reshape(-1, 6)
    n, norm = _unit_normal(normal, "box_plane_distance")
    c = 0.5 * (b[:, :3] + b[:, 3:])
    h = 0.5 * (b[:, 3:] - b[:, :3])
    return np.abs(c @ n + d / norm) + h @ np.abs(n)


def outline_add(lo: np.ndarray, hi: np.ndarray, xy: np.ndarray, seg: np.ndarray) -> None:
    """Grow the outlines ``lo``, ``hi`` (shape ``(n_segments + 1, OUTLINE_DIRECTIONS)``, the
    least and greatest projection per segment and direction) by the points ``xy`` of
    segments ``seg``, in place; :data:`OUTLINE_DIRECTIONS`.

    >>> lo, hi = np.full((2, 4), np.inf), np.full((2, 4), -np.inf)
    >>> outline_add(lo, hi, np.array([[0.0, 0.0], [2.0, 0.0]]), np.array([1, 1]))
    >>> np.round(hi[1], 3).tolist(), np.round(lo[1], 3).tolist()
    ([2.0, 1.414, 0.0, 0.0], [0.0, 0.0, 0.0, -1.414])
    """
    if not len(seg):
        return
    k = lo.shape[1]
    order = np.argsort(seg)  # any order within a segment: min and max do not care
    ss = seg[order]
    starts = np.flatnonzero(np.r_[True, ss[1:] != ss[:-1]])
    ids = ss[starts]
    x, y = xy[order, 0], xy[order, 1]
    for j in range(k):
        t = j * math.pi / k
        p = x * math.cos(t) + y * math.sin(t)
        lo[ids, j] = np.minimum(lo[ids, j], np.minimum.reduceat(p, starts))
        hi[ids, j] = np.maximum(hi[ids, j], np.maximum.reduceat(p, starts))


def outline_plane_distance(outlines: npt.ArrayLike, zlim: npt.ArrayLike, normal: npt.ArrayLike,
                           d: float) -> npt.NDArray[np.float64]:
    """Largest distance to the plane ``normal . x + d = 0`` of each outline (a row of ``k``
    least then ``k`` greatest projections, :func:`outline_add`) extruded over its
    ``zlim`` row ``(zmin, zmax)``: the points lie inside, so none is farther.

    The outline's support in the plane normal's horizontal direction is that of its
    vertex between the two nearest of its ``2k`` edge directions.

    A 2 m piece 0.5 m off a wall along the x axis, and its end 0.5 m off a wall turned 30
    degrees from it:

    >>> lo, hi = np.full((1, 16), np.inf), np.full((1, 16), -np.inf)
    >>> outline_add(lo, hi, np.array([[-1.0, 0.0], [1.0, 0.0]]), np.array([0, 0]))
    >>> o, z = np.hstack([lo, hi]), [[0.0, 3.0]]
    >>> round(float(outline_plane_distance(o, z, [0, 1, 0], 0.5)[0]), 6)
    0.5
    >>> n = [-math.sin(math.radians(30)), math.cos(math.radians(30)), 0]
    >>> round(float(outline_plane_distance(o, z, n, 0.0)[0]), 3)
    0.5
    """
    o = np.asarray(outlines, dtype=np.float64)
    o = o.reshape(-1, o.shape[-1])
    z = np.asarray(zlim, dtype=np.float64).reshape(-1, 2)
    n, norm = _unit_normal(normal, "outline_plane_distance")
    d = d / norm
    k = o.shape[1] // 2
    h = np.concatenate([o[:, k:], -o[:, :k]], axis=1)  # support at angles j pi / k, j < 2k
    step = math.pi / k

    def support(phi: float) -> np.ndarray:
        phi %= 2 * math.pi
        j = min(int(phi // step), 2 * k - 1)
        a = phi - j * step
        return (h[:, j] * math.sin(step - a) + h[:, (j + 1) % (2 * k)] * math.sin(a)) / math.sin(step)

    r = math.hypot(n[0], n[1])
    phi = math.atan2(n[1], n[0])
    zs = n[2] * z
    top = r * support(phi) + zs.max(axis=1) + d
    bottom = -r * support(phi + math.pi) + zs.min(axis=1) + d
    return np.maximum(np.abs(top), np.abs(bottom))


def set_in_plane(boxes: npt.ArrayLike, normal: npt.ArrayLike, d: float, plane_box: npt.ArrayLike,
                 tol: float, outlines: npt.ArrayLike | None = None) -> npt.NDArray[np.bool_]:
    """Whether each box is set in a plane: within ``tol`` of it and inside its box grown by ``tol``.
    With ``outlines`` (one per box, :func:`outline_add`), the distance is the outline's
    (:func:`outline_plane_distance`), not the box's corners'.

    The pieces of an arch set in a facade (its jambs and intrados) lie within the wall's
    thickness of the facade's plane and inside the facade; a minaret or a dome beside it
    does not (docs/method.md, "Element groups").

    Examples
    --------
    >>> wall = [0, 0, 0, 60, 0.05, 7.5]  # a facade in the plane y = 0
    >>> jamb, minaret = [10, 0, 0, 11, 1.0, 3.5], [-5, -2, 0, -1, 2, 33]
    >>> set_in_plane([jamb, minaret], [0, 1, 0], 0.0, wall, 1.5).tolist()
    [True, False]
    """
    if not (np.isfinite(tol) and tol > 0):
        raise ConfigError(f"The 'tol' parameter of set_in_plane must be a float in the range (0.0, inf). "
                          f"Got {tol!r} instead.")
    b = np.asarray(boxes, dtype=np.float64).reshape(-1, 6)
    pb = np.asarray(plane_box, dtype=np.float64).reshape(6)
    inside = np.all(b[:, :3] >= pb[:3] - tol, axis=1) & np.all(b[:, 3:] <= pb[3:] + tol, axis=1)
    if outlines is None:
        return inside & (box_plane_distance(b, normal, d) <= tol)
    return inside & (outline_plane_distance(outlines, b[:, [2, 5]], normal, d) <= tol)


def stacked_pairs(boxes: npt.ArrayLike, gap: float, *, overlap: float = 0.7, area_ratio: float = 3.0
                  ) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """Pairs of boxes stacked one on the other: the upper one starts at most ``gap`` above
    (or 0.3 x ``gap`` below) the top of the lower one, their x-y footprints overlap by at
    least ``overlap`` of the smaller footprint, and the larger footprint is at most
    ``area_ratio`` times the smaller.

    A minaret's balcony overhangs the shaft above it and hides the joint from every
    station, so its stages come out as separate groups about a metre apart, one on the
    other; two elements side by side do not overlap in plan, and a small element over a
    wide piece (a dome over a hall's interior) differs from it in size (docs/method.md,
    "Element groups").

    Parameters
    ----------
    boxes : array-like of shape (m, 6)
        ``xmin, ymin, zmin, xmax, ymax, zmax`` per box.
    gap : float
        Largest vertical gap, metres (> 0).
    overlap : float
        Smallest share of the smaller footprint the two footprints share, in (0, 1].
    area_ratio : float
        Largest ratio of the two footprints' areas (>= 1).

    Returns
    -------
    lower, upper : ndarrays of int64
        Row of the lower and of the upper box of every stacked pair.

    Examples
    --------
    >>> stage1, stage2 = [0, 0, 0, 4, 4, 10], [0.5, 0.5, 10.2, 3.5, 3.5, 16]
    >>> beside = [5, 0, 10.2, 9, 4, 16]
    >>> lo, up = stacked_pairs([stage1, stage2, beside], 1.0)
    >>> lo.tolist(), up.tolist()
    ([0], [1])
    """
    b = np.asarray(boxes, dtype=np.float64).reshape(-1, 6)
    if not (np.isfinite(gap) and gap > 0):
        raise ConfigError(f"The 'gap' parameter of stacked_pairs must be a float in the range (0.0, inf). "
                          f"Got {gap!r} instead.")
    if not (0 < overlap <= 1):
        raise ConfigError(f"The 'overlap' parameter of stacked_pairs must be a float in the range (0.0, 1.0]. "
                          f"Got {overlap!r} instead.")
    if not area_ratio >= 1:
        raise ConfigError(f"The 'area_ratio' parameter of stacked_pairs must be a float in the range [1.0, inf). "
                          f"Got {area_ratio!r} instead.")
    area = np.maximum(b[:, 3] - b[:, 0], 0) * np.maximum(b[:, 4] - b[:, 1], 0)
    lower: list[npt.NDArray[np.int64]] = []
    upper: list[npt.NDArray[np.int64]] = []
    for i in range(len(b)):  # O(m^2) over groups, one vectorised row at a time
        dz = b[:, 2] - b[i, 5]
        cand = np.flatnonzero((dz <= gap) & (dz >= -0.3 * gap) & (b[:, 5] > b[i, 5]))
        if not len(cand):
            continue
        w = np.minimum(b[cand, 3], b[i, 3]) - np.maximum(b[cand, 0], b[i, 0])
        h = np.minimum(b[cand, 4], b[i, 4]) - np.maximum(b[cand, 1], b[i, 1])
        inter = np.maximum(w, 0) * np.maximum(h, 0)
        small, large = np.minimum(area[cand], area[i]), np.maximum(area[cand], area[i])
        ok = (inter >= overlap * small) & (small > 0) & (large <= area_ratio * small)
        lower.append(np.full(int(ok.sum()), i, dtype=np.int64))
        upper.append(cand[ok].astype(np.int64))
    if not lower:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    return np.concatenate(lower), np.concatenate(upper)


def large_segments(kinds: Sequence[str], boxes: npt.ArrayLike, max_plane: float, *,
                   strip_factor: float = 3.0) -> npt.NDArray[np.bool_]:
    """Which segments are too wide to be grouped with their neighbours.

    A plane is large above ``max_plane`` metres of x-y bounding-box diagonal (ground,
    roofs, facades: elements stand on them or in them); a free segment (no primitive)
    above ``strip_factor`` times that: no element is so wide, but the points RANSAC
    leaves along a facade can be one free strip touching everything on it. Cylinders,
    cones and spheres stay groupable at any size: a curved arcade is one
    (docs/method.md, "Element groups").

    Examples
    --------
    >>> boxes = [[0, 0, 0, 30, 1, 8], [0, 0, 0, 10, 10, 6], [0, 0, 0, 41, 4, 11], [0, 0, 0, 28, 3, 20]]
    >>> large_segments(["plane", "free", "free", "cylinder"], boxes, 6.0).tolist()
    [True, False, True, False]
    """
    b = np.asarray(boxes, dtype=np.float64).reshape(-1, 6)
    if len(kinds) != len(b):
        raise ConfigError(f"The 'kinds' parameter of large_segments must have one entry per box ({len(b)}). "
                          f"Got {len(kinds)} instead.")
    if not (np.isfinite(max_plane) and max_plane > 0 and np.isfinite(strip_factor) and strip_factor >= 1):
        raise ConfigError(f"large_segments needs max_plane > 0 and strip_factor >= 1. "
                          f"Got {max_plane!r} and {strip_factor!r} instead.")
    diag = np.hypot(b[:, 3] - b[:, 0], b[:, 4] - b[:, 1])
    plane = np.asarray([k == "plane" for k in kinds], dtype=bool)
    free = np.asarray([k == "free" for k in kinds], dtype=bool)
    return (plane & (diag > max_plane)) | (free & (diag > strip_factor * max_plane))


def join_stacked(uf: UnionFind, large: np.ndarray, box: dict[int, list[float]], gap: float) -> None:
    """Join the element groups stacked one on another (``CoarseParams.group_stack``,
    :func:`primitives.group.stacked_pairs`); groups holding a large segment stay apart."""
    roots = np.asarray(sorted(box), dtype=np.int64)
    if len(roots) < 2:
        return
    g = uf.find(roots)
    gbox: dict[int, np.ndarray] = {}
    has_large: set[int] = set()
    for r, gr in zip(roots.tolist(), g.tolist(), strict=True):
        b = np.asarray(box[r], dtype=np.float64)
        cur = gbox.get(gr)
        gbox[gr] = b if cur is None else np.r_[np.minimum(cur[:3], b[:3]), np.maximum(cur[3:], b[3:])]
        if large[r]:
            has_large.add(gr)
    groups = [gr for gr in sorted(gbox) if gr not in has_large]
    if len(groups) < 2:
        return
    lo, up = stacked_pairs(np.vstack([gbox[gr] for gr in groups]), gap)
    if len(lo):
        ids = np.asarray(groups, dtype=np.int64)
        uf.union_pairs(ids[lo], ids[up])



#: A free segment (no primitive) is large, and never grouped, above this many times
#: ``group_max_plane`` in x-y: no element is that wide, but the leftover points along a
#: facade can be one free strip that touches everything on it.
STRIP_FACTOR = 3.0

#: A large plane takes the segments set in it only when it is a wall: the z component of
#: its unit normal at most this (about 17 degrees from vertical).
SET_IN_MAX_NZ = 0.3


def set_in_walls(ra: np.ndarray, rb: np.ndarray, cnt: np.ndarray, large: np.ndarray, plane: dict[int, Any],
                  box: dict[int, list[float]], offset: np.ndarray, tol: float, *,
                  outline: dict[int, np.ndarray] | None = None) -> dict[int, int]:
    """The wall each stitched segment is set in (``CoarseParams.group_set_in``): a
    segment that touches a large near-vertical plane and lies within ``tol`` of it and
    inside its box (:func:`primitives.group.set_in_plane`; the distance that of its
    ``outline`` where given, in the planes' store-local frame, else of its box); of
    several, the one with most contacts. Such a segment joins that wall and none of its
    other neighbours, so two walls never join through it."""
    one = large[ra] != large[rb]
    small = np.where(large[ra[one]], rb[one], ra[one])
    wall = np.where(large[ra[one]], ra[one], rb[one])
    count: dict[tuple[int, int], int] = {}
    for s_, w, k in zip(small.tolist(), wall.tolist(), cnt[one].tolist(), strict=True):
        count[(s_, w)] = count.get((s_, w), 0) + k
    by_wall: dict[int, list[int]] = {}
    for s_, w in count:
        by_wall.setdefault(w, []).append(s_)
    shift = np.r_[offset, offset]
    best: dict[int, tuple[int, int]] = {}
    for w, smalls in sorted(by_wall.items()):
        fit = json.loads(plane[w]) if isinstance(plane[w], str) else plane[w]
        if len(fit) < 4:
            continue
        normal = np.asarray(fit[:3], dtype=np.float64)
        if abs(normal[2]) > SET_IN_MAX_NZ * float(np.linalg.norm(normal)):
            continue
        smalls = sorted(smalls)
        boxes = np.asarray([box[s_] for s_ in smalls], dtype=np.float64) - shift
        outlines = None if outline is None else np.asarray([outline[s_] for s_ in smalls], dtype=np.float64)
        inside = set_in_plane(boxes, normal, float(fit[3]), np.asarray(box[w], dtype=np.float64) - shift, tol,
                              outlines=outlines)
        for s_, ok in zip(smalls, inside.tolist(), strict=True):
            if ok and count[(s_, w)] > best.get(s_, (-1, -1))[0]:
                best[s_] = (count[(s_, w)], w)
    return {s_: w for s_, (_, w) in sorted(best.items())}
