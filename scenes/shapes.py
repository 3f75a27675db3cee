"""Generic triangle-mesh builders: boxes, surfaces of revolution, polygons, thick panels.

Pure NumPy plus ``mapbox_earcut`` for polygon triangulation. Every builder returns a new
:class:`~scenes.mesh.TriMesh` in metres, z up. The architectural element builders of
:mod:`scenes.elements` are made of these pieces.

Thick panels (walls with arched openings, roof slabs with round holes) are built in a 2D
parametric space -- ``(u, z)`` along a wall, ``(x, y)`` for a slab -- triangulated once,
then mapped to 3D at both faces, with a side strip along every boundary edge (the reveals
and soffits of the openings, the top, the end caps). A wall maps ``u`` onto a straight
line (:class:`StraightPath`) or a circular arc (:class:`ArcPath`); on an arc the
triangulation is subdivided conformingly (no T-junctions, hence no cracks) until every
edge is short enough for the chords to follow the curve.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import mapbox_earcut
import numpy as np
import numpy.typing as npt

from hollowtree.arrays import FloatArray, IntArray
from hollowtree.scenes.mesh import TriMesh, concat_meshes

__all__ = [
    "ArcPath",
    "StraightPath",
    "annulus",
    "arch_outline",
    "box",
    "ellipsoid",
    "frustum",
    "planar_panel",
    "prism",
    "revolve",
    "shell_of_revolution",
    "slab",
    "subdivide",
    "triangulate_polygon",
    "wall_panel",
]

_EPS = 1e-9


# --------------------------------------------------------------------------- solids
def box(lo: Sequence[float], hi: Sequence[float]) -> TriMesh:
    """Axis-aligned box between the corners ``lo`` and ``hi`` (12 triangles).

    Examples
    --------
    >>> m = box((0, 0, 0), (1, 2, 3))
    >>> m.n_faces, round(m.area(), 6)
    (12, 22.0)
    """
    lo_, hi_ = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    corners = np.array([[i & 1, (i >> 1) & 1, (i >> 2) & 1] for i in range(8)], dtype=np.float64)
    v = lo_ + corners * (hi_ - lo_)
    f = np.array(
        [[0, 2, 1], [1, 2, 3], [4, 5, 6], [5, 7, 6], [0, 1, 4], [1, 5, 4],
         [2, 6, 3], [3, 6, 7], [0, 4, 2], [2, 4, 6], [1, 3, 5], [3, 7, 5]],
        dtype=np.int64,
    )
    return TriMesh(v, f)


def revolve(
    profile: npt.ArrayLike,
    *,
    n_segments: int = 48,
    closed: bool = False,
    angle0: float = 0.0,
    center: Sequence[float] = (0.0, 0.0, 0.0),
) -> TriMesh:
    """Surface of revolution of a profile ``(r, z)`` about the vertical axis.

    Parameters
    ----------
    profile : array_like of shape (n_points, 2)
        ``(radius, height)`` samples; a point with radius 0 becomes a single apex vertex.
    n_segments : int
        Vertices around; 8 gives an octagonal (n-gon) cross-section whose corners lie at
        the given radius.
    closed : bool
        Also join the last profile point back to the first.
    angle0 : float
        Angle (radians) of the first vertex around the axis.
    center : sequence of 3 floats
        Where the axis' ``z = 0`` lies.

    Examples
    --------
    >>> cone = revolve([(1.0, 0.0), (0.0, 2.0)], n_segments=8)
    >>> cone.n_faces, len(cone.vertices)
    (8, 9)
    """
    p = np.asarray(profile, dtype=np.float64).reshape(-1, 2)
    keep = np.ones(len(p), dtype=bool)
    keep[1:] = np.any(np.abs(np.diff(p, axis=0)) > _EPS, axis=1)
    p = p[keep]
    if closed and len(p) > 2 and np.all(np.abs(p[0] - p[-1]) < _EPS):
        p = p[:-1]
    n = int(n_segments)
    theta = angle0 + 2.0 * np.pi * np.arange(n) / n
    cos, sin = np.cos(theta), np.sin(theta)
    apex = p[:, 0] <= _EPS
    counts = np.where(apex, 1, n)
    start = np.concatenate([[0], np.cumsum(counts)[:-1]])
    verts = []
    for (r, z), is_apex in zip(p, apex, strict=True):
        if is_apex:
            verts.append([[0.0, 0.0, z]])
        else:
            verts.append(np.stack([r * cos, r * sin, np.full(n, z)], axis=1))
    v = np.concatenate(verts) + np.asarray(center, dtype=np.float64)
    j = np.arange(n)
    jn = (j + 1) % n
    faces = []
    pairs = [(i, i + 1) for i in range(len(p) - 1)]
    if closed and len(p) > 2:
        pairs.append((len(p) - 1, 0))
    for a, b in pairs:
        sa, sb = start[a], start[b]
        if apex[a] and apex[b]:
            continue
        if apex[a]:
            faces.append(np.stack([np.full(n, sa), sb + jn, sb + j], axis=1))
        elif apex[b]:
            faces.append(np.stack([sa + j, sa + jn, np.full(n, sb)], axis=1))
        else:
            faces.append(np.stack([sa + j, sa + jn, sb + jn], axis=1))
            faces.append(np.stack([sa + j, sb + jn, sb + j], axis=1))
    f = np.concatenate(faces) if faces else np.zeros((0, 3), dtype=np.int64)
    return TriMesh(v, f)


def frustum(
    r0: float,
    r1: float,
    z0: float,
    z1: float,
    *,
    n_segments: int = 48,
    caps: bool = True,
    center: Sequence[float] = (0.0, 0.0, 0.0),
    angle0: float = 0.0,
) -> TriMesh:
    """Truncated cone (a cylinder when ``r0 == r1``) from ``z0`` to ``z1``, optionally capped.

    Examples
    --------
    >>> frustum(1.0, 1.0, 0.0, 2.0, n_segments=12).n_faces
    48
    """
    prof = [(r0, z0), (r1, z1)]
    if caps:
        prof = [(0.0, z0), *prof, (0.0, z1)]
    return revolve(prof, n_segments=n_segments, center=center, angle0=angle0)


def annulus(
    r_in: float,
    r_out: float,
    *,
    z: float = 0.0,
    n_segments: int = 48,
    center: Sequence[float] = (0.0, 0.0, 0.0),
) -> TriMesh:
    """Flat horizontal ring between radii ``r_in`` and ``r_out`` at height ``z``.

    Examples
    --------
    >>> round(annulus(1.0, 2.0, n_segments=256).area(), 2)
    9.42
    """
    return revolve([(r_in, z), (r_out, z)], n_segments=n_segments, center=center)


def shell_of_revolution(
    outer: npt.ArrayLike,
    inner: npt.ArrayLike,
    *,
    n_segments: int = 48,
    center: Sequence[float] = (0.0, 0.0, 0.0),
    angle0: float = 0.0,
) -> TriMesh:
    """Hollow shell: outer surface, inner surface and the rims joining their ends.

    Parameters
    ----------
    outer, inner : array_like of shape (n, 2)
        ``(r, z)`` profiles, both from the base upwards (a profile ending at ``r = 0``
        closes over the axis, as a dome does).

    Examples
    --------
    >>> import numpy as np
    >>> t = np.linspace(0, np.pi / 2, 9)
    >>> sh = shell_of_revolution(np.c_[np.cos(t), np.sin(t)], np.c_[0.9 * np.cos(t), 0.9 * np.sin(t)],
    ...                          n_segments=16)
    >>> float(sh.bounds()[1, 2]), sh.n_faces
    (1.0, 512)
    """
    o = np.asarray(outer, dtype=np.float64).reshape(-1, 2)
    i = np.asarray(inner, dtype=np.float64).reshape(-1, 2)[::-1]
    return revolve(np.concatenate([o, i]), n_segments=n_segments, closed=True,
                   center=center, angle0=angle0)


def ellipsoid(
    radii: Sequence[float],
    *,
    center: Sequence[float] = (0.0, 0.0, 0.0),
    n_segments: int = 16,
    n_rings: int = 8,
) -> TriMesh:
    """Closed ellipsoid with semi-axes ``radii`` (rx, ry, rz).

    Examples
    --------
    >>> e = ellipsoid((1, 1, 2), n_segments=8, n_rings=4)
    >>> e.bounds()[:, 2].tolist()
    [-2.0, 2.0]
    """
    phi = np.linspace(-np.pi / 2, np.pi / 2, n_rings + 1)
    m = revolve(np.c_[np.cos(phi), np.sin(phi)], n_segments=n_segments)
    return m.scaled(radii).translated(center)


# --------------------------------------------------------------------------- polygons
def triangulate_polygon(
    outer: npt.ArrayLike, holes: Sequence[npt.ArrayLike] = ()
) -> tuple[FloatArray, IntArray]:
    """Triangulate a simple 2D polygon with optional holes (ear clipping, mapbox_earcut).

    Returns
    -------
    vertices : ndarray of shape (n, 2)
    faces : ndarray of shape (m, 3), int64

    Examples
    --------
    >>> v, f = triangulate_polygon([(0, 0), (4, 0), (4, 4), (0, 4)], [[(1, 1), (2, 1), (2, 2), (1, 2)]])
    >>> len(v), len(f)
    (8, 8)
    """
    rings = [_clean_ring(outer)] + [_clean_ring(h) for h in holes]
    v = np.concatenate(rings)
    ends = np.cumsum([len(r) for r in rings]).astype(np.uint32)
    f = np.asarray(mapbox_earcut.triangulate_float64(v, ends), dtype=np.int64).reshape(-1, 3)
    return v, _drop_degenerate(v, f)


def subdivide(
    vertices: npt.ArrayLike,
    faces: npt.ArrayLike,
    *,
    max_edge: float,
    weights: Sequence[float] | None = None,
    max_iter: int = 40,
) -> tuple[FloatArray, IntArray]:
    """Split triangles until no edge is longer than ``max_edge``, without T-junctions.

    Every edge longer than ``max_edge`` is split at its midpoint, and every triangle is
    re-triangulated according to which of its edges were split (1, 2 or 4 children), so
    neighbours always agree on shared edges. Works on 2D or 3D vertices. ``weights``
    scales each coordinate when measuring length (``(1, 0)`` measures only ``u``, which is
    all a wall bent along an arc needs).

    Examples
    --------
    >>> v, f = subdivide([(0, 0), (2, 0), (0, 2)], [(0, 1, 2)], max_edge=1.0)
    >>> bool(np.all(np.linalg.norm(v[f] - v[np.roll(f, 1, axis=1)], axis=2) <= 1.0))
    True
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    w = np.ones(v.shape[1]) if weights is None else np.asarray(weights, dtype=np.float64)
    for _ in range(max_iter):
        e = np.sort(np.stack([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]], axis=1).reshape(-1, 2), axis=1)
        uniq, inv = np.unique(e, axis=0, return_inverse=True)
        inv = inv.reshape(-1)
        length = np.linalg.norm((v[uniq[:, 0]] - v[uniq[:, 1]]) * w, axis=1)
        split = length > max_edge
        if not split.any():
            break
        mid = np.full(len(uniq), -1, dtype=np.int64)
        mid[split] = len(v) + np.arange(split.sum())
        v = np.concatenate([v, 0.5 * (v[uniq[split, 0]] + v[uniq[split, 1]])])
        m = mid[inv].reshape(-1, 3)  # m[:, k] = midpoint of edge (k, k+1)
        s = m >= 0
        ns = s.sum(axis=1)
        out = [f[ns == 0]]
        # one split edge: roll it to position 0
        sel = ns == 1
        if sel.any():
            k = np.argmax(s[sel], axis=1)
            a, b, c, mm = _rolled(f[sel], m[sel], k)
            out += [np.stack([a, mm[:, 0], c], 1), np.stack([mm[:, 0], b, c], 1)]
        sel = ns == 2
        if sel.any():
            k = (np.argmin(s[sel], axis=1) + 1) % 3  # unsplit edge goes to position 2
            a, b, c, mm = _rolled(f[sel], m[sel], k)
            m0, m1 = mm[:, 0], mm[:, 1]
            d1 = np.linalg.norm(v[a] - v[m1], axis=1)
            d2 = np.linalg.norm(v[m0] - v[c], axis=1)
            short = d1 <= d2
            out += [
                np.stack([m0, b, m1], 1),
                np.where(short[:, None], np.stack([a, m0, m1], 1), np.stack([a, m0, c], 1)),
                np.where(short[:, None], np.stack([a, m1, c], 1), np.stack([m0, m1, c], 1)),
            ]
        sel = ns == 3
        if sel.any():
            a, b, c = f[sel].T
            m0, m1, m2 = m[sel].T
            out += [np.stack(t, 1) for t in ((a, m0, m2), (m0, b, m1), (m2, m1, c), (m0, m1, m2))]
        f = np.concatenate(out)
    return v, f


