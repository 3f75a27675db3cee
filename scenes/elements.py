"""Parametric architectural elements with realistic default proportions.

Every builder takes keyword parameters only (defaults are plausible for Mughal and
Sindhi mosques, Cholistan forts and a Colosseum-like facade; all can be overridden, so
training data can vary them) and returns a :class:`~scenes.mesh.TriMesh` placed in
world coordinates, or, for an arcade, a small dataclass of parts to be labelled
separately. Labelling is left to :mod:`scenes.sites`: one element (a dome with its drum,
a minaret with its balconies and cupola, one arcade bay) is one instance.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from hollowtree.arrays import FloatArray
from hollowtree.scenes.clutter import bench, bicycle, car, place, tree
from hollowtree.scenes.mesh import TriMesh, concat_meshes
from hollowtree.scenes.shapes import (
    ArcPath,
    StraightPath,
    WallPath,
    arch_outline,
    box,
    frustum,
    revolve,
    shell_of_revolution,
    slab,
    wall_panel,
)

__all__ = [
    "ArcPath",
    "ArcadeParts",
    "arcade",
    "bastion",
    "bench",
    "bicycle",
    "car",
    "chattri",
    "dome",
    "dome_profile",
    "ground",
    "minaret",
    "pillar",
    "place",
    "portal",
    "roof_slab",
    "StraightPath",
    "tree",
    "wall",
]



# --------------------------------------------------------------------------- domes
def dome_profile(
    kind: str = "hemispherical",
    *,
    radius: float = 4.0,
    height: float | None = None,
    pointedness: float = 1.4,
    bulge: float = 1.2,
    chord: float = 0.15,
) -> FloatArray:
    """Outer ``(r, z)`` profile of a dome from its springing ``(radius, 0)`` to its top.

    Parameters
    ----------
    kind : {"hemispherical", "onion", "pointed"}
        Hemispherical (an ellipse if ``height`` differs from ``radius``); onion (bulbous,
        widest at ``bulge * radius``, concave towards a pointed tip, ``height`` defaults to
        ``1.75 * radius``); pointed (Persian/Mughal: each side an arc of radius
        ``pointedness * radius`` whose centre lies beyond the axis).
    chord : float
        Approximate spacing of profile samples (metres).

    Examples
    --------
    >>> p = dome_profile("pointed", radius=2.0)
    >>> p[0].tolist(), bool(p[-1, 0] == 0.0), round(float(p[-1, 1]), 2)
    ([2.0, 0.0], True, 2.68)
    """
    a = float(radius)
    if kind == "hemispherical":
        h = a if height is None else float(height)
        n = max(8, int(np.ceil(0.5 * np.pi * max(a, h) / chord)))
        t = np.linspace(0.0, 0.5 * np.pi, n + 1)
        p = np.c_[a * np.cos(t), h * np.sin(t)]
    elif kind == "pointed":
        rho = max(float(pointedness), 1.01) * a
        tc = np.arccos((rho - a) / rho)
        n = max(8, int(np.ceil(tc * rho / chord)))
        t = np.linspace(0.0, tc, n + 1)
        p = np.c_[(a - rho) + rho * np.cos(t), rho * np.sin(t)]
        if height is not None:
            p[:, 1] *= float(height) / p[-1, 1]
    elif kind == "onion":
        h = 1.75 * a if height is None else float(height)
        n = max(16, int(np.ceil(2.2 * h / chord)))
        t = np.linspace(0.0, 1.0, n + 1)
        k = 0.35
        low = a * (1.0 + (bulge - 1.0) * np.sin(0.5 * np.pi * np.minimum(t, k) / k))
        s = np.clip((t - k) / (1.0 - k), 0.0, 1.0)
        high = a * bulge * np.cos(0.5 * np.pi * s) ** 1.6
        p = np.c_[np.where(t <= k, low, high), h * t]
    else:
        raise ValueError(f"unknown dome kind {kind!r}; known kinds: hemispherical, onion, pointed")
    p[-1, 0] = 0.0
    return p


def _finial(length: float, *, z: float, center: Sequence[float], n_segments: int = 12) -> TriMesh:
    r = 0.04 * length + 0.03
    prof = [(0.0, 0.0), (2 * r, 0.0), (r, 0.15 * length), (r, 0.35 * length), (2.6 * r, 0.45 * length),
            (r, 0.55 * length), (r, 0.7 * length), (1.8 * r, 0.78 * length), (0.5 * r, 0.9 * length),
            (0.0, length)]
    c = np.asarray(center, dtype=np.float64)
    return revolve(prof, n_segments=n_segments, center=(c[0], c[1], c[2] + z))


def dome(
    *,
    center: Sequence[float] = (0.0, 0.0, 0.0),
    kind: str = "hemispherical",
    radius: float = 4.0,
    height: float | None = None,
    thickness: float = 0.3,
    drum_height: float = 2.0,
    drum_thickness: float = 0.5,
    finial: float = 1.2,
    pointedness: float = 1.4,
    bulge: float = 1.2,
    n_segments: int = 64,
) -> TriMesh:
    """A dome shell (outer and inner surface) on a cylindrical drum, with a finial.

    Parameters
    ----------
    center : sequence of 3 floats
        Centre of the drum's base (on the roof).
    kind, radius, height, pointedness, bulge
        See :func:`dome_profile`; ``radius`` is the outer radius at the springing, which
        is also the drum's outer radius.
    thickness : float
        Shell thickness; the inner surface is the outer profile scaled down by it.
    drum_height, drum_thickness : float
        A drum of height 0 is left out.
    finial : float
        Length of the finial on the top (0: none).

    Examples
    --------
    >>> d = dome(radius=2.0, drum_height=1.0, finial=0.0, n_segments=16)
    >>> d.bounds()[:, 2].tolist()
    [0.0, 3.0]
    """
    c = np.asarray(center, dtype=np.float64)
    outer = dome_profile(kind, radius=radius, height=height, pointedness=pointedness, bulge=bulge)
    h_out = outer[-1, 1]
    a_in = radius - thickness
    inner = outer * np.array([a_in / radius, max(h_out - thickness, 0.1) / h_out])
    parts = [shell_of_revolution(outer + [0, drum_height], inner + [0, drum_height],
                                 n_segments=n_segments, center=c)]
    if drum_height > 0:
        r_in = radius - drum_thickness
        parts.append(revolve([(radius, 0.0), (radius, drum_height), (r_in, drum_height), (r_in, 0.0)],
                             n_segments=n_segments, center=c))
    if finial > 0:
        parts.append(_finial(finial, z=drum_height + h_out - 0.05, center=c))
    return concat_meshes(parts)


def chattri(
    *,
    center: Sequence[float] = (0.0, 0.0, 0.0),
    radius: float = 1.3,
    n_posts: int = 4,
    post_height: float = 2.2,
    post_width: float = 0.22,
    platform_height: float = 0.45,
    kind: str = "hemispherical",
    finial: float = 0.6,
    yaw: float = 0.0,
) -> TriMesh:
    """A chattri: small dome on a ring beam carried by slender posts on a platform.

    The whole chattri is one dome instance. ``radius`` is the dome's radius; the posts
    stand at the corners of an ``n_posts``-gon of circumradius ``radius``.

    Examples
    --------
    >>> c = chattri(n_posts=6)
    >>> bool(c.bounds()[1, 2] > 4.0)
    True
    """
    c = np.asarray(center, dtype=np.float64)
    n = int(n_posts)
    a0 = np.pi / n + yaw
    r_plat = radius + 0.35
    parts = [revolve([(0, 0), (r_plat / np.cos(np.pi / n), 0), (r_plat / np.cos(np.pi / n), platform_height),
                      (0, platform_height)], n_segments=n, angle0=a0, center=c)]
    ang = a0 + 2 * np.pi * np.arange(n) / n
    rp = radius - 0.5 * post_width
    z1 = platform_height + post_height
    for t in ang:
        x, y = c[0] + rp * np.cos(t), c[1] + rp * np.sin(t)
        hw = 0.5 * post_width
        parts.append(box((x - hw, y - hw, c[2] + platform_height), (x + hw, y + hw, c[2] + z1)))
    beam = 0.3
    ro = (radius + 0.15) / np.cos(np.pi / n)
    ri = (radius - post_width - 0.05) / np.cos(np.pi / n)
    parts.append(revolve([(ri, z1), (ro, z1), (ro, z1 + beam), (ri, z1 + beam)], n_segments=n,
                         angle0=a0, closed=True, center=c))
    parts.append(dome(center=(c[0], c[1], c[2] + z1 + beam), kind=kind, radius=radius,
                      thickness=0.12, drum_height=0.25, drum_thickness=0.2, finial=finial,
                      n_segments=32))
    return concat_meshes(parts)


# --------------------------------------------------------------------------- towers
def minaret(
    *,
    center: Sequence[float] = (0.0, 0.0, 0.0),
    height: float = 33.0,
    base_radius: float = 2.4,
    n_stages: int = 4,
    n_segments: int = 8,
    taper: float = 0.05,
    setback: float = 0.04,
    balcony_depth: float = 0.9,
    balcony_thickness: float = 0.35,
    parapet_height: float = 1.0,
    plinth_height: float = 1.5,
    cupola: str = "posts",
    n_posts: int = 8,
) -> TriMesh:
    """A minaret: plinth, ``n_stages`` tapering shaft stages, a balcony between stages, a cupola.

    Parameters
    ----------
    height : float
        Total height including the cupola's finial.
    n_segments : int
        8 gives an octagonal shaft, 48 or more a round one.
    taper, setback : float
        Relative radius loss within a stage and at each balcony.
    balcony_depth, balcony_thickness, parapet_height : float
        Each balcony is an annular slab (with a conical corbel below) and a parapet ring.
    cupola : {"posts", "dome"}
        A small dome on ``n_posts`` posts (a chattri), or a small dome on the shaft.

    Examples
    --------
    >>> m = minaret(height=20.0, n_stages=3)
    >>> round(float(m.bounds()[1, 2]), 3)
    20.0
    """
    c = np.asarray(center, dtype=np.float64)
    ns = int(n_segments)
    a0 = np.pi / ns if ns <= 12 else 0.0
    k = 1.0 / np.cos(np.pi / ns)  # circumradius per apothem
    r = float(base_radius)
    r_top_est = r * ((1 - taper) * (1 - setback)) ** n_stages
    cup_r = 1.05 * r_top_est
    finial_len = 0.5 * cup_r + 0.4
    if cupola == "posts":
        post_h = 1.6 * cup_r + 0.3
        cup_h = 0.25 + post_h + 0.3 + 0.25 + cup_r + finial_len - 0.05
    else:
        post_h = 0.0
        cup_h = 0.25 + 0.3 + 1.2 * cup_r + finial_len - 0.05
    shaft_h = height - plinth_height - cup_h
    if shaft_h <= 0:
        raise ValueError(f"minaret height {height} is too small for its cupola ({cup_h:.2f} m)")
    parts = [revolve([(0, 0), ((r + 0.4) * k, 0), ((r + 0.4) * k, plinth_height), (0, plinth_height)],
                     n_segments=ns, angle0=a0, center=c)]
    w = 0.8 ** np.arange(n_stages)
    stage_h = (shaft_h - (n_stages - 1) * balcony_thickness) * w / w.sum()
    z = plinth_height
    for i in range(n_stages):
        r_top = r * (1 - taper)
        parts.append(frustum(r * k, r_top * k, z, z + stage_h[i], caps=False, n_segments=ns,
                             center=c, angle0=a0))
        z += stage_h[i]
        if i < n_stages - 1:
            rb = r_top + balcony_depth
            corbel = min(0.9, 0.5 * stage_h[i])
            parts.append(revolve([(r_top * k, z - corbel), (rb * k, z), (rb * k, z + balcony_thickness),
                                  (r_top * 0.95 * k, z + balcony_thickness)],
                                 n_segments=ns, angle0=a0, center=c))
            zt = z + balcony_thickness
            parts.append(revolve([(rb * k - 0.12, zt), (rb * k, zt), (rb * k, zt + parapet_height),
                                  (rb * k - 0.12, zt + parapet_height)], n_segments=ns, angle0=a0,
                                 closed=True, center=c))
            z = zt
            r = r_top * (1 - setback)
        else:
            r = r_top
    # cupola floor
    parts.append(revolve([(0, z), ((r + 0.3) * k, z), ((r + 0.3) * k, z + 0.25), (0, z + 0.25)],
                         n_segments=ns, angle0=a0, center=c))
    z += 0.25
    if cupola == "posts":
        parts.append(chattri(center=(c[0], c[1], c[2] + z - 0.25), radius=cup_r, n_posts=n_posts,
                             post_height=post_h, post_width=0.12 + 0.05 * cup_r, platform_height=0.25,
                             finial=finial_len, kind="hemispherical"))
    elif cupola == "dome":
        parts.append(dome(center=(c[0], c[1], c[2] + z), radius=cup_r, height=1.2 * cup_r,
                          thickness=0.1, drum_height=0.3, drum_thickness=0.15, finial=finial_len,
                          n_segments=max(ns, 24)))
    else:
        raise ValueError(f"unknown cupola {cupola!r}; known: posts, dome")
    return concat_meshes(parts)


def bastion(
    *,
    center: Sequence[float] = (0.0, 0.0, 0.0),
    radius: float = 5.5,
    height: float = 27.0,
    batter: float = 0.12,
    parapet_height: float = 1.6,
    parapet_thickness: float = 0.6,
    n_segments: int = 64,
) -> TriMesh:
    """A round fort bastion: battered (tapering) drum, a moulding band, a parapet on top.

    Examples
    --------
    >>> b = bastion(radius=5.0, height=25.0)
    >>> b.bounds()[:, 2].tolist()
    [0.0, 25.0]
    """
    c = np.asarray(center, dtype=np.float64)
    r_top = radius * (1 - batter)
    z_deck = height - parapet_height
    zm = 0.72 * height
    rm = radius + (r_top - radius) * zm / z_deck
    parts = [
        frustum(radius, r_top, 0.0, z_deck, caps=False, n_segments=n_segments, center=c),
        revolve([(0, z_deck), (r_top, z_deck)], n_segments=n_segments, center=c),
        revolve([(r_top - parapet_thickness, z_deck), (r_top, z_deck), (r_top, height),
                 (r_top - parapet_thickness, height)], n_segments=n_segments, closed=True, center=c),
        revolve([(rm, zm - 0.3), (rm + 0.3, zm - 0.15), (rm + 0.3, zm + 0.15), (rm, zm + 0.3)],
                n_segments=n_segments, center=c),
    ]
    return concat_meshes(parts)


def pillar(
    *,
    center: Sequence[float] = (0.0, 0.0, 0.0),
    height: float = 4.0,
    radius: float = 0.25,
    n_segments: int = 16,
    base_width: float = 0.7,
    base_height: float = 0.3,
    capital_width: float = 0.65,
    capital_height: float = 0.35,
    entasis: float = 0.1,
) -> TriMesh:
    """A free-standing column: square base block, round or polygonal shaft, capital block.

    Examples
    --------
    >>> pillar(height=3.0).bounds()[:, 2].tolist()
    [0.0, 3.0]
    """
    c = np.asarray(center, dtype=np.float64)
    hb, hc = 0.5 * base_width, 0.5 * capital_width
    z0, z1 = base_height, height - capital_height
    return concat_meshes([
        box(c + (-hb, -hb, 0.0), c + (hb, hb, base_height)),
        frustum(radius, radius * (1 - entasis), z0, z1, caps=False, n_segments=n_segments, center=c),
        box(c + (-hc, -hc, z1), c + (hc, hc, height)),
    ])


# --------------------------------------------------------------------------- arcades
@dataclass(frozen=True, kw_only=True, eq=False)
class ArcadeParts:
    """The pieces of an arcade: one mesh per bay (an arch instance each) and the wall above.

    Attributes
    ----------
    bays : tuple of TriMesh
        Bay ``i`` spans from mid-pier to mid-pier, floor to crown plus frame band.
    wall : TriMesh or None
        The wall band above the bays, up to ``height`` (None if there is none).
    frame_top : float
        Height of the top of the bays' frame band.
    """

    bays: tuple[TriMesh, ...]
    wall: TriMesh | None
    frame_top: float


def _crown(kind: str, span: float, spring: float, pointedness: float) -> float:
    return float(arch_outline(0.0, span, spring, kind=kind, pointedness=pointedness, chord=0.2)[:, 1].max())


def arcade(
    path: WallPath,
    *,
    n_bays: int,
    u_start: float = 0.0,
    bay_width: float = 3.6,
    span: float = 2.4,
    spring: float = 3.0,
    kind: str = "round",
    pointedness: float = 1.0,
    height: float | None = None,
    thickness: float = 1.0,
    frame: float = 0.2,
    z0: float = 0.0,
    cap_start: bool = True,
    cap_end: bool = True,
    chord: float = 0.05,
) -> ArcadeParts:
    """A run of ``n_bays`` arched bays with piers between them along a straight or curved wall.

    Parameters
    ----------
    path : StraightPath or ArcPath
        The wall's centre line; the arcade covers ``[u_start, u_start + n_bays * bay_width]``.
    bay_width, span : float
        Bay pitch and clear span; the piers are ``bay_width - span`` wide (half piers at
        the two ends).
    spring : float
        Springing height above ``z0`` (the storey's floor).
    kind, pointedness
        Arch shape (:func:`scenes.shapes.arch_outline`).
    height : float, optional
        Top of the wall band above the bays, relative to ``z0``; none if not above the
        bays' frame.
    frame : float
        Height of the frame band above the crown, as a fraction of the span.

    Examples
    --------
    >>> p = StraightPath(x0=0, y0=0, x1=18, y1=0)
    >>> a = arcade(p, n_bays=5, height=6.0)
    >>> len(a.bays), a.wall is not None, round(a.frame_top, 2)
    (5, True, 4.68)
    """
    if not 0 < span < bay_width:
        raise ValueError(f"span must be in (0, bay_width={bay_width}); got {span}")
    crown = _crown(kind, span, spring, pointedness)
    top = z0 + crown + frame * span
    has_wall = height is not None and z0 + height > top + 1e-6
    bays = []
    for i in range(n_bays):
        u0 = u_start + i * bay_width
        u1 = u0 + bay_width
        uc = 0.5 * (u0 + u1)
        op = arch_outline(uc - 0.5 * span, uc + 0.5 * span, z0 + spring, kind=kind, base=z0,
                          chord=chord, pointedness=pointedness)
        caps = [] if has_wall else ["top"]
        if i == 0 and cap_start:
            caps.append("start")
        if i == n_bays - 1 and cap_end:
            caps.append("end")
        bays.append(wall_panel(path, u0=u0, u1=u1, z0=z0, z1=top, thickness=thickness,
                               openings=[op], caps=caps))
    wall_mesh = None
    if has_wall:
        caps = ["top"] + (["start"] if cap_start else []) + (["end"] if cap_end else [])
        wall_mesh = wall_panel(path, u0=u_start, u1=u_start + n_bays * bay_width, z0=top,
                               z1=z0 + height, thickness=thickness, caps=caps)  # type: ignore[operator]
    return ArcadeParts(bays=tuple(bays), wall=wall_mesh, frame_top=top)


def portal(
    path: WallPath,
    *,
    u0: float,
    u1: float,
    span: float,
    spring: float,
    height: float,
    thickness: float = 2.5,
    kind: str = "pointed",
    pointedness: float = 0.9,
    z0: float = 0.0,
    chord: float = 0.05,
) -> TriMesh:
    """A single large arched portal (iwan-like frame, a pishtaq) spanning ``[u0, u1]`` of ``path``.

    The frame panel is ``thickness`` deep, so the opening's soffit forms a vaulted
    passage. The whole panel is one arch instance.

    Examples
    --------
    >>> p = StraightPath(x0=0, y0=0, x1=10, y1=0)
    >>> portal(p, u0=0, u1=10, span=6, spring=5, height=12).bounds()[:, 2].tolist()
    [0.0, 12.0]
    """
    uc = 0.5 * (u0 + u1)
    op = arch_outline(uc - 0.5 * span, uc + 0.5 * span, z0 + spring, kind=kind, base=z0, chord=chord,
                      pointedness=pointedness)
    if op[:, 1].max() >= z0 + height:
        raise ValueError("portal height must exceed the crown of its arch")
    return wall_panel(path, u0=u0, u1=u1, z0=z0, z1=z0 + height, thickness=thickness, openings=[op],
                      caps=("top", "start", "end"))


# --------------------------------------------------------------------------- planar pieces
def wall(
    path: WallPath,
    *,
    height: float,
    thickness: float = 1.0,
    z0: float = 0.0,
    openings: Sequence[npt.ArrayLike] = (),
    caps: Sequence[str] = ("top", "start", "end"),
) -> TriMesh:
    """A thick wall along the whole of ``path``, from ``z0`` to ``z0 + height``, with openings.

    Examples
    --------
    >>> w = wall(StraightPath(x0=0, y0=0, x1=5, y1=0), height=3.0, thickness=0.4)
    >>> round(w.area(), 6)
    34.4
    """
    return wall_panel(path, u0=0.0, u1=path.length, z0=z0, z1=z0 + height, thickness=thickness,
                      openings=openings, caps=caps)


def roof_slab(
    outer: npt.ArrayLike,
    *,
    z: float,
    thickness: float = 0.5,
    holes: Sequence[tuple[float, float, float]] = (),
    n_segments: int = 64,
) -> TriMesh:
    """A flat roof slab with its top at ``z``, optionally with round holes ``(x, y, r)`` under domes.

    The holes are ``n_segments``-gons matching the drums of :func:`dome` built with the
    same ``n_segments``.

    Examples
    --------
    >>> s = roof_slab([(0, 0), (10, 0), (10, 10), (0, 10)], z=5.0, holes=[(5, 5, 2)])
    >>> s.bounds()[:, 2].tolist()
    [4.5, 5.0]
    """
    t = 2 * np.pi * np.arange(n_segments) / n_segments
    rings = [np.c_[x + r * np.cos(t), y + r * np.sin(t)] for x, y, r in holes]
    return slab(outer, z0=z - thickness, z1=z, holes=rings)


def ground(xmin: float, xmax: float, ymin: float, ymax: float) -> TriMesh:
    """The ground: one horizontal rectangle at ``z = 0`` (two triangles).

    Examples
    --------
    >>> ground(-1, 1, -2, 2).area()
    8.0
    """
    v = np.array([[xmin, ymin, 0], [xmax, ymin, 0], [xmax, ymax, 0], [xmin, ymax, 0]], dtype=np.float64)
    return TriMesh(v, np.array([[0, 1, 2], [0, 2, 3]]))
