"""Labelled synthetic scans: parametric architectural elements, the paper's sites, and a
virtual terrestrial laser scanner that ray-casts them (``hollowtree synth``)."""

from hollowtree.exports import lazy_exports

# Imported on first use: ``hollowtree.scenes.scan_params`` stays light (no NumPy).
__all__, __getattr__ = lazy_exports(__name__, {"mesh": "TriMesh concat_meshes", "scene": "Element Scene SceneBuilder"})
