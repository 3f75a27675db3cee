"""Triangle meshes as plain arrays, and the few operations every element builder needs.

Pure NumPy (plus ``mapbox_earcut`` for polygon triangulation). A :class:`TriMesh` is a
frozen pair ``vertices (n, 3) float64`` and ``faces (m, 3) int64``; every builder returns
a new one.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

__all__ = ["TriMesh", "concat_meshes"]


@dataclass(frozen=True, eq=False)
class TriMesh:
    """A triangle mesh in metres, z up.

    Parameters
    ----------
    vertices : ndarray of shape (n_vertices, 3), float64
    faces : ndarray of shape (n_faces, 3), int64
        Indices into ``vertices``; the winding does not matter to the scanner.
    """

    vertices: npt.NDArray[np.float64]
    faces: npt.NDArray[np.int64]

    def __post_init__(self) -> None:
        v = np.ascontiguousarray(self.vertices, dtype=np.float64).reshape(-1, 3)
        f = np.ascontiguousarray(self.faces, dtype=np.int64).reshape(-1, 3)
        if f.size and (f.min() < 0 or f.max() >= len(v)):
            raise ValueError("face index out of range")
        object.__setattr__(self, "vertices", v)
        object.__setattr__(self, "faces", f)

    @property
    def n_faces(self) -> int:
        return int(len(self.faces))

    def translated(self, offset: Sequence[float] | npt.ArrayLike) -> TriMesh:
        """Return the mesh moved by ``offset`` (3 values)."""
        return TriMesh(self.vertices + np.asarray(offset, dtype=np.float64), self.faces)

    def rotated_z(self, angle: float, *, about: Sequence[float] = (0.0, 0.0)) -> TriMesh:
        """Return the mesh rotated by ``angle`` radians about the vertical axis through ``about``."""
        c, s = np.cos(angle), np.sin(angle)
        v = self.vertices.copy()
        x = v[:, 0] - about[0]
        y = v[:, 1] - about[1]
        v[:, 0] = about[0] + c * x - s * y
        v[:, 1] = about[1] + s * x + c * y
        return TriMesh(v, self.faces)

    def scaled(self, factor: float | Sequence[float]) -> TriMesh:
        """Return the mesh scaled about the origin (one factor or one per axis)."""
        return TriMesh(self.vertices * np.asarray(factor, dtype=np.float64), self.faces)

    def bounds(self) -> npt.NDArray[np.float64]:
        """Return ``[[xmin, ymin, zmin], [xmax, ymax, zmax]]``."""
        return np.stack([self.vertices.min(axis=0), self.vertices.max(axis=0)])

    def area(self) -> float:
        """Total surface area in square metres."""
        t = self.vertices[self.faces]
        return float(0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1).sum())


def concat_meshes(meshes: Sequence[TriMesh]) -> TriMesh:
    """Concatenate meshes into one (faces re-indexed).

    Examples
    --------
    >>> a = TriMesh(np.eye(3), np.array([[0, 1, 2]]))
    >>> concat_meshes([a, a.translated((0, 0, 1))]).faces.tolist()
    [[0, 1, 2], [3, 4, 5]]
    """
    if not meshes:
        return TriMesh(np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64))
    offsets = np.cumsum([0] + [len(m.vertices) for m in meshes[:-1]])
    v = np.concatenate([m.vertices for m in meshes])
    f = np.concatenate([m.faces + o for m, o in zip(meshes, offsets, strict=True)])
    return TriMesh(v, f)
