"""The three projection sequences of the paper, each proposing a split of one node.

- ``S1 = rho(v2(p(psi(v1(x)))))``: the profile curve (minaret stages, drum vs dome);
- ``S2 = rho(v2(h(x)))``: the dominant vertical plane (bays of straight walls and arcades);
- ``S3 = rho(v2(u(psi(v1(x)))))``: the un-warped transport curve (bays of curved arcades).

Each returns a :class:`Proposal` (children as index arrays into the node's points, in
order along the cut axis) or None when it has nothing to propose: no transport curve
(S1, S3), fewer than two children, or too few points.

What each histogram holds (the paper says only "the histogram of the profile curve"):
S1 bins the height and keeps the profile's outline, the largest distance from the axis
in each bin, so a balcony or a moulding is a peak; S2 and S3 bin the position along the
wall and count the occupied 0.1 m cells of the wall's (position, height) projection
(:func:`occupancy_cut`; a plain point count follows the scan's density, highest near each
station), so a pier (solid over the wall's height) is a peak and an opening a valley.
Cuts at peaks put each balcony or pier on a boundary, as the ground truth's "mid-pier to
mid-pier" bays are.

A fourth proposal, the storeys (:func:`storeys`), cuts the same projection along the
height: a facade of several storeys of arcades is cut into storeys first, then each
storey into bays (the paper's S2 gives "bays and storeys").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.spatial import cKDTree

from hollowtree.arrays import FloatArray, IntArray
from hollowtree.params import Params, param
from hollowtree.primitives.dbscan import dbscan_labels
from hollowtree.tree.operators import (
    Histogram,
    RngLike,
    TransportCurve,
    _groups,
    _refine,
    h,
    limited,
    p,
    peak_bins,
    plateaus,
    psi,
    rho,
    u,
    v1,
    v2,
)

__all__ = ["GAP_SEQUENCE", "PART_SEQUENCE", "POST_SEQUENCE", "SEQUENCES", "Proposal", "SequenceParams", "gaps", "occupancy_cut", "occupancy_grid", "occupancy_signal", "parts", "propose", "s1",
           "s2", "s3", "storeys"]


#: Sequence ids as stored in the node table (0 = the root, produced by no sequence).
SEQUENCES: tuple[int, ...] = (1, 2, 3)

#: An occupancy cell of :func:`occupancy_cut` must hold about this many points of a
#: surface; a sparser node's cells grow by sqrt(2) until they do (:func:`occupancy_grid`,
#: read through :data:`_SINGLE`). With points spread evenly over a surface a cell of the
#: surface then stays empty with a chance of about exp(-3) = 5 %: an empty cell is an
#: opening, not the scan's noise.
CELL_MIN_POINTS = 3.0
#: The share of occupied cells that hold one point where a surface holds
#: :data:`CELL_MIN_POINTS` per cell (Poisson): lam exp(-lam) / (1 - exp(-lam)).
_SINGLE = CELL_MIN_POINTS * np.exp(-CELL_MIN_POINTS) / (1.0 - np.exp(-CELL_MIN_POINTS))
#: At most this many sqrt(2) steps (a cell of 16 x ``params.cell``).
CELL_MAX_STEPS = 8
#: How far (a share of its height) a solid band reaching the top of a node must stand
#: above the occupancy below it to be a storey cut (:func:`occupancy_cut`).
OPEN_HIGH_PROMINENCE = 0.25
#: The node table's sequence id of a split at gaps (:func:`gaps`).
GAP_SEQUENCE = 5
#: The node table's sequence id of a split into parts apart (:func:`parts`).
PART_SEQUENCE = 6
#: The node table's sequence id of a split into posts and what they carry (:func:`posts`).
POST_SEQUENCE = 7
#: A part of :func:`parts` holds at least this share of the node's points (smaller
#: pieces go with the nearest part; in a frame's rest, :func:`_is_frame`, the nearest in height).
PART_MIN_SHARE = 0.05
#: Two parts of :func:`parts` whose x-y boxes overlap by more than this share of the
#: smaller box's area are one (one stands on or inside the other).
PART_MAX_OVERLAP = 0.2
#: A column of the wall's projection is empty, for :func:`gaps`, when it holds fewer
#: occupied cells than this share of the node's full columns (their 90th percentile).
GAP_LEVEL = 0.02
#: Where a band ends (:func:`occupancy_cut` with ``bands``): the outermost place where the
#: occupancy is this share of the way from the valley on that side to the band's level
#: (its plateau's median, so a spike on one edge neither sets the level nor ends the band).
BAND_LEVEL = 0.9


@dataclass(frozen=True, kw_only=True)
class SequenceParams(Params, owner="SequenceParams"):
    """Settings shared by the three sequences, each declared once (``hollowtree.params``):
    its default, range and meaning."""

    prominence: float = param(0.05, gt=0, doc="peak prominence as a fraction of the histogram's range "
                                              "(:func:`~tree.operators.rho`)")
    sigma: float = param(1.0, ge=0, doc="smoothing of the fine histogram, in fine bins")
    bins_per_crossing: float = param(1.0, gt=0, doc="limited bins per zero crossing of the derivative "
                                                    "(:func:`~tree.operators.v2`)")
    min_points: int = param(30, ge=0, doc="nodes with fewer points get no proposal")
    min_child_fraction: float = param(
        0.02, ge=0, lt=1, doc="a child holding less than this share of the node's points (S1) or of its occupied "
                              "cells (S2, S3, storeys: :func:`occupancy_signal`) is merged into its neighbour across "
                              "the weaker cut (a peak in a sparse stretch is not a boundary)")
    residual_threshold: float | None = param(
        None, gt=0, doc="circle/n-gon RANSAC inlier distance; None = 1 % of the footprint")
    curve_min_inliers: float = param(
        0.15, ge=0, lt=1, doc="a transport curve holding fewer of the footprint's points than this share is none: "
                              "S1 and S3 propose nothing (a circle through some posts of a colonnade or the edge of "
                              "a slab is no ring; chosen on training seeds, docs/generalize.md)")
    flat_ratio: float = param(
        0.05, ge=0, doc="a node is flat, and :func:`tree.build.build_tree` does not split it, when its height (1st "
                        "to 99th percentile of z) is under ``max(flat_height, flat_ratio x its larger horizontal "
                        "extent)``: a ground or roof patch has no vertical structure for S1 or S3 to cut, and S2 "
                        "would only follow its point density")
    flat_height: float = param(0.5, ge=0, doc="see ``flat_ratio`` (metres)")
    cell: float = param(0.1, ge=0, doc="edge of the occupancy cells of S2 and S3 (metres; :func:`occupancy_cut`); "
                                       "0 = the plain point count (the histogram follows the scan's density)")
    storeys: bool = param(True, doc="also propose a cut along the height from the same occupancy (:func:`storeys`)")
    bands: bool = param(True, doc="a kept storeys split makes each solid band (the wall over a row of arches) a "
                                  "child of its own, cut at both its ends (:data:`BAND_LEVEL`), instead of halving it")
    gap: float = param(2.0, ge=0, doc="a stretch at least this long (metres) along the node's wall with (almost) "
                                      "nothing in it separates two parts that do not touch: "
                                      ":func:`tree.build.build_tree` splits the root there before anything else "
                                      "(:func:`gaps`); 0 = never")
    part_gap: float = param(0.2, ge=0, doc="parts of a node whose points come no closer than this (metres) are "
                                           "apart (:func:`parts`); :func:`tree.build.build_tree` splits a root that "
                                           "nothing else splits into them when HollowNet calls them different "
                                           "classes; 0 = never")

    def to_dict(self) -> dict[str, object]:
        return dict(self.__dict__)

    @classmethod
    def from_dict(cls, d: dict[str, object]) -> SequenceParams:
        return cls(**d)  # type: ignore[arg-type]


@dataclass(frozen=True, kw_only=True, eq=False)
class Proposal:
    """One sequence's proposed split of a node.

    Attributes
    ----------
    sequence : int
        1, 2 or 3 (the storeys carry the sequence whose projection they cut: 2 or 3).
    children : tuple of ndarray of int64
        Indices into the node's points; disjoint, covering every point.
    cuts : ndarray of float64
        Cut positions along the sequence's axis (z for S1, t for S2, arc length for S3).
    curve : TransportCurve or None
        The transport curve (S1, S3).
    kept_children, kept_cuts : optional
        The children made when the proposal is kept, when they differ from those it is
        judged by (the storeys: judged by their cuts at the bands' middles, as the split
        model was fitted, kept with each band a child of its own; ``SequenceParams.bands``).
    kept_bands : tuple of int
        Which of ``kept_children`` are bands (the tree calls them wall).
    """

    sequence: int
    children: tuple[IntArray, ...]
    cuts: FloatArray
    curve: TransportCurve | None = None
    kept_children: tuple[IntArray, ...] | None = None
    kept_cuts: FloatArray | None = None
    kept_bands: tuple[int, ...] = ()

    @property
    def n_children(self) -> int:
        return len(self.children)


def _merge_small(counts: npt.ArrayLike, min_count: float) -> IntArray:
    """Cuts kept (indices into the sorted cuts) once every child holds at least
    ``min_count``: the smallest child first, merged with its smaller neighbour.
    ``counts`` are the children's sizes between the cuts (points or occupied cells; one
    more than cuts); dropping a cut adds up its two children, so nothing is counted twice."""
    counts = np.asarray(counts, dtype=np.float64).copy()
    kept = np.arange(len(counts) - 1)
    while len(kept):
        k = int(np.argmin(counts))
        if counts[k] >= min_count:
            break
        if k == 0:
            drop = 0
        elif k == len(kept):
            drop = len(kept) - 1
        else:
            drop = k - 1 if counts[k - 1] <= counts[k + 1] else k
        counts[drop] += counts[drop + 1]
        counts = np.delete(counts, drop + 1)
        kept = np.delete(kept, drop)
    return kept


def _merge_short_ends(lo: float, hi: float, cuts: FloatArray) -> IntArray:
    """Cuts kept (indices into ``cuts``) after dropping each end cut whose end child is
    shorter than half the median length of the children (a half pier or an end cap at
    the end of a wall is not a bay); ``lo``, ``hi``: the extent of the points."""
    a, b = 0, len(cuts)
    while b - a >= 2:
        lengths = np.diff(np.r_[lo, cuts[a:b], hi])
        med = float(np.median(lengths))
        if lengths[-1] < 0.5 * med and lengths[-1] <= lengths[0]:
            b -= 1
        elif lengths[0] < 0.5 * med:
            a += 1
        else:
            break
    return np.arange(a, b)


def _finish(seq: int, x: FloatArray, cuts: FloatArray, params: SequenceParams,
            curve: TransportCurve | None, area: tuple[FloatArray, float, float] | None = None) -> Proposal | None:
    """Merge small children and short end children, then split: the points are labelled
    once (one ``searchsorted``) and the merges work on the children's counts, of points,
    or with ``area`` (:func:`occupancy_signal`) of occupied cells."""
    cuts = np.sort(np.asarray(cuts, dtype=np.float64))
    lab = np.searchsorted(cuts, x, side="right")
    if area is None:
        counts = np.bincount(lab, minlength=len(cuts) + 1).astype(np.float64)
        least = max(1.0, float(np.ceil(params.min_child_fraction * len(x))))
    else:  # occupied cells: a bay far from every station is as big as one beside a station
        f, lo, hi = area
        at = lo + (np.arange(len(f)) + 0.5) * ((hi - lo) / len(f))
        counts = np.bincount(np.searchsorted(cuts, at, side="right"), weights=f, minlength=len(cuts) + 1)
        least = params.min_child_fraction * float(f.sum())
    kept = _merge_small(counts, least)
    if len(kept) and len(x):
        kept = kept[_merge_short_ends(float(x.min()), float(x.max()), cuts[kept])]
    keep = np.zeros(len(cuts), dtype=bool)
    keep[kept] = True
    relabel = np.r_[0, np.cumsum(keep)]  # original child -> merged child
    children = _groups(relabel[lab], len(kept) + 1)
    if len(children) < 2:
        return None
    return Proposal(sequence=seq, children=tuple(children), cuts=cuts[keep], curve=curve)


def _as_xyz(xyz: npt.ArrayLike) -> FloatArray:
    a = np.asarray(xyz, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"The 'xyz' parameter must be an array of shape (n_points, 3). Got shape {a.shape} instead.")
    return a


def _with_curve(xyz: npt.ArrayLike, params: SequenceParams | None, rng: RngLike,
                curve: TransportCurve | None) -> tuple[FloatArray, SequenceParams, TransportCurve | None]:
    """A node's points, its settings (``params``, else the defaults) and its transport curve:
    ``curve``, else ``psi(v1(x))``; None for a node of fewer than ``params.min_points``
    points or one that no curve fits."""
    a = _as_xyz(xyz)
    params = params or SequenceParams()
    if len(a) < params.min_points:
        return a, params, None
    if curve is None:
        fit = psi(v1(a), residual_threshold=params.residual_threshold, rng=rng)
        curve = fit if isinstance(fit, TransportCurve) and fit.inlier_fraction >= params.curve_min_inliers else None
    return a, params, curve


def s1(xyz: npt.ArrayLike, *, params: SequenceParams | None = None, rng: RngLike = None,
       curve: TransportCurve | None = None) -> Proposal | None:
    """``S1 = rho(v2(p(psi(v1(x)))))``: cut at the peaks of the profile curve.

    ``curve`` skips ``psi`` (S1 and S3 share one transport curve in :func:`propose`).

    Examples
    --------
    >>> z = np.linspace(0, 9, 200)
    >>> r = np.where(np.abs(z - 4.5) < 0.5, 2.0, 1.0)   # a balcony at z = 4.5
    >>> t = np.linspace(0, 40 * np.pi, 200)
    >>> xyz = np.column_stack([r * np.cos(t), r * np.sin(t), z])
    >>> prop = s1(xyz, rng=0)
    >>> prop.n_children, [round(float(c), 1) for c in prop.cuts]
    (2, [4.5])
    """
    a, params, curve = _with_curve(xyz, params, rng, curve)
    if curve is None:
        return None
    prof = p(a, curve)
    hist = v2(prof[:, 1], prof[:, 0], statistic="max", sigma=params.sigma,
              bins_per_crossing=params.bins_per_crossing)
    return _finish(1, prof[:, 1], rho(hist, prominence=params.prominence), params, curve)


def s2(xyz: npt.ArrayLike, *, params: SequenceParams | None = None) -> Proposal | None:
    """``S2 = rho(v2(h(x)))``: cut at the peaks of the occupancy along the dominant vertical
    plane (:func:`occupancy_cut`; ``params.cell`` 0: of the point count).

    Examples
    --------
    >>> t, z = np.meshgrid(np.arange(0, 8, 0.05), np.arange(0, 3, 0.05))
    >>> bays = (np.abs(t % 4.0 - 2.0) > 1.0) | (z > 2.0)  # two 4 m bays, a 2 m pier between
    >>> prop = s2(np.column_stack([t[bays], np.zeros(bays.sum()), z[bays]]))
    >>> prop.n_children, abs(float(prop.cuts[0])) < 0.1  # cut at the pier's middle (t = 0 there)
    (2, True)
    """
    a = _as_xyz(xyz)
    params = params or SequenceParams()
    if len(a) < params.min_points:
        return None
    tz = h(a)
    sig = _signal(tz[:, 0], tz[:, 1], params)
    return _finish(2, tz[:, 0], occupancy_cut(tz[:, 0], tz[:, 1], params, signal=sig), params, None, sig)


def s3(xyz: npt.ArrayLike, *, params: SequenceParams | None = None, rng: RngLike = None,
       curve: TransportCurve | None = None) -> Proposal | None:
    """``S3 = rho(v2(u(psi(v1(x)))))``: cut at the peaks of the un-warped wall's occupancy
    along the curve (:func:`occupancy_cut`; ``params.cell`` 0: of its point count).

    Examples
    --------
    >>> th = np.r_[np.linspace(0, 1, 40), np.full(40, 1.25), np.linspace(1.5, 2.5, 40)]
    >>> xyz = np.column_stack([5 * np.cos(th), 5 * np.sin(th), np.linspace(0, 1, 120)])
    >>> prop = s3(xyz, params=SequenceParams(cell=0.0), rng=0)  # a density peak at 1.25 rad
    >>> prop.n_children, round(prop.curve.radius, 3)
    (2, 5.0)
    """
    a, params, curve = _with_curve(xyz, params, rng, curve)
    if curve is None:
        return None
    sz = u(a, curve)
    sig = _signal(sz[:, 0], sz[:, 1], params)
    return _finish(3, sz[:, 0], occupancy_cut(sz[:, 0], sz[:, 1], params, signal=sig), params, curve, sig)


def storeys(xyz: npt.ArrayLike, *, params: SequenceParams | None = None,
            curve: TransportCurve | None = None) -> Proposal | None:
    """Storeys: S3's (or, without a transport curve, S2's) projection cut along the height.

    The occupancy of the un-warped (or projected) wall, counted per height, is high
    where the wall is solid across its length (the band over a row of arches, a floor
    edge) and low through a row of openings; the cuts are its peaks, as along the wall.
    The proposal carries the sequence whose projection it uses (2 or 3), so its prior
    ``W`` is that sequence's: the paper's S2 gives "bays and storeys".

    Examples
    --------
    >>> t = np.tile(np.linspace(0, 10, 201), 119)
    >>> z = np.repeat(np.linspace(0, 5.9, 119), 201)
    >>> solid = (np.abs(z - 3.0) < 0.35) | (np.abs(t % 2.0 - 1.0) > 0.6)  # a band at 3 m
    >>> xyz = np.column_stack([t, np.zeros_like(t), z])[solid]
    >>> prop = storeys(xyz)
    >>> prop.sequence, prop.n_children, [round(float(c), 1) for c in prop.cuts]
    (2, 2, [3.0])
    """
    a = _as_xyz(xyz)
    params = params or SequenceParams()
    if len(a) < params.min_points:
        return None
    pz = u(a, curve) if curve is not None else h(a)
    seq = 3 if curve is not None else 2
    sig = _signal(pz[:, 1], pz[:, 0], params)
    cuts, bands = occupancy_cut(pz[:, 1], pz[:, 0], params, open_high=True, bands=True, signal=sig)
    prop = _finish(seq, pz[:, 1], cuts, params, curve, sig)
    if prop is None or not params.bands or not len(bands):
        return prop
    banded = _finish(seq, pz[:, 1], np.unique(bands), params, curve, sig)
    if banded is None or banded.n_children <= prop.n_children:
        return prop
    # A child between the two ends of one band is that band.
    ends = {(float(lo), float(hi)) for lo, hi in bands}
    kept_bands = tuple(k for k in range(1, banded.n_children - 1)
                       if (float(banded.cuts[k - 1]), float(banded.cuts[k])) in ends)
    return Proposal(sequence=seq, children=prop.children, cuts=prop.cuts, curve=curve,
                    kept_children=banded.children, kept_cuts=banded.cuts, kept_bands=kept_bands)


def _open_high(hist: Histogram) -> Histogram:
    """``hist`` with one empty limited bin (and its fine bins) past its high end, so a
    plateau that reaches the top of the node is a peak when it stands above the rest."""
    nf, nb = len(hist.fine_values), len(hist.values)
    k = max(1, nf // nb)
    df = float(hist.fine_edges[1] - hist.fine_edges[0])
    fine_edges = np.r_[hist.fine_edges, hist.fine_edges[-1] + df * np.arange(1, k + 1)]
    return Histogram(edges=np.r_[hist.edges, fine_edges[-1]], values=np.r_[hist.values, 0.0],
                     fine_edges=fine_edges, fine_values=np.r_[hist.fine_values, np.zeros(k)],
                     n_zero_crossings=hist.n_zero_crossings)


def occupancy_grid(x: FloatArray, y: FloatArray, cell: float) -> tuple[float, IntArray, IntArray, IntArray]:
    """The occupied cells of the ``(x, y)`` projection: ``(cell, kx, ky, first)``, the cell
    edge used, each point's cell column and row, and one point index per occupied cell.

    The cell is ``cell``, grown by sqrt(2) (at most :data:`CELL_MAX_STEPS` times) until
    no more of the occupied cells hold a single point than where a surface holds
    :data:`CELL_MIN_POINTS` points a cell (:data:`_SINGLE`, 15.7 %): a fixed cell follows
    the scan's density where it is thinner than the cell (a far facade at 0.3 m spacing
    in 0.1 m cells is a scatter of single points whose occupancy is noise). Not the mean
    count: a node scanned from a station close to one of its parts has most of its
    points there, and their mean would keep the cells too fine for the rest.

    Examples
    --------
    >>> def wall(spacing):  # 10 x 3 m
    ...     t, z = np.meshgrid(np.arange(0, 10, spacing), np.arange(0, 3, spacing))
    ...     return t.ravel(), z.ravel()
    >>> round(occupancy_grid(*wall(0.02), 0.1)[0], 3), round(occupancy_grid(*wall(0.27), 0.1)[0], 3)
    (0.1, 0.566)
    """
    x0, y0 = float(x.min()), float(y.min())
    for step in range(CELL_MAX_STEPS + 1):
        c = cell * 2.0 ** (0.5 * step)
        kx = ((x - x0) * (1.0 / c)).astype(np.int64)
        ky = ((y - y0) * (1.0 / c)).astype(np.int64)
        _, first, counts = np.unique(kx * (int(ky.max()) + 1) + ky, return_index=True, return_counts=True)
        if np.count_nonzero(counts == 1) <= _SINGLE * len(counts):
            break
    return c, kx, ky, first


def _signal(x: FloatArray, y: FloatArray, params: SequenceParams) -> tuple[FloatArray, float, float] | None:
    """:func:`occupancy_signal`, or None where ``params.cell`` is 0 or there are no points."""
    return occupancy_signal(x, y, params.cell) if params.cell > 0 and len(x) else None


def occupancy_cut(x: FloatArray, y: FloatArray, params: SequenceParams, *,
                  open_high: bool = False, bands: bool = False,
                  signal: tuple[FloatArray, float, float] | None = None) -> FloatArray | tuple[FloatArray, FloatArray]:
    """Cuts along ``x`` at the peaks of the wall's occupancy: how many cells of
    ``params.cell`` x ``params.cell`` (grown where the node is sparse: :func:`occupancy_grid`)
    in the ``(x, y)`` projection hold a point, per position along ``x``.

    A plain count follows the scan's density, which is highest near each station, so
    on a wall scanned from a few stations its peaks are the stations, not the piers.
    The occupancy counts each cell once: a pier (solid over the wall's height) is a
    peak and an opening a valley wherever the points are at least a cell apart, and a
    plain wall has no peaks at all. The fine histogram (:func:`occupancy_signal`, or
    ``signal`` when the caller has it) has one bin per cell (16 to 1024 bins);
    ``limited`` (``v2``'s limited bins) and ``rho`` do the rest. ``params.cell`` 0 counts
    points.

    ``open_high`` (the storeys): the signal is also read as empty past the high end of
    ``x``, so a solid band that reaches it (the wall over a row of arches, up to the
    node's top, with nothing above) is a peak as it is when something stands above it.
    Such a top peak counts when it stands at least :data:`OPEN_HIGH_PROMINENCE` of its
    height above the signal below it (a row of openings, not a door in a plain wall);
    a plain wall, solid all the way, has none.

    ``bands`` (the storeys): also the bands, each peak's plateau with two ends inside
    ``x`` (each end measured from the valley on its own side, at :data:`BAND_LEVEL` of the
    way to the plateau's median: ``plateaus(robust=True)``; a side whose valley lies less
    than :data:`OPEN_HIGH_PROMINENCE` of the top below it has no end): returns ``(cuts, bands)``, ``bands`` of shape (m, 2).
    """
    kw = dict(sigma=params.sigma, bins_per_crossing=params.bins_per_crossing)
    if len(x) == 0:
        return (np.empty(0), np.empty(0)) if bands else np.empty(0)
    if params.cell <= 0:
        hist = v2(x, statistic="count", **kw)  # type: ignore[arg-type]
        return _cuts(hist, params.prominence, open_high, bands)
    f, lo, hi = signal if signal is not None else occupancy_signal(x, y, params.cell)
    hist = limited(f, lo, hi, **kw)  # type: ignore[arg-type]
    return _cuts(hist, params.prominence, open_high, bands)


def occupancy_signal(x: FloatArray, y: FloatArray, cell: float) -> tuple[FloatArray, float, float]:
    """The occupied cells of the ``(x, y)`` projection (:func:`occupancy_grid`) per fine
    bin along ``x``, one bin per cell (16 to 1024 bins): ``(signal, lo, hi)``, the fine
    signal of :func:`occupancy_cut` and the sizes of the children in :func:`_finish`.

    Examples
    --------
    >>> t, z = np.meshgrid(np.arange(0, 10, 0.02), np.arange(0, 3, 0.02))
    >>> f, lo, hi = occupancy_signal(t.ravel(), z.ravel(), 0.1)
    >>> len(f), float(f.min()), float(f.max())  # 100 columns of 30 cells
    (100, 30.0, 30.0)
    """
    c, _, _, first = occupancy_grid(x, y, cell)
    xs = x[first]
    lo, hi = float(xs.min()), float(xs.max())
    if hi <= lo:
        hi = lo + 1.0
    nf = int(np.clip(np.ceil((float(x.max()) - float(x.min())) / c), 16, 1024))
    b = np.clip(((xs - lo) / (hi - lo) * nf).astype(np.int64), 0, nf - 1)
    return np.bincount(b, minlength=nf).astype(np.float64), lo, hi


def _cuts(hist: Histogram, prominence: float, open_high: bool,
          bands: bool) -> FloatArray | tuple[FloatArray, FloatArray]:
    """``rho``'s cuts, plus, with ``open_high``, the top plateau's; with ``bands`` also the
    plateaus' ends (see :func:`occupancy_cut`)."""
    lo, hi = float(hist.fine_edges[0]), float(hist.fine_edges[-1])
    peaks = peak_bins(hist, prominence=prominence)
    if open_high:
        padded = _open_high(hist)
        top = peak_bins(padded, prominence=max(prominence, OPEN_HIGH_PROMINENCE))
        top = top[top > (peaks.max() if len(peaks) else -1)][-1:]
        if len(top):
            hist, peaks = padded, np.r_[peaks, top]
    cuts = _refine(hist, peaks)
    if not bands:
        return cuts
    start, stop = plateaus(hist, peaks, level=BAND_LEVEL, per_side=True, min_drop=OPEN_HIGH_PROMINENCE, robust=True)
    margin = 2.0 * float(hist.fine_edges[1] - hist.fine_edges[0])
    inside = np.isfinite(start) & np.isfinite(stop) & (start > lo + margin) & (stop < hi - margin)
    return cuts, np.column_stack([start, stop])[inside]


def gaps(xyz: npt.ArrayLike, *, params: SequenceParams | None = None) -> Proposal | None:
    """The node cut at its gaps: parts side by side that do not touch, such as two
    bastions that the coarse stage joined through a few points of the curtain wall
    between them.

    Along the node's wall (``h``: the principal axis of its footprint) each column of
    ``params.cell`` holds some occupied cells of the ``(t, z)`` projection; a column is
    empty when it holds fewer than :data:`GAP_LEVEL` of the node's full columns (their
    90th percentile), and a run of empty columns at least ``params.gap`` long is a gap,
    cut at its middle. A cut that would leave a part under ``params.min_points`` points
    or ``5 x params.min_child_fraction`` of the node is dropped. None when there is no
    gap (or ``params.gap`` is 0 or ``params.cell`` is 0).

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> a = rng.uniform(0, 1, (2000, 3)) * [4.0, 1.0, 10.0]
    >>> pr = gaps(np.r_[a, a + [7.0, 0, 0]])
    >>> pr.n_children, [len(c) for c in pr.children]
    (2, [2000, 2000])
    >>> gaps(a) is None
    True
    """
    a = _as_xyz(xyz)
    params = params or SequenceParams()
    if params.gap <= 0 or params.cell <= 0 or len(a) < 2 * params.min_points:
        return None
    t, z = h(a).T
    t0, z0 = float(t.min()), float(z.min())
    # The fixed cell, not occupancy_grid's: grown cells let a few stray points fill a gap's columns.
    kx = ((t - t0) * (1.0 / params.cell)).astype(np.int64)
    kz = ((z - z0) * (1.0 / params.cell)).astype(np.int64)
    _, first = np.unique(kx * (int(kz.max()) + 1) + kz, return_index=True)
    occ = np.bincount(kx[first], minlength=int(kx.max()) + 1).astype(np.float64)
    empty = occ < GAP_LEVEL * float(np.percentile(occ, 90))
    # Runs of empty columns: starts and ends (exclusive), inside the node (both ends occupied).
    d = np.diff(np.r_[0, empty.astype(np.int8), 0])
    start, stop = np.flatnonzero(d == 1), np.flatnonzero(d == -1)
    inner = (start > 0) & (stop < len(occ)) & ((stop - start) * params.cell >= params.gap)
    if not inner.any():
        return None
    cuts = t0 + 0.5 * (start[inner] + stop[inner]) * params.cell
    min_n = max(params.min_points, int(np.ceil(5 * params.min_child_fraction * len(a))))
    while len(cuts):
        counts = np.bincount(np.searchsorted(cuts, t), minlength=len(cuts) + 1)
        small = np.flatnonzero(counts < min_n)
        if not len(small):
            break
        j = int(small[0])  # drop the cut on that part's side that bounds it
        cuts = np.delete(cuts, min(j, len(cuts) - 1))
    if not len(cuts):
        return None
    part = np.searchsorted(cuts, t)
    children = tuple(np.flatnonzero(part == k).astype(np.int64) for k in range(len(cuts) + 1))
    return Proposal(sequence=GAP_SEQUENCE, children=children, cuts=cuts, curve=None)


def parts(xyz: npt.ArrayLike, *, params: SequenceParams | None = None, stacked: bool = False,
          posts_z: tuple[float, float] | None = None) -> Proposal | None:
    """The node as its parts apart, side by side: the sets of points joined by steps of at
    most ``params.part_gap`` (DBSCAN with one sample, :func:`primitives.dbscan.dbscan_labels`)
    that hold at least :data:`PART_MIN_SHARE` of the node and ``params.min_points`` (every
    smaller piece goes with the part nearest to it), then joined while two of them have
    x-y boxes that overlap by more than :data:`PART_MAX_OVERLAP` of the smaller one (the
    stages of a minaret apart at a balcony's shadow stand one on the other: one part).
    None when fewer than two parts are left (or ``params.part_gap`` is 0). Children in
    the order of their lowest point index; no cuts.

    ``stacked=True`` keeps parts that stand one on another apart too (no joining by
    x-y boxes): the rest of a frame whose posts were cut out (:func:`posts`), its slab
    and dome above its platform. ``posts_z`` is then the height range of those posts (the
    median of their lowest and of their highest points): where no part reaches across its
    middle height the rest is a frame's (a slab and a dome above the posts, a platform
    under them; :func:`_is_frame`), and a smaller piece goes, whole, with the part nearest
    to it in height (:func:`_by_height`), not point by point with the nearest part. A
    tomb's walls beside the piers taken for posts reach across: their pieces do not move.

    Unlike :func:`gaps` this sees any direction (a chattri standing 0.25 m off a minaret's
    balcony, beside it and overlapping it in height), and it is not a split by itself:
    :func:`tree.build.build_tree` keeps it only when the parts are different classes.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> a = rng.uniform(0, 1, (2000, 3)) * [1.0, 1.0, 3.0]
    >>> b = a[:500] * [0.5, 0.5, 0.2] + [1.3, 0.0, 2.5]     # 0.3 m off a's side
    >>> pr = parts(np.r_[a, b])
    >>> pr.sequence, [len(c) for c in pr.children]
    (6, [2000, 500])
    >>> parts(a) is None
    True
    """
    a = _as_xyz(xyz)
    params = params or SequenceParams()
    if params.part_gap <= 0 or len(a) < 2 * params.min_points:
        return None
    label = dbscan_labels(a, eps=params.part_gap, min_samples=1)
    count = np.bincount(label)
    big = np.flatnonzero(count >= max(params.min_points, int(np.ceil(PART_MIN_SHARE * len(a)))))
    if len(big) < 2:
        return None
    part = np.searchsorted(big, label)
    small = ~np.isin(label, big)
    if small.any() and stacked and posts_z is not None and _is_frame(a[:, 2], part, small, len(big), posts_z):
        part[small] = _by_height(a, label, part, small, len(big))
    elif small.any():
        _, j = cKDTree(a[~small]).query(a[small])
        part[small] = part[~small][j]
    if not stacked:
        part = _side_by_side(a, part, len(big))
    if part.max() == 0:
        return None
    children = tuple(np.flatnonzero(part == k).astype(np.int64) for k in range(int(part.max()) + 1))
    return Proposal(sequence=PART_SEQUENCE, children=children, cuts=np.zeros(0), curve=None)


def _is_frame(z: FloatArray, part: IntArray, small: npt.NDArray[np.bool_], n_parts: int,
              posts_z: tuple[float, float]) -> bool:
    """Whether no part (its points outside ``small``) reaches across the middle of the
    posts' height range ``posts_z``: all the parts stand on the posts or under them."""
    mid = 0.5 * (posts_z[0] + posts_z[1])
    lo, hi = _part_heights(z, part, small, n_parts)
    return not bool(((lo < mid) & (hi > mid)).any())


def _part_heights(z: FloatArray, part: IntArray, small: npt.NDArray[np.bool_], n_parts: int
                  ) -> tuple[FloatArray, FloatArray]:
    """Each part's lowest and highest point (its points outside ``small``)."""
    lo = np.full(n_parts, np.inf)
    hi = np.full(n_parts, -np.inf)
    np.minimum.at(lo, part[~small], z[~small])
    np.maximum.at(hi, part[~small], z[~small])
    return lo, hi


def _by_height(a: FloatArray, label: IntArray, part: IntArray, small: npt.NDArray[np.bool_],
               n_parts: int) -> IntArray:
    """The part of each small piece's points (``small``; ``label``: their pieces), when the
    parts stand one on another: each piece whole with the part whose height range is
    nearest to the piece's median height (0 inside it), of equals the one whose points come
    nearest to the piece's. A post the posts missed goes with what it stands under, not with
    the dome above it that its top point happens to be nearest to."""
    z = a[:, 2]
    lo, hi = _part_heights(z, part, small, n_parts)
    trees: dict[int, cKDTree] = {}
    out = np.empty(int(small.sum()), dtype=part.dtype)
    idx = np.flatnonzero(small)
    order = np.argsort(label[idx], kind="stable")
    _, starts = np.unique(label[idx][order], return_index=True)
    for rows in np.split(order, starts[1:]):
        mz = float(np.median(z[idx[rows]]))
        gap = np.maximum(lo - mz, 0.0) + np.maximum(mz - hi, 0.0)
        near = np.flatnonzero(gap <= gap.min() + 1e-9)
        if len(near) > 1:
            dist = []
            for p in near.tolist():
                if p not in trees:
                    trees[p] = cKDTree(a[~small & (part == p)])
                dist.append(float(trees[p].query(a[idx[rows]])[0].min()))
            near = near[[int(np.argmin(dist))]]
        out[rows] = near[0]
    return out


def _side_by_side(a: FloatArray, part: IntArray, n_parts: int) -> IntArray:
    """Join the parts whose x-y boxes overlap by more than :data:`PART_MAX_OVERLAP` of the
    smaller box's area (stages of one minaret, a chattri's legs under its roof: one above
    or inside the other), until every two left stand side by side. Returns parts
    renumbered ``0..`` in the order of their lowest point index."""
    lo = np.full((n_parts, 2), np.inf)
    hi = np.full((n_parts, 2), -np.inf)
    for axis in range(2):
        np.minimum.at(lo[:, axis], part, a[:, axis])
        np.maximum.at(hi[:, axis], part, a[:, axis])
    root = np.arange(n_parts)
    joined = True
    while joined:
        joined = False
        live = np.flatnonzero(root == np.arange(n_parts))
        for i in live.tolist():
            for j in live.tolist():
                if j <= i or root[i] != i or root[j] != j:
                    continue
                inter = np.prod(np.clip(np.minimum(hi[i], hi[j]) - np.maximum(lo[i], lo[j]), 0.0, None))
                area = np.prod(np.maximum(hi[[i, j]] - lo[[i, j]], 1e-6), axis=1)
                if inter > PART_MAX_OVERLAP * float(area.min()):
                    root[root == j] = i
                    lo[i], hi[i] = np.minimum(lo[i], lo[j]), np.maximum(hi[i], hi[j])
                    joined = True
    _, first = np.unique(root[part], return_index=True)
    order = np.argsort(first)  # the parts' new numbers, by lowest point index
    new = np.empty(n_parts, dtype=np.int64)
    new[np.unique(root[part])[order]] = np.arange(len(order))
    return new[root[part]]


def propose(xyz: npt.ArrayLike, *, params: SequenceParams | None = None,
            rng: RngLike = None) -> dict[int, Proposal | None]:
    """Every proposal for one node, ``{1: S1, 2: S2, 3: S3, 4: storeys}`` (one ``psi`` fit
    shared by S1, S3 and the storeys; the storeys' ``Proposal.sequence`` is 2 or 3)."""
    a, params, curve = _with_curve(xyz, params, rng, None)
    return {
        1: s1(a, params=params, curve=curve) if curve is not None else None,
        2: s2(a, params=params),
        3: s3(a, params=params, curve=curve) if curve is not None else None,
        4: storeys(a, params=params, curve=curve) if params.storeys else None,
    }