def _rolled(f: IntArray, m: IntArray, k: IntArray) -> tuple[IntArray, IntArray, IntArray, IntArray]:
    idx = (k[:, None] + np.arange(3)) % 3
    fr = np.take_along_axis(f, idx, axis=1)
    mr = np.take_along_axis(m, idx, axis=1)
    return fr[:, 0], fr[:, 1], fr[:, 2], mr


def planar_panel(
    outer: npt.ArrayLike,
    *,
    holes: Sequence[npt.ArrayLike] = (),
    max_edge: float | None = None,
    origin: Sequence[float] = (0.0, 0.0, 0.0),
    u_axis: Sequence[float] = (1.0, 0.0, 0.0),
    v_axis: Sequence[float] = (0.0, 1.0, 0.0),
) -> TriMesh:
    """Flat polygon (with holes) placed in 3D at ``origin + u * u_axis + v * v_axis``.

    Parameters
    ----------
    outer : array_like of shape (n, 2)
        Simple polygon (an inverted U for a doorway reaching the bottom edge).
    holes : sequence of array_like of shape (k, 2)
        Polygons fully inside ``outer`` (windows).
    max_edge : float, optional
        Subdivide until every edge is at most this long.

    Examples
    --------
    >>> p = planar_panel([(0, 0), (2, 0), (2, 1), (0, 1)], max_edge=0.5)
    >>> round(p.area(), 6), bool(p.n_faces > 2)
    (2.0, True)
    """
    v2, f = triangulate_polygon(outer, holes)
    if max_edge is not None:
        v2, f = subdivide(v2, f, max_edge=max_edge)
    o, ua, va = (np.asarray(a, dtype=np.float64) for a in (origin, u_axis, v_axis))
    return TriMesh(o + v2[:, :1] * ua + v2[:, 1:2] * va, f)


