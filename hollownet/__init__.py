"""HollowNet: hollow voxels and the 3D CNN that classifies segments (``docs/method.md``, "HollowNet").

``voxels`` (NumPy) turns a segment into a 30^3 grid; ``model`` holds the network, its
registry and checkpoints; ``predict`` the batched :class:`Classifier` (one per process);
``dataset`` makes training data from synthetic scans; ``train`` trains and reports.
"""

from hollowtree.hollownet.model import (
    DEFAULT_WEIGHTS,
    NUM_OUTPUTS,
    OUTPUT_CLASSES,
    HollowNet,
    WeightsError,
    get_model,
    hollownet_v1,
    list_models,
    load_model,
)
from hollowtree.hollownet.predict import Classifier, Prediction
from hollowtree.hollownet.voxels import (
    EMPTY,
    OCCUPIED,
    DegenerateSegmentError,
    voxelize,
    voxelize_batch,
)

__all__ = [
    "DEFAULT_WEIGHTS",
    "EMPTY",
    "NUM_OUTPUTS",
    "OCCUPIED",
    "OUTPUT_CLASSES",
    "Classifier",
    "DegenerateSegmentError",
    "HollowNet",
    "Prediction",
    "WeightsError",
    "get_model",
    "hollownet_v1",
    "list_models",
    "load_model",
    "voxelize",
    "voxelize_batch",
]
