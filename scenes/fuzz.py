"""Small random scans for the never-crash harness: random scene compositions and degenerate
point sets, each fully described by a :class:`FuzzSpec`.

A spec is either ``kind="scene"`` (a random set of elements, placed at random in a square
site with or without ground, scanned from random stations by :mod:`scenes.scanner`) or one
of the degenerate kinds in :data:`DEGENERATE_KINDS` (points written directly: a lone point,
one point per tile, a 1 x 200 strip, an all-identical cloud, uniform noise, ...). Any spec
can be duplicated point for point, moved to survey-sized coordinates and given a tile size,
so that the ingest's tiling and the coarse stage's stitching see one tile, many tiles and
tiles whose core holds nothing.

:func:`fuzz_points` turns a spec into arrays; :func:`fuzz_specs` is the hypothesis
strategy over specs (hypothesis is a development dependency, imported only there). The
same spec and seed give the same points.

Examples
--------
>>> pts = fuzz_points(FuzzSpec(kind="strip", seed=1, n_points=500))
>>> pts["xyz"].shape, int(pts["gt_class"].max())
((500, 3), 0)
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from hollowtree.classes import ClassId
from hollowtree.errors import ConfigError
from hollowtree.scenes._builders import EYE, Jitter, add_arcade, add_clutter
from hollowtree.scenes.elements import (
    arcade,
    chattri,
    dome,
    ground,
    minaret,
    pillar,
    roof_slab,
    wall,
)
from hollowtree.scenes.scanner import RayCaster, ScanParams, estimate_step, scan
from hollowtree.scenes.scene import Scene, SceneBuilder
from hollowtree.scenes.shapes import ArcPath, StraightPath

__all__ = ["DEGENERATE_KINDS", "ELEMENT_KINDS", "FuzzSpec", "fuzz_points", "fuzz_scene", "fuzz_specs"]

#: What a random scene may hold (any number of each; ``terrain`` is a ground plane over the
#: whole site, ``wall_run`` a plain wall, ``slab`` a flat roof, ``column`` a pillar).
ELEMENT_KINDS = ("terrain", "wall_run", "slab", "arcade", "dome", "chattri", "minaret", "column", "clutter")
#: Point sets written directly, without a scene or a scanner.
DEGENERATE_KINDS = (
    "single",      # 1 to 3 points
    "identical",   # every point at one position
    "line",        # collinear points
    "noise",       # uniform in a box: nothing for RANSAC to find
    "plane",       # one horizontal plane (only ground)
    "vplanes",     # a few vertical planes (only walls)
    "strip",       # a 1 x 200 footprint
    "sparse",      # one point in each of many far-apart cells (one point per tile)
    "tiny",        # a 1 cm cube
)
KINDS = ("scene", *DEGENERATE_KINDS)


@dataclass(frozen=True, kw_only=True)
class FuzzSpec:
    """One random scan.

    Attributes
    ----------
    kind : str
        ``"scene"`` or one of :data:`DEGENERATE_KINDS`.
    seed : int
        Seeds every random choice below it (placement, proportions, stations, noise).
    n_points : int
        About how many distinct points (before ``duplicate``).
    parts : tuple of str
        For ``"scene"``: the elements, from :data:`ELEMENT_KINDS` (repeats allowed).
    extent : float
        Side of the site's square footprint, metres.
    stations : int
        Scanner stations of a scene.
    duplicate : int
        Every point written this many times (1 = no duplicates).
    survey : bool
        Shift to survey-sized coordinates (E 500 000, N 3 500 000).
    tiles_across : int or None
        The ingest's tile size for this scan is the footprint's longer side over this
        (at least 2.5 m, above the default workflow's 2 m buffer); None = the workflow's
        default tile size.
    density_cap : bool
        Keep the workflow's density cap (``ingest.voxel``); False runs without one, so
        that duplicated points reach the coarse stage.
    """

    kind: str
    seed: int = 0
    n_points: int = 20_000
    parts: tuple[str, ...] = ()
    extent: float = 30.0
    stations: int = 2
    duplicate: int = 1
    survey: bool = False
    tiles_across: int | None = None
    density_cap: bool = True

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ConfigError(f"fuzz kind {self.kind!r} is not one of {', '.join(KINDS)}")
        bad = sorted(set(self.parts) - set(ELEMENT_KINDS))
        if bad:
            raise ConfigError(f"fuzz parts {bad} are not among {', '.join(ELEMENT_KINDS)}")
        if self.n_points < 1 or self.duplicate < 1 or self.stations < 1 or (self.tiles_across or 1) < 1:
            raise ConfigError("fuzz n_points, duplicate, stations and tiles_across must be positive")
        if not (np.isfinite(self.extent) and self.extent > 0):
            raise ConfigError(f"fuzz extent must be a positive length; got {self.extent}")

    def describe(self) -> str:
        """One line, enough to rebuild the spec by hand."""
        parts = f" parts={'+'.join(self.parts) or '-'}" if self.kind == "scene" else ""
        return (f"{self.kind} seed={self.seed} n={self.n_points}{parts} extent={self.extent:g} "
                f"stations={self.stations} dup={self.duplicate} survey={self.survey} tiles={self.tiles_across} "
                f"cap={self.density_cap}")


SURVEY_SHIFT = np.array([500_000.0, 3_500_000.0, 200.0])


def _place(rng: np.random.Generator, extent: float, margin: float) -> tuple[float, float]:
    half = max(0.5 * extent - margin, 0.0)
    return float(rng.uniform(-half, half)), float(rng.uniform(-half, half))


def fuzz_scene(spec: FuzzSpec) -> Scene:
    """The scene of a ``kind="scene"`` spec: its parts placed at random, random stations."""
    rng = np.random.default_rng(spec.seed)
    b = SceneBuilder(f"fuzz-{spec.seed}")
    e = spec.extent
    for i, part in enumerate(spec.parts):
        x, y = _place(rng, e, 0.15 * e)
        yaw = float(rng.uniform(0, np.pi))
        if part == "terrain":
            b.add(ground(-0.5 * e, 0.5 * e, -0.5 * e, 0.5 * e), ClassId.GROUND, "ground")
        elif part == "wall_run":
            length = float(rng.uniform(2.0, 0.8 * e))
            dx, dy = 0.5 * length * np.cos(yaw), 0.5 * length * np.sin(yaw)
            path = StraightPath(x0=x - dx, y0=y - dy, x1=x + dx, y1=y + dy)
            b.add(wall(path, height=float(rng.uniform(1.0, 12.0)), thickness=float(rng.uniform(0.2, 1.5))),
                  ClassId.WALL, f"wall {i}")
        elif part == "slab":
            w, d = rng.uniform(2.0, 0.5 * e, size=2)
            outer = [(x - w / 2, y - d / 2), (x + w / 2, y - d / 2), (x + w / 2, y + d / 2), (x - w / 2, y + d / 2)]
            b.add(roof_slab(outer, z=float(rng.uniform(2.0, 10.0)), thickness=float(rng.uniform(0.2, 0.8))),
                  ClassId.ROOF, f"roof {i}")
        elif part == "arcade":
            bay = float(rng.uniform(2.0, 5.0))
            n_bays = int(rng.integers(1, 8))
            length = bay * n_bays
            span = bay * float(rng.uniform(0.5, 0.8))
            spring = float(rng.uniform(1.5, 5.0))
            kind = str(rng.choice(["round", "pointed"]))
            if rng.random() < 0.3:  # a curved arcade
                radius = float(rng.uniform(0.6, 1.5)) * length / np.pi
                t0 = float(rng.uniform(0, 2 * np.pi))
                path = ArcPath(cx=x, cy=y, radius=radius, theta0=t0, theta1=t0 + length / radius)
            else:
                dx, dy = 0.5 * length * np.cos(yaw), 0.5 * length * np.sin(yaw)
                path = StraightPath(x0=x - dx, y0=y - dy, x1=x + dx, y1=y + dy)
            parts = arcade(path, n_bays=n_bays, bay_width=bay, span=span, spring=spring, kind=kind,
                           height=spring + span * float(rng.uniform(0.8, 1.6)) if rng.random() < 0.6 else None,
                           thickness=float(rng.uniform(0.4, 1.5)))
            add_arcade(b, parts, f"arcade {i}")
        elif part == "dome":
            kind = str(rng.choice(["hemispherical", "onion", "pointed"]))
            r = float(rng.uniform(1.0, 6.0))
            b.add(dome(center=(x, y, float(rng.uniform(0.0, 8.0))), kind=kind, radius=r,
                       drum_height=float(rng.uniform(0.0, 2.5)), thickness=0.3,
                       drum_thickness=min(0.5, 0.3 * r), finial=float(rng.uniform(0.0, 1.5))),
                  ClassId.DOME, f"dome {i}")
        elif part == "chattri":
            b.add(chattri(center=(x, y, 0.0), radius=float(rng.uniform(0.8, 2.5)), n_posts=int(rng.integers(4, 9)),
                          post_height=float(rng.uniform(1.5, 3.5)), yaw=yaw), ClassId.DOME, f"chattri {i}")
        elif part == "minaret":
            r = float(rng.uniform(0.8, 3.0))  # tall enough for its cupola
            b.add(minaret(center=(x, y, 0.0), height=float(rng.uniform(max(8.0, 5.0 * r + 4.0), 45.0)),
                          base_radius=r, n_stages=int(rng.integers(1, 6)),
                          n_segments=int(rng.choice([6, 8, 12, 16, 32]))), ClassId.MINARET, f"minaret {i}")
        elif part == "column":
            b.add(pillar(center=(x, y, 0.0), height=float(rng.uniform(1.5, 8.0)),
                         radius=float(rng.uniform(0.1, 0.6))), ClassId.PILLAR, f"pillar {i}")
        elif part == "clutter":
            kind = str(rng.choice(["bench", "car", "bicycle", "tree"]))
            add_clutter(b, Jitter(int(rng.integers(2**31))), [(kind, x, y, yaw)])
    if not spec.parts:  # a scene of nothing but the scanner would be an error: one small wall
        b.add(wall(StraightPath(x0=-1.0, y0=2.0, x1=1.0, y1=2.0), height=2.0, thickness=0.3),
              ClassId.WALL, "wall")
    for _ in range(spec.stations):
        x, y = _place(rng, e, 0.05 * e)
        b.add_station((x, y, EYE if "terrain" in spec.parts else float(rng.uniform(0.3, 3.0))))
    return b.build()


def _scan_scene(spec: FuzzSpec) -> dict[str, npt.NDArray[Any]]:
    scene = fuzz_scene(spec)
    caster = RayCaster(scene)
    try:
        step = estimate_step(scene, spec.n_points, caster=caster)
    except ConfigError:  # the stations see nothing: an empty scan is a valid result here
        return {"xyz": np.zeros((0, 3)), "gt_class": np.zeros(0, np.uint8), "gt_instance": np.zeros(0, np.uint32)}
    # at most about 3 M rays a station: a scene the stations barely see gets fewer points
    params = ScanParams(step_deg=max(step, 0.15), seed=spec.seed,
                        registration_error=0.002 * (spec.seed % 3))
    chunks = list(scan(scene, params, caster=caster, workers=1))
    if not chunks:
        return {"xyz": np.zeros((0, 3)), "gt_class": np.zeros(0, np.uint8), "gt_instance": np.zeros(0, np.uint32)}
    return {
        "xyz": np.concatenate([c.xyz for c in chunks]),
        "gt_class": np.concatenate([c.gt_class for c in chunks]),
        "gt_instance": np.concatenate([c.gt_instance for c in chunks]),
    }


def _degenerate(spec: FuzzSpec) -> npt.NDArray[np.float64]:
    rng = np.random.default_rng(spec.seed)
    n, e = spec.n_points, spec.extent
    if spec.kind == "single":
        return rng.uniform(0, e, size=(min(n, 3), 3))
    if spec.kind == "identical":
        return np.tile(rng.uniform(0, e, size=(1, 3)), (n, 1))
    if spec.kind == "line":
        d = rng.normal(size=3)
        return rng.uniform(0, e, size=(1, 3)) + np.outer(rng.uniform(0, e, n), d / np.linalg.norm(d))
    if spec.kind == "noise":
        return rng.uniform(0, e, size=(n, 3))
    if spec.kind == "plane":
        return np.c_[rng.uniform(0, e, size=(n, 2)), rng.normal(0, 0.003, n)]
    if spec.kind == "vplanes":
        k = int(rng.integers(1, 5))
        which = rng.integers(0, k, n)
        ang = rng.uniform(0, np.pi, k)[which]
        u, z = rng.uniform(-0.5 * e, 0.5 * e, n), rng.uniform(0, 0.3 * e, n)
        c = rng.uniform(-0.3 * e, 0.3 * e, size=(k, 2))[which]
        return np.c_[c[:, 0] + u * np.cos(ang), c[:, 1] + u * np.sin(ang), z] + rng.normal(0, 0.003, (n, 3))
    if spec.kind == "strip":
        return np.c_[rng.uniform(0, e, n), rng.uniform(0, e / 200.0, n), rng.uniform(0, 0.1 * e, n)]
    if spec.kind == "sparse":
        n = min(n, 400)
        side = int(np.ceil(np.sqrt(n)))
        ij = np.stack(np.meshgrid(np.arange(side), np.arange(side)), -1).reshape(-1, 2)[:n]
        return np.c_[ij * e, rng.uniform(0, 1, n)]
    if spec.kind == "tiny":
        return rng.uniform(0, 0.01, size=(n, 3))
    raise ConfigError(f"fuzz kind {spec.kind!r} has no point maker")


def fuzz_points(spec: FuzzSpec) -> dict[str, npt.NDArray[Any]]:
    """The points of ``spec``: ``xyz`` (float64, metres), ``gt_class`` and ``gt_instance``.

    Degenerate kinds have no ground truth (class 0, instance 0).
    """
    if spec.kind == "scene":
        pts = _scan_scene(spec)
    else:
        xyz = _degenerate(spec)
        pts = {"xyz": xyz, "gt_class": np.zeros(len(xyz), np.uint8), "gt_instance": np.zeros(len(xyz), np.uint32)}
    if spec.duplicate > 1:
        pts = {k: np.repeat(v, spec.duplicate, axis=0) for k, v in pts.items()}
    if spec.survey:
        pts["xyz"] = pts["xyz"] + SURVEY_SHIFT
    return pts


def fuzz_specs(max_points: int = 300_000) -> Any:
    """A hypothesis strategy over :class:`FuzzSpec` (needs the ``dev`` extra).

    Scenes get 10 k to ``max_points`` points; degenerate kinds 1 to 50 k. A third of the
    specs get a small tile size, so that several tiles (and empty ones) are stitched.
    """
    from hypothesis import strategies as st

    top = max(10_000, max_points)
    sizes = st.one_of(st.integers(10_000, min(60_000, top)), st.integers(10_000, top))
    tile = st.one_of(st.none(), st.integers(1, 12))
    common = {
        "seed": st.integers(0, 2**31 - 1),
        "duplicate": st.sampled_from([1, 1, 1, 1, 2, 3]),
        "survey": st.booleans(),
        "tiles_across": tile,
        "density_cap": st.sampled_from([True, True, True, False]),
    }
    scene = st.builds(
        FuzzSpec, kind=st.just("scene"), n_points=sizes,
        parts=st.lists(st.sampled_from(ELEMENT_KINDS), min_size=0, max_size=8).map(tuple),
        extent=st.floats(8.0, 120.0), stations=st.integers(1, 4), **common,
    )
    degenerate = st.builds(
        FuzzSpec, kind=st.sampled_from(DEGENERATE_KINDS), n_points=st.integers(1, 50_000),
        extent=st.one_of(st.floats(0.05, 400.0), st.sampled_from([1.0, 100.0, 200.0])), **common,
    )
    return st.one_of(scene, scene, degenerate)
