"""The element check: a learned decision on every element instance the tree made (not in
the paper).

HollowNet scales each part to its 30^3 grid, so it sees shape without size: a person is a
column, a tree's crown a dome, a scaffold's bay an arch. The rules of :mod:`tree.tall`
mend the cases one bound at a time. The element check looks at each element instance
after the merge across element groups (:mod:`tree.merge`) with what the tree knows of it
(:func:`instance_features`: its class, HollowNet's score, its points, its box, its
height above the local ground, how many tree nodes it was made of) and gives, for each
element class, the probability that it is an element of that class
(:class:`ElementCheck`): the instance takes the most probable class when that
probability reaches the check's threshold, and becomes ``other`` otherwise. Each class's
model is the same kind of gradient-boosted trees as the split model
(:class:`tree.split.SplitModel`), fitted on the instances of procedural training sites run
through the default workflow, an instance being an element of a class when it matches
one (IoU >= 0.5) in the run's final labels (``benchmarks/fit_verify.py``;
docs/generalize.md for the protocol).

Pure NumPy.
"""

from __future__ import annotations

import functools
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

from hollowtree.arrays import FloatArray, IntArray
from hollowtree.classes import ELEMENT_CLASSES, ClassId, class_id
from hollowtree.errors import ConfigError
from hollowtree.tree.split import SplitModel, file_stamp

__all__ = ["DEFAULT_VERIFY_PATH", "SHAPE_FEATURES", "VERIFY_FEATURES", "ElementCheck", "VerifyModel",
           "instance_features", "load_verify_model", "local_shape"]

#: The element check shipped with the package.
DEFAULT_VERIFY_PATH = Path(__file__).resolve().parent / "data" / "verify-v3.json"

_ELEMENTS = tuple(int(c) for c in ELEMENT_CLASSES)

#: The local shape of an instance's points (:func:`local_shape`), in order: the mean
#: linearity, planarity and scattering of the points' neighbourhoods, the mean |z| of their
#: normals, and the shares of points on horizontal and on vertical surfaces.
SHAPE_FEATURES: tuple[str, ...] = ("linearity", "planarity", "scattering", "normal_z", "horizontal_share",
                                   "vertical_share")

#: Names of the columns of :func:`instance_features`, in order.
VERIFY_FEATURES: tuple[str, ...] = (
    *(f"is_{c.label}" for c in ELEMENT_CLASSES), "score", "log10_points", "log10_height", "log10_long",
    "log10_short", "footprint_ratio", "base_above_ground", "top_above_ground", "n_nodes", "n_segments",
    "min_depth", *SHAPE_FEATURES,
)

#: :func:`local_shape`: the grid the points are thinned on (metres; a scan's density no
#: longer matters above it), the neighbours of a point and the points sampled per instance.
SHAPE_VOXEL = 0.03
SHAPE_NEIGHBOURS = 16
SHAPE_SAMPLE = 1500


class VerifyModel(SplitModel):
    """Gradient-boosted trees giving P(instance is an element of its class | features);
    fitted on :data:`VERIFY_FEATURES`, or on its columns before :data:`SHAPE_FEATURES` (a
    check fitted before those existed keeps working)."""

    FEATURES: ClassVar[tuple[str, ...]] = VERIFY_FEATURES
    REFIT: ClassVar[str] = "refit it with benchmarks/fit_verify.py"

    @classmethod
    def _known_features(cls, names: tuple[str, ...]) -> bool:
        return names in (cls.FEATURES, cls.FEATURES[:-len(SHAPE_FEATURES)])

    def columns(self) -> IntArray:
        """The columns of :data:`VERIFY_FEATURES` the model reads, in its order."""
        return np.asarray([VERIFY_FEATURES.index(n) for n in self.feature_names], dtype=np.int64)


