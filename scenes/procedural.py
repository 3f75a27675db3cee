"""Procedural architectural sites from a small style grammar: a new site for every seed.

The five paper sites (:mod:`scenes.paper_sites`) are fixed compositions; a user's scan is
not one of them. This module draws whole sites from a distribution instead:

layout families (:data:`FAMILIES`)
    ``courtyard_mosque`` (arcaded courtyard, domed prayer hall, corner minarets, gateway),
    ``linear_facade`` (a straight facade of 1-3 arcade storeys, towers, roof pavilions),
    ``fort`` (an enclosure of high walls, bastions, a gateway),
    ``pavilion_garden`` (pavilions, colonnades and free-standing pillars among trees),
    ``curved_facade`` (an arena-like curved facade of 1-4 arcade storeys),
    ``monument`` (an isolated domed tomb on a plinth, with minarets and pavilions),
    ``ruins`` (any other family with elements missing and others broken off).
compound elements
    a *pavilion* (chattri) is a dome, its columns and its slab, each labelled as its own
    part (dome, pillar per column, roof); a *gateway* is one arch, two piers (pillars) and
    the wall around; a *colonnade* is a row of pillars under a roof beam; an arcade is one
    arch instance per bay in 1-4 storeys, straight or curved.
element styles
    domes hemispherical, shallow, onion, pointed or ribbed (faceted), on drums or not;
    minarets of 1-8 stages, round or polygonal; pillars round, square or clustered.
proportions, counts, clutter
    every size and count is drawn from a wide range; clutter (trees, people, cars,
    benches, bicycles, scaffolding) is scattered around, never inside anything; stations
    are random, inside and outside, sometimes all on one side (a partial scan); the whole
    site is turned by a random heading.

A site is a pure function of ``(seed, family)``. :data:`SPLITS` fixes which seeds are for
training, validation and test (docs/generalize.md): learned parts and thresholds are
fitted on training seeds only, chosen on validation seeds, and reported on test seeds.

Labels follow docs/scenes.md (an arch instance is one bay, a minaret instance all its
stages, a bastion is a minaret instance, every planar piece its own instance) except
that compound elements are split into their parts, as above.

Examples
--------
>>> s = procedural_site(200_000)
>>> s.name.startswith("gen-") and len(s.stations) >= 3
True
>>> procedural_site(5, "fort").name
'gen-fort-5'
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from hollowtree.classes import ClassId
from hollowtree.errors import ConfigError
from hollowtree.scenes._builders import EYE
from hollowtree.scenes.clutter import bench, bicycle, car, person, scaffold, tree
from hollowtree.scenes.elements import (
    arcade,
    bastion,
    dome,
    ground,
    minaret,
    pillar,
    portal,
    roof_slab,
    wall,
)
from hollowtree.scenes.mesh import TriMesh, concat_meshes
from hollowtree.scenes.scene import Scene, SceneBuilder
from hollowtree.scenes.shapes import ArcPath, StraightPath, box

__all__ = ["FAMILIES", "GENERATOR", "SPLITS", "ScanDraw", "family_of", "procedural_site", "scan_draw", "site_points",
           "split_seeds"]

#: The generator's version, in the names of the scans made from it (a changed distribution
#: makes new scans, never reuses old ones): ``gen-v2`` draws a site heading; ``gen-v3``
#: stands every raised column on something (a pavilion's platform square to its columns,
#: a facade's roof pavilions on a platform on the wall top, a monument's on its roof);
#: ``gen-v4`` stands nothing inside anything else (a garden's pavilions, colonnades and
#: pillars apart, clutter and stations clear of what stands on the ground).
GENERATOR = "gen-v4"

#: What stands on the ground is kept apart on a raster of :data:`FOOT_CELL` metres: the
#: cells of a thing's surface below :data:`FOOT_HEIGHT` metres (a column, a wall, a
#: platform; not a slab or a dome overhead) are taken, and clutter or a station goes only
#: where its own cells and :data:`FOOT_CLEAR` cells around them are free.
FOOT_CELL = 0.25
FOOT_HEIGHT = 2.0
FOOT_CLEAR = 1
#: Metres kept between a garden's pavilions, colonnades and free-standing pillars.
GARDEN_CLEAR = 0.8
#: Draws of a position before a thing that finds no free one is left out.
PLACE_TRIES = 30


def _footprint(m: TriMesh, below: float = FOOT_HEIGHT) -> np.ndarray:
    """The :data:`FOOT_CELL` cells (keys, unique) of ``m``'s surface below ``below`` metres:
    every face reaching below it sampled at about 16 points per cell area (its corners
    among them), with a fixed random source (a site stays a function of its seed).

    >>> from hollowtree.scenes.shapes import box
    >>> len(_footprint(box((0.1, 0.1, 0.0), (0.9, 0.4, 3.0))))  # 4 x 2 cells
    8
    >>> len(_footprint(box((0.0, 0.0, 2.5), (1.0, 1.0, 3.0))))  # all of it overhead
    0
    """
    t = m.vertices[m.faces]
    t = t[t[:, :, 2].min(axis=1) < below]
    if not len(t):
        return np.zeros(0, dtype=np.int64)
    area = 0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1)
    n = np.minimum(np.ceil(16.0 * area / FOOT_CELL**2), 200_000).astype(np.int64)
    face = np.repeat(np.arange(len(t)), n)
    ab = np.random.default_rng(0).random((len(face), 2))
    flip = ab.sum(axis=1) > 1.0
    ab[flip] = 1.0 - ab[flip]
    p = t[face, 0] + ab[:, :1] * (t[face, 1] - t[face, 0]) + ab[:, 1:] * (t[face, 2] - t[face, 0])
    p = np.vstack([p, t.reshape(-1, 3)])
    p = p[p[:, 2] < below]
    return np.unique(_cell(p[:, 0], p[:, 1]))


def _cell(x: npt.ArrayLike, y: npt.ArrayLike) -> np.ndarray:
    """The key of the :data:`FOOT_CELL` cell holding each point ``(x, y)``."""
    i = np.floor(np.asarray(x, dtype=np.float64) / FOOT_CELL).astype(np.int64)
    return i * (1 << 32) + np.floor(np.asarray(y, dtype=np.float64) / FOOT_CELL).astype(np.int64)


def _grown(keys: np.ndarray, cells: int = FOOT_CLEAR) -> np.ndarray:
    """``keys`` (of :func:`_footprint`) and the cells within ``cells`` of them."""
    d = np.arange(-cells, cells + 1)
    return np.unique(keys[:, None] + (d[:, None] * (1 << 32) + d[None, :]).reshape(1, -1))


#: The layout families, in the order :func:`family_of` cycles through them.
FAMILIES = ("courtyard_mosque", "linear_facade", "fort", "pavilion_garden", "curved_facade", "monument", "ruins")

#: Seed ranges ``[start, stop)`` of the three splits. Seed s builds family
#: ``FAMILIES[s % 7]`` unless a family is named, so every split holds every family.
SPLITS = {"train": (0, 100_000), "val": (100_000, 110_000), "test": (200_000, 210_000)}


def split_seeds(split: str, n: int, *, family: str | None = None) -> list[int]:
    """The first ``n`` seeds of ``split`` (of ``family`` only, when given).

    >>> split_seeds("test", 3)
    [200000, 200001, 200002]
    >>> split_seeds("val", 2, family="fort")
    [100004, 100011]
    """
    if split not in SPLITS:
        raise ConfigError(f"split {split!r} is not one of {', '.join(SPLITS)}")
    if family is not None and family not in FAMILIES:
        raise ConfigError(f"family {family!r} is not one of {', '.join(FAMILIES)}")
    a, b = SPLITS[split]
    seeds = range(a, b) if family is None else [s for s in range(a, b) if family_of(s) == family]
    return list(seeds[:n]) if isinstance(seeds, range) else seeds[:n]


def family_of(seed: int) -> str:
    """The family seed ``seed`` builds when none is named."""
    return FAMILIES[int(seed) % len(FAMILIES)]


# --------------------------------------------------------------------------- element styles
class _Site:
    """A SceneBuilder with the random source and the ruin rule of one site."""

    def __init__(self, name: str, rng: np.random.Generator, *, ruin: float = 0.0,
                 ruin_rng: np.random.Generator | None = None, place_rng: np.random.Generator | None = None) -> None:
        self.b = SceneBuilder(name)
        self.rng = rng
        self.ruin = ruin
        # the ruin's own draws: the same seed makes the same layout, ruined or not
        self.ruin_rng = ruin_rng if ruin_rng is not None else np.random.default_rng(0)
        # a blocked position's redraws: the site's own draws stay those of ``gen-v3``
        self.place_rng = place_rng if place_rng is not None else np.random.default_rng(1)
        self.extent = np.array([[np.inf, np.inf], [-np.inf, -np.inf]])
        self.solid: list[tuple[float, float, float, float]] = []  # footprints no station stands in
        self.fallen = False  # in a ruin: what is built now stood on something that fell
        self.taken: set[int] = set()  # the raster cells (:func:`_footprint`) of what stands on the ground
        self.apart: list[tuple[float, float, float, float, float]] = []  # a garden's (x0, y0, x1, y1, r)

    def free(self, keys: np.ndarray) -> bool:
        """Whether the cells ``keys`` and :data:`FOOT_CLEAR` around them are all free."""
        return not any(int(k) in self.taken for k in _grown(keys))

    def spot(self, x: float, y: float, box: tuple[float, float, float, float], radius: float,
             along: tuple[float, float] = (0.0, 0.0)) -> tuple[float, float] | None:
        """``(x, y)``, or a position redrawn in ``box`` (x0, x1, y0, y1) from the placement's
        own draws (up to :data:`PLACE_TRIES`), for a thing reaching ``radius`` metres around
        the segment from it to it + ``along``: :data:`GARDEN_CLEAR` apart from every thing
        placed so far (then it is kept); None where none is free."""
        for k in range(PLACE_TRIES):
            if k:
                x, y = (float(self.place_rng.uniform(box[0], box[1])), float(self.place_rng.uniform(box[2], box[3])))
            seg = np.linspace((x, y), (x + along[0], y + along[1]), 16)
            if all(np.hypot(*(seg[:, None, :] - np.linspace((a, b), (c, d), 16)[None, :, :]).T).min()
                   >= radius + r + GARDEN_CLEAR for a, b, c, d, r in self.apart):
                self.apart.append((x, y, x + along[0], y + along[1], radius))
                return x, y
        return None

    def u(self, lo: float, hi: float) -> float:
        return float(self.rng.uniform(lo, hi))

    def i(self, lo: int, hi: int) -> int:
        """An integer in ``[lo, hi]``."""
        return int(self.rng.integers(lo, hi + 1))

    def pick(self, options: tuple) -> object:
        return options[int(self.rng.integers(len(options)))]

    @contextmanager
    def falling(self, fell: bool) -> Iterator[None]:
        """In a ruin, what is built in this block is missing when ``fell``: it stood on
        something missing or broken off (the layout's draws are made all the same)."""
        before = self.fallen
        self.fallen = before or fell
        try:
            yield
        finally:
            self.fallen = before

    def add(self, mesh: TriMesh | list[TriMesh], cls: ClassId, name: str, *, cells: np.ndarray | None = None) -> bool:
        """Add one instance; in a ruin it may be missing or broken off at a random height.
        True when it stands whole (what stands on it can stand). ``cells``: its
        :func:`_footprint` where the caller has it already."""
        m = mesh if isinstance(mesh, TriMesh) else concat_meshes(mesh)
        if cls != ClassId.GROUND:  # fallen or not: the layout is the same, ruined or not
            self.taken.update((_footprint(m) if cells is None else cells).tolist())
        if self.fallen:
            return False
        whole = True
        if self.ruin and cls != ClassId.GROUND:
            if self.ruin_rng.random() < 0.5 * self.ruin:
                return False
            if self.ruin_rng.random() < self.ruin:
                lo, hi = m.bounds()[:, 2]
                cut = lo + (hi - lo) * float(self.ruin_rng.uniform(0.35, 0.9))
                keep = m.vertices[m.faces][:, :, 2].max(axis=1) <= cut
                if keep.sum() < 4:
                    return False
                m = TriMesh(m.vertices, m.faces[keep])
                whole = False
        bb = m.bounds()
        self.extent[0] = np.minimum(self.extent[0], bb[0, :2])
        self.extent[1] = np.maximum(self.extent[1], bb[1, :2])
        self.b.add(m, cls, name)
        return whole


def _dome(s: _Site, center: tuple[float, float, float], radius: float, name: str, *, drum: bool | None = None) -> None:
    style = s.pick(("hemispherical", "shallow", "onion", "pointed", "ribbed"))
    kw: dict = {}
    kind = "hemispherical" if style in ("shallow", "ribbed") else style
    if style == "shallow":
        kw["height"] = radius * s.u(0.35, 0.6)
    if style == "pointed":
        kw["pointedness"] = s.u(1.15, 1.6)
    if style == "onion":
        kw["bulge"] = s.u(1.1, 1.3)
    drum_h = (s.u(0.5, 0.6 * radius + 0.5) if (drum if drum is not None else s.rng.random() < 0.6) else 0.0)
    s.add(dome(center=center, kind=kind, radius=radius, thickness=min(0.35, 0.12 * radius + 0.05),
               drum_height=drum_h, drum_thickness=min(0.5, 0.2 * radius), finial=s.u(0.0, 0.4 * radius + 0.3),
               n_segments=s.i(10, 16) if style == "ribbed" else 48, **kw), ClassId.DOME, name)


def _minaret(s: _Site, x: float, y: float, name: str, *, z0: float = 0.0, height: float | None = None) -> None:
    r = s.u(0.9, 2.8)
    h = height if height is not None else s.u(max(10.0, 5.5 * r + 5.0), 48.0)
    h = max(h, 5.5 * r + 5.0)  # room for the cupola
    s.add(minaret(center=(x, y, z0), height=h, base_radius=r, n_stages=s.i(1, 8),
                  n_segments=int(s.pick((6, 8, 8, 12, 16, 48, 48))),  # polygonal or round shafts
                  balcony_depth=s.u(0.3, 1.1), taper=s.u(0.0, 0.08), setback=s.u(0.0, 0.06)),
          ClassId.MINARET, name)


def _pillar(s: _Site, x: float, y: float, height: float, name: str, *, z0: float = 0.0,
            style: str | None = None, radius: float | None = None) -> bool:
    style = style or str(s.pick(("round", "round", "square", "clustered")))
    r = radius if radius is not None else s.u(0.15, 0.55)
    c = (x, y, z0)
    if style == "clustered":  # four shafts on one base, one pillar
        d = 0.9 * r
        shafts = [pillar(center=(x + dx, y + dy, z0), height=height, radius=0.55 * r, n_segments=12,
                         base_width=1.3 * r, capital_width=1.2 * r, base_height=0.2, capital_height=0.25)
                  for dx, dy in ((d, 0), (-d, 0), (0, d), (0, -d))]
        shafts.append(box((x - 1.6 * r, y - 1.6 * r, z0), (x + 1.6 * r, y + 1.6 * r, z0 + 0.3)))
        return s.add(shafts, ClassId.PILLAR, name)
    n = 4 if style == "square" else 20
    return s.add(pillar(center=c, height=height, radius=r, n_segments=n, base_width=2.6 * r + 0.1,
                 capital_width=2.4 * r + 0.1, base_height=min(0.3, 0.08 * height),
                 capital_height=min(0.35, 0.09 * height), entasis=s.u(0.0, 0.15)), ClassId.PILLAR, name)


def _pavilion(s: _Site, x: float, y: float, name: str, *, z0: float = 0.0, size: float | None = None,
              platform: bool = False) -> None:
    """A chattri as its parts: columns (pillars), the slab they carry (roof), the dome on it.

    On the ground it stands on a platform (roof) in 60 % of the sites; with ``platform`` it
    always does, at any ``z0`` (a roof pavilion on a wall top it overhangs). The platform is
    square to the columns and half a metre wider, so that every column stands on it. In a
    ruin a fallen platform takes the pavilion with it, and the slab and dome stand on at
    least three whole columns."""
    half = size if size is not None else s.u(1.2, 3.5)
    n_side = s.i(2, 3)
    post_h = s.u(1.8, 4.0)
    r = s.u(0.1, 0.25)
    yaw = s.u(0.0, np.pi / 2)
    c, sn = np.cos(yaw), np.sin(yaw)

    def at(u: float, v: float) -> tuple[float, float]:  # the pavilion's (u, v) in the site
        return x + c * u - sn * v, y + sn * u + c * v

    ring = set()
    for i in range(n_side):
        for j in range(n_side):
            if 0 < i < n_side - 1 and 0 < j < n_side - 1:
                continue
            ring.add((i, j))
    fell = False
    if platform or (z0 == 0.0 and s.rng.random() < 0.6):
        pz = s.u(0.3, 1.2)
        p = half + 0.5
        square = [at(u, v) for u, v in ((-p, -p), (p, -p), (p, p), (-p, p))]
        fell = not s.add(roof_slab(square, z=z0 + pz, thickness=pz), ClassId.ROOF, f"{name} platform")
        z0 += pz
    standing = 0
    with s.falling(fell):
        for k, (i, j) in enumerate(sorted(ring)):
            u = -half + 2 * half * i / (n_side - 1)
            v = -half + 2 * half * j / (n_side - 1)
            standing += _pillar(s, *at(u, v), post_h, f"{name} column {k + 1}", z0=z0,
                                style=str(s.pick(("round", "square"))), radius=r)
    t = s.u(0.2, 0.45)
    e = half + s.u(0.2, 0.6)
    corners = [at(u, v) for u, v in ((-e, -e), (e, -e), (e, e), (-e, e))]
    with s.falling(standing < 3):
        slab = s.add(roof_slab(corners, z=z0 + post_h + t, thickness=t), ClassId.ROOF, f"{name} slab")
        with s.falling(not slab):
            _dome(s, (x, y, z0 + post_h + t), half * s.u(0.8, 1.05), f"{name} dome", drum=s.rng.random() < 0.3)


def _gateway(s: _Site, path: StraightPath, u0: float, width: float, height: float, name: str,
             depth: float) -> None:
    """One arch (the opening and its frame), two piers (pillars) at its sides."""
    pier = s.u(0.6, 1.6)
    span = width * s.u(0.55, 0.8)
    spring = min(height * s.u(0.35, 0.6), height - 0.9 * span)
    spring = max(spring, 1.5)
    top = max(height, spring + 0.8 * span + 1.0)
    s.add(portal(path, u0=u0 + pier, u1=u0 + pier + width, span=span, spring=spring, height=top,
                 thickness=depth, kind=str(s.pick(("pointed", "round"))), pointedness=s.u(0.7, 1.0)),
          ClassId.ARCH, f"{name} arch")
    t = np.array([path.x1 - path.x0, path.y1 - path.y0]) / path.length
    for k, uc in enumerate((u0 + 0.5 * pier, u0 + 1.5 * pier + width)):
        px, py = path.x0 + uc * t[0], path.y0 + uc * t[1]
        _pillar(s, px, py, top + s.u(0.5, 3.0), f"{name} pier {k + 1}", style="square",
                radius=0.5 * pier)


def _arcade_storeys(s: _Site, path: StraightPath | ArcPath, name: str, *, storeys: int | None = None,
                    top_wall: bool = True) -> float:
    """1-4 storeys of arcades along ``path``; returns the height of the top."""
    n_storeys = storeys if storeys is not None else s.i(1, 3)
    bay = s.u(2.5, 6.0)
    n_bays = max(1, int(path.length // bay))
    bay = path.length / n_bays
    z = 0.0
    thick = s.u(0.5, 1.6)
    for k in range(n_storeys):
        span = bay * s.u(0.5, 0.78)
        spring = s.u(1.8, 4.5) if k == 0 else s.u(1.5, 3.5)
        band = s.u(0.4, 2.0)
        parts = arcade(path, n_bays=n_bays, bay_width=bay, span=span, spring=spring,
                       kind=str(s.pick(("round", "pointed"))), pointedness=s.u(0.7, 1.0),
                       height=None, thickness=thick, z0=z)
        for i, bay_mesh in enumerate(parts.bays):
            s.add(bay_mesh, ClassId.ARCH, f"{name} storey {k + 1} bay {i + 1}")
        top = parts.frame_top + band if (top_wall or k < n_storeys - 1) else parts.frame_top
        if top > parts.frame_top + 0.05:
            s.add(wall(path, height=top - parts.frame_top, thickness=thick, z0=parts.frame_top,
                       caps=("top", "start", "end")), ClassId.WALL, f"{name} storey {k + 1} wall")
        z = top
    return z


def _clutter(s: _Site, x0: float, x1: float, y0: float, y1: float, n: int) -> None:
    """``n`` things (trees, people, cars, ...) drawn in the box, each where it stands clear
    of everything on the ground so far (:meth:`_Site.free`): a blocked one is moved (the
    placement's own draws, :data:`PLACE_TRIES` at most) or left out."""
    placed = 0
    for _ in range(n):
        x, y, yaw = s.u(x0, x1), s.u(y0, y1), s.u(0, 2 * np.pi)
        kind = s.pick(("tree", "tree", "person", "person", "car", "bench", "bicycle", "scaffold"))
        size = (s.u(3.0, 12.0), s.u(1.0, 4.0)) if kind == "tree" else (s.u(1.5, 1.9),) if kind == "person" \
            else (s.u(2.0, 6.0), s.u(1.0, 2.0), s.u(3.0, 10.0)) if kind == "scaffold" else ()
        for k in range(PLACE_TRIES):
            if k:
                x, y = float(s.place_rng.uniform(x0, x1)), float(s.place_rng.uniform(y0, y1))
            if kind == "tree":
                m = tree(x=x, y=y, height=size[0], crown_radius=size[1])
            elif kind == "person":
                m = person(x=x, y=y, height=size[0])
            elif kind == "car":
                m = car(x=x, y=y, yaw=yaw)
            elif kind == "bench":
                m = bench(x=x, y=y, yaw=yaw)
            elif kind == "bicycle":
                m = bicycle(x=x, y=y, yaw=yaw)
            else:
                m = scaffold(x=x, y=y, yaw=yaw, width=size[0], depth=size[1], height=size[2])
            cells = _footprint(m)
            if s.free(cells):
                placed += 1
                s.add(m, ClassId.OTHER, f"{kind} {placed}", cells=cells)
                break


# --------------------------------------------------------------------------- layouts
def _hall(s: _Site, x0: float, x1: float, y0: float, y1: float, name: str) -> tuple[float, bool]:
    """A walled hall with a flat roof and 1-3 domes on it; returns the roof height and
    whether the roof stands whole (in a ruin)."""
    h = s.u(5.0, 14.0)
    t = s.u(0.6, 1.8)
    s.solid.append((x0 - t, x1 + t, y0 - t, y1 + t))
    for side, (a, b, c, d) in {"front": (x0, y0, x1, y0), "right": (x1, y0, x1, y1),
                               "back": (x1, y1, x0, y1), "left": (x0, y1, x0, y0)}.items():
        s.add(wall(StraightPath(x0=a, y0=b, x1=c, y1=d), height=h, thickness=t), ClassId.WALL, f"{name} {side} wall")
    n_domes = s.i(1, 3)
    w = (x1 - x0) / n_domes
    radius = min(0.42 * w, 0.42 * (y1 - y0))
    holes = [(x0 + (k + 0.5) * w, 0.5 * (y0 + y1), 0.85 * radius) for k in range(n_domes)]
    whole = s.add(roof_slab([(x0, y0), (x1, y0), (x1, y1), (x0, y1)], z=h + 0.4, thickness=0.4, holes=holes),
                  ClassId.ROOF, f"{name} roof")
    with s.falling(not whole):
        for k, (hx, hy, _) in enumerate(holes):
            _dome(s, (hx, hy, h + 0.4), radius * (1.0 if k == n_domes // 2 else s.u(0.6, 1.0)),
                  f"{name} dome {k + 1}", drum=s.rng.random() < 0.7)
    return h + 0.4, whole


def _courtyard_mosque(s: _Site) -> None:
    w, d = s.u(30.0, 80.0), s.u(25.0, 60.0)
    hall_d = s.u(10.0, 0.4 * d + 6)
    # courtyard sides: arcades (1-2 storeys) backed by nothing (a riwaq face), or plain walls
    for side, path in {"south": StraightPath(x0=-w / 2, y0=-d / 2, x1=w / 2, y1=-d / 2),
                       "east": StraightPath(x0=w / 2, y0=-d / 2, x1=w / 2, y1=d / 2 - hall_d),
                       "west": StraightPath(x0=-w / 2, y0=d / 2 - hall_d, x1=-w / 2, y1=-d / 2)}.items():
        if side == "south" and s.rng.random() < 0.7:  # the gateway in the middle
            g = s.u(4.0, 10.0)
            u0 = 0.5 * (path.length - g) - 1.0
            depth = s.u(1.0, 3.0)
            _gateway(s, path, u0, g, s.u(8.0, 18.0), "gateway", depth)
            for k, (a, b) in enumerate(((0.0, u0), (u0 + g + 2.0 * 1.6, path.length))):
                if b - a > 3.0:
                    s.add(wall(StraightPath(x0=path.x0 + a * (path.x1 - path.x0) / path.length, y0=path.y0,
                                            x1=path.x0 + b * (path.x1 - path.x0) / path.length, y1=path.y1),
                               height=s.u(4.0, 9.0), thickness=depth), ClassId.WALL, f"south wall {k + 1}")
        elif s.rng.random() < 0.75:
            _arcade_storeys(s, path, f"{side} arcade", storeys=s.i(1, 2))
        else:
            s.add(wall(path, height=s.u(3.0, 8.0), thickness=s.u(0.5, 1.5)), ClassId.WALL, f"{side} wall")
    roof, roof_whole = _hall(s, -w / 2, w / 2, d / 2 - hall_d, d / 2, "prayer hall")
    corners = [(-w / 2, d / 2), (w / 2, d / 2), (-w / 2, -d / 2), (w / 2, -d / 2)]
    for k, (x, y) in enumerate(corners[: int(s.pick((0, 2, 2, 4)))]):
        _minaret(s, x + np.sign(x) * 2.5, y + np.sign(y) * 2.5, f"minaret {k + 1}")
    for k in range(s.i(0, 2)):  # roof pavilions at the hall's front corners
        with s.falling(not roof_whole):
            _pavilion(s, (-1) ** k * (w / 2 - 2.5), d / 2 - hall_d + 2.5, f"roof pavilion {k + 1}", z0=roof,
                      size=s.u(1.0, 1.8))


def _linear_facade(s: _Site) -> None:
    length = s.u(25.0, 110.0)
    yaw = s.u(0.0, np.pi)
    c, sn = np.cos(yaw), np.sin(yaw)
    path = StraightPath(x0=-0.5 * length * c, y0=-0.5 * length * sn, x1=0.5 * length * c, y1=0.5 * length * sn)
    top = _arcade_storeys(s, path, "facade", storeys=s.i(1, 3))
    for k, end in enumerate((-1, 1)[: int(s.pick((0, 1, 2, 2)))]):
        _minaret(s, end * (0.5 * length + 3.0) * c, end * (0.5 * length + 3.0) * sn, f"tower {k + 1}")
    for k in range(s.i(0, 3)):
        f = s.u(-0.4, 0.4)
        _pavilion(s, f * length * c, f * length * sn, f"roof pavilion {k + 1}", z0=top, size=s.u(0.9, 1.6),
                  platform=True)


def _fort(s: _Site) -> None:
    w, d = s.u(40.0, 140.0), s.u(30.0, 110.0)
    h = s.u(7.0, 20.0)
    t = s.u(1.5, 4.0)
    corners = [(-w / 2, -d / 2), (w / 2, -d / 2), (w / 2, d / 2), (-w / 2, d / 2)]
    gate_side = s.i(0, 3)
    # Bastions: round or polygonal drums at the corners and along the curtain walls, a
    # bastion every 15-45 m (none at all along the walls in a quarter of the forts).
    sides = s.pick((64, 64, 8, 12, 16))
    spacing = s.u(15.0, 45.0) if s.rng.random() < 0.75 else float("inf")
    r_lo, r_hi = s.pick(((3.0, 5.0), (3.0, 8.0), (5.0, 9.0)))
    towers: list[tuple[float, float]] = list(corners)
    for k in range(4):
        (ax, ay), (bx, by) = corners[k], corners[(k + 1) % 4]
        path = StraightPath(x0=ax, y0=ay, x1=bx, y1=by)
        tx, ty = (bx - ax) / path.length, (by - ay) / path.length
        free = [(0.0, path.length)]
        if k == gate_side:
            g = s.u(4.0, 8.0)
            u0 = 0.5 * (path.length - g) - 1.0
            _gateway(s, path, u0, g, h + s.u(1.0, 6.0), "gateway", t)
            free = [(0.0, u0), (u0 + g + 3.2, path.length)]
            for j, (a, b) in enumerate(free):
                if b - a > 2.0:
                    s.add(wall(StraightPath(x0=ax + a * tx, y0=ay + a * ty, x1=ax + b * tx, y1=ay + b * ty),
                               height=h, thickness=t), ClassId.WALL, f"curtain wall {k + 1}.{j + 1}")
        else:
            s.add(wall(path, height=h, thickness=t), ClassId.WALL, f"curtain wall {k + 1}")
        n = int(path.length // spacing) if np.isfinite(spacing) else 0
        for j in range(1, n + 1):  # evenly along the wall, clear of the corners and the gateway
            u = j * path.length / (n + 1)
            if any(a + r_hi + 2.0 <= u <= b - r_hi - 2.0 for a, b in free):
                towers.append((ax + u * tx, ay + u * ty))
    for k, (x, y) in enumerate(towers):
        corner = k < 4
        s.add(bastion(center=(x, y, 0.0), radius=s.u(r_lo, r_hi) * (1.0 if corner else s.u(0.7, 1.0)),
                      height=h + s.u(1.0, 8.0) if corner else h + s.u(0.5, 5.0), batter=s.u(0.0, 0.15),
                      n_segments=sides),
              ClassId.MINARET, f"bastion {k + 1}")
    if s.rng.random() < 0.5:
        _pavilion(s, s.u(-w / 4, w / 4), s.u(-d / 4, d / 4), "inner pavilion")


def _pavilion_garden(s: _Site) -> None:
    """Pavilions, colonnades and free-standing pillars, each :data:`GARDEN_CLEAR` apart from
    the others and inside the enclosure's square (:meth:`_Site.spot`)."""
    size = s.u(30.0, 90.0)
    h = size / 2 + 3
    walls = ((-h, -h, h, -h), (h, -h, h, h), (h, h, -h, h), (-h, h, -h, -h))
    s.apart.extend((a, b, c, d, 0.25) for a, b, c, d in walls)
    done = 0
    inner = (-size / 2 + 5, size / 2 - 5, -size / 2 + 5, size / 2 - 5)
    for _ in range(s.i(1, 6)):
        x, y, half = s.u(*inner[:2]), s.u(*inner[2:]), s.u(1.2, 3.5)
        at = s.spot(x, y, inner, (half + 0.6) * np.sqrt(2.0))
        if at is not None:
            done += 1
            _pavilion(s, *at, f"pavilion {done}", size=half)
    done = 0
    for _ in range(s.i(0, 2)):  # a colonnade: a row of pillars under a beam
        n = s.i(3, 10)
        pitch = s.u(2.0, 4.0)
        x0, y0, yaw = s.u(-size / 3, size / 3), s.u(-size / 3, size / 3), s.u(0, np.pi)
        h_col = s.u(2.5, 6.0)
        style = str(s.pick(("round", "square", "clustered")))
        r = s.u(0.15, 0.4)
        ex, ey = (n - 1) * pitch * np.cos(yaw), (n - 1) * pitch * np.sin(yaw)
        at = s.spot(x0, y0, (-size / 3, size / 3, -size / 3, size / 3), 2.3 * r + 0.6, along=(ex, ey))
        if at is None:
            continue
        done += 1
        x0, y0 = at
        for i in range(n):
            _pillar(s, x0 + i * pitch * np.cos(yaw), y0 + i * pitch * np.sin(yaw), h_col,
                    f"colonnade {done} pillar {i + 1}", style=style, radius=r)
        if s.rng.random() < 0.6:
            s.add(wall(StraightPath(x0=x0 - 0.5 * np.cos(yaw), y0=y0 - 0.5 * np.sin(yaw), x1=x0 + ex + 0.5 * np.cos(yaw),
                                    y1=y0 + ey + 0.5 * np.sin(yaw)), height=s.u(0.4, 0.9), thickness=3.0 * r + 0.2,
                       z0=h_col), ClassId.WALL, f"colonnade {done} beam")
    done = 0
    for _ in range(s.i(0, 8)):  # free-standing pillars (at most 0.55 m in radius, 2.3 x that clustered)
        x, y, height = s.u(-size / 2, size / 2), s.u(-size / 2, size / 2), s.u(2.0, 8.0)
        at = s.spot(x, y, (-size / 2, size / 2, -size / 2, size / 2), 1.3)
        if at is not None:
            done += 1
            _pillar(s, *at, height, f"pillar {done}")
    if s.rng.random() < 0.5:  # a low enclosure wall
        for k, (a, b, c, d) in enumerate(walls):
            s.add(wall(StraightPath(x0=a, y0=b, x1=c, y1=d), height=s.u(1.0, 3.0), thickness=0.5), ClassId.WALL,
                  f"garden wall {k + 1}")


def _curved_facade(s: _Site) -> None:
    radius = s.u(18.0, 60.0)
    sweep = s.u(0.8, 2.6)
    t0 = s.u(0.0, 2 * np.pi)
    path = ArcPath(cx=0.0, cy=0.0, radius=radius, theta0=t0, theta1=t0 + sweep)
    _arcade_storeys(s, path, "curved facade", storeys=s.i(1, 4), top_wall=s.rng.random() < 0.7)


def _monument(s: _Site) -> None:
    half = s.u(6.0, 16.0)
    plinth = s.u(0.0, 3.0)
    if plinth > 0.5:
        p = half + s.u(4.0, 12.0)
        s.add(roof_slab([(-p, -p), (p, -p), (p, p), (-p, p)], z=plinth, thickness=plinth), ClassId.ROOF, "plinth")
    else:
        plinth, p = 0.0, half + 6.0
    h = s.u(6.0, 16.0)
    s.solid.append((-half - 1.0, half + 1.0, -half - 1.0, half + 1.0))
    for side, (a, b, c, d) in {"south": (-half, -half, half, -half), "east": (half, -half, half, half),
                               "north": (half, half, -half, half), "west": (-half, half, -half, -half)}.items():
        path = StraightPath(x0=a, y0=b, x1=c, y1=d)
        if s.rng.random() < 0.5:  # a portal in the middle of the side
            g = s.u(0.3, 0.55) * 2 * half
            span = g * s.u(0.55, 0.8)
            s.add(portal(path, u0=half - 0.5 * g, u1=half + 0.5 * g, span=span, spring=min(h - 0.9 * span - 0.5, s.u(2.5, 6.0)),
                         height=h, thickness=s.u(1.0, 2.5), z0=plinth), ClassId.ARCH, f"{side} portal")
            for j, (u0, u1) in enumerate(((0.0, half - 0.5 * g), (half + 0.5 * g, 2 * half))):
                tx, ty = (c - a) / (2 * half), (d - b) / (2 * half)
                s.add(wall(StraightPath(x0=a + u0 * tx, y0=b + u0 * ty, x1=a + u1 * tx, y1=b + u1 * ty), height=h,
                           thickness=1.2, z0=plinth), ClassId.WALL, f"{side} wall {j + 1}")
        else:
            s.add(wall(path, height=h, thickness=1.2, z0=plinth), ClassId.WALL, f"{side} wall")
    radius = half * s.u(0.55, 0.85)
    roof = s.add(roof_slab([(-half, -half), (half, -half), (half, half), (-half, half)], z=plinth + h + 0.5,
                           thickness=0.5, holes=[(0.0, 0.0, 0.85 * radius)]), ClassId.ROOF, "roof")
    with s.falling(not roof):
        _dome(s, (0.0, 0.0, plinth + h + 0.5), radius, "main dome", drum=s.rng.random() < 0.8)
    if s.rng.random() < 0.6:
        for k, (x, y) in enumerate(((-1, -1), (1, -1), (1, 1), (-1, 1))):
            _minaret(s, x * (p - 2.5), y * (p - 2.5), f"minaret {k + 1}", z0=plinth, height=s.u(12.0, 35.0))
    for k in range(int(s.pick((0, 0, 2, 4)))):
        x, y = ((-1, -1), (1, 1), (1, -1), (-1, 1))[k]
        size = s.u(0.8, 1.5)  # every column on the roof, clear of its edge
        with s.falling(not roof):
            _pavilion(s, x * (half - 0.5 - size * np.sqrt(2)), y * (half - 0.5 - size * np.sqrt(2)),
                      f"roof pavilion {k + 1}", z0=plinth + h + 0.5, size=size)


_LAYOUTS: dict[str, Callable[[_Site], None]] = {
    "courtyard_mosque": _courtyard_mosque, "linear_facade": _linear_facade, "fort": _fort,
    "pavilion_garden": _pavilion_garden, "curved_facade": _curved_facade, "monument": _monument,
}


def procedural_site(seed: int, family: str | None = None, *, ruin: float | None = None,
                    heading: float | None = None) -> Scene:
    """The site of ``seed``: family ``family`` (default :func:`family_of`), with ground,
    clutter and 3-10 random stations (a partial scan in about one site in four), turned
    about the vertical axis by a random heading: a scan's frame is the scanner's or the
    survey's, never the building's.

    ``ruin`` (``ruins`` only) overrides the drawn share of elements that are missing or
    broken off (0.2-0.5); 0 builds the same layout intact. ``heading`` (radians) overrides
    the drawn heading (0-2 pi, its own draw: the same seed makes the same site at any
    heading); 0 builds the layout along the axes.
    """
    family = family or family_of(seed)
    if family not in FAMILIES:
        raise ConfigError(f"family {family!r} is not one of {', '.join(FAMILIES)}")
    if ruin is not None and not 0.0 <= ruin <= 1.0:
        raise ConfigError(f"ruin must be between 0 and 1; got {ruin}")
    if heading is not None and not np.isfinite(heading):
        raise ConfigError(f"heading must be a finite angle in radians; got {heading}")
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), FAMILIES.index(family)]))
    ruin_rng = np.random.default_rng(np.random.SeedSequence([int(seed), FAMILIES.index(family), 1]))
    if heading is None:
        heading = float(np.random.default_rng(np.random.SeedSequence([int(seed), FAMILIES.index(family), 2]))
                        .uniform(0.0, 2 * np.pi))
    s = _Site(f"gen-{family}-{seed}", rng, ruin_rng=ruin_rng,
              place_rng=np.random.default_rng(np.random.SeedSequence([int(seed), FAMILIES.index(family), 3])))
    if family == "ruins":
        drawn = float(ruin_rng.uniform(0.2, 0.5))
        s.ruin = drawn if ruin is None else float(ruin)
        layout = _LAYOUTS[str(s.pick(tuple(_LAYOUTS)))]
    else:
        layout = _LAYOUTS[family]
    layout(s)
    if len(s.b._elements) == 0:  # a ruin of nothing: one broken wall stays
        s.ruin = 0.0
        s.add(wall(StraightPath(x0=-4.0, y0=0.0, x1=4.0, y1=0.0), height=2.0, thickness=0.8), ClassId.WALL, "wall")
    (x0, y0), (x1, y1) = s.extent
    m = s.u(8.0, 25.0)
    _clutter(s, x0 - m + 1, x1 + m - 1, y0 - m + 1, y1 + m - 1, s.i(0, 12))
    s.b.add(ground(x0 - m, x1 + m, y0 - m, y1 + m), ClassId.GROUND, "ground")
    n = s.i(3, 10)
    one_side = s.rng.random() < 0.25
    if one_side:  # a partial scan: every station south of the site
        box = (x0 - 0.5 * m, x1 + 0.5 * m, y0 - m + 1.0, y0 - 1.0)
    else:
        box = (x0 - 0.7 * m, x1 + 0.7 * m, y0 - 0.7 * m, y1 + 0.7 * m)

    def solid(x: float, y: float) -> bool:
        return any(a <= x <= b and c <= y <= d for a, b, c, d in s.solid)

    for _ in range(n):
        for _try in range(50):  # not inside a hall or a tomb
            x, y = float(s.rng.uniform(*box[:2])), float(s.rng.uniform(*box[2:]))
            if not solid(x, y):
                break
        for _try in range(50):  # nor in a wall, a column or a tree's trunk (the placement's own draws)
            if int(_cell(x, y)) not in s.taken and not solid(x, y):
                break
            x, y = float(s.place_rng.uniform(*box[:2])), float(s.place_rng.uniform(*box[2:]))
        s.b.add_station((x, y, EYE))
    return _turned(s.b.build(), heading)


def _turned(scene: Scene, angle: float) -> Scene:
    """``scene`` turned by ``angle`` radians about the vertical axis through the origin."""
    if angle == 0.0:
        return scene
    c, sn = np.cos(angle), np.sin(angle)
    rot = np.array([[c, -sn, 0.0], [sn, c, 0.0], [0.0, 0.0, 1.0]])
    return dataclasses.replace(scene, vertices=scene.vertices @ rot.T, stations=scene.stations @ rot.T)


@dataclass(frozen=True, kw_only=True)
class ScanDraw:
    """The scanner settings drawn for a seed's site (see :func:`scan_draw`)."""

    noise: float
    registration_error: float


def scan_draw(seed: int) -> ScanDraw:
    """Range noise 1.5-6 mm at 10 m and registration error 0-5 mm, drawn from ``seed``.

    >>> d = scan_draw(3)
    >>> 0.0015 <= d.noise <= 0.006 and 0.0 <= d.registration_error <= 0.005
    True
    """
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 99]))
    return ScanDraw(noise=float(rng.uniform(0.0015, 0.006)), registration_error=float(rng.uniform(0.0, 0.005)))


def site_points(seed: int, lo: float, hi: float) -> int:
    """Points of the scan of ``seed``'s site, drawn log-uniformly from ``lo``-``hi`` (to the
    thousand) by the seed; ``lo == hi`` gives that count.

    >>> site_points(5, 5e5, 2e6), site_points(5, 4e6, 4e6)
    (1017000, 4000000)
    """
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 7]))
    return int(round(math.exp(rng.uniform(math.log(lo), math.log(hi))), -3))
