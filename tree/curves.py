"""The transport curves of :func:`tree.operators.psi`: a circle or a regular polygon fitted
to a footprint by RANSAC with a least-squares refit (:func:`fit_circle`, :func:`fit_ngon`)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from hollowtree.arrays import FloatArray
from hollowtree.columns import column_span
from hollowtree.primitives.shapes import FailedFit

__all__ = ["DEFAULT_SIDES", "TransportCurve", "fit_circle", "fit_ngon"]

RngLike = int | np.random.Generator | np.random.SeedSequence | None

#: Polygons tried by :func:`psi` after the circle (square, hexagonal, octagonal plans).
DEFAULT_SIDES: tuple[int, ...] = (4, 6, 8)
#: ``psi``, ``fit_circle`` and ``fit_ngon`` work on a random sample of at most this many
#: footprint points (hypotheses, refits, inlier fraction and RMS): a 100 k-point segment
#: costs what a 2 k-point one does.
_FIT_SAMPLE = 2048
#: Points of that sample that score the circle hypotheses, and the polygon hypotheses.
_SCORE_SAMPLE = 1024
_SCORE_SAMPLE_NGON = 512
#: Hypotheses scored at a time (the adaptive stop is checked after each batch).
_CHUNK = 32
#: Confidence of RANSAC's adaptive stop.
_CONFIDENCE = 0.999



# --------------------------------------------------------------------------- psi
@dataclass(frozen=True, kw_only=True)
class TransportCurve:
    """A circle or a regular polygon in the horizontal plane: the transport curve.

    Attributes
    ----------
    center : tuple of 2 floats
    radius : float
        Circle radius, or the polygon's apothem (centre to the middle of a side).
    n_sides : int
        0 for a circle, otherwise the number of sides of the regular polygon.
    angle : float
        Polygon only: direction (radians) of the outward normal of one side.
    inlier_fraction : float
        Share of the footprint within the residual threshold of the curve.
    rms : float
        Root mean square residual of the inliers, metres.
    """

    center: tuple[float, float]
    radius: float
    n_sides: int = 0
    angle: float = 0.0
    inlier_fraction: float = 1.0
    rms: float = 0.0

    def _polar(self, xy: FloatArray) -> tuple[FloatArray, FloatArray]:
        q = np.asarray(xy, dtype=np.float64)
        dx, dy = q[:, 0] - self.center[0], q[:, 1] - self.center[1]
        return np.hypot(dx, dy), np.arctan2(dy, dx)

    def _face_angle(self, theta: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Side index and the angle from that side's normal, in [-pi/n, pi/n)."""
        step = 2.0 * math.pi / self.n_sides
        rel = np.mod(theta - self.angle + 0.5 * step, 2.0 * math.pi)
        k = np.floor(rel / step)
        return k, rel - k * step - 0.5 * step

    def distance(self, xy: npt.ArrayLike) -> FloatArray:
        """Distance of each point from the axis in the curve's own metric.

        A circle gives the Euclidean distance from the centre; a polygon the distance
        along the nearest side's normal, so every point of a prism's side has the same
        distance (the apothem).
        """
        q = np.asarray(xy, dtype=np.float64)
        if self.n_sides == 0:
            return np.hypot(q[:, 0] - self.center[0], q[:, 1] - self.center[1])
        r, theta = self._polar(q)
        _, phi = self._face_angle(theta)
        return np.asarray(r * np.cos(phi))

    def position(self, xy: npt.ArrayLike) -> FloatArray:
        """Position along the curve, metres from the angle 0 (circle) or from the start of
        side 0 (polygon); in ``[0, perimeter)``."""
        q = np.asarray(xy, dtype=np.float64)
        theta = np.arctan2(q[:, 1] - self.center[1], q[:, 0] - self.center[0])
        if self.n_sides == 0:
            # theta is in [-pi, pi]: one add instead of np.mod (a slow ufunc).
            theta += np.where(theta < 0.0, 2.0 * math.pi, 0.0)
            return np.asarray(theta * self.radius)
        t = math.tan(math.pi / self.n_sides)
        k, phi = self._face_angle(theta)
        return np.asarray(self.radius * (2.0 * t * k + t + np.tan(phi)))

    @property
    def perimeter(self) -> float:
        if self.n_sides == 0:
            return 2.0 * math.pi * self.radius
        return 2.0 * self.n_sides * self.radius * math.tan(math.pi / self.n_sides)

    def residuals(self, xy: npt.ArrayLike) -> FloatArray:
        return np.abs(self.distance(xy) - self.radius)