def _clean_ring(ring: npt.ArrayLike) -> FloatArray:
    r = np.asarray(ring, dtype=np.float64).reshape(-1, 2)
    keep = np.ones(len(r), dtype=bool)
    keep[1:] = np.linalg.norm(np.diff(r, axis=0), axis=1) > 1e-7
    r = r[keep]
    if len(r) > 1 and np.linalg.norm(r[0] - r[-1]) <= 1e-7:
        r = r[:-1]
    return r


def _drop_degenerate(v: FloatArray, f: IntArray) -> IntArray:
    t = v[f]
    d1, d2 = t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]
    area2 = np.abs(d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0])
    return f[area2 > 1e-12]


# --------------------------------------------------------------------------- thick sheets
def _thick_sheet(
    v2: FloatArray,
    f: IntArray,
    *,
    mapping: Callable[[FloatArray, FloatArray, float], FloatArray],
    d0: float,
    d1: float,
    keep_edge: Callable[[FloatArray, FloatArray], npt.NDArray[np.bool_]] | None = None,
) -> TriMesh:
    """Both faces of a triangulated 2D region, plus side strips along its boundary edges."""
    n = len(v2)
    front = mapping(v2[:, 0], v2[:, 1], d1)
    back = mapping(v2[:, 0], v2[:, 1], d0)
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    key = np.sort(e, axis=1)
    _, inv, cnt = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    border = e[cnt[inv.reshape(-1)] == 1]
    if keep_edge is not None and len(border):
        border = border[keep_edge(v2[border[:, 0]], v2[border[:, 1]])]
    a, b = border[:, 0], border[:, 1]
    sides = np.concatenate([np.stack([a, b, b + n], 1), np.stack([a, b + n, a + n], 1)])
    faces = np.concatenate([f, f[:, ::-1] + n, sides])
    return TriMesh(np.concatenate([front, back]), faces)


