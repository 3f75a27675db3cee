"""Coarse-segmentation kernels (the paper's first stage): pure NumPy/SciPy.

- :func:`estimate_normals`: k-NN PCA normals and surface variation;
- :func:`efficient_ransac`: Efficient RANSAC (Schnabel, Wahl and Klein 2007) for planes,
  spheres, cylinders and cones by default, and tori on request (``shapes=KINDS``);
- :func:`dbscan_labels`, :func:`dbscan_segments`, :func:`default_eps`: exact DBSCAN
  (scikit-learn's labels) and its per-primitive use; :func:`window_spacing`: a quantile
  of the point spacing on compact windows of a scan (the coarse stage's automatic eps);
- :class:`UnionFind`, :func:`stitch_segments`, :func:`csr_by_segment`: joining tile-local
  segments across tile borders.

The per-tile Dask task and the stitching of a run store are in ``pipeline/coarse.py``.
"""

import importlib
from typing import Any

#: Where each name of the package lives: imported on first use, so that the light
#: modules (``coarse_params``: the stage's parameters) load without the kernels.
_WHERE = {
    "dbscan": ("dbscan_labels", "dbscan_segments", "default_eps", "window_spacing"),
    "normals": ("NormalResult", "estimate_normals"),
    "ransac": ("RansacParams", "RansacResult", "efficient_ransac"),
    "shapes": ("FailedFit", "PrimitiveFit"),
    "stitch": ("StitchResult", "UnionFind", "csr_by_segment", "stitch_segments"),
}
_MODULE = {name: mod for mod, names in _WHERE.items() for name in names}

__all__ = [
    "FailedFit",
    "NormalResult",
    "PrimitiveFit",
    "RansacParams",
    "RansacResult",
    "StitchResult",
    "UnionFind",
    "csr_by_segment",
    "dbscan_labels",
    "dbscan_segments",
    "default_eps",
    "efficient_ransac",
    "estimate_normals",
    "stitch_segments",
    "window_spacing",
]


def __getattr__(name: str) -> Any:
    if name in _MODULE:
        return getattr(importlib.import_module(f"hollowtree.primitives.{_MODULE[name]}"), name)
    raise AttributeError(f"module 'hollowtree.primitives' has no attribute {name!r}")
