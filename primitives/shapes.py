"""Geometric primitives for Efficient RANSAC: minimal sets, distances, bitmaps, refits.

Every primitive is a flat parameter vector (``float64``), batched as rows of a
``(n_candidates, 8)`` array so that hundreds of candidates are built, verified and
scored with a few matrix products. Layout per kind (unused slots are zero):

========  ==========================================  =============================
kind      params                                      minimal set (points + normals)
========  ==========================================  =============================
plane     ``nx, ny, nz, d`` (``n . x + d = 0``)         3 points
sphere    ``cx, cy, cz, radius``                      2 points + normals
cylinder  ``px, py, pz, ax, ay, az, radius``          2 points + normals
cone      ``apex (3), axis (3), half_angle (rad)``    3 points + normals
torus     ``centre (3), axis (3), R, r``              4 points + normals
========  ==========================================  =============================

The cylinder's ``p`` is a point on the axis; ``a`` is a unit vector. The cone's axis
points from the apex into the cone (only that nappe is a surface). The torus has major
radius ``R`` (of the tube circle about the axis) and minor radius ``r`` (of the tube),
``R > r > 0``; its geometry lives in :mod:`primitives.torus`. Tori are in :data:`KINDS`
but not in :data:`DEFAULT_KINDS`, the kinds searched unless asked (see
:mod:`primitives.ransac`).

Normals are unoriented (PCA normals): every normal test uses ``|cos|``.

Examples
--------
>>> pts = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
>>> nrm = np.tile([0.0, 0, 1], (3, 1))
>>> params, ok = candidates_from_minimal_sets("plane", pts[None], nrm[None])
>>> ok.tolist(), np.round(np.abs(params[0, :4]), 6).tolist()
([True], [0.0, 0.0, 1.0, 0.0])
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.optimize import least_squares

from hollowtree.primitives.coarse_params import DEFAULT_KINDS, KINDS
from hollowtree.primitives.torus import (
    torus_distance_and_cosine,
    torus_from_minimal_sets,
    torus_residuals,
    torus_surface_coordinates,
)

__all__ = [
    "DEFAULT_KINDS",
    "KINDS",
    "MINIMAL_SET_SIZE",
    "PARAM_NAMES",
    "FailedFit",
    "PrimitiveFit",
    "candidates_from_minimal_sets",
    "distance_and_cosine",
    "compatible",
    "surface_coordinates",
    "refine_params",
    "fit_primitive",
]

F64 = npt.NDArray[np.float64]

#: Points (with normals) that determine one candidate of each kind.
MINIMAL_SET_SIZE = {"plane": 3, "sphere": 2, "cylinder": 2, "cone": 3, "torus": 4}
#: Meaning of :attr:`PrimitiveFit.params`, per kind.
PARAM_NAMES = {
    "plane": ("nx", "ny", "nz", "d"),
    "sphere": ("cx", "cy", "cz", "radius"),
    "cylinder": ("px", "py", "pz", "ax", "ay", "az", "radius"),
    "cone": ("apex_x", "apex_y", "apex_z", "ax", "ay", "az", "half_angle"),
    "torus": ("cx", "cy", "cz", "ax", "ay", "az", "major_radius", "minor_radius"),
}
N_PARAMS = 8
_TINY = 1e-12
# A cone is only a cone between these half-angles; outside it is a cylinder or a plane.
CONE_MIN_ANGLE = math.radians(3.0)
CONE_MAX_ANGLE = math.radians(80.0)


@dataclass(frozen=True, kw_only=True)
class FailedFit:
    """A fit that did not succeed; falsy, with the reason (skimage ``FailedEstimation``).

    Examples
    --------
    >>> bool(FailedFit(reason="too few points"))
    False
    """

    reason: str

    def __bool__(self) -> bool:
        return False


@dataclass(frozen=True, kw_only=True)
class PrimitiveFit:
    """One fitted primitive.

    Parameters
    ----------
    kind : {"plane", "sphere", "cylinder", "cone", "torus"}
    params : tuple of float
        Per kind (see :data:`PARAM_NAMES`): plane ``(nx, ny, nz, d)`` with a unit normal
        and ``n . x + d = 0``; sphere ``(cx, cy, cz, radius)``; cylinder
        ``(px, py, pz, ax, ay, az, radius)``, ``p`` the axis point nearest the inliers'
        centroid and ``a`` the unit axis; cone ``(apex, axis, half_angle)`` with the unit
        axis pointing into the cone and the half-angle in radians; torus
        ``(cx, cy, cz, ax, ay, az, major_radius, minor_radius)``. Coordinates are those
        of the ``xyz`` given to the fit.
    n_points : int
        Number of inliers.
    rms : float
        Root mean square distance of the inliers to the surface.

    Examples
    --------
    >>> fit = PrimitiveFit(kind="sphere", params=(0.0, 0.0, 0.0, 2.0), n_points=6, rms=0.01)
    >>> PrimitiveFit.from_dict(fit.to_dict()) == fit, fit.named()["radius"]
    (True, 2.0)
    """

    kind: str
    params: tuple[float, ...]
    n_points: int
    rms: float

    def named(self) -> dict[str, float]:
        """The parameters keyed by their names in :data:`PARAM_NAMES`."""
        return dict(zip(PARAM_NAMES[self.kind], self.params, strict=True))

    def to_dict(self) -> dict[str, Any]:
        """Plain-Python form (JSON-ready)."""
        return {"kind": self.kind, "params": [float(p) for p in self.params],
                "n_points": int(self.n_points), "rms": float(self.rms)}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> PrimitiveFit:
        """Inverse of :meth:`to_dict`."""
        return cls(kind=str(d["kind"]), params=tuple(float(p) for p in d["params"]),
                   n_points=int(d["n_points"]), rms=float(d["rms"]))


# ----------------------------------------------------------------------------- helpers
def _unit(v: F64) -> tuple[F64, F64]:
    norm = np.linalg.norm(v, axis=-1)
    return v / np.maximum(norm, _TINY)[..., None], norm


def _dot(u: F64, x: F64) -> F64:
    """``u . x`` for candidates ``u (K, 3)`` and points ``x``: shared ``(M, 3)`` -> ``(K, M)``,
    or each candidate's own points ``(K, k, 3)`` -> ``(K, k)``."""
    if x.ndim == 2:
        return u @ x.T
    return np.einsum("kj,kij->ki", u, x)


