"""A tall pillar is a minaret: HollowNet cannot see size, the height can.

HollowNet scales every part to fit its 30^3 grid, so a slender minaret and a column look
alike; on the temple's minarets (44 m) it says ``pillar`` for the whole minaret
(docs/results.md). The training scenes of HollowNet hold pillars of 2.5-8 m and minarets
of 12-40 m (``hollownet/_scenes.py``), so a part classed pillar that is taller than a
bound between the two (``tree.pillar_max_height``, 10 m) is called a minaret. Like
:mod:`tree.ground`, this is not in the paper. Only the class changes; the score and the
probabilities stay HollowNet's.

Pure NumPy.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from tiling.classes import ClassId

__all__ = ["TallPillars", "tall_pillars"]


def tall_pillars(class_id: npt.ArrayLike, height: npt.ArrayLike, max_height: float) -> npt.NDArray[np.uint8]:
    """``class_id`` with every pillar taller than ``max_height`` (metres) made a minaret.

    Examples
    --------
    >>> tall_pillars([7, 7, 6, 2], [4.0, 30.0, 30.0, 30.0], 10.0).tolist()
    [7, 6, 6, 2]
    """
    c = np.asarray(class_id).astype(np.uint8, copy=True).reshape(-1)
    h = np.asarray(height, dtype=np.float64).reshape(-1)
    if len(h) != len(c):
        raise ValueError(f"The 'height' parameter of tall_pillars must have one entry per class ({len(c)}). "
                         f"Got {len(h)} instead.")
    c[(c == int(ClassId.PILLAR)) & (h > max_height)] = int(ClassId.MINARET)
    return c


class TallPillars:
    """A classifier (``tree.energy.Classifier``) whose pillars taller than ``max_height``
    are minarets; the height of a part is the extent of its z coordinates."""

    def __init__(self, classifier: Any, max_height: float) -> None:
        if not (np.isfinite(max_height) and max_height > 0):
            raise ValueError(f"The 'max_height' parameter of TallPillars must be a float in the range (0.0, inf). "
                             f"Got {max_height!r} instead.")
        self.classifier = classifier
        self.max_height = float(max_height)

    def predict(self, segments: Sequence[npt.NDArray[np.float64]]) -> Any:
        pred = self.classifier.predict(segments)
        cls, score, prob = pred
        height = [float(np.ptp(s[:, 2])) if len(s) else 0.0 for s in segments]
        new = tall_pillars(cls, height, self.max_height)
        if dataclasses.is_dataclass(pred) and hasattr(pred, "class_id"):
            return dataclasses.replace(pred, class_id=new)
        return new, score, prob