def local_shape(xyz: npt.ArrayLike) -> FloatArray:
    """:data:`SHAPE_FEATURES` of one instance's points (metres; NaN for fewer than
    :data:`SHAPE_NEIGHBOURS` + 1 points after thinning).

    The points are thinned to one per :data:`SHAPE_VOXEL` cell, so a dense and a sparse
    scan of one shape agree; at most :data:`SHAPE_SAMPLE` of them, evenly spaced in cell
    order, get the covariance of their :data:`SHAPE_NEIGHBOURS` nearest thinned points,
    with eigenvalues l1 >= l2 >= l3: linearity (l1 - l2) / l1 (a scaffold's tubes, a
    railing), planarity (l2 - l3) / l1 (a wall, a shaft, a dome), scattering l3 / l1 (a
    crown, a bush) and the normal (the smallest one's vector): a column shows vertical
    surfaces, a crate or a bench horizontal ones too. Deterministic.

    >>> g = np.mgrid[0:2:0.02, 0:3:0.02].reshape(2, -1).T
    >>> wall = np.c_[g[:, 0], np.zeros(len(g)), g[:, 1]]
    >>> dict(zip(SHAPE_FEATURES, local_shape(wall).round(2).tolist()))["vertical_share"]
    1.0
    >>> pole = np.c_[np.zeros(300), np.zeros(300), np.linspace(0, 6, 300)]
    >>> round(float(local_shape(pole)[0]), 2)
    1.0
    """
    from scipy.spatial import cKDTree

    p = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
    if len(p):
        cells = np.floor((p - p.min(axis=0)) / SHAPE_VOXEL).astype(np.int64)
        dims = cells.max(axis=0) + 1
        _, first = np.unique((cells[:, 0] * dims[1] + cells[:, 1]) * dims[2] + cells[:, 2], return_index=True)
        p = p[np.sort(first)]
    k = SHAPE_NEIGHBOURS
    if len(p) <= k:
        return np.full(len(SHAPE_FEATURES), np.nan)
    q = p[np.linspace(0, len(p) - 1, min(SHAPE_SAMPLE, len(p))).astype(np.int64)]
    _, nb = cKDTree(p).query(q, k=k)
    d = p[nb] - p[nb].mean(axis=1, keepdims=True)
    w, vec = np.linalg.eigh(np.einsum("nki,nkj->nij", d, d) / k)
    l3, l2, l1 = np.maximum(w[:, 0], 0.0), np.maximum(w[:, 1], 0.0), np.maximum(w[:, 2], 1e-12)
    nz = np.abs(vec[:, 2, 0])
    return np.array([np.mean((l1 - l2) / l1), np.mean((l2 - l3) / l1), np.mean(l3 / l1), nz.mean(),
                     np.mean(nz > 0.85), np.mean(nz < 0.3)])


