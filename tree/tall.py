"""A tall pillar is a minaret: HollowNet cannot see size, the height can.

HollowNet scales every part to fit its 30^3 grid, so a slender minaret and a column look
alike; on the temple's minarets (44 m) it says ``pillar`` for the whole minaret
(docs/decisions/method.md). The training scenes of HollowNet hold pillars of 2.5-8 m and minarets
of 12-40 m (``hollownet/_scenes.py``), so a part classed pillar that is taller than a
bound between the two (``tree.pillar_max_height``: 10 m where set; off by default, as it did
not earn its place on the validation split) is called a minaret, unless its
footprint is flat: a minaret is round or polygonal seen from above, even when only one
side of it was scanned (a half shaft: short over long side about 0.5), while a tall
strip of a wall, a portal's jamb say, is a plane (about 0). Parts whose footprint's short
side is under :data:`MIN_FOOTPRINT_RATIO` of its long side stay pillars. Like
:mod:`tree.ground`, this is not in the paper. Only the class changes; the score and the
probabilities stay HollowNet's.

A tall slender dome is a minaret (:func:`slender_domes`): HollowNet scales a stretch of a
minaret's shaft with its balcony to the grid as it scales a drum under a cupola, and
called 17.5 and 23 m stretches of a Wazir Khan minaret dome; a dome instance taller than
the same bound and more than :data:`DOME_MAX_SLENDERNESS` times as tall as its box is
wide is a minaret (a chattri, 3.8 m on its posts, can be 1.3 times as tall as wide). The
tree stage applies it to whole instances, before the next rule.

The mirror rule, :func:`short_minarets`: an element instance HollowNet calls minaret that
is not taller than the same bound is a pillar (a dome's finial in a group of its own, the
top stage of a minaret cut off by the coarse stage). The tree stage applies it to whole
instances after the tree (:func:`pipeline.tree_stage._group_tree`), not to every node: a
minaret's stages, each a few metres tall, are children the split model judges by their
classes. The baselines of ``hollowtree evaluate`` do not get it: their segments are pieces
(a minaret is many short primitives), not instances.

A third rule, :func:`not_clutter`, for the class ``other`` (clutter): HollowNet's clutter
is what stands on the ground before a building (benches, cars, bicycles, crates, bushes,
trees of 3-12 m in its training scenes), but seen without its size a dome on its drum
looks like a bush and a bastion scanned from one side like a tree. A part classed other
whose lowest point is more than ``tree.other_max_base`` (2 m) above the local ground
(``tree/ground.py``), or that is larger than ``tree.other_max_size`` (15 m) along x, y or
z, takes
HollowNet's most probable class but other. :class:`NotClutter` applies it to every part
the tree classifies, before the tall-pillar rule; the baselines of ``hollowtree
evaluate`` get it too (it is a rule on one part's class, like the tall-pillar rule).

Pure NumPy.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from hollowtree.classes import ClassId
from hollowtree.columns import column_span

__all__ = ["DOME_MAX_SLENDERNESS", "MIN_FOOTPRINT_RATIO", "NotClutter", "TallPillars", "footprint_ratio",
           "not_clutter", "short_minarets", "size_rules", "slender_domes", "tall_pillars"]

#: A tall pillar whose footprint's short side is under this share of its long side is
#: flat (a strip of wall), not a minaret. Minarets and bastions of the five synthetic
#: sites, whole or scanned from one side, measure 0.36 to 1.0; a portal's jamb 0.0.
MIN_FOOTPRINT_RATIO = 0.2


#: A dome instance taller than a pillar may be (``tree.pillar_max_height``) and than this
#: many times the longer horizontal side of its box is a minaret's stretch
#: (:func:`slender_domes`). The domes and chattris the tree finds on the five synthetic
#: sites measure 0.2 to 1.3 (a hemisphere on a drum, a finial; the tallest 9.1 m, at
#: 1.0); two stretches of a Wazir Khan minaret that HollowNet called dome, 1.8 (17.5 m)
#: and 2.3 (23 m).
DOME_MAX_SLENDERNESS = 1.5


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


def slender_domes(class_id: npt.ArrayLike, height: npt.ArrayLike, width: npt.ArrayLike, min_height: float,
                  max_ratio: float = DOME_MAX_SLENDERNESS) -> npt.NDArray[np.uint8]:
    """``class_id`` with every dome taller than ``min_height`` (metres) and than
    ``max_ratio`` times its ``width`` (the longer horizontal side of its box) made a minaret.

    Examples
    --------
    >>> slender_domes([5, 5, 5, 6], [17.5, 9.1, 3.8, 30.0], [9.8, 9.1, 2.0, 5.0], 10.0).tolist()
    [6, 5, 5, 6]
    """
    c = np.asarray(class_id).astype(np.uint8, copy=True).reshape(-1)
    h = np.asarray(height, dtype=np.float64).reshape(-1)
    w = np.asarray(width, dtype=np.float64).reshape(-1)
    if not len(h) == len(w) == len(c):
        raise ValueError(f"slender_domes needs one height and width per class ({len(c)}); "
                         f"got {len(h)} and {len(w)}.")
    c[(c == int(ClassId.DOME)) & (h > min_height) & (h > max_ratio * w)] = int(ClassId.MINARET)
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


def not_clutter(class_id: npt.ArrayLike, probabilities: npt.ArrayLike, base: npt.ArrayLike, size: npt.ArrayLike,
                *, max_base: float | None, max_size: float | None) -> npt.NDArray[np.uint8]:
    """``class_id`` with every part classed other that does not stand on the ground or is
    too large for clutter given its most probable class but other.

    ``probabilities``: one row per part over the classes but ``unclassified``, in id order
    (HollowNet's output, ``hollownet.model.OUTPUT_CLASSES``); ``base``: the height of the
    part's lowest point above the local ground (NaN: unknown, the base test is skipped);
    ``size``: its largest extent along x, y or z. A part is not clutter when
    ``base > max_base`` or ``size > max_size`` (None: that test is off). A part whose probabilities are all
    zero (HollowNet could not classify it) stays other.

    Examples
    --------
    >>> p = [[0, 0, 0, 0, 0.3, 0, 0, 0.7]] * 3
    >>> not_clutter([8, 8, 8], p, [0.0, 11.0, 0.0], [5.0, 5.0, 27.0], max_base=2.0, max_size=15.0).tolist()
    [8, 5, 5]
    """
    c = np.asarray(class_id).astype(np.uint8, copy=True).reshape(-1)
    n = len(c)
    p = np.asarray(probabilities, dtype=np.float64).reshape(n, -1)
    b = np.asarray(base, dtype=np.float64).reshape(-1)
    h = np.asarray(size, dtype=np.float64).reshape(-1)
    for name, v in (("base", b), ("size", h)):
        if len(v) != n:
            raise ValueError(f"The '{name}' parameter of not_clutter must have one entry per class ({n}). "
                             f"Got {len(v)} instead.")
    other = int(ClassId.OTHER)
    if p.shape[1] < other:
        raise ValueError(f"The 'probabilities' parameter of not_clutter must have {other} columns (the classes "
                         f"but unclassified). Got {p.shape[1]} instead.")
    out = np.zeros(n, dtype=bool)
    if max_base is not None:
        with np.errstate(invalid="ignore"):
            out |= b > max_base
    if max_size is not None:
        out |= h > max_size
    p = p.copy()
    p[:, other - 1] = -1.0
    best = np.argmax(p, axis=1)
    move = (c == other) & out & (p[np.arange(n), best] > 0)
    c[move] = (best[move] + 1).astype(np.uint8)
    return c


class NotClutter:
    """A classifier (``tree.energy.Classifier``) whose parts classed other are given their
    next most probable class when they do not stand on the ground or are too large for
    clutter (:func:`not_clutter`). ``ground``: the local ground's z in the coordinates
    of the parts passed to ``predict``, one value for all or one per part (None or NaN:
    unknown, only the height test applies).
    Only the class changes; the score and the probabilities stay HollowNet's."""

    def __init__(self, classifier: Any, *, ground: float | npt.ArrayLike | None, max_base: float | None,
                 max_size: float | None) -> None:
        for name, v in (("max_base", max_base), ("max_size", max_size)):
            if v is not None and not (np.isfinite(v) and v > 0):
                raise ValueError(f"The '{name}' parameter of NotClutter must be a float in the range (0.0, inf) "
                                 f"or None. Got {v!r} instead.")
        self.classifier = classifier
        self.ground = None if ground is None else np.asarray(ground, dtype=np.float64)
        self.max_base = max_base
        self.max_size = max_size

    def predict(self, segments: Sequence[npt.NDArray[np.float64]]) -> Any:
        pred = self.classifier.predict(segments)
        cls, score, prob = pred
        lo = np.array([float(s[:, 2].min()) if len(s) else np.nan for s in segments])
        size = np.array([float(column_span(s).max()) if len(s) else 0.0 for s in segments])
        if self.ground is not None and self.ground.size not in (1, len(lo)):
            raise ValueError(f"The 'ground' parameter of NotClutter must be one value or one per part ({len(lo)}). "
                             f"Got {self.ground.size} instead.")
        base = lo - self.ground.reshape(-1) if self.ground is not None else np.full(len(lo), np.nan)
        with np.errstate(invalid="ignore"):
            new = not_clutter(cls, prob, base, size, max_base=self.max_base, max_size=self.max_size)
        if dataclasses.is_dataclass(pred) and hasattr(pred, "class_id"):
            return dataclasses.replace(pred, class_id=new)
        return new, score, prob


def size_rules(classifier: Any, *, pillar_max_height: float | None, other_max_base: float | None,
               other_max_size: float | None, ground: float | npt.ArrayLike | None = None) -> Any:
    """``classifier`` with the rules of this module that apply to every part: clutter
    stands on the ground and is no larger than a tree (:class:`NotClutter`, ``ground`` as
    there), then a tall pillar is a minaret (:class:`TallPillars`). A bound of None turns
    its rule off; with all three None the classifier is returned as it is."""
    if other_max_base is not None or other_max_size is not None:
        classifier = NotClutter(classifier, ground=ground, max_base=other_max_base, max_size=other_max_size)
    if pillar_max_height is not None:
        classifier = TallPillars(classifier, pillar_max_height)
    return classifier