def slab(
    outer: npt.ArrayLike,
    *,
    z0: float,
    z1: float,
    holes: Sequence[npt.ArrayLike] = (),
) -> TriMesh:
    """Horizontal slab: a 2D polygon (x, y) with holes, extruded from ``z0`` to ``z1``.

    Top, bottom, outer rim and the rim of every hole (round holes under domes).

    Examples
    --------
    >>> s = slab([(0, 0), (4, 0), (4, 4), (0, 4)], z0=3.0, z1=3.5)
    >>> round(s.area(), 6)
    40.0
    """
    v2, f = triangulate_polygon(outer, holes)
    return _thick_sheet(v2, f, mapping=lambda x, y, d: np.c_[x, y, np.full_like(x, d)], d0=z0, d1=z1)


def prism(
    outer: npt.ArrayLike, z0: float, z1: float, *, holes: Sequence[npt.ArrayLike] = ()
) -> TriMesh:
    """Vertical prism over a 2D polygon (alias of :func:`slab` with positional heights).

    Examples
    --------
    >>> prism([(0, 0), (1, 0), (0, 1)], 0.0, 1.0).n_faces
    8
    """
    return slab(outer, z0=z0, z1=z1, holes=holes)


# --------------------------------------------------------------------------- walls
@dataclass(frozen=True, kw_only=True)
class StraightPath:
    """A wall's centre line from ``(x0, y0)`` to ``(x1, y1)``; ``d > 0`` is the left side."""

    x0: float
    y0: float
    x1: float
    y1: float

    @property
    def length(self) -> float:
        return float(np.hypot(self.x1 - self.x0, self.y1 - self.y0))

    @property
    def curved(self) -> bool:
        return False

    def map(self, u: FloatArray, z: FloatArray, d: float) -> FloatArray:
        """World points at arc length ``u``, height ``z`` and offset ``d`` from the line."""
        t = np.array([self.x1 - self.x0, self.y1 - self.y0]) / self.length
        nrm = np.array([-t[1], t[0]])
        x = self.x0 + u * t[0] + d * nrm[0]
        y = self.y0 + u * t[1] + d * nrm[1]
        return np.stack([x, y, z], axis=1)