def instance_features(
    instance: npt.ArrayLike, class_id: npt.ArrayLike, score: npt.ArrayLike, n_points: npt.ArrayLike,
    bbox: npt.ArrayLike, depth: npt.ArrayLike, segment: npt.ArrayLike, ground: npt.ArrayLike,
    shape: npt.ArrayLike | None = None,
) -> tuple[IntArray, IntArray, FloatArray]:
    """The features (:data:`VERIFY_FEATURES`) of every element instance, from its tree nodes.

    Parameters
    ----------
    instance : array-like of int, shape (n_nodes,)
        Each instance node's instance after the merge (nodes of instance 0 are left out).
    class_id, score, n_points, depth, segment : array-like, shape (n_nodes,)
        Each node's class after the merge, HollowNet's score, points, depth and segment.
    bbox : array-like of float, shape (n_nodes, 6)
        Each node's box (xmin, ymin, zmin, xmax, ymax, zmax), metres.
    ground : array-like of float, shape (n_nodes,)
        The local ground level under each node (NaN: unknown; then the instance's base).
    shape : array-like of float, shape (n_nodes, len(SHAPE_FEATURES)), optional
        Each node's :func:`local_shape` (NaN: unknown); an instance takes the mean over its
        nodes weighted by their points, -1 where none is known (and for all without it).

    Returns
    -------
    ids, classes : ndarray of int64, shape (m,)
        The element instances (ascending) and their classes; instances of other classes are
        left out.
    features : ndarray of float64, shape (m, len(VERIFY_FEATURES))

    Examples
    --------
    >>> ids, cls, f = instance_features([3, 3, 5], [7, 7, 2], [0.9, 0.7, 1.0], [100, 300, 50],
    ...                                 [[0, 0, 0, 1, 1, 2], [0, 0, 2, 1, 1, 4], [0, 0, 0, 5, 1, 3]],
    ...                                 [1, 2, 0], [4, 4, 5], [0.0, 0.0, 0.0])
    >>> ids.tolist(), cls.tolist(), dict(zip(VERIFY_FEATURES, f[0].round(2).tolist()))["log10_height"]
    ([3], [7], 0.6)
    """
    inst = np.asarray(instance, dtype=np.int64).reshape(-1)
    cls = np.asarray(class_id, dtype=np.int64).reshape(-1)
    keep = (inst > 0) & np.isin(cls, _ELEMENTS)
    inst, cls = inst[keep], cls[keep]
    sc = np.asarray(score, dtype=np.float64).reshape(-1)[keep]
    npts = np.asarray(n_points, dtype=np.float64).reshape(-1)[keep]
    box = np.asarray(bbox, dtype=np.float64).reshape(-1, 6)[keep]
    dep = np.asarray(depth, dtype=np.float64).reshape(-1)[keep]
    seg = np.asarray(segment, dtype=np.int64).reshape(-1)[keep]
    gr = np.asarray(ground, dtype=np.float64).reshape(-1)[keep]
    nsh = len(SHAPE_FEATURES)
    sh = (np.full((len(inst), nsh), np.nan) if shape is None
          else np.asarray(shape, dtype=np.float64).reshape(-1, nsh)[keep])
    ids, first, at = np.unique(inst, return_index=True, return_inverse=True)
    m = len(ids)
    total = np.bincount(at, weights=npts, minlength=m)
    mean_score = np.bincount(at, weights=sc * npts, minlength=m) / np.maximum(total, 1.0)
    lo = np.full((m, 3), np.inf)
    hi = np.full((m, 3), -np.inf)
    np.minimum.at(lo, at, box[:, :3])
    np.maximum.at(hi, at, box[:, 3:])
    ext = np.maximum(hi - lo, 0.0)
    long, short = np.maximum(ext[:, 0], ext[:, 1]), np.minimum(ext[:, 0], ext[:, 1])
    # The ground under the instance's largest node; its base where that is unknown.
    order = np.lexsort((-npts, at))
    g = gr[order[np.searchsorted(at[order], np.arange(m))]]
    g = np.where(np.isfinite(g), g, lo[:, 2])
    n_nodes = np.bincount(at, minlength=m).astype(np.float64)
    pairs = np.unique(np.c_[at, seg], axis=0) if m else np.zeros((0, 2), dtype=np.int64)
    n_segs = np.bincount(pairs[:, 0], minlength=m).astype(np.float64)
    min_depth = np.full(m, np.inf)
    np.minimum.at(min_depth, at, dep)
    onehot = (cls[first][:, None] == np.asarray(_ELEMENTS)[None, :]).astype(np.float64)
    known = np.isfinite(sh).all(axis=1)
    wsum = np.bincount(at[known], weights=npts[known], minlength=m)
    shape_mean = np.full((m, nsh), -1.0)
    for j in range(nsh):
        col = np.bincount(at[known], weights=npts[known] * sh[known, j], minlength=m)
        shape_mean[:, j] = np.where(wsum > 0, col / np.maximum(wsum, 1e-12), -1.0)

    def log10(v: FloatArray) -> FloatArray:
        return np.log10(v + 1e-3)

    f = np.column_stack([onehot, mean_score, np.log10(np.maximum(total, 1.0)), log10(ext[:, 2]), log10(long),
                         log10(short), short / np.maximum(long, 1e-3), lo[:, 2] - g, hi[:, 2] - g, n_nodes, n_segs,
                         min_depth, shape_mean])
    return ids, cls[first], f


