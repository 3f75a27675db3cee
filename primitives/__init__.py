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

from hollowtree.primitives.dbscan import dbscan_labels, dbscan_segments, default_eps, window_spacing
from hollowtree.primitives.normals import NormalResult, estimate_normals
from hollowtree.primitives.ransac import RansacParams, RansacResult, efficient_ransac
from hollowtree.primitives.shapes import FailedFit, PrimitiveFit
from hollowtree.primitives.stitch import StitchResult, UnionFind, csr_by_segment, stitch_segments

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
