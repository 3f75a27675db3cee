"""The registry of labelled synthetic scenes: the paper's five sites and small test scenes.

Each entry is a :class:`SiteSpec` whose ``build`` makes a :class:`~scenes.scene.Scene`
through :class:`~scenes.scene.SceneBuilder`, with these labelling rules (see
``docs/scenes.md``):

- an arch instance is one bay: from mid-pier to mid-pier (an end bay from the arcade's
  end), from the bay's floor to the crown plus a frame band, front, back and soffit; the
  wall above the bays and beyond the arcade's ends is wall. A single portal (pishtaq) is
  one arch instance;
- a dome instance is the shell (outer and inner surface), its drum and finial; a chattri
  (posts, platform, ring beam, dome) is one dome instance;
- a minaret instance is all its stages, balconies and cupola; a fort bastion is one
  minaret instance;
- every planar piece (wall panel, roof slab, the ground) and every clutter object is an
  instance of its own.

``rng`` seeds a small jitter of proportions and of clutter placement (same seed, same
arrays); ``rng=None`` gives the nominal proportions. Element counts never depend on it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from hollowtree.classes import ClassId
from hollowtree.scenes._builders import (
    EYE,
    Jitter,
    RngLike,
    add_arcade,
    add_ground,
    add_stations,
    counts,
    door,
    rect,
    room,
    wall_piece,
)
from hollowtree.scenes.elements import (
    arcade,
    bastion,
    chattri,
    dome,
    minaret,
    pillar,
    portal,
    roof_slab,
    wall,
)
from hollowtree.scenes.scene import Scene, SceneBuilder
from hollowtree.scenes.shapes import ArcPath, StraightPath

__all__ = ["GENERATED", "SITES", "TEST_SCENES", "SiteSpec", "UnknownSceneError", "build_scene", "scene_names"]

class UnknownSceneError(KeyError, ValueError):
    """Raised by :func:`build_scene` for a name that is neither a site nor a test scene."""

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0])


@dataclass(frozen=True, kw_only=True)
class SiteSpec:
    """One registered scene.

    Attributes
    ----------
    name : str
    description : str
        One line.
    build : callable
        ``build(rng) -> Scene``.
    expected_counts : dict of ClassId to int
        Element instances per element class (arch, dome, minaret, pillar), as built;
        empty for a generated site, whose counts depend on the seed (read them off the
        scene).
    default_stations : int or None
        How many of the scene's stations (in priority order) a scan uses by default;
        None = all.
    size : tuple of 3 floats
        Approximate x, y, z extent of the building (ground and clutter excluded), metres.
    """

    name: str
    description: str
    build: Callable[[RngLike], Scene] = field(repr=False)
    expected_counts: dict[ClassId, int]
    default_stations: int | None
    size: tuple[float, float, float]


# --------------------------------------------------------------------------- test scenes
def _plane_wall(rng: RngLike) -> Scene:
    b = SceneBuilder("plane_wall")
    t = 0.5
    # runs towards -x so that its left (the +d, front) face is the plane y = 10 facing the station
    path = StraightPath(x0=10.0, y0=10.0 + 0.5 * t, x1=-10.0, y1=10.0 + 0.5 * t)
    b.add(wall(path, height=8.0, thickness=t), ClassId.WALL, "wall")
    add_ground(b, -20.0, 20.0, -10.0, 20.0)
    b.add_station((0.0, 0.0, EYE))
    return b.build()


def _domed_hall(name: str, kind: str, rng: RngLike) -> Scene:
    j = Jitter(rng)
    b = SceneBuilder(name)
    half, hgt, t = 5.0, j(5.0), 0.6
    radius = j(3.6)
    drum_t = 0.4
    room(b, "hall", x0=-half, x1=half, y0=-half, y1=half, height=hgt, thickness=t,
          doors={"south": [door(4.2, 6.2, 2.6)]})
    b.add(roof_slab(rect(-half - t / 2, half + t / 2, -half - t / 2, half + t / 2), z=hgt + 0.4,
                    thickness=0.4, holes=[(0.0, 0.0, radius - drum_t)]), ClassId.ROOF, "roof")
    kw = {"pointedness": 1.35} if kind == "pointed" else {}
    b.add(dome(center=(0, 0, hgt + 0.4), kind=kind, radius=radius, drum_height=j(1.5),
               drum_thickness=drum_t, thickness=0.3, finial=1.0, **kw), ClassId.DOME, f"{kind} dome")
    add_ground(b, -25.0, 25.0, -25.0, 25.0)
    add_stations(b, [(14.0, -16.0), (0.0, 0.0), (-15.0, 14.0), (16.0, 12.0), (-14.0, -15.0), (0.0, -3.5)])
    return b.build()


def _chattri_scene(rng: RngLike) -> Scene:
    j = Jitter(rng)
    b = SceneBuilder("chattri")
    b.add(chattri(center=(0, 0, 0), radius=j(1.4), n_posts=6, post_height=j(2.4)), ClassId.DOME,
          "chattri")
    add_ground(b, -15.0, 15.0, -15.0, 15.0)
    add_stations(b, [(7.0, -6.0), (-7.0, 6.0), (6.0, 7.0)])
    return b.build()


def _minaret_scene(name: str, rng: RngLike, *, n_stages: int, n_segments: int) -> Scene:
    j = Jitter(rng)
    b = SceneBuilder(name)
    b.add(minaret(center=(0, 0, 0), height=j(30.0), base_radius=j(2.0), n_stages=n_stages,
                  n_segments=n_segments, balcony_depth=j(0.8)), ClassId.MINARET, "minaret")
    add_ground(b, -30.0, 30.0, -30.0, 30.0)
    add_stations(b, [(14.0, -12.0), (-15.0, 10.0), (3.0, 18.0), (-6.0, -20.0)])
    return b.build()


def _bastion_scene(rng: RngLike) -> Scene:
    j = Jitter(rng)
    b = SceneBuilder("bastion")
    r, t = j(6.0), 4.0
    b.add(bastion(center=(0, 0, 0), radius=r, height=j(27.0)), ClassId.MINARET, "bastion")
    b.add(wall(StraightPath(x0=-0.75 * r, y0=0.0, x1=-30.0, y1=0.0), height=20.0, thickness=t),
          ClassId.WALL, "curtain wall west")
    b.add(wall(StraightPath(x0=0.0, y0=0.75 * r, x1=0.0, y1=30.0), height=20.0, thickness=t),
          ClassId.WALL, "curtain wall north")
    add_ground(b, -45.0, 35.0, -35.0, 45.0)
    add_stations(b, [(22.0, -20.0), (-20.0, -22.0), (24.0, 18.0)])
    return b.build()


def _arcade_scene(name: str, rng: RngLike, *, kind: str) -> Scene:
    j = Jitter(rng)
    b = SceneBuilder(name)
    n, pitch = 5, j(3.6)
    length = n * pitch
    path = StraightPath(x0=-0.5 * length, y0=0.0, x1=0.5 * length, y1=0.0)
    parts = arcade(path, n_bays=n, bay_width=pitch, span=0.65 * pitch, spring=j(3.0), kind=kind,
                   pointedness=0.8, height=j(6.5), thickness=0.9)
    add_arcade(b, parts, "arcade")
    add_ground(b, -30.0, 30.0, -25.0, 25.0)
    add_stations(b, [(3.0, -14.0), (-4.0, 12.0), (-12.0, -10.0)])
    return b.build()


def _curved_arcade_scene(rng: RngLike) -> Scene:
    j = Jitter(rng)
    b = SceneBuilder("curved_arcade")
    radius = j(12.0)
    path = ArcPath(cx=0.0, cy=-6.0, radius=radius, theta0=np.deg2rad(25.0), theta1=np.deg2rad(155.0))
    n = 9
    pitch = path.length / n
    parts = arcade(path, n_bays=n, bay_width=pitch, span=0.65 * pitch, spring=j(2.8), kind="round",
                   height=j(6.0), thickness=0.9)
    add_arcade(b, parts, "curved arcade")
    add_ground(b, -30.0, 30.0, -30.0, 30.0)
    add_stations(b, [(0.0, 18.0), (0.0, -2.0), (-14.0, 14.0), (14.0, 14.0)])
    return b.build()


def _portal_scene(rng: RngLike) -> Scene:
    j = Jitter(rng)
    b = SceneBuilder("portal")
    path = StraightPath(x0=-14.0, y0=0.0, x1=14.0, y1=0.0)
    w = j(10.0)
    u0, u1 = 14.0 - 0.5 * w, 14.0 + 0.5 * w
    b.add(portal(path, u0=u0, u1=u1, span=0.62 * w, spring=j(5.5), height=j(14.0), thickness=2.5),
          ClassId.ARCH, "portal")
    wall_piece(b, path, "wall west", u0=0.0, u1=u0, z1=10.0, thickness=1.2)
    wall_piece(b, path, "wall east", u0=u1, u1=28.0, z1=10.0, thickness=1.2)
    add_ground(b, -35.0, 35.0, -30.0, 30.0)
    add_stations(b, [(2.0, -18.0), (-3.0, 15.0), (-15.0, -12.0)])
    return b.build()


def _pillar_scene(rng: RngLike) -> Scene:
    j = Jitter(rng)
    b = SceneBuilder("pillar")
    b.add(pillar(center=(0, 0, 0), height=j(4.5), radius=j(0.3)), ClassId.PILLAR, "pillar")
    add_ground(b, -12.0, 12.0, -12.0, 12.0)
    add_stations(b, [(5.0, -4.0), (-4.0, 5.0), (4.0, 5.0)])
    return b.build()


def _occluded_scene(rng: RngLike) -> Scene:
    j = Jitter(rng)
    b = SceneBuilder("occluded")
    t = 0.4
    room(b, "room", x0=-3.0, x1=3.0, y0=-3.0, y1=3.0, height=4.0, thickness=t)
    b.add(roof_slab(rect(-3.2, 3.2, -3.2, 3.2), z=4.3, thickness=0.3), ClassId.ROOF, "roof")
    b.add(pillar(center=(j.shift(0.5), j.shift(0.5), 0.0), height=3.5), ClassId.PILLAR,
          "hidden pillar")
    add_ground(b, -20.0, 20.0, -20.0, 20.0)
    add_stations(b, [(9.0, -7.0), (-8.0, 9.0), (10.0, 8.0), (-9.0, -9.0)])
    return b.build()


# --------------------------------------------------------------------------- sites
from hollowtree.scenes.paper_sites import derawar, khudabad, roman, temple, wazir_khan  # noqa: E402

SITES: dict[str, SiteSpec] = {
    "wazir_khan": SiteSpec(
        name="wazir_khan",
        description="Masjid Wazir Khan (Lahore): courtyard mosque with arcades, a five-domed "
        "prayer hall, a gateway, chattris and four octagonal minarets, 91 x 53 x 33 m",
        build=wazir_khan, expected_counts=counts(46, 12, 6), default_stations=12,
        size=(91.0, 53.0, 33.0)),
    "khudabad": SiteSpec(
        name="khudabad",
        description="Masjid Khudabad (Sindh): prayer hall under 3 x 7 domes behind a 12-bay "
        "arcade facade, 60 x 36 x 16 m",
        build=khudabad, expected_counts=counts(12, 21, 0), default_stations=10,
        size=(60.0, 36.0, 16.0)),
    "derawar": SiteSpec(
        name="derawar",
        description="Derawar Fort (Cholistan), scaled to 212 x 182 m: curtain walls and 38 round "
        "battered bastions up to 29 m",
        build=derawar, expected_counts=counts(0, 0, 38), default_stations=10,
        size=(212.0, 182.0, 28.0)),
    "roman": SiteSpec(
        name="roman",
        description="Roman building (synthetic): Colosseum-like curved facade, three storeys of "
        "27 + 26 + 26 arches, 20 x 36 x 14 m",
        build=roman, expected_counts=counts(79, 0, 0), default_stations=8,
        size=(20.0, 36.0, 14.0)),
    "temple": SiteSpec(
        name="temple",
        description="Temple (synthetic): two-tier block with 7 onion domes and 4 slender "
        "minarets, 10 x 16 x 44 m",
        build=temple, expected_counts=counts(0, 7, 4), default_stations=8,
        size=(10.0, 16.0, 44.0)),
}


def _test(name: str, description: str, build: Callable[[RngLike], Scene], expected: dict[ClassId, int],
          stations: int, size: tuple[float, float, float]) -> SiteSpec:
    return SiteSpec(name=name, description=description, build=build, expected_counts=expected,
                    default_stations=stations, size=size)


TEST_SCENES: dict[str, SiteSpec] = {
    "plane_wall": _test("plane_wall", "one 20 x 8 m wall whose front face is the plane y = 10, "
                        "one station at the origin", _plane_wall, counts(), 1, (20.0, 0.5, 8.0)),
    "dome": _test("dome", "hemispherical dome on a drum over a small hall with a door; stations "
                  "outside and one under the dome", lambda r: _domed_hall("dome", "hemispherical", r),
                  counts(dome_=1), 4, (10.6, 10.6, 11.4)),
    "onion_dome": _test("onion_dome", "onion dome on a drum over a small hall",
                        lambda r: _domed_hall("onion_dome", "onion", r), counts(dome_=1), 4,
                        (10.6, 10.6, 14.2)),
    "pointed_dome": _test("pointed_dome", "pointed (Persian) dome on a drum over a small hall",
                          lambda r: _domed_hall("pointed_dome", "pointed", r), counts(dome_=1), 4,
                          (10.6, 10.6, 12.5)),
    "chattri": _test("chattri", "a six-post chattri on its platform", _chattri_scene,
                     counts(dome_=1), 3, (3.5, 4.0, 5.4)),
    "minaret": _test("minaret", "round minaret, 8 stages, 7 balconies, cupola on posts, 30 m",
                     lambda r: _minaret_scene("minaret", r, n_stages=8, n_segments=48),
                     counts(minaret_=1), 4, (5.4, 5.4, 30.0)),
    "octagonal_minaret": _test("octagonal_minaret", "octagonal minaret, 4 stages, cupola, 30 m",
                               lambda r: _minaret_scene("octagonal_minaret", r, n_stages=4,
                                                        n_segments=8),
                               counts(minaret_=1), 4, (5.4, 5.4, 30.0)),
    "bastion": _test("bastion", "round battered fort bastion with two curtain-wall stubs",
                     _bastion_scene, counts(minaret_=1), 3, (36.0, 36.0, 27.0)),
    "arcade": _test("arcade", "straight arcade of 5 round arches with the wall above",
                    lambda r: _arcade_scene("arcade", r, kind="round"), counts(arch=5), 3,
                    (18.0, 0.9, 6.5)),
    "pointed_arcade": _test("pointed_arcade", "straight arcade of 5 pointed arches",
                            lambda r: _arcade_scene("pointed_arcade", r, kind="pointed"),
                            counts(arch=5), 3, (18.0, 0.9, 6.5)),
    "curved_arcade": _test("curved_arcade", "9 round arches on a circular-arc wall (r = 12 m)",
                           _curved_arcade_scene, counts(arch=9), 4, (22.6, 7.6, 6.0)),
    "portal": _test("portal", "a single pointed portal (pishtaq) in a wall", _portal_scene,
                    counts(arch=1), 3, (28.0, 2.5, 14.0)),
    "pillar": _test("pillar", "one free-standing column", _pillar_scene, counts(pillar_=1), 3,
                    (0.7, 0.7, 4.5)),
    "occluded": _test("occluded", "closed 6 x 6 x 4 m room with a pillar inside that no station "
                      "can see", _occluded_scene, counts(pillar_=1), 4, (6.4, 6.4, 4.3)),
}


def _generated(family: str | None) -> SiteSpec:
    from hollowtree.scenes.procedural import procedural_site

    def build(rng: RngLike) -> Scene:
        seed = rng if isinstance(rng, (int, np.integer)) else (
            0 if rng is None else int(np.random.default_rng(rng).integers(2**31)))
        return procedural_site(int(seed), family)

    what = f"a {family.replace('_', ' ')}" if family else "a site of the family its seed picks"
    return SiteSpec(name=f"gen-{family}" if family else "gen",
                    description=f"procedural: {what}, a new one for every seed (scenes/procedural.py)",
                    build=build, expected_counts={}, default_stations=None, size=(0.0, 0.0, 0.0))


def _generated_specs() -> dict[str, SiteSpec]:
    from hollowtree.scenes.procedural import FAMILIES

    specs = [_generated(None), *(_generated(f) for f in FAMILIES)]
    return {s.name: s for s in specs}


#: Procedural sites (:mod:`scenes.procedural`): ``gen`` (the family is drawn from the
#: seed) and ``gen-<family>``; the seed picks the site. Seeds are split into training,
#: validation and test ranges (``scenes.procedural.SPLITS``).
GENERATED: dict[str, SiteSpec] = _generated_specs()


def scene_names() -> list[str]:
    """All registered names: the five sites first, then the test scenes, then the
    procedural sites.

    Examples
    --------
    >>> scene_names()[:5]
    ['wazir_khan', 'khudabad', 'derawar', 'roman', 'temple']
    """
    return [*SITES, *TEST_SCENES, *GENERATED]


def build_scene(name: str, *, rng: RngLike = None) -> Scene:
    """Build the scene registered as ``name``.

    Parameters
    ----------
    name : str
        A site (:data:`SITES`), a test scene (:data:`TEST_SCENES`) or a procedural site
        (:data:`GENERATED`).
    rng : int, Generator or None
        Seeds the jitter of proportions and clutter placement; None gives the nominal
        geometry. Element counts never depend on it.

    Raises
    ------
    UnknownSceneError
        (a ``KeyError`` and ``ValueError``) if ``name`` is unknown; the message lists the
        known names.

    Examples
    --------
    >>> s = build_scene("plane_wall")
    >>> s.stations.tolist(), s.element_counts()[ClassId.ARCH]
    ([[0.0, 0.0, 1.6]], 0)
    """
    spec = SITES.get(name) or TEST_SCENES.get(name) or GENERATED.get(name)
    if spec is None:
        raise UnknownSceneError(
            f"unknown site {name!r}; known sites: {', '.join(SITES)}; "
            f"test scenes: {', '.join(TEST_SCENES)}; procedural: {', '.join(GENERATED)}"
        )
    return spec.build(rng)

