"""A tall pillar is a minaret: HollowNet cannot see size, the height can.

HollowNet scales every part to fit its 30^3 grid, so a slender minaret and a column look
alike; on the temple's minarets (44 m) it says ``pillar`` for the whole minaret
(docs/results.md). The training scenes of HollowNet hold pillars of 2.5-8 m and minarets
of 12-40 m (``hollownet/_scenes.py``), so a part classed pillar that is taller than a
bound between the two (``tree.pillar_max_height``, 10 m) is called a minaret, unless its
footprint is flat: a minaret is round or polygonal seen from above, even when only one
side of it was scanned (a half shaft: short over long side about 0.5), while a tall
strip of a wall, a portal's jamb say, is a plane (about 0). Parts whose footprint's short
side is under :data:`MIN_FOOTPRINT_RATIO` of its long side stay pillars. Like
:mod:`tree.ground`, this is not in the paper. Only the class changes; the score and the
probabilities stay HollowNet's.

The mirror rule, :func:`short_minarets`: an element instance HollowNet calls minaret that
is not taller than the same bound is a pillar (a dome's finial in a group of its own, the
top stage of a minaret cut off by the coarse stage). The tree stage applies it to whole
instances after the tree (:func:`pipeline.tree_stage._group_tree`), not to every node: a
minaret's stages, each a few metres tall, are children the split model judges by their
classes. The baselines of ``hollowtree evaluate`` do not get it: their segments are pieces
(a minaret is many short primitives), not instances.

Pure NumPy.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from tiling.classes import ClassId

__all__ = ["MIN_FOOTPRINT_RATIO", "TallPillars", "footprint_ratio", "short_minarets", "tall_pillars"]

#: A tall pillar whose footprint's short side is under this share of its long side is
#: flat (a strip of wall), not a minaret. Minarets and bastions of the five synthetic
#: sites, whole or scanned from one side, measure 0.36 to 1.0; a portal's jamb 0.0.
MIN_FOOTPRINT_RATIO = 0.2


def footprint_ratio(xyz: npt.ArrayLike) -> float:
    """Short over long side of a part's footprint: the 1st to 99th percentile extents of
    its x, y coordinates along their two principal axes (0 for a vertical plane, about
    1 for a round or square shaft; 0 when the part has no extent).

    Examples
    --------
    >>> t = np.linspace(0, 2 * np.pi, 200)
    >>> round(footprint_ratio(np.c_[np.cos(t), np.sin(t), t]), 2)
    1.0
    >>> round(footprint_ratio(np.c_[t, 2 * t, t]), 2)
    0.0
    """
    a = np.asarray(xyz, dtype=np.float64)
    if len(a) < 3:
        return 0.0
    xy = a[:, :2] - a[:, :2].mean(axis=0)
    _, vec = np.linalg.eigh(np.cov(xy.T))
    lo, hi = np.percentile(xy @ vec, [1.0, 99.0], axis=0)
    ext = hi - lo
    return float(ext.min() / ext.max()) if ext.max() > 0 else 0.0


def tall_pillars(class_id: npt.ArrayLike, height: npt.ArrayLike, max_height: float,
                 ratio: npt.ArrayLike | None = None) -> npt.NDArray[np.uint8]:
    """``class_id`` with every pillar taller than ``max_height`` (metres) made a minaret,
    unless its footprint ``ratio`` (:func:`footprint_ratio`; None: all round) is under
    :data:`MIN_FOOTPRINT_RATIO`.

    Examples
    --------
    >>> tall_pillars([7, 7, 6, 2], [4.0, 30.0, 30.0, 30.0], 10.0).tolist()
    [7, 6, 6, 2]
    >>> tall_pillars([7, 7], [30.0, 30.0], 10.0, ratio=[0.9, 0.01]).tolist()
    [6, 7]
    """
    c = np.asarray(class_id).astype(np.uint8, copy=True).reshape(-1)
    h = np.asarray(height, dtype=np.float64).reshape(-1)
    r = np.ones(len(c)) if ratio is None else np.asarray(ratio, dtype=np.float64).reshape(-1)
    for name, v in (("height", h), ("ratio", r)):
        if len(v) != len(c):
            raise ValueError(f"The '{name}' parameter of tall_pillars must have one entry per class ({len(c)}). "
                             f"Got {len(v)} instead.")
    c[(c == int(ClassId.PILLAR)) & (h > max_height) & (r >= MIN_FOOTPRINT_RATIO)] = int(ClassId.MINARET)
    return c


def short_minarets(class_id: npt.ArrayLike, height: npt.ArrayLike, max_height: float) -> npt.NDArray[np.uint8]:
    """``class_id`` with every minaret not taller than ``max_height`` (metres) made a pillar.

    Examples
    --------
    >>> short_minarets([6, 6, 7, 2], [2.1, 30.0, 2.1, 2.1], 10.0).tolist()
    [7, 6, 7, 2]
    """
    c = np.asarray(class_id).astype(np.uint8, copy=True).reshape(-1)
    h = np.asarray(height, dtype=np.float64).reshape(-1)
    if len(h) != len(c):
        raise ValueError(f"The 'height' parameter of short_minarets must have one entry per class ({len(c)}). "
                         f"Got {len(h)} instead.")
    c[(c == int(ClassId.MINARET)) & (h <= max_height)] = int(ClassId.PILLAR)
    return c


class TallPillars:
    """A classifier (``tree.energy.Classifier``) whose pillars taller than ``max_height``
    are minarets unless flat (:func:`tall_pillars`); the height of a part is the extent
    of its z coordinates."""

    def __init__(self, classifier: Any, max_height: float) -> None:
        if not (np.isfinite(max_height) and max_height > 0):
            raise ValueError(f"The 'max_height' parameter of TallPillars must be a float in the range (0.0, inf). "
                             f"Got {max_height!r} instead.")
        self.classifier = classifier
        self.max_height = float(max_height)

    def predict(self, segments: Sequence[npt.NDArray[np.float64]]) -> Any:
        pred = self.classifier.predict(segments)
        cls, score, prob = pred
        height = np.array([float(np.ptp(s[:, 2])) if len(s) else 0.0 for s in segments])
        tall = (np.asarray(cls).reshape(-1) == int(ClassId.PILLAR)) & (height > self.max_height)
        ratio = np.array([footprint_ratio(s) if t else 1.0 for s, t in zip(segments, tall, strict=True)])
        new = tall_pillars(cls, height, self.max_height, ratio)
        if dataclasses.is_dataclass(pred) and hasattr(pred, "class_id"):
            return dataclasses.replace(pred, class_id=new)
        return new, score, prob