def _circles_through(a: FloatArray, b: FloatArray, c: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Centres (m, 2) and radii (m,) of the circles through triples of points (NaN if collinear)."""
    bx, by = b[:, 0] - a[:, 0], b[:, 1] - a[:, 1]
    cx, cy = c[:, 0] - a[:, 0], c[:, 1] - a[:, 1]
    det = 2.0 * (bx * cy - by * cx)
    with np.errstate(divide="ignore", invalid="ignore"):
        ux = (cy * (bx**2 + by**2) - by * (cx**2 + cy**2)) / det
        uy = (bx * (cx**2 + cy**2) - cx * (bx**2 + by**2)) / det
    return np.stack([ux + a[:, 0], uy + a[:, 1]], axis=1), np.hypot(ux, uy)


def _kasa(xy: FloatArray) -> tuple[FloatArray, float]:
    """Algebraic least-squares circle (Kasa), then a few Gauss-Newton steps on the
    geometric residual."""
    m = xy.mean(axis=0)
    q = xy - m
    a = np.column_stack([q, np.ones(len(q))])
    b = (q**2).sum(axis=1)
    sol = np.linalg.lstsq(a, b, rcond=None)[0]
    c = 0.5 * sol[:2]
    r = math.sqrt(max(sol[2] + c @ c, 1e-300))
    for _ in range(5):
        d = q - c
        rr = np.hypot(d[:, 0], d[:, 1])
        ok = rr > 1e-12
        jac = np.column_stack([-d[ok] / rr[ok, None], -np.ones(int(ok.sum()))])
        res = rr[ok] - r
        step = np.linalg.lstsq(jac, -res, rcond=None)[0]
        c, r = c + step[:2], r + float(step[2])
        if np.abs(step).max() < 1e-9:
            break
    return c + m, abs(r)


def _span(a: FloatArray) -> FloatArray:
    """``a.max(axis=0) - a.min(axis=0)`` of an (n, k) array in float64 (:func:`column_span`);
    zeros for no rows."""
    if not len(a):
        return np.zeros(a.shape[1])
    return column_span(np.asarray(a, dtype=np.float64))


def _threshold(xy: FloatArray, residual_threshold: float | None) -> float:
    if residual_threshold is not None:
        return float(residual_threshold)
    extent = float(np.hypot(*_span(xy)[:2])) if len(xy) else 0.0
    return max(0.02, 0.01 * extent)


def _subsample(pts: FloatArray, k: int, rng: np.random.Generator) -> FloatArray:
    """``pts`` itself when it holds at most ``k`` points, else ``k`` of them drawn without
    replacement, in random order."""
    if len(pts) <= k:
        return pts
    return pts[rng.choice(len(pts), k, replace=False)]


def _trials_needed(inlier_ratio: float, sample_size: int) -> float:
    """RANSAC's adaptive trial count: hypotheses needed to draw one all-inlier sample of
    ``sample_size`` points with probability :data:`_CONFIDENCE`."""
    w = inlier_ratio**sample_size
    if w >= 1.0:
        return 1.0
    if w <= 0.0:
        return math.inf
    return math.log(1.0 - _CONFIDENCE) / math.log1p(-w)


def fit_circle(
    xy: npt.ArrayLike,
    *,
    residual_threshold: float | None = None,
    max_trials: int = 256,
    rng: RngLike = None,
) -> TransportCurve | FailedFit:
    """Circle RANSAC on a footprint: 3-point hypotheses, the one with most inliers, refit.

    The fit works on a random sample of at most :data:`_FIT_SAMPLE` footprint points
    (the threshold uses the whole footprint's extent): hypotheses are scored on
    :data:`_SCORE_SAMPLE` of them, 32 at a time (squared distances from one matrix
    product), and the search stops early once the best hypothesis' inlier ratio ``w``
    makes ``max_trials`` more than enough (``1 - (1 - w^3)^trials >= 0.999``). The best
    circle is refitted twice on its inliers (Kasa, then Gauss-Newton on the geometric
    residual); the inlier fraction and RMS are those of the sample.

    Parameters
    ----------
    xy : array-like of shape (n_points, 2)
    residual_threshold : float, optional
        Inlier distance, metres; default 1 % of the footprint's diagonal, at least 2 cm.
    max_trials : int
        Most hypotheses drawn.
    rng : int, Generator or None

    Returns
    -------
    TransportCurve or FailedFit

    Examples
    --------
    >>> t = np.linspace(0, 2 * np.pi, 6, endpoint=False)
    >>> xy = np.column_stack([1 + 2 * np.cos(t), -1 + 2 * np.sin(t)])
    >>> c = fit_circle(xy, rng=0)
    >>> np.round(c.center, 6).tolist(), round(c.radius, 6)
    ([1.0, -1.0], 2.0)
    """
    pts = np.asarray(xy, dtype=np.float64)
    if len(pts) < 3:
        return FailedFit(reason=f"a circle needs 3 points; got {len(pts)}")
    rng = np.random.default_rng(rng)
    thr = _threshold(pts, residual_threshold)
    fit = _subsample(pts, _FIT_SAMPLE, rng)
    m = np.array([fit[:, 0].mean(), fit[:, 1].mean()])
    q = fit - m  # centred: the squared-distance expansion below keeps its precision
    sc = _subsample(q, _SCORE_SAMPLE, rng)
    sc2 = (sc**2).sum(axis=1)
    idx = rng.integers(0, len(q), size=(max_trials, 3))
    centres, radii = _circles_through(q[idx[:, 0]], q[idx[:, 1]], q[idx[:, 2]])
    ok = np.isfinite(radii) & (radii > thr)
    if not ok.any():
        return FailedFit(reason="every sampled triple is collinear or degenerate")
    centres, radii = centres[ok], radii[ok]
    lo2, hi2 = (radii - thr) ** 2, (radii + thr) ** 2  # |d - r| < thr, as r > thr
    best, best_count = -1, -1
    for start in range(0, len(radii), _CHUNK):
        sl = slice(start, start + _CHUNK)
        cc = centres[sl]
        d2 = sc2[None, :] - 2.0 * (cc @ sc.T) + (cc**2).sum(axis=1)[:, None]
        counts = ((d2 > lo2[sl, None]) & (d2 < hi2[sl, None])).sum(axis=1)
        k = int(np.argmax(counts))
        if counts[k] > best_count:
            best, best_count = start + k, int(counts[k])
        if start + _CHUNK >= _trials_needed(best_count / len(sc), 3):
            break
    c, r = centres[best], float(radii[best])
    for _ in range(2):  # refit on the inliers, inliers recomputed
        inl = np.abs(np.hypot(q[:, 0] - c[0], q[:, 1] - c[1]) - r) < thr
        if inl.sum() < 3:
            return FailedFit(reason="the best circle has fewer than 3 inliers")
        c, r = _kasa(q[inl])
    res = np.abs(np.hypot(q[:, 0] - c[0], q[:, 1] - c[1]) - r)
    inl = res < thr
    if inl.sum() < 3:
        return FailedFit(reason="the refitted circle has fewer than 3 inliers")
    return TransportCurve(center=(float(c[0] + m[0]), float(c[1] + m[1])), radius=r,
                          inlier_fraction=float(inl.mean()),
                          rms=float(np.sqrt(np.mean(res[inl] ** 2))))


def _polygon_distance(q: FloatArray, c: FloatArray, angle: FloatArray | float,
                      n_sides: int) -> tuple[FloatArray, FloatArray]:
    """Polygonal distance of points ``q`` (..., S, 2) from centres ``c`` (..., 2) and the
    angle of each point's side normal; ``angle`` broadcasts like ``c[..., 0]``."""
    step = 2.0 * math.pi / n_sides
    dx, dy = q[..., 0] - c[..., 0, None], q[..., 1] - c[..., 1, None]
    r, th = np.hypot(dx, dy), np.arctan2(dy, dx)
    a = np.asarray(angle, dtype=np.float64)[..., None]
    phi = np.mod(th - a + 0.5 * step, step) - 0.5 * step
    return r * np.cos(phi), th - phi


def fit_ngon(
    xy: npt.ArrayLike,
    *,
    n_sides: int,
    start: TransportCurve | None = None,
    residual_threshold: float | None = None,
    max_trials: int = 64,
    rng: RngLike = None,
) -> TransportCurve | FailedFit:
    """Regular ``n_sides``-gon RANSAC on a footprint.

    A hypothesis is a centre (from a 3-point circle, or ``start``'s centre), an orientation
    (the phase of the n-th angular harmonic of the radius around that centre: a regular
    polygon's radius peaks at its corners) and an apothem (the median polygonal distance).
    As :func:`fit_circle`, the fit works on a sample of at most :data:`_FIT_SAMPLE`
    points, scores hypotheses (``start`` first, then 16 at a time, vectorised) on
    :data:`_SCORE_SAMPLE_NGON` of them and stops early by the same rule. The hypothesis with
    most inliers is refined by three Gauss-Newton steps (analytic Jacobian) on the
    inliers' residuals.

    Parameters
    ----------
    xy : array-like of shape (n_points, 2)
    n_sides : int
        At least 3.
    start : TransportCurve, optional
        A circle already fitted (its centre is the first hypothesis).
    residual_threshold, max_trials, rng
        As :func:`fit_circle`.

    Examples
    --------
    >>> t = np.linspace(0, 2 * np.pi, 8, endpoint=False)
    >>> corners = np.column_stack([np.cos(t), np.sin(t)])
    >>> s = np.linspace(0, 1, 7)[:, None, None]
    >>> xy = (corners[None] * (1 - s) + np.roll(corners, -1, axis=0)[None] * s).reshape(-1, 2)
    >>> g = fit_ngon(xy, n_sides=8, rng=0)
    >>> round(g.radius, 4), round(g.rms, 6)
    (0.9239, 0.0)
    """
    pts = np.asarray(xy, dtype=np.float64)
    if n_sides < 3:
        raise ValueError(f"The 'n_sides' parameter of fit_ngon must be an int >= 3. Got {n_sides} instead.")
    if len(pts) < 4:
        return FailedFit(reason=f"a polygon needs 4 points; got {len(pts)}")
    rng = np.random.default_rng(rng)
    thr = _threshold(pts, residual_threshold)
    step = 2.0 * math.pi / n_sides
    fit = _subsample(pts, _FIT_SAMPLE, rng)
    m = np.array([fit[:, 0].mean(), fit[:, 1].mean()])
    q = fit - m
    sc = _subsample(q, _SCORE_SAMPLE_NGON, rng)
    idx = rng.integers(0, len(q), size=(max_trials, 3))
    centres, radii = _circles_through(q[idx[:, 0]], q[idx[:, 1]], q[idx[:, 2]])
    centres = centres[np.isfinite(radii)]
    if start is not None:
        centres = np.vstack([np.asarray(start.center, dtype=np.float64)[None] - m, centres])
    if not len(centres):
        return FailedFit(reason="no centre hypothesis")

    best_c, best_a, best_ang, best_count = centres[0], 0.0, 0.0, -1
    for lo in range(0, len(centres), 16):
        cc = centres[lo:lo + 16]
        dx, dy = sc[None, :, 0] - cc[:, 0, None], sc[None, :, 1] - cc[:, 1, None]
        r, th = np.hypot(dx, dy), np.arctan2(dy, dx)
        # Phase of the n-th harmonic of the radius: the corners' direction.
        corner = np.arctan2((r * np.sin(n_sides * th)).sum(axis=1),
                            (r * np.cos(n_sides * th)).sum(axis=1)) / n_sides
        ang = corner + math.pi / n_sides
        phi = np.mod(th - ang[:, None] + 0.5 * step, step) - 0.5 * step
        dist = r * np.cos(phi)
        apo = np.median(dist, axis=1)
        counts = (np.abs(dist - apo[:, None]) < thr).sum(axis=1)
        k = int(np.argmax(counts))
        if counts[k] > best_count:
            best_c, best_a, best_ang, best_count = cc[k], float(apo[k]), float(ang[k]), int(counts[k])
        if lo + 16 >= _trials_needed(best_count / len(sc), 3):
            break
    params = np.array([best_c[0], best_c[1], best_a, best_ang])
    for _ in range(3):  # Gauss-Newton on (cx, cy, apothem, angle) over the inliers
        dist, nrm = _polygon_distance(q, params[:2], params[3], n_sides)
        inl = np.abs(dist - params[2]) < thr
        if inl.sum() < 4:
            return FailedFit(reason="the best polygon has fewer than 4 inliers")
        qi, ni = q[inl], nrm[inl]
        cn, sn = np.cos(ni), np.sin(ni)
        dx, dy = qi[:, 0] - params[0], qi[:, 1] - params[1]
        jac = np.column_stack([-cn, -sn, -np.ones(len(qi)), -dx * sn + dy * cn])
        delta = np.linalg.lstsq(jac, -(dist[inl] - params[2]), rcond=None)[0]
        params = params + delta
        params[2] = abs(params[2])
        params[3] = np.mod(params[3], step)
    dist, _ = _polygon_distance(q, params[:2], params[3], n_sides)
    res = np.abs(dist - params[2])
    inl = res < thr
    if inl.sum() < 4:
        return FailedFit(reason="the refined polygon has fewer than 4 inliers")
    return TransportCurve(center=(float(params[0] + m[0]), float(params[1] + m[1])),
                          radius=float(params[2]), n_sides=n_sides, angle=float(params[3]),
                          inlier_fraction=float(inl.mean()),
                          rms=float(np.sqrt(np.mean(res[inl] ** 2))))