def _canonical_sign(v: F64) -> F64:
    """Flip unit vectors so the last clearly non-zero component (z, then y, x) is > 0."""
    out = v.copy()
    for j in (2, 1, 0):
        undecided = np.abs(out[..., j]) > 1e-9
        flip = undecided & (out[..., j] < 0)
        out[flip] *= -1
        if undecided.all():
            break
    return out


def _basis(axis: F64) -> tuple[F64, F64]:
    """Two unit vectors completing the unit ``axis (3,)`` to an orthonormal basis."""
    helper = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(axis, helper)
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(axis, e1)


# ----------------------------------------------------------------- distance and normal
def distance_and_cosine(kind: str, params: F64, xyz: F64, normals: F64) -> tuple[F64, F64]:
    """Distance to the surface and ``|cos|`` of the normal deviation, for many candidates.

    Parameters
    ----------
    kind : str
        One of :data:`KINDS`.
    params : ndarray of shape (n_candidates, 8)
    xyz, normals : ndarray of shape (n_points, 3) or (n_candidates, k, 3)
        Shared points (every candidate against every point) or each candidate's own points.

    Returns
    -------
    distance, cosine : ndarray of shape (n_candidates, n_points) or (n_candidates, k)

    Examples
    --------
    >>> params = np.array([[0.0, 0, 0, 1, 0, 0, 0, 0]])  # unit sphere at the origin
    >>> d, c = distance_and_cosine("sphere", params, np.array([[0.0, 0, 2]]), np.array([[0.0, 0, 1]]))
    >>> float(d[0, 0]), float(c[0, 0])
    (1.0, 1.0)
    """
    pp = np.einsum("...j,...j->...", xyz, xyz)
    npt_ = np.einsum("...j,...j->...", normals, xyz)
    if kind == "plane":
        n = params[:, :3]
        d = _dot(n, xyz) + params[:, 3:4]
        return np.abs(d), np.abs(_dot(n, normals))
    if kind == "sphere":
        c = params[:, :3]
        v2 = pp - 2.0 * _dot(c, xyz) + np.einsum("kj,kj->k", c, c)[:, None]
        r = np.sqrt(np.maximum(v2, 0.0))
        cos = np.abs(npt_ - _dot(c, normals)) / np.maximum(r, _TINY)
        return np.abs(r - params[:, 3:4]), cos
    if kind == "cylinder":
        p, a = params[:, :3], params[:, 3:6]
        h = _dot(a, xyz) - np.einsum("kj,kj->k", p, a)[:, None]
        v2 = pp - 2.0 * _dot(p, xyz) + np.einsum("kj,kj->k", p, p)[:, None]
        rho = np.sqrt(np.maximum(v2 - h * h, 0.0))
        nw = npt_ - _dot(p, normals) - h * _dot(a, normals)
        return np.abs(rho - params[:, 6:7]), np.abs(nw) / np.maximum(rho, _TINY)
    if kind == "cone":
        c, a, w = params[:, :3], params[:, 3:6], params[:, 6:7]
        h = _dot(a, xyz) - np.einsum("kj,kj->k", c, a)[:, None]
        v2 = np.maximum(pp - 2.0 * _dot(c, xyz) + np.einsum("kj,kj->k", c, c)[:, None], 0.0)
        rho = np.sqrt(np.maximum(v2 - h * h, 0.0))
        cw, sw = np.cos(w), np.sin(w)
        along = h * cw + rho * sw  # position along the generating line from the apex
        dist = np.where(along >= 0.0, np.abs(rho * cw - h * sw), np.sqrt(v2))
        na = _dot(a, normals)
        cos = np.abs(cw * (npt_ - _dot(c, normals) - h * na) / np.maximum(rho, _TINY) - sw * na)
        return dist, cos
    if kind == "torus":
        return torus_distance_and_cosine(params, xyz, normals)
    raise ValueError(f"unknown primitive kind {kind!r}")


