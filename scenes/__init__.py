"""Labelled synthetic scans: parametric architectural elements, the paper's sites, and a
virtual terrestrial laser scanner that ray-casts them (``hollowtree synth``)."""

from hollowtree.scenes.mesh import TriMesh, concat_meshes
from hollowtree.scenes.scene import Element, Scene, SceneBuilder

__all__ = ["Element", "Scene", "SceneBuilder", "TriMesh", "concat_meshes"]
