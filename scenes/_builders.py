"""Shared pieces of the scene builders (:mod:`scenes.sites`, :mod:`scenes.paper_sites`).

Jitter, station placement, and the small recipes (an arcade's labelled parts, a room of
four walls) that several scenes use.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from hollowtree.classes import ClassId
from hollowtree.scenes.elements import ArcadeParts, bench, bicycle, car, ground, tree, wall
from hollowtree.scenes.mesh import TriMesh
from hollowtree.scenes.scene import SceneBuilder
from hollowtree.scenes.shapes import ArcPath, StraightPath, wall_panel

RngLike = int | np.random.Generator | np.random.SeedSequence | None
EYE = 1.6  # scanner optical centre above the floor it stands on (m)


class Jitter:
    """Relative jitter drawn from ``rng``; identity when ``rng`` is None."""

    def __init__(self, rng: RngLike) -> None:
        self.rng = None if rng is None else np.random.default_rng(rng)

    def __call__(self, value: float, rel: float = 0.03) -> float:
        if self.rng is None:
            return float(value)
        return float(value) * (1.0 + rel * float(self.rng.uniform(-1.0, 1.0)))

    def shift(self, scale: float) -> float:
        return 0.0 if self.rng is None else scale * float(self.rng.uniform(-1.0, 1.0))


def counts(arch: int = 0, dome_: int = 0, minaret_: int = 0, pillar_: int = 0) -> dict[ClassId, int]:
    return {ClassId.ARCH: arch, ClassId.DOME: dome_, ClassId.MINARET: minaret_, ClassId.PILLAR: pillar_}


# --------------------------------------------------------------------------- helpers
def add_arcade(b: SceneBuilder, parts: ArcadeParts, name: str) -> None:
    for i, bay in enumerate(parts.bays):
        b.add(bay, ClassId.ARCH, f"{name} bay {i + 1}")
    if parts.wall is not None:
        b.add(parts.wall, ClassId.WALL, f"{name} wall above")


def wall_piece(b: SceneBuilder, path: StraightPath | ArcPath, name: str, *, u0: float, u1: float,
                z1: float, thickness: float, z0: float = 0.0,
                openings: Sequence[np.ndarray] = ()) -> None:
    b.add(wall_panel(path, u0=u0, u1=u1, z0=z0, z1=z1, thickness=thickness, openings=openings,
                     caps=("top", "start", "end")), ClassId.WALL, name)


def room(b: SceneBuilder, name: str, *, x0: float, x1: float, y0: float, y1: float, height: float,
          thickness: float, doors: dict[str, Sequence[np.ndarray]] | None = None) -> None:
    """Four wall panels centred on the rectangle's outline, overlapping at the corners."""
    h = 0.5 * thickness
    sides = {
        "south": StraightPath(x0=x0 - h, y0=y0, x1=x1 + h, y1=y0),
        "east": StraightPath(x0=x1, y0=y0 - h, x1=x1, y1=y1 + h),
        "north": StraightPath(x0=x1 + h, y0=y1, x1=x0 - h, y1=y1),
        "west": StraightPath(x0=x0, y0=y1 + h, x1=x0, y1=y0 - h),
    }
    doors = doors or {}
    for side, path in sides.items():
        b.add(wall(path, height=height, thickness=thickness, openings=doors.get(side, ())),
              ClassId.WALL, f"{name} {side} wall")


def rect(x0: float, x1: float, y0: float, y1: float) -> list[tuple[float, float]]:
    return [(x0, y0), (x1, y0), (x1, y1), (x0, y1)]


def door(u0: float, u1: float, top: float) -> np.ndarray:
    return np.array([[u0, 0.0], [u0, top], [u1, top], [u1, 0.0]])


def add_ground(b: SceneBuilder, xmin: float, xmax: float, ymin: float, ymax: float) -> None:
    b.add(ground(xmin, xmax, ymin, ymax), ClassId.GROUND, "ground")


def add_clutter(b: SceneBuilder, j: Jitter, items: Sequence[tuple[str, float, float, float]]) -> None:
    """Add clutter objects ``(kind, x, y, yaw)`` with a small jitter of position and heading."""
    makers: dict[str, Callable[..., TriMesh]] = {"bench": bench, "car": car, "bicycle": bicycle}
    for k, (kind, x, y, yaw) in enumerate(items):
        x, y = x + j.shift(0.5), y + j.shift(0.5)
        if kind == "tree":
            mesh = tree(x=x, y=y, height=j(8.0, 0.15), crown_radius=j(2.6, 0.15))
        else:
            mesh = makers[kind](x=x, y=y, yaw=yaw + j.shift(0.2))
        b.add(mesh, ClassId.OTHER, f"{kind} {k + 1}")


def add_stations(b: SceneBuilder, xys: Sequence[Sequence[float]]) -> None:
    for p in xys:
        z = EYE if len(p) == 2 else float(p[2]) + EYE
        b.add_station((float(p[0]), float(p[1]), z))