def compatible(kind: str, params: F64, xyz: F64, normals: F64, *, epsilon: float, cos_alpha: float,
               sq_norm: F64 | None = None, normal_dot: F64 | None = None) -> npt.NDArray[np.bool_]:
    """Whether each point is within ``epsilon`` of each candidate with ``|cos| > cos_alpha``.

    The same test as :func:`distance_and_cosine`, written with squared distances (no
    square roots or divisions for planes, spheres and cylinders): the scoring kernel.
    Cones and tori use :func:`distance_and_cosine` itself.

    Parameters
    ----------
    kind : str
    params : ndarray of shape (n_candidates, 8)
    xyz, normals : ndarray of shape (n_points, 3)
    epsilon, cos_alpha : float
    sq_norm, normal_dot : ndarray of shape (n_points,), optional
        Precomputed ``|x|^2`` and ``n . x`` of the points.

    Returns
    -------
    ndarray of bool, shape (n_candidates, n_points)

    Examples
    --------
    >>> params = np.array([[0.0, 0, 1, 0, 0, 0, 0, 0]])  # the plane z = 0
    >>> xyz = np.array([[0.0, 0, 0.01], [0, 0, 0.5]])
    >>> compatible("plane", params, xyz, np.tile([0.0, 0, 1], (2, 1)), epsilon=0.1, cos_alpha=0.9).tolist()
    [[True, False]]
    """
    if kind == "plane":
        n = params[:, :3]
        d = xyz @ n.T
        d += params[:, 3]
        c = normals @ n.T
        return ((np.abs(d) < epsilon) & (np.abs(c) > cos_alpha)).T
    if kind == "cone":
        d, c = distance_and_cosine(kind, params, xyz, normals)
        return (d < epsilon) & (c > cos_alpha)
    if kind == "torus":
        d, c = torus_distance_and_cosine(params, xyz, normals, sq_norm=sq_norm, normal_dot=normal_dot)
        return (d < epsilon) & (c > cos_alpha)
    pp = np.einsum("ij,ij->i", xyz, xyz) if sq_norm is None else sq_norm
    npx = np.einsum("ij,ij->i", normals, xyz) if normal_dot is None else normal_dot
    c = params[:, :3]
    cos2 = cos_alpha * cos_alpha
    v2 = xyz @ (-2.0 * c.T)
    v2 += pp[:, None]
    v2 += np.einsum("kj,kj->k", c, c)
    nv = normals @ (-c.T)
    nv += npx[:, None]
    r = params[:, 3] if kind == "sphere" else params[:, 6]
    lo, hi = np.maximum(r - epsilon, 0.0) ** 2, (r + epsilon) ** 2
    if kind == "cylinder":
        a = params[:, 3:6]
        h = xyz @ a.T
        h -= np.einsum("kj,kj->k", c, a)
        nv -= h * (normals @ a.T)
        v2 -= h * h
    elif kind != "sphere":
        raise ValueError(f"unknown primitive kind {kind!r}")
    return ((v2 > lo) & (v2 < hi) & (nv * nv > cos2 * v2)).T


