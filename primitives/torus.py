"""Tori for Efficient RANSAC: minimal sets, distance and normal, bitmap coordinates, refit.

:mod:`primitives.shapes` dispatches here for ``kind="torus"``; the functions follow its
conventions (batched parameter rows of 8 slots, unoriented normals, ``|cos|``). A torus
is ``centre (3), axis (3), major_radius R, minor_radius r``: the surface of the points at
distance ``r`` from the circle of radius ``R`` about the unit ``axis`` through ``centre``
(the *tube circle*). Only ring tori (``R > r > 0``) are candidates; a spindle torus
(``R <= r``) is not a surface the detector reports, and its ``R -> 0`` limit is a sphere.

Minimal set (Schnabel et al. 2007, §3): every normal line of a torus meets its axis, so
the axis is a line meeting the normal lines of 4 points. In Plücker coordinates
``(d, m)`` (``m = p x d``) "meets the normal line ``(n_i, p_i x n_i)``" is linear,
``d . (p_i x n_i) + n_i . m = 0``: the 4 conditions leave a pencil ``L = s u + t v`` of
the null space, and the Plücker condition ``d . m = 0`` (a quadratic form in ``(s, t)``)
picks at most two real lines. For each, the points' meridian coordinates ``(rho, h)``
(distance from the axis, height along it) and their normals' meridian directions give the
tube circle's centre ``(R, h0)`` as the least-squares meeting point of the 4 normal lines
in the meridian half-plane, and ``r`` as the mean distance of the points from it. Of the
two lines the one whose torus lies closer to the 4 points is kept.

Examples
--------
>>> params = np.array([[0.0, 0, 0, 0, 0, 1, 2.0, 0.5]])
>>> xyz = np.array([[2.5, 0, 0], [0, 0, 0]])
>>> d, c = torus_distance_and_cosine(params, xyz, np.array([[1.0, 0, 0], [0, 0, 1]]))
>>> np.round(d[0], 6).tolist(), np.round(c[0, :1], 6).tolist()
([0.0, 1.5], [1.0])
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

__all__ = [
    "torus_distance_and_cosine",
    "torus_from_minimal_sets",
    "torus_surface_coordinates",
    "torus_residuals",
]

F64 = npt.NDArray[np.float64]
_TINY = 1e-12
#: Smallest 4th/1st singular value of the 4 x 6 incidence system (else the normal lines
#: have infinitely many common transversals: a sphere, a plane, parallel normals).
RANK_TOL = 1e-3
#: Smallest determinant of the 2 x 2 meridian system, about the sum of the squared sines
#: of the angles between the meridian normals (else the tube radius is undetermined:
#: a cylinder or cone patch).
MERIDIAN_TOL = 1e-3


def _dot(u: F64, x: F64) -> F64:
    """``u . x`` for ``u (K, 3)`` and shared ``x (M, 3)`` -> ``(K, M)`` or own ``(K, k, 3)`` -> ``(K, k)``."""
    if x.ndim == 2:
        return u @ x.T
    return np.einsum("kj,kij->ki", u, x)


def torus_distance_and_cosine(params: F64, xyz: F64, normals: F64, *, sq_norm: F64 | None = None,
                              normal_dot: F64 | None = None) -> tuple[F64, F64]:
    """Distance to the torus and ``|cos|`` between each normal and the surface normal.

    The distance is ``| sqrt((rho - R)^2 + h^2) - r |`` (``rho`` the distance from the axis,
    ``h`` the height above the centre); the surface normal at the nearest point is the
    direction from the nearest point of the tube circle.

    Parameters
    ----------
    params : ndarray of shape (n_candidates, 8)
    xyz, normals : ndarray of shape (n_points, 3) or (n_candidates, k, 3)
        Shared points or each candidate's own points.
    sq_norm, normal_dot : ndarray, optional
        Precomputed ``|x|^2`` and ``n . x`` (shared points only).

    Returns
    -------
    distance, cosine : ndarray of shape (n_candidates, n_points) or (n_candidates, k)
    """
    c, a, big_r, small_r = params[:, :3], params[:, 3:6], params[:, 6:7], params[:, 7:8]
    pp = np.einsum("...j,...j->...", xyz, xyz) if sq_norm is None else sq_norm
    npx = np.einsum("...j,...j->...", normals, xyz) if normal_dot is None else normal_dot
    h = _dot(a, xyz) - np.einsum("kj,kj->k", c, a)[:, None]
    v2 = pp - 2.0 * _dot(c, xyz) + np.einsum("kj,kj->k", c, c)[:, None]
    rho = np.sqrt(np.maximum(v2 - h * h, 0.0))
    dr = rho - big_r
    t = np.sqrt(dr * dr + h * h)  # distance from the tube circle
    na = _dot(a, normals)
    nv = npx - _dot(c, normals)
    # n . (x - q), q the nearest point of the tube circle: h n.a + (rho - R) / rho * n.(v - h a)
    nw = h * na + dr / np.maximum(rho, _TINY) * (nv - h * na)
    return np.abs(t - small_r), np.abs(nw) / np.maximum(t, _TINY)


def _cross(u: F64, v: F64) -> F64:
    return np.stack([u[..., 1] * v[..., 2] - u[..., 2] * v[..., 1],
                     u[..., 2] * v[..., 0] - u[..., 0] * v[..., 2],
                     u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]], axis=-1)


def _torus_on_axis(q: F64, n: F64, a: F64, p0: F64) -> tuple[F64, F64, F64, npt.NDArray[np.bool_]]:
    """Centre height, ``R`` and ``r`` of the tori about the axes ``p0 + t a`` through ``q``."""
    v = q - p0[:, None]
    h = np.einsum("kij,kj->ki", v, a)
    w = v - h[..., None] * a[:, None]
    rho = np.linalg.norm(w, axis=2)
    u = w / np.maximum(rho, _TINY)[..., None]
    m = np.stack([np.einsum("kij,kij->ki", n, u), np.einsum("kij,kj->ki", n, a)], axis=2)
    mn = np.linalg.norm(m, axis=2)
    ok = mn.min(axis=1) > 0.5  # the normals lie (nearly) in their meridian planes
    m = m / np.maximum(mn, _TINY)[..., None]
    proj = np.eye(2) - m[..., :, None] * m[..., None, :]  # (K, k, 2, 2)
    y = np.stack([rho, h], axis=2)
    mat = proj.sum(axis=1)
    rhs = np.einsum("kiab,kib->ka", proj, y)
    det = np.linalg.det(mat)
    ok &= det > MERIDIAN_TOL
    mat = np.where(ok[:, None, None], mat, np.eye(2))
    tube = np.linalg.solve(mat, rhs[..., None])[..., 0]
    small_r = np.linalg.norm(y - tube[:, None], axis=2).mean(axis=1)
    return tube[:, 1], tube[:, 0], small_r, ok


def torus_from_minimal_sets(xyz: F64, normals: F64) -> tuple[F64, npt.NDArray[np.bool_]]:
    """Torus candidates from minimal sets of 4 points with normals (see the module notes).

    Parameters
    ----------
    xyz, normals : ndarray of shape (n_sets, k, 3)
        ``k >= 4``; the first 4 points build the candidate.

    Returns
    -------
    params : ndarray of shape (n_sets, 8)
        ``centre, axis, R, r`` (axis sign as the caller canonicalises it).
    ok : ndarray of bool, shape (n_sets,)
        False where the set is degenerate or gives no ring torus (``R > r > 0``).

    Examples
    --------
    >>> th = np.array([0.3, 1.9, 3.5, 5.0]); ph = np.array([0.0, 1.0, 2.0, 4.0])
    >>> nrm = np.stack([np.cos(th) * np.cos(ph), np.cos(th) * np.sin(ph), np.sin(th)], axis=1)
    >>> xyz = 3.0 * np.stack([np.cos(ph), np.sin(ph), 0 * ph], axis=1) + 1.0 * nrm
    >>> params, ok = torus_from_minimal_sets(xyz[None], nrm[None])
    >>> ok.tolist(), np.round(np.abs(params[0]), 6).tolist()
    ([True], [0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 3.0, 1.0])
    """
    p, n = xyz[:, :4], normals[:, :4]
    n_sets = len(p)
    g = p.mean(axis=1)
    q = p - g[:, None]
    scale = np.maximum(np.linalg.norm(q, axis=2).max(axis=1), _TINY)
    q = q / scale[:, None, None]  # unit-size sets: a well-conditioned 4 x 6 system
    mat = np.concatenate([_cross(q, n), n], axis=2)
    _, sv, vt = np.linalg.svd(mat)
    ok = sv[:, 3] > RANK_TOL * np.maximum(sv[:, 0], _TINY)
    u, v = vt[:, 4], vt[:, 5]

    def pl(x: F64, y: F64) -> F64:
        return np.einsum("kj,kj->k", x[:, :3], y[:, 3:])

    b = 0.5 * (pl(u, v) + pl(v, u))
    quad = np.stack([np.stack([pl(u, u), b], axis=1), np.stack([b, pl(v, v)], axis=1)], axis=1)
    lam, e = np.linalg.eigh(quad)
    ok &= (lam[:, 0] <= 0.0) & (lam[:, 1] >= 0.0)
    s_pos, s_neg = np.sqrt(np.maximum(lam[:, 1], 0.0)), np.sqrt(np.maximum(-lam[:, 0], 0.0))
    best = np.zeros((n_sets, 8))
    best_d = np.full(n_sets, np.inf)
    for sign in (1.0, -1.0):
        coef = s_pos[:, None] * e[:, :, 0] + sign * s_neg[:, None] * e[:, :, 1]
        line = coef[:, :1] * u + coef[:, 1:] * v
        dn = np.linalg.norm(line[:, :3], axis=1)
        ok_s = ok & (dn > 0.1 * np.maximum(np.linalg.norm(line, axis=1), _TINY))
        a = line[:, :3] / np.maximum(dn, _TINY)[:, None]
        p0 = _cross(a, line[:, 3:] / np.maximum(dn, _TINY)[:, None])  # axis point nearest g
        h0, big_r, small_r, ok_t = _torus_on_axis(q, n, a, p0)
        ok_s &= ok_t & (small_r > 0.0) & (big_r > small_r)
        params = np.zeros((n_sets, 8))
        params[:, :3] = g + scale[:, None] * (p0 + h0[:, None] * a)
        params[:, 3:6] = a
        params[:, 6], params[:, 7] = scale * big_r, scale * small_r
        d, _ = torus_distance_and_cosine(params, p, n)
        d = np.where(ok_s, d.max(axis=1), np.inf)
        better = d < best_d
        best[better], best_d[better] = params[better], d[better]
    return best, np.isfinite(best_d)


def torus_surface_coordinates(params: F64, xyz: F64, basis: tuple[F64, F64]) -> list[F64]:
    """Unrolled ``(R * phi, r * theta)`` of points near the torus ``params (8,)``.

    ``phi`` is the angle about the axis (in the ``basis`` of the plane normal to it),
    ``theta`` the angle about the tube circle. Both are periodic: the two returned
    parametrisations have both seams shifted by half a turn (see
    :func:`primitives.shapes.surface_coordinates`). The ``phi`` scale is the tube circle's
    length, so the inner side (``rho = R - r``) is stretched by ``R / (R - r)`` and the
    outer side shrunk by ``R / (R + r)``.
    """
    e1, e2 = basis
    v = xyz - params[:3]
    h = v @ params[3:6]
    x1, x2 = v @ e1, v @ e2
    phi = np.arctan2(x2, x1)
    theta = np.arctan2(h, np.hypot(x1, x2) - params[6])
    out = []
    for s in (0.0, np.pi):
        out.append(np.stack([params[6] * _wrap(phi + s), params[7] * _wrap(theta + s)], axis=1))
    return out


def _wrap(phi: F64) -> F64:
    return np.mod(phi + np.pi, 2.0 * np.pi) - np.pi


def torus_residuals(centre: F64, axis: F64, big_r: float, small_r: float, xyz: F64) -> F64:
    """Signed distances ``sqrt((rho - R)^2 + h^2) - r`` of ``xyz`` to one torus (refit residuals)."""
    v = xyz - centre
    h = v @ axis
    rho = np.sqrt(np.maximum(np.einsum("ij,ij->i", v, v) - h * h, 0.0))
    return np.sqrt((rho - big_r) ** 2 + h * h) - small_r