@dataclass(frozen=True, kw_only=True)
class ArcPath:
    """A wall's centre line on a circle: centre, radius, angles (radians) from start to end.

    ``d > 0`` is outwards (away from the centre), whatever the direction of travel.
    """

    cx: float
    cy: float
    radius: float
    theta0: float
    theta1: float

    @property
    def length(self) -> float:
        return float(abs(self.theta1 - self.theta0) * self.radius)

    @property
    def curved(self) -> bool:
        return True

    def map(self, u: FloatArray, z: FloatArray, d: float) -> FloatArray:
        """World points at arc length ``u``, height ``z`` and radial offset ``d``."""
        sign = 1.0 if self.theta1 >= self.theta0 else -1.0
        th = self.theta0 + sign * u / self.radius
        r = self.radius + d
        return np.stack([self.cx + r * np.cos(th), self.cy + r * np.sin(th), z], axis=1)

    def default_max_edge(self, tol: float = 0.002) -> float:
        """Edge length whose chord strays at most ``tol`` metres from the circle."""
        return float(np.sqrt(8.0 * self.radius * tol))


WallPath = StraightPath | ArcPath


def arch_outline(
    u0: float,
    u1: float,
    spring: float,
    *,
    kind: str = "round",
    base: float = 0.0,
    chord: float = 0.05,
    pointedness: float = 1.0,
) -> FloatArray:
    """Outline of an arched opening, from ``(u0, base)`` up, over the arch, down to ``(u1, base)``.

    Parameters
    ----------
    u0, u1 : float
        Jambs (``u0 < u1``); the span is ``u1 - u0``.
    spring : float
        Springing height (where the arch starts).
    kind : {"round", "pointed", "four_centred"}
        Semicircular; two-centred pointed (each side an arc of radius
        ``pointedness * span``, 1 = equilateral); four-centred (Mughal/Tudor).
    base : float
        Sill height; an opening whose base equals its panel's bottom is a doorway.
    chord : float
        Longest chord along the curve (metres).

    Returns
    -------
    ndarray of shape (n, 2)

    Examples
    --------
    >>> o = arch_outline(0.0, 2.0, 3.0, kind="round")
    >>> o[0].tolist(), o[-1].tolist(), round(float(o[:, 1].max()), 6)
    ([0.0, 0.0], [2.0, 0.0], 4.0)
    >>> round(float(arch_outline(0.0, 2.0, 3.0, kind="pointed")[:, 1].max()), 3)
    4.732
    """
    s = u1 - u0
    uc = 0.5 * (u0 + u1)
    if kind == "round":
        left = _arc_pts((uc, spring), 0.5 * s, np.pi, np.pi / 2, chord)
    elif kind == "pointed":
        rho = max(pointedness, 0.5) * s
        tc = np.arccos(np.clip((0.5 * s - rho) / rho, -1.0, 1.0))
        left = _arc_pts((u0 + rho, spring), rho, np.pi, tc, chord)
    elif kind == "four_centred":
        r1, r2, alpha = 0.25 * s, s, np.pi / 4
        c1 = np.array([u0 + r1, spring])
        arc1 = _arc_pts(c1, r1, np.pi, np.pi - alpha, chord)
        c2 = c1 + (r2 - r1) * np.array([np.cos(alpha), -np.sin(alpha)])
        beta = np.arccos(np.clip((uc - c2[0]) / r2, -1.0, 1.0))
        arc2 = _arc_pts(c2, r2, np.pi - alpha, beta, chord)
        left = np.concatenate([arc1, arc2[1:]])
    else:
        raise ValueError(f"unknown arch kind {kind!r}; known kinds: round, pointed, four_centred")
    left[-1, 0] = uc
    right = np.c_[2 * uc - left[::-1, 0], left[::-1, 1]][1:]
    return np.concatenate([[[u0, base]], left, right, [[u1, base]]])