# ------------------------------------------------------------------------ minimal sets
def _closest_points(p1: F64, d1: F64, p2: F64, d2: F64) -> tuple[F64, F64, F64]:
    """Closest points of lines ``p1 + t d1`` and ``p2 + s d2`` (unit directions)."""
    w0 = p1 - p2
    b = np.einsum("kj,kj->k", d1, d2)
    d = np.einsum("kj,kj->k", d1, w0)
    e = np.einsum("kj,kj->k", d2, w0)
    den = 1.0 - b * b
    ok = den > 1e-6
    den = np.where(ok, den, 1.0)
    t = (b * e - d) / den
    s = (e - b * d) / den
    return p1 + t[:, None] * d1, p2 + s[:, None] * d2, ok


def candidates_from_minimal_sets(kind: str, xyz: F64, normals: F64) -> tuple[F64, npt.NDArray[np.bool_]]:
    """Candidate primitives from a batch of minimal sets (Schnabel et al. 2007, §4.2).

    Parameters
    ----------
    kind : str
        One of :data:`KINDS`.
    xyz, normals : ndarray of shape (n_sets, k, 3)
        ``k >= MINIMAL_SET_SIZE[kind]``; the first points build the candidate.

    Returns
    -------
    params : ndarray of shape (n_sets, 8)
    ok : ndarray of bool, shape (n_sets,)
        False where the minimal set is degenerate (parallel normals, collinear points).

    Examples
    --------
    >>> pts = np.array([[[1.0, 0, 0], [0, 1, 0]]])
    >>> params, ok = candidates_from_minimal_sets("sphere", pts, pts)
    >>> ok.tolist(), np.round(params[0, :4], 6).tolist()
    ([True], [0.0, 0.0, 0.0, 1.0])
    """
    n_sets = xyz.shape[0]
    out = np.zeros((n_sets, N_PARAMS))
    p1, p2, n1, n2 = xyz[:, 0], xyz[:, 1], normals[:, 0], normals[:, 1]
    if kind == "plane":
        n, norm = _unit(np.cross(p2 - p1, xyz[:, 2] - p1))
        scale = np.maximum(np.linalg.norm(p2 - p1, axis=1) * np.linalg.norm(xyz[:, 2] - p1, axis=1), _TINY)
        ok = norm > 1e-3 * scale  # not collinear (angle > ~0.06 deg)
        n = _canonical_sign(n)
        out[:, :3], out[:, 3] = n, -np.einsum("kj,kj->k", n, p1)
        return out, ok
    if kind == "sphere":
        q1, q2, ok = _closest_points(p1, n1, p2, n2)
        c = 0.5 * (q1 + q2)
        r = 0.5 * (np.linalg.norm(p1 - c, axis=1) + np.linalg.norm(p2 - c, axis=1))
        out[:, :3], out[:, 3] = c, r
        return out, ok & (r > _TINY)
    if kind == "cylinder":
        a, norm = _unit(np.cross(n1, n2))
        ok = norm > 0.02  # normals more than ~1 deg apart
        # Project onto the plane normal to the axis; the normal lines meet on the axis.
        pr1 = p1 - np.einsum("kj,kj->k", p1, a)[:, None] * a
        pr2 = p2 - np.einsum("kj,kj->k", p2, a)[:, None] * a
        m1, _ = _unit(n1 - np.einsum("kj,kj->k", n1, a)[:, None] * a)
        m2, _ = _unit(n2 - np.einsum("kj,kj->k", n2, a)[:, None] * a)
        q1, q2, ok2 = _closest_points(pr1, m1, pr2, m2)
        p = 0.5 * (q1 + q2)
        r = 0.5 * (np.linalg.norm(pr1 - p, axis=1) + np.linalg.norm(pr2 - p, axis=1))
        out[:, :3], out[:, 3:6], out[:, 6] = p, _canonical_sign(a), r
        return out, ok & ok2 & (r > _TINY)
    if kind == "cone":
        rhs = np.einsum("kij,kij->ki", normals[:, :3], xyz[:, :3])
        mat = normals[:, :3]
        det = np.linalg.det(mat)
        ok = np.abs(det) > 1e-3
        safe = np.where(ok[:, None, None], mat, np.eye(3))
        apex = np.linalg.solve(safe, np.where(ok[:, None], rhs, 0.0)[..., None])[..., 0]
        e, _ = _unit(xyz[:, :3] - apex[:, None, :])
        a, norm = _unit(np.cross(e[:, 1] - e[:, 0], e[:, 2] - e[:, 0]))
        ok &= norm > 1e-6
        a = np.where((np.einsum("kj,kij->k", a, e) < 0)[:, None], -a, a)
        w = np.mean(np.arccos(np.clip(np.einsum("kj,kij->ki", a, e), -1.0, 1.0)), axis=1)
        ok &= (w > CONE_MIN_ANGLE) & (w < CONE_MAX_ANGLE)
        out[:, :3], out[:, 3:6], out[:, 6] = apex, a, w
        return out, ok
    if kind == "torus":
        out, ok = torus_from_minimal_sets(xyz, normals)
        out[:, 3:6] = _canonical_sign(out[:, 3:6])
        return out, ok
    raise ValueError(f"unknown primitive kind {kind!r}")


