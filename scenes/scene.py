"""A labelled scene: one triangle soup, an instance id per triangle, the scanner stations.

Every site and every small test scene is built through :class:`SceneBuilder`, which hands
out instance ids (1, 2, ...; 0 means "none" in ``gt_instance``) and records each
instance's class. An element (arch, dome, minaret, pillar) is one instance however many
meshes it is made of; planar pieces (a wall panel, a roof slab, the ground) and clutter
objects get one instance each, as ``../shared/METHOD.md`` defines instances.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from hollowtree.classes import ELEMENT_CLASSES, ClassId
from hollowtree.scenes.mesh import TriMesh, concat_meshes

__all__ = ["Element", "Scene", "SceneBuilder"]


@dataclass(frozen=True, kw_only=True)
class Element:
    """One instance of the ground truth: its id, class and a readable name."""

    instance: int
    class_id: ClassId
    name: str


@dataclass(frozen=True, kw_only=True, eq=False)
class Scene:
    """A labelled triangle scene in local metres (z up, ground at z = 0).

    Attributes
    ----------
    name : str
    vertices : ndarray of shape (n_vertices, 3), float64
    faces : ndarray of shape (n_faces, 3), int64
    face_instance : ndarray of shape (n_faces,), uint32
        Instance id of every triangle (>= 1).
    elements : tuple of Element
        One entry per instance id, ``elements[i].instance == i + 1``.
    stations : ndarray of shape (n_stations, 3), float64
        Scanner positions (the optical centre) in priority order: a scan with K stations
        uses the first K.
    """

    name: str
    vertices: npt.NDArray[np.float64]
    faces: npt.NDArray[np.int64]
    face_instance: npt.NDArray[np.uint32]
    elements: tuple[Element, ...]
    stations: npt.NDArray[np.float64]

    @property
    def instance_class(self) -> npt.NDArray[np.uint8]:
        """Class id by instance id (index 0 is ``UNCLASSIFIED``)."""
        out = np.zeros(len(self.elements) + 1, dtype=np.uint8)
        for e in self.elements:
            out[e.instance] = int(e.class_id)
        return out

    @property
    def face_class(self) -> npt.NDArray[np.uint8]:
        """Class id of every triangle."""
        return self.instance_class[self.face_instance]

    def bounds(self) -> npt.NDArray[np.float64]:
        """``[[xmin, ymin, zmin], [xmax, ymax, zmax]]`` of the geometry."""
        return np.stack([self.vertices.min(axis=0), self.vertices.max(axis=0)])

    def element_counts(self) -> dict[ClassId, int]:
        """Number of instances per element class (arch, dome, minaret, pillar)."""
        c = Counter(e.class_id for e in self.elements)
        return {k: c.get(k, 0) for k in ELEMENT_CLASSES}


@dataclass
class SceneBuilder:
    """Collects labelled meshes and stations, then freezes them into a :class:`Scene`.

    Examples
    --------
    >>> from hollowtree.scenes.mesh import TriMesh
    >>> b = SceneBuilder("toy")
    >>> tri = TriMesh(np.eye(3), np.array([[0, 1, 2]]))
    >>> i = b.add(tri, ClassId.PILLAR, "pillar 1")
    >>> b.extend(i, tri.translated((0, 0, 1)))
    >>> b.add_station((5.0, 0.0, 1.6))
    >>> s = b.build()
    >>> s.face_instance.tolist(), s.element_counts()[ClassId.PILLAR]
    ([1, 1], 1)
    """

    name: str
    _meshes: list[TriMesh] = field(default_factory=list)
    _owners: list[int] = field(default_factory=list)
    _elements: list[Element] = field(default_factory=list)
    _stations: list[tuple[float, float, float]] = field(default_factory=list)

    def add(self, mesh: TriMesh | Sequence[TriMesh], class_id: ClassId, name: str) -> int:
        """Add a new instance made of ``mesh`` (one or several); return its instance id."""
        instance = len(self._elements) + 1
        self._elements.append(Element(instance=instance, class_id=ClassId(class_id), name=name))
        self.extend(instance, mesh)
        return instance

    def extend(self, instance: int, mesh: TriMesh | Sequence[TriMesh]) -> None:
        """Add more surface to an existing instance."""
        if not 1 <= instance <= len(self._elements):
            raise ValueError(f"unknown instance {instance}")
        meshes = [mesh] if isinstance(mesh, TriMesh) else list(mesh)
        for m in meshes:
            self._meshes.append(m)
            self._owners.append(instance)

    def add_station(self, xyz: Sequence[float]) -> None:
        """Add a scanner position (x, y, z of the optical centre, metres)."""
        x, y, z = (float(a) for a in xyz)
        self._stations.append((x, y, z))

    def build(self) -> Scene:
        """Freeze into a :class:`Scene`; instances without any triangle are an error."""
        if not self._stations:
            raise ValueError(f"scene {self.name!r} has no scanner station")
        mesh = concat_meshes(self._meshes)
        owner = np.repeat(
            np.asarray(self._owners, dtype=np.uint32), [m.n_faces for m in self._meshes]
        )
        empty = set(range(1, len(self._elements) + 1)) - set(np.unique(owner).tolist())
        if empty:
            names = [self._elements[i - 1].name for i in sorted(empty)]
            raise ValueError(f"scene {self.name!r}: instances without surface: {names}")
        return Scene(
            name=self.name,
            vertices=mesh.vertices,
            faces=mesh.faces,
            face_instance=owner,
            elements=tuple(self._elements),
            stations=np.asarray(self._stations, dtype=np.float64),
        )