@dataclass(frozen=True, eq=False)
class ElementCheck:
    """One :class:`VerifyModel` per element class (P(an element of that class)) and the
    threshold the most probable class must reach: ``class_thresholds`` of that class where
    it names one, else ``threshold``."""

    models: dict[int, VerifyModel]
    threshold: float = 0.5
    info: dict[str, Any] = field(default_factory=dict)
    class_thresholds: dict[int, float] = field(default_factory=dict)

    def thresholds(self) -> FloatArray:
        """The threshold of each :data:`_ELEMENTS` class, in order."""
        return np.asarray([self.class_thresholds.get(c, self.threshold) for c in _ELEMENTS], dtype=np.float64)

    def probabilities(self, features: npt.ArrayLike) -> FloatArray:
        """P(element of class) per row of ``features``, one column per :data:`_ELEMENTS` class."""
        f = np.atleast_2d(np.asarray(features, dtype=np.float64))
        return np.column_stack([self.models[c].probability(f[:, self.models[c].columns()]) if c in self.models
                                else np.zeros(len(f)) for c in _ELEMENTS]) if len(f) else np.zeros((0, len(_ELEMENTS)))

    def decide(self, features: npt.ArrayLike) -> IntArray:
        """The class of each instance: the most probable element class, or ``other``
        where no class reaches the threshold.

        >>> leaf = dict(feature=np.array([-2]), threshold=np.array([0.0]), left=np.array([-1]),
        ...             right=np.array([-1]), value=np.array([0.0]))
        >>> yes, no = (VerifyModel(init=v, learning_rate=0.1, trees=(leaf,)) for v in (3.0, -3.0))
        >>> check = ElementCheck({4: no, 5: yes, 6: no, 7: no})
        >>> check.decide(np.zeros((1, len(VERIFY_FEATURES)))).tolist()
        [5]
        >>> ElementCheck(check.models, class_thresholds={5: 0.99}).decide(np.zeros((1, len(VERIFY_FEATURES)))).tolist()
        [8]
        """
        p = self.probabilities(features)
        best = p.argmax(axis=1) if len(p) else np.zeros(0, dtype=np.int64)
        ok = p[np.arange(len(p)), best] >= self.thresholds()[best]
        return np.where(ok, np.asarray(_ELEMENTS)[best], int(ClassId.OTHER)).astype(np.int64)

    def to_dict(self) -> dict[str, Any]:
        d = {"version": 1, "threshold": self.threshold, "info": self.info,
             "models": {ClassId(c).label: m.to_dict() for c, m in self.models.items()}}
        if self.class_thresholds:
            d["class_thresholds"] = {ClassId(c).label: t for c, t in self.class_thresholds.items()}
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> ElementCheck:
        unknown = set(d) - {"version", "threshold", "info", "models", "class_thresholds"}
        if unknown:
            raise ValueError(f"unknown keys in an element check: {sorted(unknown)}")
        models = {int(class_id(k)): VerifyModel.from_dict(v) for k, v in d["models"].items()}
        per = {int(class_id(k)): float(v) for k, v in d.get("class_thresholds", {}).items()}
        return cls(models=models, threshold=float(d.get("threshold", 0.5)), info=dict(d.get("info", {})),
                   class_thresholds=per)

    def save(self, path: str | Path) -> None:
        Path(path).write_text(json.dumps(self.to_dict(), separators=(",", ":")) + "\n")


def load_verify_model(path: str | Path | None = None) -> ElementCheck:
    """Read an element check; the package's ``verify-v3.json`` by default (read once per
    process while the file's size and modification time stay the same)."""
    p = DEFAULT_VERIFY_PATH if path is None else Path(path).resolve()
    return _load(str(p), file_stamp(p))


@functools.lru_cache(maxsize=4)
def _load(path: str, stamp: tuple[int, int]) -> ElementCheck:
    """The check in ``path``; ``stamp`` (size, mtime) is part of the cache key only."""
    try:
        check = ElementCheck.from_dict(json.loads(Path(path).read_text()))
    except (OSError, ValueError, KeyError, TypeError) as e:
        reason = e.strerror if isinstance(e, OSError) and e.strerror else e
        raise ConfigError(f"{path} is not a readable element check: {reason}") from None
    if not all(math.isfinite(t) for t in (check.threshold, *check.class_thresholds.values())):
        raise ConfigError(f"{path}: the element check's threshold is not a number")
    if set(check.class_thresholds) - set(_ELEMENTS):
        raise ConfigError(f"{path}: class_thresholds names a class that is not an element class")
    return check
