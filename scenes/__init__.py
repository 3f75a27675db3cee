"""Labelled synthetic scans: parametric architectural elements, the paper's sites, and a
virtual terrestrial laser scanner that ray-casts them (``hollowtree synth``)."""

from scenes.mesh import TriMesh, concat_meshes
from scenes.scene import Element, Scene, SceneBuilder

__all__ = ["Element", "Scene", "SceneBuilder", "TriMesh", "concat_meshes"]
