"""Frames: a portal's face joins its passage, a lone bay's piece takes its piers and its
neighbour bay (tree-v16).

Two failures the rows (tree/rows.py) cannot reach, because they need a row of three:

1. **Faces.** A portal (a pishtaq) is a deep passage in a frame: its face is a plane a
   little wider and taller than the passage, in front of it. The tree sometimes cuts
   the two apart (Wazir Khan's gateway portal: on one seed its face comes out as its
   group's wall, on another as an arch of another element group that touches the
   passage over 0.1 m, too little for the merge's box test, tree/merge.py), and then
   neither covers the portal with IoU 0.5. An instance ``F`` of class wall or arch is the
   face of an arch instance ``A`` when, in ``A``'s frame (its horizontal axis along the
   wall, :func:`tree.rows._bay`): ``F`` is thin across the wall (``FACE_DEPTH``), it
   covers ``A`` along the wall and in height (within ``FACE_PAD``), it is at most
   ``FACE_WIDE`` times as wide as ``A`` (a face is a frame round the passage, not the
   facade the passage opens in), and it lies at the front or back of ``A``
   (``FACE_TOUCH``). ``F`` then joins ``A`` and takes class arch.
2. **Lone pieces.** An arcade's bay is the opening and half the pier on each side. When
   the tree keeps only a bay's intrados (its two jambs and soffit) and leaves its pier
   faces in the facade's wall, and the arcade has fewer than three bays found (Wazir
   Khan's gateway: two bays each side of the portal, one of each pair found as its
   intrados), no row gives the pitch. A *piece* is an arch instance, in no row, at least
   ``PIECE_DEPTH`` deep across its wall (the jambs run through it), whose lower points
   (its lower ``LOW`` of height) lie mostly (``JAMB_SHARE``) within ``JAMB`` of its two
   ends: jambs, no pier faces. It takes its piers when one wall instance holds points
   just outside both its jambs (within ``SIDE``, in the lower band across the wall's
   thickness) and, on at least one side, the wall's lower band breaks off (a gap of at
   least ``GAP``) within one opening width: the next bay's opening. The pier is the wall
   between the jamb and that gap; the piece's cell reaches half of it, and on a side with
   no gap within reach the other side's half pier (an arcade's end bay has a half pier,
   like its inner side). A piece with no such gap on either side stays as it is (a lone
   door in a wall gives no pier width). The cell takes the ``ROW_TAKE`` points (wall,
   other, pillar, dome) inside it, up to the piece's top, like a row's piece (the labels
   stage applies it, :func:`tree.rows.apply_cells`).
3. **Next bays.** The break beside a lone piece's pier is the next bay's opening when the
   wall shows over its first ``NEXT_REACH`` metres at the piece's top (``NEXT_TOP``,
   ``NEXT_COVER``): a shadow (of a minaret in front of the facade) has no wall over it,
   an opening has its arch and the wall band above. It gets a new instance with a cell one
   pitch wide (the piece's opening and its pier) from the middle of that pier, taking the
   same classes, unless an arch instance has ``NEXT_TAKEN`` of its points in the cell (the
   bay is there already) or another piece's next bay lies there. Wazir Khan's inner
   gateway bays stand behind the gateway's minarets: 80 of their 1 539 and 1 575 points
   are intrados, the rest their faces in the facade's wall, and no instance had them.

Not in the paper. Thresholds from the Wazir Khan reference stores (three seeds,
docs/method.md gives the failure behind each). Pure NumPy.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import numpy.typing as npt

from hollowtree.columns import column_max, column_min
from hollowtree.tree.rows import ArcadeCells, _bay, _wpct

__all__ = ["frame_cells", "FACE_DEPTH", "FACE_WIDE", "PIECE_DEPTH", "JAMB_SHARE", "GAP"]

#: A face is at most this thick across the wall (m; 2nd to 98th percentile).
FACE_DEPTH = 1.2
#: A face covers the passage along the wall and in height within this (m).
FACE_PAD = 0.3
#: A face reaches down to this share of the passage's height above its base (2nd percentile).
FACE_LOW = 0.25
#: A face is at most this many times as wide as its passage.
FACE_WIDE = 2.0
#: A face lies within this (m) of the passage's front or back.
FACE_TOUCH = 0.6
#: A piece is at least this deep across its wall (m; 2nd to 98th percentile).
PIECE_DEPTH = 1.0
#: The lower band of a piece: this share of its height above its base.
LOW = 0.4
#: Lower points within this (m) of the piece's two ends are at its jambs ...
JAMB = 0.3
#: ... and at least this share of them are, for a piece.
JAMB_SHARE = 0.8
#: Wall points within this (m) outside a jamb make that side a pier.
SIDE = 0.3
#: Least sampled wall points on each side.
SIDE_POINTS = 3
#: A break of the wall's lower band at least this long (m) is the next opening.
GAP = 0.5
#: The next bay: wall over the break (from this far below the piece's top to this far
#: above it) in at least ``NEXT_COVER`` of its ``NEXT_BIN`` m bins ...
NEXT_TOP = (0.6, 0.4)
#: ... over its first ``NEXT_REACH`` metres makes the break an opening (a shadow beside
#: the opening leaves its start seen; a shadow alone has no wall over it).
NEXT_REACH = 1.0
NEXT_BIN = 0.25
NEXT_COVER = 0.5
#: An arch instance with this share of its points in a next bay's cell is that bay already.
NEXT_TAKEN = 0.3
#: Widening (m) of a piece's cell across the wall, and below and above it.
BAND_PAD = 0.2
Z_PAD = (0.2, 0.05)


def _frame_of(pts: npt.NDArray[np.float64], w: npt.NDArray[np.float64]) -> tuple[np.ndarray, np.ndarray]:
    b = _bay(0, pts, w)
    return b.c, b.u


def _coords(pts: npt.NDArray[np.float64], o: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    d = pts[:, :2] - o
    return d @ u, d @ np.array([-u[1], u[0]])


def _next_gap(t: npt.NDArray[np.float64], start: float, reach: float) -> float | None:
    """Distance from ``start`` (going up ``t``) to the first break of at least ``GAP`` in
    the sorted positions ``t`` beyond it (the end of ``t`` is one), if it begins within
    ``reach``.

    >>> _next_gap(np.array([0.1, 0.3, 0.5, 1.5, 1.7]), 0.0, 2.0), _next_gap(np.array([0.1, 0.3]), 0.0, 2.0)
    (0.5, 0.3)
    """
    t = np.sort(t[t >= start])
    edges = np.r_[start, t, np.inf]
    gaps = np.flatnonzero(np.diff(edges) >= GAP)
    if not len(gaps):
        return None
    at = float(edges[gaps[0]]) - start
    return at if at <= reach else None


def frame_cells(arches: Mapping[int, tuple[npt.ArrayLike, npt.ArrayLike]],
                walls: Mapping[int, tuple[npt.ArrayLike, npt.ArrayLike]],
                skip: set[int] | frozenset[int] = frozenset(), next_id: int | None = None
                ) -> tuple[ArcadeCells, dict[int, int]]:
    """The faces that join their passages and the cells of lone pieces.

    Parameters
    ----------
    arches, walls : mapping ``instance id -> (xyz (k, 3), weight (k,))``
        A sample of every arch and wall instance's points (store coordinates, metres) and
        the points each sampled point stands for (:func:`tree.rows.instance_sample`).
    skip : set of int
        Arch instances in a row (tree/rows.py): neither passages nor pieces.
    next_id : int, optional
        The id of the first next bay (new instances; none without it); the next ones follow.

    Returns
    -------
    cells : ArcadeCells
        One `take` 1 cell per lone piece that takes its piers, then one per next bay.
    joined : dict
        ``face instance -> passage instance``; a face of class wall takes class arch.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> def box(x0, x1, y0, y1, z1, n=2000):
    ...     return np.column_stack([rng.uniform(x0, x1, n), rng.uniform(y0, y1, n), rng.uniform(0, z1, n)])
    >>> passage = np.r_[box(-2.5, -2.4, 0, 3, 9), box(2.4, 2.5, 0, 3, 9)]  # its two jambs
    >>> face = box(-4, 4, 3.0, 3.1, 14)
    >>> cells, joined = frame_cells({1: (passage, np.ones(len(passage)))}, {2: (face, np.ones(len(face)))})
    >>> joined, len(cells)
    ({2: 1}, 0)
    """
    A = {int(i): (np.asarray(p, dtype=np.float64).reshape(-1, 3), np.asarray(w, dtype=np.float64))
         for i, (p, w) in arches.items() if len(np.asarray(w))}
    W = {int(i): (np.asarray(p, dtype=np.float64).reshape(-1, 3), np.asarray(w, dtype=np.float64))
         for i, (p, w) in walls.items() if len(np.asarray(w))}
    joined: dict[int, int] = {}
    box = {k: (column_min(p[:, :3]), column_max(p[:, :3])) for k, (p, _) in (A | W).items()}

    def close(i: int, j: int, pad: float) -> bool:
        return bool(np.all(box[i][0] - pad <= box[j][1]) and np.all(box[j][0] <= box[i][1] + pad))

    info = {}
    for a, (pa, wa) in sorted(A.items()):
        if a in skip:
            continue
        o, u = _frame_of(pa, wa)
        t, q = _coords(pa, o, u)
        ext = (_wpct(t, wa, 1), _wpct(t, wa, 99), _wpct(q, wa, 2), _wpct(q, wa, 98),
               _wpct(pa[:, 2], wa, 1), _wpct(pa[:, 2], wa, 99))
        info[a] = (o, u, t, q, ext)
    # 1. Faces: thin, covering the passage, at most FACE_WIDE as wide, at its front or back.
    for a in sorted(info):
        o, u, _, _, (t0, t1, q0, q1, z0, z1) = info[a]
        width = t1 - t0
        for f, (pf, wf) in sorted({**{k: v for k, v in A.items() if k != a and k not in skip}, **W}.items()):
            if f in joined or f == a or a in joined or not close(a, f, FACE_TOUCH + FACE_PAD):
                continue
            tf, qf = _coords(pf, o, u)
            T0, T1, Q0, Q1 = _wpct(tf, wf, 2), _wpct(tf, wf, 98), _wpct(qf, wf, 2), _wpct(qf, wf, 98)
            Z0, Z1 = _wpct(pf[:, 2], wf, 2), _wpct(pf[:, 2], wf, 98)
            if (Q1 - Q0 <= FACE_DEPTH and T0 <= t0 + FACE_PAD and T1 >= t1 - FACE_PAD
                    and Z0 <= z0 + FACE_LOW * (z1 - z0) and Z1 >= z1 - FACE_PAD and T1 - T0 <= FACE_WIDE * width
                    and min(abs(Q0 - q1), abs(Q1 - q0), abs(0.5 * (Q0 + Q1) - q0), abs(0.5 * (Q0 + Q1) - q1))
                    <= FACE_TOUCH):
                joined[f] = a
    # 2. Lone pieces: jambs through the wall, pier faces in one wall instance on both sides.
    frames, boxes, ids = [], [], []
    new_bays: list[tuple[int, np.ndarray, np.ndarray, tuple[float, float], tuple[float, float, float, float]]] = []
    for a in sorted(info):
        if a in joined or a in joined.values():
            continue
        o, u, t, q, (t0, t1, q0, q1, z0, z1) = info[a]
        pa, wa = A[a]
        low = pa[:, 2] < z0 + LOW * (z1 - z0)
        if q1 - q0 < PIECE_DEPTH or not low.any():
            continue
        at_jamb = np.minimum(np.abs(t[low] - t0), np.abs(t[low] - t1)) <= JAMB
        if float(wa[low][at_jamb].sum()) < JAMB_SHARE * float(wa[low].sum()):
            continue
        opening = t1 - t0
        best = None
        for k, (pw, _ww) in sorted(W.items()):
            if k in joined or not close(a, k, opening):
                continue
            tw, qw = _coords(pw, o, u)
            band = (qw > q0 - SIDE) & (qw < q1 + SIDE) & (pw[:, 2] > z0) & (pw[:, 2] < z0 + LOW * (z1 - z0))
            left = band & (tw < t0) & (tw >= t0 - SIDE)
            right = band & (tw > t1) & (tw <= t1 + SIDE)
            if left.sum() < SIDE_POINTS or right.sum() < SIDE_POINTS:
                continue
            gap_r = _next_gap(tw[band], t1, opening)
            gap_l = _next_gap(-tw[band], -t0, opening)
            if gap_r is None and gap_l is None:
                continue
            half_r = 0.5 * (gap_r if gap_r is not None else gap_l)  # type: ignore[operator]
            half_l = 0.5 * (gap_l if gap_l is not None else gap_r)  # type: ignore[operator]
            best = (half_l, half_r)
            if next_id is not None:
                top = (qw > q0 - SIDE) & (qw < q1 + SIDE) & (pw[:, 2] > z1 - NEXT_TOP[0]) & (pw[:, 2] < z1 + NEXT_TOP[1])
                for sign, gap, edge in ((1.0, gap_r, t1), (-1.0, gap_l, t0)):
                    if gap is None:
                        continue
                    # the break's visible width, and wall over it at the piece's top: an opening
                    g = sign * edge + gap
                    after = np.sort(sign * tw[band])
                    after = after[after > g + 1e-6]  # past the last point before the break
                    seen = min(float(after[0]) - g if len(after) else opening, opening, NEXT_REACH)
                    bins = np.arange(g, g + seen + 1e-9, NEXT_BIN)
                    if len(bins) < 2:
                        continue
                    hit = np.histogram(sign * tw[top], bins)[0] > 0
                    if hit.mean() < NEXT_COVER:
                        continue
                    lo = sign * edge + 0.5 * gap
                    cell = (lo, lo + opening + gap) if sign > 0 else (-(lo + opening + gap), -lo)
                    new_bays.append((a, o, u, cell, (q0 - BAND_PAD, q1 + BAND_PAD, z0 - Z_PAD[0], z1 + Z_PAD[1])))
            break
        if best is None:
            continue
        frames.append([float(o[0]), float(o[1]), float(u[0]), float(u[1])])
        boxes.append([t0 - best[0], t1 + best[1], q0 - BAND_PAD, q1 + BAND_PAD, z0 - Z_PAD[0], z1 + Z_PAD[1]])
        ids.append(a)
    # 3. The next bays: an opening beside a lone piece's pier is a bay of the same pitch,
    # unless an arch instance already stands in it (or a next bay found from another piece).
    centres: list[np.ndarray] = []
    for _a, o, u, (c0, c1), (b0, b1, h0, h1) in new_bays:
        nrm = np.array([-u[1], u[0]])
        mid = o + 0.5 * (c0 + c1) * u + 0.5 * (b0 + b1) * nrm
        if any(float(np.linalg.norm(mid - c)) < 0.5 * (c1 - c0) for c in centres):
            continue
        taken = False
        for _k, (pk, wk) in A.items():
            tk, qk = _coords(pk, o, u)
            inside = (tk >= c0) & (tk < c1) & (qk > b0) & (qk < b1) & (pk[:, 2] > h0) & (pk[:, 2] < h1)
            if float(wk[inside].sum()) >= NEXT_TAKEN * float(wk.sum()):
                taken = True
                break
        if taken:
            continue
        centres.append(mid)
        frames.append([float(o[0]), float(o[1]), float(u[0]), float(u[1])])
        boxes.append([c0, c1, b0, b1, h0, h1])
        ids.append(int(next_id))  # type: ignore[arg-type]
        next_id += 1  # type: ignore[operator]
    if not ids:
        return ArcadeCells.empty(), joined
    n = len(ids)
    return ArcadeCells(np.array(frames), np.array(boxes), np.array(ids, np.int64), np.ones(n, np.int8),
                       np.zeros(n, bool)), joined
