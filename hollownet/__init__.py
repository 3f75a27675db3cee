"""HollowNet: hollow voxels and the 3D CNN that classifies segments (``docs/method.md``, "HollowNet").

``voxels`` (NumPy) turns a segment into a 30^3 grid; ``model`` holds the network, its
registry and checkpoints; ``predict`` the batched :class:`Classifier` (one per process);
``dataset`` makes training data from synthetic scans; ``train`` trains and reports.
"""

from hollowtree.exports import lazy_exports

# Imported on first use: the package does not load torch until a name of it is used.
__all__, __getattr__ = lazy_exports(__name__, {
    "model": "DEFAULT_WEIGHTS NUM_OUTPUTS OUTPUT_CLASSES HollowNet WeightsError get_model hollownet_v1 list_models "
             "load_model",
    "predict": "Classifier Prediction",
    "voxels": "EMPTY OCCUPIED DegenerateSegmentError voxelize voxelize_batch",
})