# ---------------------------------------------------------------- surface coordinates
def _wrap(phi: F64) -> F64:
    return np.mod(phi + np.pi, 2.0 * np.pi) - np.pi


def surface_coordinates(kind: str, params: F64, xyz: F64) -> list[F64]:
    """2-D ``(u, v)`` coordinates (metres) of points on a primitive, for the bitmap.

    Plane: in-plane coordinates. Cylinder: unrolled ``(radius * angle, height)``. Cone:
    its exact development into a plane sector. Sphere: the sinusoidal (equal-area)
    projection about the inliers' mean direction. Torus: unrolled ``(R * phi, r * theta)``
    (angles about the axis and about the tube). Periodic kinds return two
    parametrisations whose seams lie half a turn apart; a caller joins the connected
    components of both, so no component is cut at a seam.

    Parameters
    ----------
    kind : str
    params : ndarray of shape (8,)
    xyz : ndarray of shape (n_points, 3)

    Returns
    -------
    list of ndarray of shape (n_points, 2)

    Examples
    --------
    >>> uv = surface_coordinates("plane", np.array([0.0, 0, 1, 0, 0, 0, 0, 0]), np.eye(3))
    >>> len(uv), uv[0].shape
    (1, (3, 2))
    """
    if kind == "plane":
        e1, e2 = _basis(params[:3])
        return [np.stack([xyz @ e1, xyz @ e2], axis=1)]
    if kind == "sphere":
        v = xyz - params[:3]
        pole, norm = _unit(v.mean(axis=0))
        if norm < 1e-6 * max(params[3], _TINY):
            pole = np.array([0.0, 0.0, 1.0])
        e1, e2 = _basis(pole)
        vn, _ = _unit(v)
        lat = np.arcsin(np.clip(vn @ pole, -1.0, 1.0))
        phi = np.arctan2(vn @ e2, vn @ e1)
        r = params[3]
        return [np.stack([r * _wrap(phi + s) * np.cos(lat), r * lat], axis=1) for s in (0.0, np.pi)]
    if kind in ("cylinder", "cone"):
        origin, a = params[:3], params[3:6]
        e1, e2 = _basis(a)
        v = xyz - origin
        h = v @ a
        phi = np.arctan2(v @ e2, v @ e1)
        if kind == "cylinder":
            return [np.stack([params[6] * _wrap(phi + s), h], axis=1) for s in (0.0, np.pi)]
        s_gen = np.linalg.norm(v, axis=1)  # distance from the apex along the surface
        out = []
        for s in (0.0, np.pi):
            psi = _wrap(phi + s) * math.sin(params[6])
            out.append(np.stack([s_gen * np.cos(psi), s_gen * np.sin(psi)], axis=1))
        return out
    if kind == "torus":
        return torus_surface_coordinates(params, xyz, _basis(params[3:6]))
    raise ValueError(f"unknown primitive kind {kind!r}")


# --------------------------------------------------------------------- least squares
def _signed(kind: str, params: F64, xyz: F64) -> F64:
    d, _ = distance_and_cosine(kind, params[None], xyz, xyz)  # cosine unused
    return d[0]