def _arc_pts(c: Sequence[float], r: float, t0: float, t1: float, chord: float) -> FloatArray:
    n = max(2, int(np.ceil(abs(t1 - t0) * r / chord)))
    t = np.linspace(t0, t1, n + 1)
    return np.c_[c[0] + r * np.cos(t), c[1] + r * np.sin(t)]


def wall_panel(
    path: WallPath,
    *,
    u0: float,
    u1: float,
    z0: float,
    z1: float,
    thickness: float,
    openings: Sequence[npt.ArrayLike] = (),
    caps: Sequence[str] = ("top", "start", "end"),
    max_edge: float | None = None,
) -> TriMesh:
    """A thick wall panel over ``[u0, u1] x [z0, z1]`` of ``path``, with openings.

    Front face, back face, the reveal and soffit surfaces of every opening, and the caps
    named in ``caps`` (any of ``"top"``, ``"bottom"``, ``"start"``, ``"end"``).

    Parameters
    ----------
    path : StraightPath or ArcPath
        The wall's centre line; ``u`` is arc length along it.
    openings : sequence of array_like of shape (k, 2)
        Outlines in ``(u, z)`` (see :func:`arch_outline`). An outline whose first and last
        points stand on ``z0`` is a doorway: it is cut into the outer boundary (the panel
        becomes an inverted U); any other outline is a hole (window).
    max_edge : float, optional
        Subdivision length; on an :class:`ArcPath` it defaults to a 2 mm chord error and
        only the ``u`` extent of an edge counts (straight vertical lines stay straight).

    Examples
    --------
    >>> p = StraightPath(x0=0, y0=0, x1=4, y1=0)
    >>> door = arch_outline(1.0, 3.0, 2.0)
    >>> w = wall_panel(p, u0=0, u1=4, z0=0, z1=4, thickness=0.5, openings=[door])
    >>> b = w.bounds(); b[:, 1].tolist(), b[:, 2].tolist()
    ([-0.25, 0.25], [0.0, 4.0])
    """
    outer, holes = _panel_rings(u0, u1, z0, z1, openings)
    v2, f = triangulate_polygon(outer, holes)
    if max_edge is None and path.curved:
        max_edge = path.default_max_edge()  # type: ignore[union-attr]
    if max_edge is not None:
        v2, f = subdivide(v2, f, max_edge=max_edge, weights=(1.0, 0.0) if path.curved else None)
    tol = 1e-7
    sides = {
        "bottom": (1, z0),
        "top": (1, z1),
        "start": (0, u0),
        "end": (0, u1),
    }
    drop = [sides[s] for s in sides if s not in caps]

    def keep_edge(pa: FloatArray, pb: FloatArray) -> npt.NDArray[np.bool_]:
        keep = np.ones(len(pa), dtype=bool)
        for axis, val in drop:
            keep &= ~((np.abs(pa[:, axis] - val) < tol) & (np.abs(pb[:, axis] - val) < tol))
        return keep

    h = 0.5 * thickness
    return _thick_sheet(v2, f, mapping=path.map, d0=-h, d1=h, keep_edge=keep_edge)


def _panel_rings(
    u0: float, u1: float, z0: float, z1: float, openings: Sequence[npt.ArrayLike]
) -> tuple[FloatArray, list[FloatArray]]:
    notches, holes = [], []
    for o in openings:
        o = np.asarray(o, dtype=np.float64).reshape(-1, 2)
        if abs(o[0, 1] - z0) < 1e-7 and abs(o[-1, 1] - z0) < 1e-7:
            notches.append(o)
        else:
            holes.append(o)
    notches.sort(key=lambda o: float(o[0, 0]))
    ring = [[u0, z0]]
    for o in notches:
        ring.extend(o.tolist())
    ring += [[u1, z0], [u1, z1], [u0, z1]]
    return _clean_ring(ring), holes


def merge(meshes: Sequence[TriMesh]) -> TriMesh:
    """Alias of :func:`scenes.mesh.concat_meshes` for builders in this package."""
    return concat_meshes(meshes)
