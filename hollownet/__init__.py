"""HollowNet: hollow voxels and the 3D CNN that classifies segments (``docs/method.md``, "HollowNet").

``voxels`` (NumPy) turns a segment into a 30^3 grid; ``model`` holds the network, its
registry and checkpoints; ``predict`` the batched :class:`Classifier` (one per process);
``dataset`` makes training data from synthetic scans; ``train`` trains and reports.
"""

from pathlib import Path

from hollowtree.exports import lazy_exports

#: The shipped weights (``docs/method.md``, "HollowNet" says how they are made); a plain
#: path, so naming it does not load torch.
DEFAULT_WEIGHTS = Path(__file__).resolve().parent / "weights" / "hollownet-v1.pt"

# Imported on first use: the package does not load torch until a name of it is used.
_lazy, __getattr__ = lazy_exports(__name__, {
    "model": "NUM_OUTPUTS OUTPUT_CLASSES HollowNet WeightsError get_model hollownet_v1 list_models "
             "load_model",
    "predict": "Classifier Prediction",
    "voxels": "EMPTY OCCUPIED DegenerateSegmentError voxelize voxelize_batch",
})
__all__ = ["DEFAULT_WEIGHTS", *_lazy]