def refine_params(kind: str, params: F64, xyz: F64, *, max_points: int = 20_000,
                  rng: np.random.Generator | None = None) -> F64:
    """Least-squares refit of one primitive to its inliers (geometric distances).

    Parameters
    ----------
    kind : str
    params : ndarray of shape (8,)
        Starting parameters.
    xyz : ndarray of shape (n_points, 3)
        Inliers; at most ``max_points`` of them (a random subset) enter the fit.

    Returns
    -------
    ndarray of shape (8,)
        Refined parameters; the input parameters where the fit fails.

    Examples
    --------
    >>> xyz = np.array([[0.0, 0, 0.1], [1, 0, 0.1], [0, 1, 0.1], [1, 1, 0.1]])
    >>> np.round(refine_params("plane", np.array([0.0, 0, 1, 0, 0, 0, 0, 0]), xyz)[:4], 6).tolist()
    [0.0, 0.0, 1.0, -0.1]
    """
    rng = np.random.default_rng(rng)
    if len(xyz) > max_points:
        xyz = xyz[rng.choice(len(xyz), max_points, replace=False)]
    p0 = np.asarray(params, dtype=np.float64)
    if kind == "plane":
        if len(xyz) < 3:
            return p0
        c = xyz.mean(axis=0)
        _, _, vt = np.linalg.svd(xyz - c, full_matrices=False)
        n = _canonical_sign(vt[-1])
        out = np.zeros(N_PARAMS)
        out[:3], out[3] = n, -n @ c
        return out
    if kind == "sphere":
        def res_s(x: F64) -> F64:
            return np.linalg.norm(xyz - x[:3], axis=1) - x[3]
        x0 = p0[:4]
        sol = _lsq(res_s, x0)
        out = np.zeros(N_PARAMS)
        out[:4] = sol
        out[3] = abs(out[3])
        return out
    # Cylinder, cone and torus: axis direction through two small rotations about e1, e2.
    a0 = p0[3:6] / np.linalg.norm(p0[3:6])
    e1, e2 = _basis(a0)

    def axis(x: F64) -> F64:
        a = a0 + x[0] * e1 + x[1] * e2
        return a / np.linalg.norm(a)

    if kind == "cylinder":
        c = xyz.mean(axis=0)
        base = p0[:3] + ((c - p0[:3]) @ a0) * a0  # axis point nearest the centroid

        def res_c(x: F64) -> F64:
            a = axis(x)
            v = xyz - (base + x[2] * e1 + x[3] * e2)
            h = v @ a
            return np.sqrt(np.maximum(np.einsum("ij,ij->i", v, v) - h * h, 0.0)) - x[4]

        sol = _lsq(res_c, np.array([0.0, 0.0, 0.0, 0.0, p0[6]]))
        out = np.zeros(N_PARAMS)
        a = axis(sol)
        p = base + sol[2] * e1 + sol[3] * e2
        out[:3] = p + ((c - p) @ a) * a
        out[3:6], out[6] = _canonical_sign(a), abs(sol[4])
        return out
    if kind == "cone":
        def res_k(x: F64) -> F64:
            a = axis(x)
            v = xyz - x[2:5]
            h = v @ a
            rho = np.sqrt(np.maximum(np.einsum("ij,ij->i", v, v) - h * h, 0.0))
            return rho * np.cos(x[5]) - h * np.sin(x[5])

        sol = _lsq(res_k, np.array([0.0, 0.0, *p0[:3], p0[6]]))
        out = np.zeros(N_PARAMS)
        out[:3], out[3:6], out[6] = sol[2:5], axis(sol), sol[5]
        return out
    if kind == "torus":
        def res_t(x: F64) -> F64:
            return torus_residuals(p0[:3] + x[2:5], axis(x), x[5], x[6], xyz)

        sol = _lsq(res_t, np.array([0.0, 0.0, 0.0, 0.0, 0.0, p0[6], p0[7]]))
        out = np.zeros(N_PARAMS)
        out[:3], out[3:6] = p0[:3] + sol[2:5], _canonical_sign(axis(sol))
        out[6], out[7] = abs(sol[5]), abs(sol[6])
        return out
    raise ValueError(f"unknown primitive kind {kind!r}")


def _lsq(fun: Any, x0: F64) -> F64:
    if not np.all(np.isfinite(fun(x0))):
        return x0
    try:
        sol = least_squares(fun, x0, method="lm", max_nfev=50 * (len(x0) + 1), x_scale="jac")
    except (ValueError, np.linalg.LinAlgError):
        return x0
    return sol.x if np.all(np.isfinite(sol.x)) else x0


