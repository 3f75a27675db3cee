"""Random small scenes for HollowNet's training data, built from :mod:`scenes.elements`.

Each recipe draws an arrangement (a domed hall, a group of minarets or a bastion, an
arcade or a portal, a colonnade or porch, a street with clutter) with proportions drawn
from wide ranges around the element builders' defaults, the ground, a few pieces of
clutter, and scanner stations around it (sometimes one on a roof or inside), so that the
scan shows occlusion, density falling with range, inner and outer surfaces.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from hollowtree.classes import ClassId
from hollowtree.scenes._builders import EYE, add_arcade
from hollowtree.scenes.elements import (
    ArcPath,
    StraightPath,
    _crown,
    arcade,
    bastion,
    bench,
    bicycle,
    car,
    chattri,
    dome,
    ground,
    minaret,
    pillar,
    portal,
    roof_slab,
    tree,
    wall,
)
from hollowtree.scenes.mesh import TriMesh
from hollowtree.scenes.scene import Scene, SceneBuilder
from hollowtree.scenes.shapes import box, ellipsoid

__all__ = ["RECIPES", "random_scene", "storeyed_arcades"]


def _u(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(rng.uniform(lo, hi))


def _clutter_mesh(rng: np.random.Generator, x: float, y: float) -> TriMesh:
    kind = int(rng.integers(0, 6))
    yaw = _u(rng, 0, 2 * math.pi)
    if kind == 0:
        return bench(x=x, y=y, yaw=yaw, length=_u(rng, 1.2, 2.4))
    if kind == 1:
        return car(x=x, y=y, yaw=yaw, length=_u(rng, 3.6, 5.0), width=_u(rng, 1.6, 2.0),
                   height=_u(rng, 1.3, 1.9))
    if kind == 2:
        return bicycle(x=x, y=y, yaw=yaw)
    if kind == 3:
        h = _u(rng, 3.0, 12.0)
        return tree(x=x, y=y, height=h, crown_radius=_u(rng, 0.2, 0.45) * h,
                    trunk_radius=_u(rng, 0.1, 0.35))
    if kind == 4:  # crates, a kiosk, a generator: boxes
        sx, sy, sz = _u(rng, 0.4, 2.5), _u(rng, 0.4, 2.5), _u(rng, 0.4, 2.2)
        return box((-sx / 2, -sy / 2, 0), (sx / 2, sy / 2, sz)).rotated_z(yaw).translated((x, y, 0))
    r = _u(rng, 0.5, 1.6)  # a bush
    return ellipsoid((r, r * _u(rng, 0.7, 1.3), r * _u(rng, 0.5, 1.0)), center=(x, y, 0.6 * r),
                     n_segments=12, n_rings=6)


def _add_clutter(b: SceneBuilder, rng: np.random.Generator, n: int, radius: float, keep_out: float) -> None:
    for _ in range(n):
        ang = _u(rng, 0, 2 * math.pi)
        d = _u(rng, keep_out, radius)
        b.add(_clutter_mesh(rng, d * math.cos(ang), d * math.sin(ang)), ClassId.OTHER, "clutter")


def _stations(b: SceneBuilder, rng: np.random.Generator, n: int, r0: float, r1: float,
              extra: list[tuple[float, float, float]] | None = None) -> None:
    a0 = _u(rng, 0, 2 * math.pi)
    for i in range(n):
        ang = a0 + 2 * math.pi * i / n + _u(rng, -0.4, 0.4)
        d = _u(rng, r0, r1)
        b.add_station((d * math.cos(ang), d * math.sin(ang), EYE))
    for p in extra or []:
        b.add_station(p)


def _hall(rng: np.random.Generator) -> Scene:
    """A room with a flat roof, often a dome on it and chattris at its corners."""
    b = SceneBuilder("hall")
    hx, hy = _u(rng, 3.0, 9.0), _u(rng, 3.0, 9.0)
    h, t = _u(rng, 3.0, 9.0), _u(rng, 0.3, 1.0)
    for x0, y0, x1, y1 in ((-hx, -hy, hx, -hy), (hx, -hy, hx, hy), (hx, hy, -hx, hy), (-hx, hy, -hx, -hy)):
        b.add(wall(StraightPath(x0=x0, y0=y0, x1=x1, y1=y1), height=h, thickness=t), ClassId.WALL, "wall")
    rt = _u(rng, 0.25, 0.6)
    outer = [(-hx - t, -hy - t), (hx + t, -hy - t), (hx + t, hy + t), (-hx - t, hy + t)]
    has_dome = rng.random() < 0.75
    radius = min(hx, hy) * _u(rng, 0.5, 0.95)
    holes = [(0.0, 0.0, radius - 0.4)] if has_dome else []
    b.add(roof_slab(outer, z=h + rt, thickness=rt, holes=holes), ClassId.ROOF, "roof")
    top = h + rt
    if has_dome:
        kind = str(rng.choice(["hemispherical", "onion", "pointed"]))
        b.add(dome(center=(0, 0, top), kind=kind, radius=radius, drum_height=_u(rng, 0.0, 2.5),
                   drum_thickness=0.4, thickness=_u(rng, 0.15, 0.4), finial=_u(rng, 0.0, 1.5),
                   pointedness=_u(rng, 1.1, 1.6), bulge=_u(rng, 1.05, 1.3),
                   height=radius * _u(rng, 0.8, 1.3) if kind == "hemispherical" else None),
              ClassId.DOME, "dome")
    n_ch = int(rng.integers(0, 5)) if min(hx, hy) > 3.5 else 0
    for sx, sy in [(-1, -1), (1, -1), (1, 1), (-1, 1)][:n_ch]:
        cr = _u(rng, 0.8, 1.6)
        b.add(chattri(center=(sx * (hx - cr - 0.4), sy * (hy - cr - 0.4), top), radius=cr,
                      n_posts=int(rng.choice([4, 6, 8])), post_height=_u(rng, 1.5, 2.8),
                      kind=str(rng.choice(["hemispherical", "onion"]))), ClassId.DOME, "chattri")
    span = max(hx, hy) * 3 + 20
    b.add(ground(-span, span, -span, span), ClassId.GROUND, "ground")
    _add_clutter(b, rng, int(rng.integers(0, 4)), span * 0.6, max(hx, hy) + 2)
    extra = []
    if rng.random() < 0.5:  # a station on the roof sees the roof, the dome and the chattris
        extra.append((_u(rng, -0.8, 0.8) * hx, (hy - 0.8) * float(rng.choice([-1, 1])), top + EYE))
    if rng.random() < 0.3:  # one inside
        extra.append((_u(rng, -0.5, 0.5) * hx, _u(rng, -0.5, 0.5) * hy, EYE))
    _stations(b, rng, int(rng.integers(2, 5)), max(hx, hy) + 4, max(hx, hy) + 25, extra)
    return b.build()


def _towers(rng: np.random.Generator) -> Scene:
    """One to four minarets, or a bastion between curtain walls."""
    b = SceneBuilder("towers")
    if rng.random() < 0.3:
        r = _u(rng, 3.0, 8.0)
        b.add(bastion(center=(0, 0, 0), radius=r, height=_u(rng, 10.0, 30.0), batter=_u(rng, 0.0, 0.2)),
              ClassId.MINARET, "bastion")
        for ang in rng.choice([0.0, 90.0, 180.0, 270.0], size=int(rng.integers(1, 3)), replace=False):
            c, s = math.cos(math.radians(ang)), math.sin(math.radians(ang))
            b.add(wall(StraightPath(x0=0.75 * r * c, y0=0.75 * r * s, x1=(r + 25) * c, y1=(r + 25) * s),
                       height=_u(rng, 6.0, 20.0), thickness=_u(rng, 2.0, 5.0)), ClassId.WALL, "curtain")
        span = 60.0
    else:
        n = int(rng.integers(1, 5))
        pitch = _u(rng, 8.0, 20.0)
        for i in range(n):
            h = _u(rng, 12.0, 40.0)
            r = h * _u(rng, 0.05, 0.09)
            m = minaret(center=((i % 2) * pitch, (i // 2) * pitch, 0), height=h, base_radius=r,
                        n_stages=int(rng.integers(2, 7)), n_segments=int(rng.choice([8, 12, 16, 48])),
                        taper=_u(rng, 0.0, 0.1), balcony_depth=_u(rng, 0.4, 1.2),
                        cupola=str(rng.choice(["posts", "dome"])), n_posts=int(rng.choice([6, 8])))
            b.add(m, ClassId.MINARET, "minaret")
        span = 50.0
    b.add(ground(-span, span, -span, span), ClassId.GROUND, "ground")
    _add_clutter(b, rng, int(rng.integers(0, 4)), 30.0, 8.0)
    _stations(b, rng, int(rng.integers(2, 5)), 12.0, 35.0)
    return b.build()


def _arches(rng: np.random.Generator) -> Scene:
    """A straight or curved arcade with or without a wall above, or a portal in a wall."""
    b = SceneBuilder("arches")
    thick = _u(rng, 0.5, 2.0)
    if rng.random() < 0.2:
        w = _u(rng, 6.0, 14.0)
        path = StraightPath(x0=-w / 2 - 10, y0=0.0, x1=w / 2 + 10, y1=0.0)
        spring = _u(rng, 0.3, 0.6) * w
        b.add(portal(path, u0=10, u1=10 + w, span=_u(rng, 0.5, 0.75) * w, spring=spring,
                     height=spring + _u(rng, 0.6, 1.0) * w, thickness=_u(rng, 1.5, 3.5),
                     pointedness=_u(rng, 0.7, 1.2)), ClassId.ARCH, "portal")
        for u0, u1 in ((0.0, 10.0), (10 + w, 20 + w)):
            b.add(wall(StraightPath(x0=path.x0 + u0, y0=0.0, x1=path.x0 + u1, y1=0.0),
                       height=_u(rng, 5.0, 12.0), thickness=thick), ClassId.WALL, "wall")
    else:
        n = int(rng.integers(3, 10))
        pitch = _u(rng, 2.5, 6.0)
        if rng.random() < 0.3:
            radius = _u(rng, 10.0, 25.0)
            sweep = min(n * pitch / radius, 2.5)
            path: StraightPath | ArcPath = ArcPath(cx=0.0, cy=-radius * 0.5, radius=radius,
                                                   theta0=math.pi / 2 - sweep / 2, theta1=math.pi / 2 + sweep / 2)
            pitch = path.length / n
        else:
            path = StraightPath(x0=-n * pitch / 2, y0=0.0, x1=n * pitch / 2, y1=0.0)
        span = _u(rng, 0.5, 0.8) * pitch
        spring = _u(rng, 0.6, 1.6) * pitch
        has_wall = rng.random() < 0.6
        parts = arcade(path, n_bays=n, bay_width=pitch, span=span, spring=spring,
                       kind=str(rng.choice(["round", "pointed"])), pointedness=_u(rng, 0.6, 1.2),
                       height=spring + pitch * _u(rng, 1.0, 2.0) if has_wall else None, thickness=thick)
        for bay in parts.bays:
            b.add(bay, ClassId.ARCH, "bay")
        if parts.wall is not None:
            b.add(parts.wall, ClassId.WALL, "wall above")
    b.add(ground(-50, 50, -50, 50), ClassId.GROUND, "ground")
    _add_clutter(b, rng, int(rng.integers(0, 4)), 25.0, 5.0)
    _stations(b, rng, int(rng.integers(2, 5)), 8.0, 30.0)
    return b.build()


def _colonnade(rng: np.random.Generator) -> Scene:
    """Free-standing pillars in a row or a grid, sometimes under a porch roof before a wall."""
    b = SceneBuilder("colonnade")
    nx, ny = int(rng.integers(1, 5)), int(rng.integers(1, 3))
    h = _u(rng, 2.5, 8.0)
    r = h * _u(rng, 0.04, 0.09)
    px, py = _u(rng, 2.0, 5.0) + 4 * r, _u(rng, 2.0, 5.0) + 4 * r
    seg = int(rng.choice([4, 8, 16, 32]))
    for i in range(nx):
        for j in range(ny):
            b.add(pillar(center=((i - (nx - 1) / 2) * px, (j - (ny - 1) / 2) * py, 0.0), height=h,
                         radius=r, n_segments=seg, base_width=r * _u(rng, 2.2, 3.5),
                         base_height=_u(rng, 0.1, 0.5), capital_width=r * _u(rng, 2.0, 3.2),
                         capital_height=_u(rng, 0.1, 0.5), entasis=_u(rng, 0.0, 0.15)),
                  ClassId.PILLAR, "pillar")
    x1, y1 = (nx - 1) / 2 * px + 1.5, (ny - 1) / 2 * py + 1.5
    if rng.random() < 0.5:  # a porch: roof on the pillars, a wall behind
        b.add(roof_slab([(-x1, -y1), (x1, -y1), (x1, y1 + 3), (-x1, y1 + 3)], z=h + 0.4, thickness=0.4),
              ClassId.ROOF, "porch roof")
        b.add(wall(StraightPath(x0=-x1, y0=y1 + 3, x1=x1, y1=y1 + 3), height=h + 0.4,
                   thickness=_u(rng, 0.4, 1.0)), ClassId.WALL, "back wall")
    b.add(ground(-40, 40, -40, 40), ClassId.GROUND, "ground")
    _add_clutter(b, rng, int(rng.integers(0, 4)), 20.0, max(x1, y1) + 2)
    _stations(b, rng, int(rng.integers(2, 5)), max(x1, y1) + 3, max(x1, y1) + 15)
    return b.build()


def _street(rng: np.random.Generator) -> Scene:
    """Clutter (benches, cars, bicycles, trees, crates, bushes) along a wall, low flat roofs."""
    b = SceneBuilder("street")
    n = int(rng.integers(3, 9))
    for _ in range(n):
        b.add(_clutter_mesh(rng, _u(rng, -15, 15), _u(rng, -8, 8)), ClassId.OTHER, "clutter")
    b.add(wall(StraightPath(x0=-25, y0=12, x1=25, y1=12), height=_u(rng, 2.0, 12.0),
               thickness=_u(rng, 0.3, 1.5)), ClassId.WALL, "wall")
    if rng.random() < 0.6:  # a shed roof on posts-free walls: a roof seen from a raised station
        x0 = _u(rng, -20, 5)
        z = _u(rng, 2.5, 6.0)
        w, d = _u(rng, 4, 15), _u(rng, 3, 10)
        b.add(roof_slab([(x0, 12), (x0 + w, 12), (x0 + w, 12 + d), (x0, 12 + d)], z=z,
                        thickness=_u(rng, 0.2, 0.6)), ClassId.ROOF, "roof")
        for xa in (x0, x0 + w):
            b.add(wall(StraightPath(x0=xa, y0=12, x1=xa, y1=12 + d), height=z - 0.3, thickness=0.3),
                  ClassId.WALL, "side wall")
        b.add_station((x0 + w / 2, 12 - 3, z + _u(rng, 1.0, 4.0)))
    b.add(ground(-45, 45, -30, 45), ClassId.GROUND, "ground")
    _stations(b, rng, int(rng.integers(2, 4)), 4.0, 15.0)
    return b.build()


#: Recipe name -> (builder, classes it yields most of).
RECIPES: dict[str, tuple[Callable[[np.random.Generator], Scene], tuple[ClassId, ...]]] = {
    "hall": (_hall, (ClassId.DOME, ClassId.ROOF, ClassId.WALL)),
    "towers": (_towers, (ClassId.MINARET,)),
    "arches": (_arches, (ClassId.ARCH,)),
    "colonnade": (_colonnade, (ClassId.PILLAR, ClassId.ROOF)),
    "street": (_street, (ClassId.OTHER, ClassId.ROOF, ClassId.GROUND)),
}


def random_scene(recipe: str, rng: np.random.Generator) -> Scene:
    """Build one random scene of ``recipe`` (a key of :data:`RECIPES`)."""
    return RECIPES[recipe][0](rng)


def storeyed_arcades(rng: np.random.Generator) -> Scene:
    """Two or three storeys of arcades, one above the other, each with a wall band above
    its bays, straight or curved (the training scenes of the split model,
    :mod:`tree.fit_split`; not a HollowNet recipe). Every bay is one arch instance."""
    b = SceneBuilder("storeyed")
    n_st = int(rng.integers(2, 4))
    n = int(rng.integers(5, 16))
    pitch = _u(rng, 2.0, 4.5)
    thick = _u(rng, 0.6, 1.8)
    path: ArcPath | StraightPath
    if rng.random() < 0.5:
        radius = _u(rng, 12.0, 30.0)
        sweep = min(n * pitch / radius, 3.3)
        path = ArcPath(cx=0.0, cy=-radius * 0.5, radius=radius, theta0=math.pi / 2 - sweep / 2,
                       theta1=math.pi / 2 + sweep / 2)
        pitch = path.length / n
    else:
        path = StraightPath(x0=-n * pitch / 2, y0=0.0, x1=n * pitch / 2, y1=0.0)
    z0 = 0.0
    kind = str(rng.choice(["round", "pointed"]))
    for s in range(n_st):
        span = _u(rng, 0.55, 0.75) * pitch
        spring = _u(rng, 0.8, 1.5) * pitch
        pointed = _u(rng, 0.7, 1.2)
        top = _crown(kind, span, spring, pointed) + 0.2 * span
        hgt = top + _u(rng, 0.4, 1.5)
        parts = arcade(path, n_bays=n, bay_width=pitch, span=span, spring=spring, kind=kind,
                       pointedness=pointed, height=hgt, thickness=thick, z0=z0)
        add_arcade(b, parts, f"storey {s + 1}")
        z0 += hgt
    b.add(ground(-60, 60, -60, 60), ClassId.GROUND, "ground")
    _add_clutter(b, rng, int(rng.integers(0, 4)), 30.0, 6.0)
    _stations(b, rng, int(rng.integers(3, 7)), 10.0, 35.0)
    return b.build()
