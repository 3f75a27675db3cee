"""Clutter objects (class other): benches, cars, bicycles and trees, as coarse meshes.

Re-exported by :mod:`scenes.elements`.
"""

from __future__ import annotations

import numpy as np

from hollowtree.scenes.mesh import TriMesh, concat_meshes
from hollowtree.scenes.shapes import box, ellipsoid, frustum, revolve

__all__ = ["bench", "bicycle", "car", "place", "tree"]


def place(mesh: TriMesh, *, x: float = 0.0, y: float = 0.0, z: float = 0.0, yaw: float = 0.0) -> TriMesh:
    """Rotate ``mesh`` by ``yaw`` radians about the z axis through the origin, then move it.

    Examples
    --------
    >>> place(box((0, 0, 0), (1, 1, 1)), x=10.0).bounds()[:, 0].tolist()
    [10.0, 11.0]
    """
    return mesh.rotated_z(yaw).translated((x, y, z))


def _horizontal_cylinder(radius: float, width: float, *, n_segments: int = 16, hollow: float = 0.0) -> TriMesh:
    """A cylinder (or ring) with its axis along y, centred at the origin."""
    h = 0.5 * width
    if hollow > 0:
        ri = radius - hollow
        m = revolve([(ri, -h), (radius, -h), (radius, h), (ri, h)], n_segments=n_segments, closed=True)
    else:
        m = frustum(radius, radius, -h, h, n_segments=n_segments)
    v = m.vertices[:, [0, 2, 1]]
    return TriMesh(v, m.faces)


def bench(*, x: float = 0.0, y: float = 0.0, yaw: float = 0.0, length: float = 1.8) -> TriMesh:
    """A park bench: seat, backrest and two leg blocks (about 1.8 x 0.6 x 0.85 m).

    Examples
    --------
    >>> float(bench().bounds()[1, 2])
    0.85
    """
    h = 0.5 * length
    m = concat_meshes([
        box((-h, -0.25, 0.42), (h, 0.25, 0.48)),
        box((-h, 0.22, 0.48), (h, 0.28, 0.85)),
        box((-h + 0.1, -0.22, 0.0), (-h + 0.18, 0.22, 0.42)),
        box((h - 0.18, -0.22, 0.0), (h - 0.1, 0.22, 0.42)),
    ])
    return place(m, x=x, y=y, yaw=yaw)


def car(*, x: float = 0.0, y: float = 0.0, yaw: float = 0.0, length: float = 4.4,
        width: float = 1.8, height: float = 1.45) -> TriMesh:
    """A car: body box, cabin box and four wheels (x along its length).

    Examples
    --------
    >>> bool(abs(car().bounds()[1, 2] - 1.45) < 1e-9)
    True
    """
    hl, hw = 0.5 * length, 0.5 * width
    body_top = 0.62 * height
    parts = [
        box((-hl, -hw, 0.3), (hl, hw, body_top)),
        box((-0.3 * length, -hw + 0.08, body_top), (0.2 * length, hw - 0.08, height)),
    ]
    for sx in (-0.32 * length, 0.32 * length):
        for sy in (-hw + 0.1, hw - 0.1):
            parts.append(_horizontal_cylinder(0.32, 0.2).translated((sx, sy, 0.32)))
    return place(concat_meshes(parts), x=x, y=y, yaw=yaw)


def bicycle(*, x: float = 0.0, y: float = 0.0, yaw: float = 0.0) -> TriMesh:
    """A bicycle: two thin wheel rings, frame bars, saddle and handlebar (about 1.7 m long).

    Examples
    --------
    >>> bool(bicycle().bounds()[1, 2] < 1.2)
    True
    """
    r = 0.34
    # wheels rotated so that their axis is along y (the bicycle runs along x)
    parts = [
        _horizontal_cylinder(r, 0.04, n_segments=24, hollow=0.04).translated((-0.52, 0, r)),
        _horizontal_cylinder(r, 0.04, n_segments=24, hollow=0.04).translated((0.52, 0, r)),
        box((-0.52, -0.02, r - 0.02), (0.05, 0.02, r + 0.02)),  # chain stay
        box((-0.1, -0.02, r), (0.45, 0.02, 0.82)),  # down tube (coarse)
        box((-0.12, -0.02, r), (-0.06, 0.02, 0.88)),  # seat tube
        box((-0.2, -0.08, 0.88), (0.02, 0.08, 0.93)),  # saddle
        box((0.42, -0.02, r), (0.48, 0.02, 1.0)),  # fork and stem
        box((0.42, -0.3, 0.98), (0.48, 0.3, 1.02)),  # handlebar
    ]
    return place(concat_meshes(parts), x=x, y=y, yaw=yaw)


def tree(*, x: float = 0.0, y: float = 0.0, height: float = 8.0, crown_radius: float = 2.5,
         trunk_radius: float = 0.2) -> TriMesh:
    """A tree: trunk cylinder and an ellipsoidal crown.

    Examples
    --------
    >>> float(tree(height=6.0).bounds()[1, 2])
    6.0
    """
    crown_h = 0.55 * height
    rz = 0.5 * crown_h
    return concat_meshes([
        frustum(trunk_radius, 0.7 * trunk_radius, 0.0, height - crown_h + 0.3 * rz, n_segments=10,
                center=(x, y, 0)),
        ellipsoid((crown_radius, crown_radius, rz), center=(x, y, height - rz), n_segments=16, n_rings=8),
    ])



def person(*, x: float = 0.0, y: float = 0.0, height: float = 1.7) -> TriMesh:
    """A standing person: legs and torso as two frustums, and a head.

    Examples
    --------
    >>> round(float(person(height=1.8).bounds()[1, 2]), 2)
    1.79
    """
    h = height
    return concat_meshes([frustum(0.18, 0.15, 0.0, 0.55 * h, n_segments=8, center=(x, y, 0.0)),
                          frustum(0.2, 0.16, 0.55 * h, 0.87 * h, n_segments=8, center=(x, y, 0.0)),
                          ellipsoid((0.1, 0.1, 0.12), center=(x, y, 0.93 * h), n_segments=8, n_rings=4)])


def scaffold(*, x: float = 0.0, y: float = 0.0, yaw: float = 0.0, width: float = 4.0, depth: float = 1.5,
             height: float = 6.0) -> TriMesh:
    """Scaffolding: two rows of thin poles (one every 2 m or so) and a plank deck every 2 m.

    Examples
    --------
    >>> float(scaffold(height=5.0).bounds()[1, 2])
    5.0
    """
    w, d, h = width, depth, height
    poles = [box((x + u - 0.03, y + v - 0.03, 0.0), (x + u + 0.03, y + v + 0.03, h))
             for u in np.linspace(0, w, max(2, int(w // 2) + 1)) for v in (0.0, d)]
    planks = [box((x, y, z), (x + w, y + d, z + 0.05)) for z in np.arange(2.0, h, 2.0)]
    return concat_meshes(poles + planks).rotated_z(yaw, about=(x, y))