# Quantiles (along the principal direction) of the points of fit_primitive's torus minimal sets.
_QUADRUPLES = ((0.0, 1 / 3, 2 / 3, 1.0), (0.25, 0.5, 0.75, 0.125), (0.125, 0.375, 0.625, 0.875),
               (0.0, 0.25, 0.5, 0.75), (0.1, 0.4, 0.6, 0.9), (0.05, 0.3, 0.55, 0.8))


def fit_primitive(xyz: F64, normals: F64, *, kind: str) -> PrimitiveFit | FailedFit:
    """Least-squares fit of one primitive to points that all lie on it.

    Starts from a few minimal sets of points far apart along the principal direction
    (three for the 2- and 3-point kinds, six for tori) and refines each with
    :func:`refine_params`; the refit with the smallest RMS distance wins.

    Parameters
    ----------
    xyz, normals : ndarray of shape (n_points, 3)
    kind : str
        One of :data:`KINDS`.

    Returns
    -------
    PrimitiveFit or FailedFit
        A falsy :class:`FailedFit` when the points are too few or degenerate.

    Examples
    --------
    >>> t = np.linspace(0, 2 * np.pi, 6, endpoint=False)
    >>> xyz = np.stack([np.cos(t), np.sin(t), t / 4], axis=1)
    >>> fit = fit_primitive(xyz, np.stack([np.cos(t), np.sin(t), 0 * t], axis=1), kind="cylinder")
    >>> round(fit.named()["radius"], 6)
    1.0
    """
    xyz = np.asarray(xyz, dtype=np.float64)
    normals = np.asarray(normals, dtype=np.float64)
    k = MINIMAL_SET_SIZE.get(kind)
    if k is None:
        return FailedFit(reason=f"unknown primitive kind {kind!r}")
    finite = np.isfinite(xyz).all(axis=1) & np.isfinite(normals).all(axis=1)
    xyz, normals = xyz[finite], normals[finite]
    if len(xyz) < max(k, 3):
        return FailedFit(reason=f"{len(xyz)} finite points; a {kind} needs at least {max(k, 3)}")
    centre = xyz.mean(axis=0)
    local = xyz - centre
    # Minimal sets from spread-out points: try a few deterministic triples.
    order = np.argsort(local @ np.linalg.svd(local, full_matrices=False)[2][0])
    n = len(order)
    picks = np.array([[order[0], order[n // 2], order[-1]], [order[n // 4], order[3 * n // 4], order[n // 8]],
                      [order[0], order[n // 3], order[2 * n // 3]]])
    if k > 3:  # tori: quadruples spread along the principal direction
        picks = np.array([[order[round(f * (n - 1))] for f in q] for q in _QUADRUPLES])
    params, ok = candidates_from_minimal_sets(kind, local[picks], normals[picks])
    if not ok.any():
        return FailedFit(reason=f"the points are degenerate for a {kind}")
    best, best_rms = None, np.inf
    for p in params[ok]:
        ref = refine_params(kind, p, local)
        rms = float(np.sqrt(np.mean(_signed(kind, ref, local) ** 2)))
        if rms < best_rms:
            best, best_rms = ref, rms
    if best is None or not np.isfinite(best_rms):
        return FailedFit(reason=f"the {kind} fit did not converge")
    return to_fit(kind, best, local, centre)


def to_fit(kind: str, params: F64, local: F64, centre: F64) -> PrimitiveFit:
    """A :class:`PrimitiveFit` in input coordinates from local ``params`` and inliers."""
    p = np.asarray(params, dtype=np.float64).copy()
    rms = float(np.sqrt(np.mean(_signed(kind, p, local) ** 2))) if len(local) else 0.0
    if kind == "plane":
        p[3] -= p[:3] @ centre
        vals = p[:4]
    elif kind == "sphere":
        p[:3] += centre
        vals = p[:4]
    elif kind == "cylinder":
        a = p[3:6]
        c = local.mean(axis=0) if len(local) else p[:3]
        p[:3] = p[:3] + ((c - p[:3]) @ a) * a + centre
        vals = p[:7]
    elif kind == "cone":
        p[:3] += centre
        vals = p[:7]
    else:
        p[:3] += centre
        vals = p[:8]
    return PrimitiveFit(kind=kind, params=tuple(float(v) for v in vals), n_points=len(local), rms=rms)
