"""The paper's projection operators: ``v1``, ``psi``, ``p``, ``u``, ``h``, ``v2``, ``rho``.

Each operator is a pure NumPy/SciPy function (``../shared/METHOD.md``, "Operators"):

- :func:`v1` drops z and keeps the footprint ``(x, y)``;
- :func:`psi` fits the transport curve to the footprint: circle RANSAC, then regular
  n-gon RANSAC (octagonal minarets, bastions) seeded by the circle; a straight footprint
  has no transport curve and gives a falsy :class:`~primitives.shapes.FailedFit`;
- :func:`p` is the profile curve (distance from the curve's axis, height);
- :func:`u` un-warps along the curve (arc length, height);
- :func:`h` projects on the dominant vertical plane (principal horizontal axis, height);
- :func:`v2` is the limited-bin histogram whose bin count is the number of zero crossings
  of the derivative of a fine, lightly smoothed histogram;
- :func:`rho` finds the histogram's peaks (``scipy.signal.find_peaks``) and refines each
  inside its bin on the fine histogram; the refined peaks are the cut positions.

The sequences ``S1``, ``S2`` and ``S3`` that chain them are in :mod:`tree.sequences`.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Literal

import numpy as np
import numpy.typing as npt
from scipy.ndimage import gaussian_filter1d
from scipy.signal import find_peaks

from hollowtree.arrays import FloatArray, IntArray
from hollowtree.primitives.shapes import FailedFit
from hollowtree.tree.curves import (
    _FIT_SAMPLE,
    DEFAULT_SIDES,
    RngLike,
    TransportCurve,
    _kasa,
    _span,
    _subsample,
    fit_circle,
    fit_ngon,
)

#: :func:`settle` refits the circle on the occupied cells within this many RANSAC thresholds
#: of it: both faces of a wall with depth (piers and recesses) hold it.
SETTLE_BAND = 2.0

__all__ = [
    "Histogram",
    "TransportCurve",
    "fit_circle",
    "fit_ngon",
    "h",
    "p",
    "peak_bins",
    "plateaus",
    "psi",
    "rho",
    "settle",
    "split_at",
    "u",
    "v1",
    "v2",
]



# --------------------------------------------------------------------------- v1, h
def v1(xyz: npt.ArrayLike) -> FloatArray:
    """Vertical projection ``v1``: drop z, keep the footprint.

    Parameters
    ----------
    xyz : array-like of shape (n_points, 3)

    Returns
    -------
    xy : ndarray of shape (n_points, 2), float64

    Examples
    --------
    >>> v1([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]).tolist()
    [[1.0, 2.0], [4.0, 5.0]]
    """
    return np.array(np.asarray(xyz, dtype=np.float64)[:, :2])


def h(xyz: npt.ArrayLike) -> FloatArray:
    """Projection ``h`` on the dominant vertical plane: ``(t, z)``.

    ``t`` is the coordinate along the principal axis of the footprint (PCA of ``x, y``),
    measured from the footprint's centroid, so a straight wall of any orientation lies
    along ``t``. The paper zeroes the y axis; this is the same for a wall along x.

    Parameters
    ----------
    xyz : array-like of shape (n_points, 3)

    Returns
    -------
    tz : ndarray of shape (n_points, 2), float64

    Examples
    --------
    >>> xyz = [[0, 0, 0], [1, 1, 1], [2, 2, 0], [3, 3, 1], [4, 4, 0], [5, 5, 1]]
    >>> np.round(np.abs(h(xyz)[:, 0]), 3).tolist()
    [3.536, 2.121, 0.707, 0.707, 2.121, 3.536]
    """
    a = np.asarray(xyz, dtype=np.float64)
    if not len(a):
        return np.empty((0, 2))
    dx, dy = a[:, 0] - a[:, 0].mean(), a[:, 1] - a[:, 1].mean()
    axis = np.array([1.0, 0.0])
    if len(a) >= 2:
        # Element-wise sums, not BLAS dots: a threaded dot of 100 k points can stall on
        # a loaded machine.
        sxy = float((dx * dy).sum())
        w, vecs = np.linalg.eigh(np.array([[float((dx * dx).sum()), sxy], [sxy, float((dy * dy).sum())]]))
        axis = vecs[:, int(np.argmax(w))]
        # Fixed sign, so equal input gives an equal projection.
        if axis[np.argmax(np.abs(axis))] < 0:
            axis = -axis
    out = np.empty((len(a), 2))
    np.multiply(dx, axis[0], out=out[:, 0])
    out[:, 0] += dy * axis[1]
    out[:, 1] = a[:, 2]
    return out



def psi(
    xy: npt.ArrayLike,
    *,
    sides: tuple[int, ...] = DEFAULT_SIDES,
    residual_threshold: float | None = None,
    max_trials: int = 256,
    straightness: float = 3.0,
    refit_cells: bool = True,
    rng: RngLike = None,
) -> TransportCurve | FailedFit:
    """Transport curve ``psi`` of a footprint: circle RANSAC, then n-gon RANSAC.

    A polygon replaces the circle when it holds at least 10 % more inliers (an octagonal
    shaft fits a circle only near its corners and mid-sides). A footprint whose circle
    inliers lie on a straight line as well as on the circle (line RMS below
    ``straightness`` x the circle's RMS, or a radius over 10 x the footprint's size) has no
    transport curve: a straight wall is ``h``'s case, not ``p``'s or ``u``'s.

    One random sample of at most :data:`_FIT_SAMPLE` footprint points serves the circle,
    every polygon and the straightness test, so their inlier fractions compare on the
    same points; the threshold and the size come from the whole footprint.

    Where that fit fails and ``refit_cells`` is set, the same fits run again on one point
    of each occupied ``residual_threshold / 2`` cell of the footprint: a crowded part (the
    bay beside a station) can hold the points' best circle on its own short, straight arc,
    while the cells weigh the whole footprint alike. The curve's inlier share and RMS are
    still those of the points' sample, so a threshold on the share keeps its meaning.

    Not in the paper: a circle that wins is then settled (:func:`settle`) on those
    cells: refitted on the cells within :data:`SETTLE_BAND` thresholds of it until it
    stops moving, so one footprint gives one circle whatever RANSAC drew (on a curved
    facade 30 m across, ten draws put the centre up to 2.8 m apart and S3 cut 15 to 23 bays;
    settled, one centre and 19 bays; docs/decisions/method.md, `tree-v36`).

    Parameters
    ----------
    xy : array-like of shape (n_points, 2)
    sides : tuple of int
        Polygons tried after the circle; ``()`` for circles only.
    residual_threshold, max_trials, rng
        As :func:`fit_circle`.
    straightness : float
        See above.
    refit_cells : bool
        Fit again on the occupied cells when the points' fit fails (see above).

    Returns
    -------
    TransportCurve or FailedFit

    Examples
    --------
    >>> t = np.linspace(0, np.pi, 6)
    >>> c = psi(np.column_stack([3 * np.cos(t), 3 * np.sin(t)]), rng=0)
    >>> round(c.radius, 6), c.n_sides
    (3.0, 0)
    >>> bool(psi([[0, 0], [1, 0], [2, 0], [3, 0], [4, 0], [5, 0.001]], rng=0))
    False
    """
    pts = np.asarray(xy, dtype=np.float64)
    rng = np.random.default_rng(rng)
    if len(pts) < 3:
        return FailedFit(reason=f"a circle needs 3 points; got {len(pts)}")
    size = float(np.hypot(*_span(pts)[:2]))
    thr = float(residual_threshold) if residual_threshold is not None else max(0.02, 0.01 * size)
    fit = _subsample(pts, _FIT_SAMPLE, rng)
    occupied = functools.cache(lambda: _occupied(pts, 0.5 * thr))  # made when first needed
    curve = _psi_on(fit, fit, occupied, thr, size, sides, max_trials, straightness, rng)
    if isinstance(curve, TransportCurve) or not refit_cells:
        return curve
    cells = _subsample(occupied(), _FIT_SAMPLE, rng)
    again = _psi_on(cells, fit, occupied, thr, size, sides, max_trials, straightness, rng)
    return again if isinstance(again, TransportCurve) else curve


def settle(circle: TransportCurve, cells: FloatArray, thr: float, *, band: float = SETTLE_BAND,
           max_iter: int = 10) -> TransportCurve:
    """The circle refitted (:func:`~tree.curves._kasa`) on the ``cells`` within ``band`` x
    ``thr`` of it, again until it stops moving (``max_iter`` at most): a fixed point of
    the footprint's occupied cells, the same for any nearby start.

    RANSAC's best circle is one of many that hold about as many inliers when the wall
    has depth (piers in front of recessed arches): on a long shallow arc its centre
    and radius drift by a metre from draw to draw, and S3's un-warped bays with them.
    ``circle`` itself where fewer than 3 cells lie in the band. The ``inlier_fraction``
    and ``rms`` stay the given circle's (how well a circle holds the footprint: the
    middle of a thick wall may hold few points within ``thr``, both its faces do).

    >>> t = np.linspace(0.0, 1.0, 200)
    >>> wall = np.r_[np.column_stack([30 * np.cos(t), 30 * np.sin(t)]),
    ...              np.column_stack([31 * np.cos(t[::4]), 31 * np.sin(t[::4])])]  # piers in front
    >>> a = settle(TransportCurve(center=(0.2, 0.1), radius=30.0), wall, 0.6)
    >>> b = settle(TransportCurve(center=(-0.3, 0.2), radius=30.4), wall, 0.6)
    >>> bool(np.allclose(a.center, b.center) and abs(a.radius - b.radius) < 1e-6)
    True
    """
    c, r = np.asarray(circle.center, dtype=np.float64), float(circle.radius)
    for _ in range(max_iter):
        inl = np.abs(np.hypot(cells[:, 0] - c[0], cells[:, 1] - c[1]) - r) < band * thr
        if inl.sum() < 3:
            break
        c2, r2 = _kasa(cells[inl])
        if not (np.all(np.isfinite(c2)) and math.isfinite(r2)):
            break
        moved = float(np.hypot(*(c2 - c))) + abs(r2 - r)
        c, r = c2, r2
        if moved < 1e-6 * max(r, 1.0):
            break
    return replace(circle, center=(float(c[0]), float(c[1])), radius=r)


def _psi_on(sample: FloatArray, fit: FloatArray, occupied: Callable[[], FloatArray], thr: float, size: float,
            sides: tuple[int, ...], max_trials: int, straightness: float,
            rng: np.random.Generator) -> TransportCurve | FailedFit:
    """``psi``'s fits on ``sample``, the curve's inlier share and RMS on ``fit``; a circle
    that wins is settled on the footprint's ``occupied()`` cells (:func:`settle`)."""
    circle = fit_circle(sample, residual_threshold=thr, max_trials=max_trials, rng=rng)
    if not circle:
        return circle
    assert isinstance(circle, TransportCurve)
    if circle.radius > 10.0 * max(size, thr):
        return FailedFit(reason=f"footprint is straight (circle radius {circle.radius:.3g} m)")
    inl = sample[circle.residuals(sample) < thr]
    q = inl - inl.mean(axis=0)
    line_rms = math.sqrt(max(float(np.linalg.eigvalsh(q.T @ q)[0]), 0.0) / len(q))
    if line_rms < straightness * max(circle.rms, 1e-3 * thr):
        return FailedFit(reason=f"footprint is straight (line RMS {line_rms:.3g} m, "
                                f"circle RMS {circle.rms:.3g} m)")
    best: TransportCurve = circle
    for n in sides:
        g = fit_ngon(sample, n_sides=n, start=circle, residual_threshold=thr,
                     max_trials=max(8, max_trials // 16 - 1), rng=rng)
        if g and isinstance(g, TransportCurve) and g.inlier_fraction > 1.1 * best.inlier_fraction:
            best = g
    if sample is not fit:
        res = best.residuals(fit)
        ok = res < thr
        best = replace(best, inlier_fraction=float(ok.mean()),
                       rms=float(np.sqrt(np.mean(res[ok] ** 2))) if ok.any() else best.rms)
    # A circle's place settles on the cells; its share and RMS stay those of the fit that chose it.
    return settle(best, occupied(), thr) if best.n_sides == 0 else best


def _occupied(xy: FloatArray, cell: float) -> FloatArray:
    """One point of each occupied ``cell`` x ``cell`` square of ``xy``, in input order.

    >>> _occupied(np.array([[0.0, 0.0], [0.1, 0.1], [1.2, 0.0], [0.05, 0.9]]), 0.5).tolist()
    [[0.0, 0.0], [1.2, 0.0], [0.05, 0.9]]
    """
    k = ((xy - xy.min(axis=0)) * (1.0 / cell)).astype(np.int64)
    key = k[:, 0] * (int(k[:, 1].max()) + 1) + k[:, 1]
    n_cells = int(key.max()) + 1
    if n_cells > 8 * len(xy):  # a sparse grid: sort rather than a table of every cell
        _, first = np.unique(key, return_index=True)
        return xy[np.sort(first)]
    first = np.full(n_cells, len(xy), dtype=np.int64)
    np.minimum.at(first, key, np.arange(len(xy)))
    return xy[np.sort(first[first < len(xy)])]


# --------------------------------------------------------------------------- p, u
def p(xyz: npt.ArrayLike, curve: TransportCurve) -> FloatArray:
    """Profile curve ``p``: ``(distance from the curve's axis, z)`` of every point.

    Examples
    --------
    >>> c = TransportCurve(center=(1.0, 0.0), radius=2.0)
    >>> p([[3, 0, 5], [1, 0.5, 7]], c).tolist()
    [[2.0, 5.0], [0.5, 7.0]]
    """
    a = np.asarray(xyz, dtype=np.float64)
    out = np.empty((len(a), 2))
    out[:, 0] = curve.distance(a[:, :2])
    out[:, 1] = a[:, 2]
    return out


def u(xyz: npt.ArrayLike, curve: TransportCurve) -> FloatArray:
    """Circular un-warping ``u``: ``(arc length along the curve, z)`` of every point.

    The arc length is measured on the curve itself (radius x angle for a circle, along
    the sides for a polygon) and starts just after the widest empty angular gap of the
    points, so a partial ring (a curved arcade) un-warps without a seam inside it.

    Examples
    --------
    >>> c = TransportCurve(center=(0.0, 0.0), radius=2.0)
    >>> xyz = [[0, 2, 0], [2, 0, 1], [0, -3, 2], [1.4142, 1.4142, 3]]  # 90, 0, -90, 45 deg
    >>> np.round(u(xyz, c), 4).tolist()
    [[6.2832, 0.0], [3.1416, 1.0], [0.0, 2.0], [4.7124, 3.0]]
    """
    a = np.asarray(xyz, dtype=np.float64)
    s = curve.position(a[:, :2])
    per = curve.perimeter
    if len(s) >= 2:
        srt = np.sort(s)
        gaps = np.diff(np.r_[srt, srt[0] + per])
        k = int(np.argmax(gaps))
        start = srt[(k + 1) % len(srt)]
        s = s - start  # in (-per, per): wrap with one add, not np.mod
        s += np.where(s < 0.0, per, 0.0)
    elif len(s):
        s = np.zeros_like(s)
    out = np.empty((len(a), 2))
    out[:, 0] = s
    out[:, 1] = a[:, 2]
    return out


# --------------------------------------------------------------------------- v2, rho
@dataclass(frozen=True, kw_only=True, eq=False)
class Histogram:
    """The limited-bin histogram of ``v2`` and the fine one it came from.

    Attributes
    ----------
    edges : ndarray of shape (n_bins + 1,)
    values : ndarray of shape (n_bins,)
        Limited-bin signal: mean of the smoothed fine signal over each bin.
    fine_edges : ndarray of shape (n_fine + 1,)
    fine_values : ndarray of shape (n_fine,)
        The fine, lightly smoothed signal (peaks are refined on it).
    n_zero_crossings : int
        Sign changes of the fine signal's derivative (sets ``n_bins``).
    """

    edges: FloatArray
    values: FloatArray
    fine_edges: FloatArray
    fine_values: FloatArray
    n_zero_crossings: int

    @property
    def n_bins(self) -> int:
        return len(self.values)


def _fine_bins(n: int) -> int:
    return int(np.clip(round(math.sqrt(max(n, 1))), 16, 512))


def v2(
    x: npt.ArrayLike,
    values: npt.ArrayLike | None = None,
    *,
    statistic: Literal["count", "max"] = "count",
    n_fine: int | None = None,
    sigma: float = 1.0,
    bins_per_crossing: float = 1.0,
) -> Histogram:
    """Limited-bin histogram ``v2`` of positions ``x``.

    A fine histogram (``n_fine`` bins, default ``sqrt(n)`` clipped to 16..512) holds, per
    bin, either the point count (``statistic="count"``) or the largest of ``values``
    (``"max"``: the profile curve's outline, empty bins set to the signal's minimum so a
    gap is a valley). It is smoothed with a Gaussian of ``sigma`` fine bins; the number of
    sign changes of its derivative plus one, times ``bins_per_crossing``, is the number of
    limited bins (the paper's rule; at least 3, so one peak can show); each limited bin holds the mean of the smoothed fine values
    it covers.

    Parameters
    ----------
    x : array-like of shape (n_points,)
    values : array-like of shape (n_points,), optional
        Needed for ``statistic="max"``.
    statistic : {"count", "max"}
    n_fine : int, optional
    sigma : float
    bins_per_crossing : float

    Returns
    -------
    Histogram

    Examples
    --------
    >>> x = np.r_[np.zeros(5), np.ones(2), 2 * np.ones(5)]
    >>> hh = v2(x, n_fine=16, sigma=0.0)   # fine counts 5, 0.., 2, 0.., 5
    >>> hh.n_zero_crossings, hh.n_bins
    (3, 4)
    >>> hh.values.round(2).tolist()
    [1.25, 0.0, 0.5, 1.25]
    """
    xs = np.asarray(x, dtype=np.float64)
    nf = _fine_bins(len(xs)) if n_fine is None else int(n_fine)
    lo, hi = (float(xs.min()), float(xs.max())) if len(xs) else (0.0, 1.0)
    if hi <= lo:
        hi = lo + 1.0
    b = np.clip(((xs - lo) / (hi - lo) * nf).astype(np.int64), 0, nf - 1)
    if statistic == "count":
        f = np.bincount(b, minlength=nf).astype(np.float64)
    elif statistic == "max":
        if values is None:
            raise ValueError("v2 with statistic='max' needs values")
        f = np.full(nf, -np.inf)
        np.maximum.at(f, b, np.asarray(values, dtype=np.float64))
        empty = ~np.isfinite(f)
        f[empty] = f[~empty].min() if (~empty).any() else 0.0
    else:
        raise ValueError(f"The 'statistic' parameter of v2 must be 'count' or 'max'. Got {statistic!r} instead.")
    return limited(f, lo, hi, sigma=sigma, bins_per_crossing=bins_per_crossing)


def limited(f: FloatArray, lo: float, hi: float, *, sigma: float = 1.0, bins_per_crossing: float = 1.0) -> Histogram:
    """The limited-bin histogram of a fine signal ``f`` (equal bins from ``lo`` to ``hi``):
    ``v2``'s second half, for a fine signal made otherwise (:func:`tree.sequences.occupancy_cut`)."""
    nf = len(f)
    fine_edges = np.linspace(lo, hi, nf + 1)
    g = gaussian_filter1d(f, sigma, mode="nearest") if sigma > 0 else f
    sg = np.sign(np.diff(g))
    sg = sg[sg != 0]
    z = int(np.count_nonzero(sg[1:] != sg[:-1]))
    nb = int(np.clip(round(bins_per_crossing * (z + 1)), min(3, nf), nf))
    edges = np.linspace(lo, hi, nb + 1)
    cb = np.minimum(np.arange(nf) * nb // nf, nb - 1)
    vals = np.bincount(cb, g, minlength=nb) / np.maximum(np.bincount(cb, minlength=nb), 1)
    return Histogram(edges=edges, values=vals, fine_edges=fine_edges, fine_values=g,
                     n_zero_crossings=z)


def rho(hist: Histogram, *, prominence: float = 0.1) -> FloatArray:
    """Peak finding ``rho``: cut positions at the limited histogram's peaks.

    Peaks are ``scipy.signal.find_peaks`` maxima of ``hist.values`` whose prominence is at
    least ``prominence`` x the larger of the signal's range and its largest absolute value
    (an edge bin is never a peak). Each peak is
    refined inside its bin: the position of the fine signal's maximum within the bin,
    with a parabola through that fine bin and its neighbours.

    Returns
    -------
    cuts : ndarray of shape (n_peaks,), sorted

    Examples
    --------
    >>> x = np.r_[np.zeros(5), np.ones(9), 2 * np.ones(5)]
    >>> rho(v2(x, n_fine=16, sigma=0.0)).round(4).tolist()   # fine bin [1, 1.125)
    [1.0625]
    """
    return _refine(hist, peak_bins(hist, prominence=prominence))


def peak_bins(hist: Histogram, *, prominence: float = 0.1) -> IntArray:
    """The limited bins that are peaks for :func:`rho` (sorted; none for fewer than 3 bins
    or a flat signal)."""
    vals = hist.values
    if len(vals) < 3:
        return np.empty(0, dtype=np.int64)
    span = float(vals.max() - vals.min())
    if span <= 0:
        return np.empty(0, dtype=np.int64)
    # Relative to the signal's level too, so the wiggles of a flat histogram are no peaks.
    peaks, _ = find_peaks(vals, prominence=prominence * max(span, float(np.abs(vals).max())))
    return peaks.astype(np.int64)


def _refine(hist: Histogram, peaks: IntArray) -> FloatArray:
    """Exact positions of the peaks found in limited bins ``peaks``.

    Each peak's fine maximum is looked for inside its own bin; the fine signal between
    two neighbouring peaks is split at its minimum (the valley), so every peak owns a
    region. The position is the centre of the run around the maximum where the fine
    signal stays above a quarter of the way from the higher of the region's two valleys
    to the maximum: the middle of a plateau (a pier, a balcony), not a spike on its edge.
    """
    start, stop = plateaus(hist, peaks, level=0.25)
    return 0.5 * (start + stop)


def plateaus(hist: Histogram, peaks: npt.ArrayLike, *, level: float = 0.25, per_side: bool = False,
             min_drop: float = 0.0, robust: bool = False) -> tuple[FloatArray, FloatArray]:
    """Start and end of the plateau around each peak of limited bins ``peaks``: the run
    around the peak's fine maximum where the fine signal stays above ``level`` of the way
    from the higher of its region's two valleys to the maximum (:func:`rho` cuts at the
    run's middle with ``level`` 0.25). ``per_side``: each end's level is measured from the
    valley on its own side (a band between a low and a high stretch has both ends); an
    end whose valley lies less than ``min_drop`` of the top below it is NaN (no end).

    ``robust``: the top is the plateau's median (the fine signal over the run above half
    way from the higher valley to the maximum), not its maximum, and each end is the
    outermost fine bin between the peak and that side's valley at or above the level: a
    spike on the plateau's edge, or a shallow dip inside it, does not end the plateau
    early (the bands of :func:`tree.sequences.occupancy_cut`)."""
    fe, fv = hist.fine_edges, hist.fine_values
    nf = len(fv)
    tops = []
    for k in peaks:
        b0 = min(int(np.searchsorted(fe, hist.edges[k], side="left")), nf - 1)
        b1 = max(min(int(np.searchsorted(fe, hist.edges[k + 1], side="left")), nf), b0 + 1)
        tops.append(b0 + int(np.argmax(fv[b0:b1])))
    valleys = [0]
    for a, b in zip(tops[:-1], tops[1:], strict=True):
        valleys.append(a + int(np.argmin(fv[a:b + 1])) if b > a else a)
    valleys.append(nf - 1)
    start, stop = [], []
    for i, j in enumerate(tops):
        lo, hi = valleys[i], max(valleys[i + 1], j)
        left, right = float(fv[lo:j + 1].min()), float(fv[j:hi + 1].min())
        if not per_side:
            left = right = max(left, right)
        top = float(fv[j])
        if robust:
            half = max(left, right) + 0.5 * (top - max(left, right))
            a, b = _run_above(fv, j, lo, hi, half, half)
            top = float(np.median(fv[a:b + 1]))
        cut_a, cut_b = left + level * (top - left), right + level * (top - right)
        if robust:
            a = lo + int(np.argmax(fv[lo:j + 1] >= cut_a))
            b = hi - int(np.argmax(fv[j:hi + 1][::-1] >= cut_b))
        else:
            a, b = _run_above(fv, j, lo, hi, cut_a, cut_b)
        start.append(fe[a] if top - left >= min_drop * top else np.nan)
        stop.append(fe[b + 1] if top - right >= min_drop * top else np.nan)
    return np.asarray(start, dtype=np.float64), np.asarray(stop, dtype=np.float64)


def _run_above(fv: FloatArray, j: int, lo: int, hi: int, cut_a: float, cut_b: float) -> tuple[int, int]:
    """First and last fine bin of the run around ``j`` (within ``lo..hi``) where ``fv``
    stays at or above ``cut_a`` (on the low side) and ``cut_b`` (on the high side)."""
    a = j
    while a > lo and fv[a - 1] >= cut_a:
        a -= 1
    b = j
    while b < hi and fv[b + 1] >= cut_b:
        b += 1
    return a, b


def split_at(x: npt.ArrayLike, cuts: npt.ArrayLike) -> list[IntArray]:
    """Children of a split: indices of the points between consecutive cuts (empty ones
    dropped), in order of position.

    Examples
    --------
    >>> [c.tolist() for c in split_at([0.5, 2.5, 1.5, 0.1, 9.0], [1.0, 2.0, 3.0])]
    [[0, 3], [2], [1], [4]]
    """
    xs = np.asarray(x, dtype=np.float64)
    c = np.sort(np.asarray(cuts, dtype=np.float64))
    return _groups(np.searchsorted(c, xs, side="right"), len(c) + 1)


def _groups(lab: IntArray, n_groups: int) -> list[IntArray]:
    """Indices of each label ``0..n_groups-1`` (empty groups dropped), each in index
    order: one stable sort of small integers (a radix sort) and their counts."""
    if not len(lab):
        return []
    small = lab.astype(np.int16 if n_groups < 2**15 else np.int64)
    order = np.argsort(small, kind="stable")
    bounds = np.r_[0, np.cumsum(np.bincount(lab, minlength=n_groups))]
    out = [order[bounds[i]:bounds[i + 1]].astype(np.int64) for i in range(n_groups)]
    return [g for g in out if len(g)]
