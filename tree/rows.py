"""Arcades are rows of bays: the completion after the tree and the merge (tree-v15).

The tree cuts an arcade into bays one element group at a time, and where a bay's cut
goes wrong the bay comes out as a piece: its intrados alone, with its pier faces left in
the wall (about a third of the bay's points, IoU 0.3), or nothing at all (its faces in the
facade's plane and its intrados in no instance), or the last bay together with the end
wall beside it (IoU 0.46). Its neighbours are usually right, and an arcade is periodic:
the bays of one row share their base, their top, the wall's line and the pitch. So, after
the merge across groups (tree/merge.py):

1. **Rows.** Arch instances (a sample of each one's points, :func:`instance_sample`)
   whose horizontal axes are parallel (``|cos| >= ROW_PARALLEL``), whose centres lie on
   one line (``ROW_OFFSET``) within ``ROW_REACH`` of each other and whose bases meet
   (``ROW_BASE``) are linked; a row is a linked set of at least ``ROW_MIN_BAYS`` instances,
   its line fitted through their centres, and it must be straight: at least
   ``ROW_STRAIGHT_SHARE`` of them within ``ROW_STRAIGHT`` of the line (the others leave
   the row). A linked set on no line is the seed of a curved row (tree-v41): the circle
   through its bays' centres, grown over the arch instances whose centres lie near it
   (``ARC_GROW``), axes along its tangent and bases at the seed's (:func:`_arc`), then
   kept within ``ROW_STRAIGHT`` of it; the other storeys of the facade on the same circle
   seed rows of their own, and a straight row with half its bays in a longer curved row
   is a stretch of it. Along a curved row ``t`` is the arc length and ``q`` the distance
   inside the circle, and each cell is stored in its own straight frame, the tangent at
   its middle. Steps 2 and 3 are the same for both.
2. **Pitch and cells.** The pitch is the median spacing of the bays' mid-points along the
   line; a bay at least ``FULL_SHARE`` of the pitch wide is *full*, unless it is under
   ``DEEP_SHARE`` of the wide bays' median depth across the line (one face of a bay,
   tree-v31). Each bay gets a cell
   along the line: up to its neighbour's edge where the neighbour is full and it is not
   (a piece's cell reaches the piers), the mid-point between two edges otherwise, its own
   edge where it is full and its neighbour is a piece. The band across the line and the
   heights are the full bays' (medians of their 2nd/98th and 1st/99th percentiles,
   widened by ``BAND_PAD`` and ``Z_PAD``).
   Pieces of one bay are one first: a piece whose mid-point lies in a full bay is part
   of it, and two neighbouring pieces no wider together than ``PIECES`` pitches are one.
3. **What changes.** The cells partition the row's band (tree-v42):
   - A piece's cell takes the points of the wall, other, pillar, dome and arch classes
     inside it (``PIECE_TAKE``; `take` 2): its pier faces and the band of wall above it,
     to the row's top, as its full neighbours have, and what a neighbour took beyond its
     cell. A full bay's cell takes the wall, dome and arch points inside it
     (``FULL_TAKE``; `take` 3): the pier faces the tree left in the wall, and a
     neighbour's overreach (a storey cut at a plane's edge, not at a pier's middle,
     holds one opening and a sixth of each neighbour); no dome stands in an arcade's
     wall below its top, and HollowNet calls some pieces of bays dome.
   - A gap between two bays of ``k`` pitches (within ``GAP_TOLERANCE``) holds ``k - 1``
     bays: each gets a new instance with a cell of equal share of the gap, unless an arch
     instance a full bay wide already lies in it (a bay the row left out).
   - The first or last bay wider than ``WIDE`` pitches (up to ``WIDE_MAX``, and no taller
     than the row) is cut to one pitch from its inner edge (`trim`): its points beyond the cell go back to the wall (class wall, no
     instance).
   - A dome instance with at least ``ABSORB`` of its points inside a row's cells is no
     instance (HollowNet calls some pieces of bays dome): its points inside the cells join
     their bays like every dome point there, the rest keep class dome with instance 0 (a
     bench on the ground beside the arcade, in one such instance on Wazir Khan seed 2).
   - An arch instance with at least ``ABSORB`` of its points inside a bay's cell (along,
     across and up) is part
     of that bay (:func:`arcade_cells`'s map, applied like the merge map).

Not in the paper, whose tree never sees an arcade as a row. Measured on Wazir Khan (three
seeds, docs/decisions/method.md, "`tree-v15`"), curved rows on the validation seeds
("`tree-v41`"). Pure NumPy.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from hollowtree.classes import ClassId

__all__ = ["ROW_TAKE", "PIECE_TAKE", "FULL_TAKE", "ArcadeCells", "arcade_cells", "apply_cells", "cell_corners", "instance_sample", "SAMPLE_POINTS"]

#: Points sampled from each arch and dome instance for the row analysis (seeded).
SAMPLE_POINTS = 4096
SAMPLE_CLASSES: tuple[int, ...] = (int(ClassId.ARCH), int(ClassId.DOME))
#: Least number of arch instances in a row.
ROW_MIN_BAYS = 3
#: Two bays' horizontal axes are parallel when ``|cos|`` of their angle is at least this.
ROW_PARALLEL = 0.97
#: Largest distance (m) of a bay's centre from the other's line, to link them.
ROW_OFFSET = 0.75
#: Largest distance (m) between two linked bays' centres along the line.
ROW_REACH = 20.0
#: Largest difference of two linked bays' bases (their 1st percentile of z, m).
ROW_BASE = 0.4
#: A row is straight when ``ROW_STRAIGHT_SHARE`` of its bays are within ``ROW_STRAIGHT`` m of its line.
ROW_STRAIGHT = 0.6
ROW_STRAIGHT_SHARE = 0.8
#: A curved row's circle: its radius (m) at least this (neighbouring bays' axes are
#: parallel, ``ROW_PARALLEL``, only when the pitch is under about a quarter of the radius)
#: and at most ``ARC_MAX_RADIUS`` (beyond it the bays are on no circle the fit can tell).
ARC_MIN_RADIUS = 8.0
ARC_MAX_RADIUS = 500.0
#: Rounds of growing a curved row (take the bays within ``ARC_GROW`` m of the circle,
#: refit the circle).
ARC_ROUNDS = 5
ARC_GROW = 2 * ROW_STRAIGHT
#: A bay at least this share of the pitch wide is full, unless it is thin: less deep across
#: the line than ``DEEP_SHARE`` of the wide bays' median depth (one face of a bay, its
#: intrados and other face left in the wall).
FULL_SHARE = 0.85
DEEP_SHARE = 0.5
#: Two neighbouring pieces (bays not full) no wider together than this many pitches are one bay.
PIECES = 1.0
#: Two bays are neighbours when their mid-points are at most this many pitches apart.
NEIGHBOUR = 1.3
#: An end bay wider than ``WIDE`` pitches (and not wider than ``WIDE_MAX``, nor taller than
#: the row's top by ``TALL`` m: a portal is no bay with its end wall) is cut to one pitch.
WIDE = 1.25
WIDE_MAX = 1.6
TALL = 0.5
#: A gap between two bays is ``k`` pitches when within this share of a pitch of ``k``.
GAP_TOLERANCE = 0.2
#: An arch instance with this share of its points in a bay's cell is part of the bay.
ABSORB = 0.6
#: Widening (m) of the full bays' band across the line, and of their heights (below, above).
BAND_PAD = 0.2
Z_PAD = (0.2, 0.05)
#: Points of a cut end bay farther than this (m) beyond its cell go back to the wall.
TRIM_PAD = 0.05
#: Classes whose points a cell takes: a lone piece's (tree/frames.py; `take` 1), a row's
#: piece's or gap's (`take` 2), a row's full bay's (`take` 3).
ROW_TAKE: tuple[int, ...] = (int(ClassId.WALL), int(ClassId.OTHER), int(ClassId.PILLAR), int(ClassId.DOME))
PIECE_TAKE: tuple[int, ...] = (*ROW_TAKE, int(ClassId.ARCH))
FULL_TAKE: tuple[int, ...] = (int(ClassId.WALL), int(ClassId.DOME), int(ClassId.ARCH))
_TAKE = {1: ROW_TAKE, 2: PIECE_TAKE, 3: FULL_TAKE}
_ARCH = int(ClassId.ARCH)
_WALL = int(ClassId.WALL)


@dataclass(frozen=True)
class ArcadeCells:
    """The cells that change labels (one row per cell).

    ``frame``: ``(m, 4)`` the row's origin ``x, y`` and unit direction ``ux, uy`` (store
    coordinates, metres; a curved row's cell: the point of the circle at its middle and the
    tangent there); ``box``: ``(m, 6)`` ``t0, t1`` along the line, ``q0, q1`` across
    it (towards ``(-uy, ux)``), ``z0, z1``; ``instance``: the bay's instance id (merged id;
    a new bay's id is given by the caller, see :func:`arcade_cells`); ``take``: the cell
    takes the ``ROW_TAKE`` (1), ``PIECE_TAKE`` (2) or ``FULL_TAKE`` (3) points inside it
    (0: none); ``trim``: the bay's points outside ``t0 ..
    t1`` (by more than ``TRIM_PAD``) go back to the wall.
    """

    frame: npt.NDArray[np.float64]
    box: npt.NDArray[np.float64]
    instance: npt.NDArray[np.int64]
    take: npt.NDArray[np.int8]
    trim: npt.NDArray[np.bool_]

    def __len__(self) -> int:
        return len(self.instance)

    @classmethod
    def empty(cls) -> ArcadeCells:
        return cls(np.zeros((0, 4)), np.zeros((0, 6)), np.zeros(0, np.int64), np.zeros(0, np.int8), np.zeros(0, bool))

    def to_arrays(self) -> dict[str, npt.NDArray[np.float64]]:
        """One ``(m, 13)`` float64 array (frame, box, instance, take, trim) for the store."""
        return {"cells": np.column_stack([self.frame, self.box, self.instance.astype(np.float64),
                                          self.take.astype(np.float64), self.trim.astype(np.float64)]).reshape(-1, 13)}

    @classmethod
    def from_array(cls, a: npt.ArrayLike) -> ArcadeCells:
        a = np.asarray(a, dtype=np.float64).reshape(-1, 13)
        return cls(a[:, :4].copy(), a[:, 4:10].copy(), a[:, 10].astype(np.int64), a[:, 11].astype(np.int8), a[:, 12] > 0)


def instance_sample(xyz: npt.ArrayLike, instance: npt.ArrayLike, class_id: npt.ArrayLike,
                    rng: np.random.Generator, *, n: int = SAMPLE_POINTS, classes: tuple[int, ...] = SAMPLE_CLASSES
                    ) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.float32], npt.NDArray[np.float32],
                               npt.NDArray[np.uint8]]:
    """A seeded sample of at most ``n`` points of every instance of ``classes`` (arch and
    dome): ``(instance, xyz (k, 3), weight, class)``, the weight being the instance's points
    per sampled point.

    >>> xyz = np.arange(30, dtype=float).reshape(10, 3)
    >>> inst, pts, w, c = instance_sample(xyz, [1] * 6 + [2] * 4, [4] * 6 + [2] * 4, np.random.default_rng(0), n=3)
    >>> inst.tolist(), pts.shape, w.tolist(), c.tolist()
    ([1, 1, 1], (3, 3), [2.0, 2.0, 2.0], [4, 4, 4])
    """
    xyz = np.asarray(xyz)
    instance = np.asarray(instance).astype(np.int64)
    class_id = np.asarray(class_id)
    sel = np.flatnonzero(np.isin(class_id, classes) & (instance > 0))
    out_i, out_p, out_w, out_c = [], [], [], []
    if len(sel):
        order = sel[np.argsort(instance[sel], kind="stable")]
        ids, starts, counts = np.unique(instance[order], return_index=True, return_counts=True)
        for i, a, c in zip(ids.tolist(), starts.tolist(), counts.tolist(), strict=True):
            rows = order[a:a + c]
            if c > n:
                rows = np.sort(rng.choice(rows, n, replace=False))
            out_i.append(np.full(len(rows), i, np.int64))
            out_p.append(xyz[rows].astype(np.float32))
            out_w.append(np.full(len(rows), c / len(rows), np.float32))
            out_c.append(class_id[rows].astype(np.uint8))
    if not out_i:
        return np.zeros(0, np.int64), np.zeros((0, 3), np.float32), np.zeros(0, np.float32), np.zeros(0, np.uint8)
    return np.concatenate(out_i), np.concatenate(out_p), np.concatenate(out_w), np.concatenate(out_c)


def _wpct(v: npt.NDArray[np.float64], w: npt.NDArray[np.float64], q: float) -> float:
    """Weighted percentile ``q`` (0..100) of ``v``."""
    o = np.argsort(v, kind="stable")
    cw = np.cumsum(w[o])
    return float(v[o][min(int(np.searchsorted(cw, q / 100.0 * cw[-1])), len(v) - 1)])


@dataclass
class _Bay:
    id: int
    pts: npt.NDArray[np.float64]
    w: npt.NDArray[np.float64]
    c: npt.NDArray[np.float64]
    u: npt.NDArray[np.float64]
    zmin: float
    zmax: float


def _bay(i: int, pts: npt.NDArray[np.float64], w: npt.NDArray[np.float64]) -> _Bay:
    xy = pts[:, :2]
    c = np.array([_wpct(xy[:, 0], w, 50), _wpct(xy[:, 1], w, 50)])
    d = xy - c
    cov = (d * w[:, None]).T @ d / w.sum()
    u = np.linalg.eigh(cov)[1][:, 1]
    if u[0] < 0 or (abs(u[0]) < 1e-12 and u[1] < 0):
        u = -u
    return _Bay(i, pts, w, c, u, _wpct(pts[:, 2], w, 1), _wpct(pts[:, 2], w, 99))


def _rows(bays: list[_Bay]) -> list[list[_Bay]]:
    n = len(bays)
    parent = list(range(n))

    def find(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for a in range(n):
        A = bays[a]
        na = np.array([-A.u[1], A.u[0]])
        for b in range(a + 1, n):
            B = bays[b]
            d = B.c - A.c
            if (abs(float(A.u @ B.u)) >= ROW_PARALLEL and abs(float(d @ na)) <= ROW_OFFSET
                    and abs(A.zmin - B.zmin) <= ROW_BASE and abs(float(d @ A.u)) <= ROW_REACH):
                parent[find(a)] = find(b)
    groups: dict[int, list[_Bay]] = {}
    for k in range(n):
        groups.setdefault(find(k), []).append(bays[k])
    return [g for g in groups.values() if len(g) >= ROW_MIN_BAYS]


@dataclass(frozen=True)
class _Line:
    """A straight row: ``t`` along ``u`` from ``o``, ``q`` across it (towards ``(-uy, ux)``)."""

    o: npt.NDArray[np.float64]
    u: npt.NDArray[np.float64]

    def tq(self, xy: npt.NDArray[np.float64]) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        d = xy - self.o
        return d @ self.u, d @ np.array([-self.u[1], self.u[0]])

    def frame(self, t0: float, t1: float) -> tuple[list[float], float]:
        """The store frame of a cell ``t0 .. t1`` and the shift of its ``t`` in that frame."""
        return [float(self.o[0]), float(self.o[1]), float(self.u[0]), float(self.u[1])], 0.0


@dataclass(frozen=True)
class _Arc:
    """A curved row on a circle (centre ``c``, radius ``r``): ``t`` the arc length from the
    angle ``a0`` (counter-clockwise), ``q`` the distance inside the circle."""

    c: npt.NDArray[np.float64]
    r: float
    a0: float

    def tq(self, xy: npt.NDArray[np.float64]) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        d = xy - self.c
        a = np.mod(np.arctan2(d[:, 1], d[:, 0]) - self.a0, 2 * np.pi)
        return self.r * a, self.r - np.hypot(d[:, 0], d[:, 1])

    def frame(self, t0: float, t1: float) -> tuple[list[float], float]:
        """A cell's own straight frame: the circle's tangent at the cell's middle ``tm``
        (so ``t - tm`` and ``q`` hold in it to ``w**2 / 8r``, a centimetre for a 5 m cell
        on a 30 m circle)."""
        tm = 0.5 * (t0 + t1)
        a = self.a0 + tm / self.r
        return ([float(self.c[0] + self.r * np.cos(a)), float(self.c[1] + self.r * np.sin(a)),
                 float(-np.sin(a)), float(np.cos(a))], tm)


def _circle(xy: npt.NDArray[np.float64]) -> tuple[npt.NDArray[np.float64], float] | None:
    """The least-squares circle through points ``xy`` (algebraic fit); None when they are on
    no circle of at most ``ARC_MAX_RADIUS``."""
    if len(xy) < 3:
        return None
    m = xy.mean(axis=0)
    d = xy - m
    sol, *_ = np.linalg.lstsq(np.column_stack([2 * d, np.ones(len(d))]), (d ** 2).sum(axis=1), rcond=None)
    r2 = float(sol[2] + sol[0] ** 2 + sol[1] ** 2)
    if not np.isfinite(r2) or r2 <= 0 or r2 > ARC_MAX_RADIUS ** 2:
        return None
    return m + sol[:2], float(np.sqrt(r2))


def _on_arc(bays: list[_Bay], c: npt.NDArray[np.float64], r: float, base: float | None,
            tol: float = ROW_STRAIGHT) -> list[_Bay]:
    """The bays on the circle: centre within ``tol`` of it, axis along its tangent
    (``ROW_PARALLEL``), base within ``ROW_BASE`` of ``base`` (any base when None)."""
    out = []
    for b in bays:
        d = b.c - c
        rad = float(np.hypot(*d))
        if rad <= 0 or abs(rad - r) > tol or (base is not None and abs(b.zmin - base) > ROW_BASE):
            continue
        if abs(float(b.u @ np.array([-d[1], d[0]]))) / rad >= ROW_PARALLEL:
            out.append(b)
    return out


def _arc(seed: list[_Bay], free: list[_Bay]) -> tuple[list[_Bay], _Arc] | None:
    """A curved row grown from ``seed`` (bays on no straight line): the circle through
    their centres, the ``free`` bays near it (within ``ARC_GROW``: a short seed's circle is
    off by metres), the circle refitted through those, until the bays stay the same (at
    most ``ARC_ROUNDS`` times); then the bays within ``ROW_STRAIGHT`` of the last circle,
    and the circle through them. A row when it holds at least
    ``ROW_MIN_BAYS`` bays, its radius is at least ``ARC_MIN_RADIUS`` and it bends: its bays
    are on no line (the arc's sagitta over them above ``ROW_STRAIGHT``)."""
    base = float(np.median([b.zmin for b in seed]))
    fit = _circle(np.array([b.c for b in seed]))
    row: list[_Bay] = []
    for _ in range(ARC_ROUNDS):
        if fit is None:
            return None
        grown = _on_arc(free, *fit, base, ARC_GROW)
        if len(grown) < ROW_MIN_BAYS:
            return None
        same = {b.id for b in grown} == {b.id for b in row}
        row = grown
        if same:
            break
        fit = _circle(np.array([b.c for b in row]))
    if fit is not None:
        row = _on_arc(row, *fit, base)
        fit = _circle(np.array([b.c for b in row]))
    if fit is None or fit[1] < ARC_MIN_RADIUS:
        return None
    c, r = fit
    row = _on_arc(row, c, r, base)
    if len(row) < ROW_MIN_BAYS:
        return None
    ang = np.sort(np.mod([np.arctan2(b.c[1] - c[1], b.c[0] - c[0]) for b in row], 2 * np.pi))
    gaps = np.diff(np.r_[ang, ang[0] + 2 * np.pi])
    k = int(np.argmax(gaps))
    span = 2 * np.pi - float(gaps[k])
    if r * (1 - np.cos(min(span, np.pi) / 2)) <= ROW_STRAIGHT:
        return None  # on a line: a straight row's business
    return row, _Arc(c, r, float(ang[k] + 0.5 * gaps[k]))  # the seam in the widest gap between bays


def _lines(bays: list[_Bay]) -> list[tuple[list[_Bay], _Line | _Arc]]:
    """The rows and their lines: straight rows of linked bays, and curved rows grown from
    the linked sets on no straight line. A straight row with half its bays in a longer
    curved row is a stretch of that curve (three bays of a 30 m circle are straight to
    0.5 m), and gives way to it."""
    lines: list[tuple[list[_Bay], _Line | _Arc]] = []
    bent: list[list[_Bay]] = []
    for row in _rows(bays):
        u = np.mean([b.u * np.sign(b.u @ row[0].u) for b in row], axis=0)
        u /= np.linalg.norm(u)
        cm = np.array([b.c for b in row])
        o = cm.mean(axis=0)
        fit = np.linalg.eigh(np.cov((cm - o).T))[1][:, 1]
        fit = fit * np.sign(fit @ u)
        if np.ptp((cm - o) @ fit) > 6.0 and abs(float(fit @ u)) >= ROW_PARALLEL:
            u = fit  # the line through the bays' centres, when they spread along it
        nrm = np.array([-u[1], u[0]])
        off = (cm - o) @ nrm
        near = np.abs(off - np.median(off)) <= ROW_STRAIGHT
        if near.mean() < ROW_STRAIGHT_SHARE or near.sum() < ROW_MIN_BAYS:
            bent.append(row)  # a curved arcade, or bays on no one line
            continue
        lines.append(([b for b, k in zip(row, near, strict=True) if k], _Line(o, u)))
    arcs: list[tuple[list[_Bay], _Arc]] = []
    taken: set[int] = set()
    seeds = sorted(bent, key=len, reverse=True)
    while seeds:
        seed = seeds.pop(0)
        if any(b.id in taken for b in seed):
            continue
        grown = _arc(seed, [b for b in bays if b.id not in taken])
        if grown is None:
            continue
        arcs.append(grown)
        taken |= {b.id for b in grown[0]}
        # the storeys of a curved facade share its circle: bays on it at other bases seed rows
        circle = grown[1]
        on = sorted(_on_arc([b for b in bays if b.id not in taken], circle.c, circle.r, None), key=lambda b: b.zmin)
        level: list[_Bay] = []
        for b in [*on, None]:
            if b is not None and (not level or b.zmin - level[0].zmin <= ROW_BASE):
                level.append(b)
                continue
            if len(level) >= ROW_MIN_BAYS:
                seeds.insert(0, level)
            level = [b] if b is not None else []
    out = [(row, line) for row, line in lines
           if not any(2 * len({b.id for b in row} & {b.id for b in curve}) >= len(row) and len(curve) > len(row)
                      for curve, _ in arcs)]
    used = {b.id for row, _ in out for b in row}
    for curve, circle in arcs:
        kept = [b for b in curve if b.id not in used]
        if len(kept) >= ROW_MIN_BAYS:
            out.append((kept, circle))
    return out


def arcade_cells(samples: Mapping[int, tuple[npt.ArrayLike, npt.ArrayLike]], next_id: int,
                 domes: Mapping[int, tuple[npt.ArrayLike, npt.ArrayLike]] | None = None
                 ) -> tuple[ArcadeCells, dict[int, int]]:
    """The cells of every straight row of arch instances, and the instances absorbed.

    Parameters
    ----------
    samples : mapping ``instance id -> (xyz (k, 3), weight (k,))``
        A sample of every arch instance's points (store coordinates, metres) and the
        points each sampled point stands for (:func:`instance_sample`).
    next_id : int
        The id of the first new bay (gaps); the next ones follow.
    domes : mapping, optional
        The same for dome instances: one with ``ABSORB`` of its points in a row's cells is
        no instance (maps to 0; pieces of bays HollowNet calls dome).

    Returns
    -------
    cells : ArcadeCells
        Only cells that may change something (`take` or `trim`).
    absorbed : dict
        ``instance -> bay instance`` for arch instances mostly inside a bay's cell, and
        ``dome instance -> 0`` for dome instances mostly inside a row's cells.
    """
    bays = [_bay(int(i), np.asarray(p, dtype=np.float64).reshape(-1, 3), np.asarray(w, dtype=np.float64))
            for i, (p, w) in sorted(samples.items()) if len(np.asarray(w))]
    frames: list[list[float]] = []
    boxes: list[list[float]] = []
    ids: list[int] = []
    takes: list[int] = []
    trims: list[bool] = []
    absorbed: dict[int, int] = {}
    for row, line in _lines(bays):
        ext = []
        for b in row:
            t, q = line.tq(b.pts[:, :2])
            ext.append((_wpct(t, b.w, 1), _wpct(t, b.w, 99), _wpct(q, b.w, 2), _wpct(q, b.w, 98)))
        order = np.argsort([lo + hi for lo, hi, _, _ in ext], kind="stable")
        row = [row[k] for k in order]
        ext = [ext[k] for k in order]
        mids = np.array([(lo + hi) / 2 for lo, hi, _, _ in ext])
        widths = np.array([hi - lo for lo, hi, _, _ in ext])
        pitch = float(np.median(np.diff(mids)))
        if pitch <= 0:
            continue
        depths = np.array([q1 - q0 for _, _, q0, q1 in ext])
        wide = widths >= FULL_SHARE * pitch
        if wide.sum() < 2:
            continue
        deep = DEEP_SHARE * float(np.median(depths[wide]))
        full = wide & (depths >= deep)
        if full.sum() < 2:
            continue
        # Pieces of one bay: a piece whose mid-point lies in a full bay is part of it, and
        # two neighbouring pieces that together are no wider than a pitch are one.
        keep = [True] * len(row)
        for k in np.flatnonzero(~full).tolist():
            host = [j for j in np.flatnonzero(full).tolist() if ext[j][0] <= mids[k] <= ext[j][1]]
            if host:
                absorbed[row[k].id] = row[host[0]].id
                keep[k] = False
        k = 0
        while k < len(row) - 1:
            j = k + 1
            while j < len(row) and not keep[j]:
                j += 1
            if (j < len(row) and keep[k] and not full[k] and not full[j]
                    and max(ext[k][1], ext[j][1]) - min(ext[k][0], ext[j][0]) <= PIECES * pitch):
                absorbed[row[j].id] = row[k].id
                ext[k] = (min(ext[k][0], ext[j][0]), max(ext[k][1], ext[j][1]), min(ext[k][2], ext[j][2]),
                          max(ext[k][3], ext[j][3]))
                keep[j] = False
                continue
            k = j
        row = [b for b, k in zip(row, keep, strict=True) if k]
        ext = [e for e, k in zip(ext, keep, strict=True) if k]
        mids = np.array([(lo + hi) / 2 for lo, hi, _, _ in ext])
        widths = np.array([hi - lo for lo, hi, _, _ in ext])
        full = (widths >= FULL_SHARE * pitch) & (np.array([q1 - q0 for _, _, q0, q1 in ext]) >= deep)
        fb = [k for k in range(len(row)) if full[k]]
        q0 = float(np.median([ext[k][2] for k in fb])) - BAND_PAD
        q1 = float(np.median([ext[k][3] for k in fb])) + BAND_PAD
        z0 = float(np.median([b.zmin for b in row])) - Z_PAD[0]
        z1 = float(np.median([row[k].zmax for k in fb])) + Z_PAD[1]
        cells: list[tuple[int, float, float, int, bool]] = []  # id (0 = new), t0, t1, take, trim
        last = len(row) - 1
        for k, b in enumerate(row):
            lo, hi = ext[k][0], ext[k][1]
            left, right = lo, hi
            if k > 0 and mids[k] - mids[k - 1] <= NEIGHBOUR * pitch:
                p_hi = ext[k - 1][1]
                left = p_hi if full[k - 1] and not full[k] else (lo if full[k] and not full[k - 1] else (p_hi + lo) / 2)
            if k < last and mids[k + 1] - mids[k] <= NEIGHBOUR * pitch:
                n_lo = ext[k + 1][0]
                right = n_lo if full[k + 1] and not full[k] else (hi if full[k] and not full[k + 1] else (hi + n_lo) / 2)
            trim = False
            if (WIDE * pitch < right - left <= WIDE_MAX * pitch and (k == 0 or k == last)
                    and b.zmax <= z1 + TALL):
                if k == 0:
                    left = right - pitch
                else:
                    right = left + pitch
                trim = True
            cells.append((b.id, left, right, 3 if full[k] else 2, trim))
        for k in range(len(row) - 1):
            m = (mids[k + 1] - mids[k]) / pitch
            km = int(round(m))
            if km >= 2 and abs(m - km) <= GAP_TOLERANCE:
                a, z = ext[k][1], ext[k + 1][0]
                w = (z - a) / (km - 1)
                cells += [(0, a + j * w, a + (j + 1) * w, 2, False) for j in range(km - 1)]
        members = {b.id for b in row}
        row_cells: list[tuple[int, float, float]] = []
        for bid, t0, t1, take, trim in cells:
            # arch instances (not bays of the row) mostly inside this cell are part of it
            grabbed = []
            for b in bays:
                if b.id in members or b.id in absorbed:
                    continue
                t, q = line.tq(b.pts[:, :2])
                zz = b.pts[:, 2]
                inside = (t >= t0) & (t < t1) & (q > q0) & (q < q1) & (zz > z0) & (zz < z1)
                if float(b.w[inside].sum()) >= ABSORB * float(b.w.sum()):
                    grabbed.append(b)
            cid = bid
            if bid == 0:
                # a gap that holds a whole bay of its own (one the row left out) is no new bay
                if any(_wpct(t_g, g.w, 99) - _wpct(t_g, g.w, 1) >= FULL_SHARE * pitch
                       for g in grabbed for t_g in (line.tq(g.pts[:, :2])[0],)):
                    continue
                cid = next_id
                next_id += 1
            for g in grabbed:
                absorbed[g.id] = cid
            row_cells.append((cid, t0, t1))
            if take or trim:
                frame, shift = line.frame(t0, t1)
                frames.append(frame)
                boxes.append([t0 - shift, t1 - shift, q0, q1, z0, z1])
                ids.append(cid)
                takes.append(take)
                trims.append(trim)
        for did, (dp, dw) in sorted((domes or {}).items()):
            if did in absorbed or not len(np.asarray(dw)):
                continue
            dp = np.asarray(dp, dtype=np.float64).reshape(-1, 3)
            dw = np.asarray(dw, dtype=np.float64)
            t, q = line.tq(dp[:, :2])
            band = (q > q0) & (q < q1) & (dp[:, 2] > z0) & (dp[:, 2] < z1)
            share = [float(dw[band & (t >= t0) & (t < t1)].sum()) for _, t0, t1 in row_cells]
            if share and sum(share) >= ABSORB * float(dw.sum()):
                absorbed[did] = 0  # no dome instance: its points in the cells join their bays
    if not ids:
        return ArcadeCells.empty(), absorbed
    return (ArcadeCells(np.array(frames), np.array(boxes), np.array(ids, np.int64), np.array(takes, np.int8),
                        np.array(trims)), absorbed)


def cell_corners(frame: npt.ArrayLike, box: npt.ArrayLike) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """The x and y (store coordinates), each ``(m, 4)``, of the corners of cells with
    frames ``frame`` ``(m, 4)`` and boxes ``t0, t1, q0, q1`` ``(m, 4)`` (:class:`ArcadeCells`).

    >>> x, y = cell_corners([[1.0, 2.0, 0.0, 1.0]], [[0.0, 3.0, -1.0, 1.0]])
    >>> x.tolist(), y.tolist()
    ([[2.0, 0.0, 2.0, 0.0]], [[2.0, 2.0, 5.0, 5.0]])
    """
    f = np.asarray(frame, dtype=np.float64).reshape(-1, 4)
    b = np.asarray(box, dtype=np.float64).reshape(-1, 4)
    t, q = b[:, [0, 0, 1, 1]], b[:, [2, 3, 2, 3]]
    ox, oy, ux, uy = (f[:, j:j + 1] for j in range(4))
    return ox + t * ux - q * uy, oy + t * uy + q * ux


def apply_cells(xyz: npt.ArrayLike, class_id: npt.ArrayLike, instance: npt.ArrayLike, cells: ArcadeCells
                ) -> tuple[npt.NDArray[np.uint8], npt.NDArray[np.uint32]]:
    """Class and instance of points (store coordinates) after the cells: a `take` cell's
    ``ROW_TAKE`` (1), ``PIECE_TAKE`` (2) or ``FULL_TAKE`` (3) points inside it join its bay (class arch), a
    `trim` cell's bay points beyond it go back to the wall (class wall, instance 0). All
    trims apply first, then the takes, frame by frame (a straight row has one, a curved row's
    cells each their own), in order; each frame reads only the points inside its cells'
    bounding box (the points sorted by x once).

    >>> cells = ArcadeCells(np.array([[0.0, 0, 1, 0]]), np.array([[0.0, 2, -1, 1, 0, 3]]),
    ...                     np.array([7]), np.array([1], np.int8), np.array([True]))
    >>> xyz = [[0.5, 0, 1], [1.5, 0, 1], [2.5, 0, 1], [1.0, 0, 5]]
    >>> c, i = apply_cells(xyz, [2, 4, 4, 2], [3, 7, 7, 3], cells)
    >>> c.tolist(), i.tolist()
    ([4, 4, 2, 2], [7, 7, 0, 3])
    """
    xyz = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
    cls = np.asarray(class_id).astype(np.uint8, copy=True)
    inst = np.asarray(instance).astype(np.uint32, copy=True)
    if not len(cells) or not len(xyz):
        return cls, inst
    frames, row_of = np.unique(cells.frame, axis=0, return_inverse=True)
    row_of = row_of.reshape(-1)
    for k in np.flatnonzero(cells.trim).tolist():  # trims first: a cut bay's points may lie anywhere
        ox, oy, ux, uy = cells.frame[k]
        t = (xyz[:, 0] - ox) * ux + (xyz[:, 1] - oy) * uy
        t0, t1 = cells.box[k, :2]
        out = (inst == cells.instance[k]) & ((t < t0 - TRIM_PAD) | (t >= t1 + TRIM_PAD))
        cls[out] = _WALL
        inst[out] = 0
    order = np.argsort(xyz[:, 0], kind="stable")  # each frame reads the points of its cells' x range
    xs = xyz[order, 0]
    for r in range(len(frames)):
        ox, oy, ux, uy = frames[r]
        ks = np.flatnonzero(row_of == r)
        ks = ks[cells.take[ks] > 0]
        if not len(ks):
            continue
        box = cells.box[ks]
        cx, cy = cell_corners(cells.frame[ks], box[:, :4])
        lo = int(np.searchsorted(xs, cx.min() - 1e-6, side="left"))
        hi = int(np.searchsorted(xs, cx.max() + 1e-6, side="right"))
        near = order[lo:hi]
        near = near[(xyz[near, 1] >= cy.min() - 1e-6) & (xyz[near, 1] <= cy.max() + 1e-6)
                    & (xyz[near, 2] > box[:, 4].min()) & (xyz[near, 2] < box[:, 5].max())]
        if not len(near):
            continue
        d = xyz[near, :2] - (ox, oy)
        tb, qb, zb = d @ (ux, uy), d @ (-uy, ux), xyz[near, 2]
        for k in ks.tolist():
            t0, t1, q0, q1, z0, z1 = cells.box[k]
            m = (tb >= t0) & (tb < t1) & (qb > q0) & (qb < q1) & (zb > z0) & (zb < z1)
            m &= np.isin(cls[near], _TAKE[int(cells.take[k])])
            cls[near[m]] = _ARCH
            inst[near[m]] = cells.instance[k]
    return cls, inst
