"""The split decision: a learned classifier of proposals (replaces ``xi >= threshold``).

The paper keeps a node's best proposal when its energy ``xi = w . e`` passes a threshold.
Fitted on the element groups the tree meets at run time, the five terms explain almost
nothing of whether a split is right (R^2 0.06, docs/decisions/method.md "Rejected: the paper's
linear energy as the split decision"): a score of population balance, size, child count, a class prior and the mean
child score cannot tell a storey of bays from half a dome. The split model adds what the
decision needs, all of it computed from the node, the proposal and HollowNet's
probabilities of the node and of each child (:func:`split_features`):

- the paper's terms e1, e3 and e5 (e2 and e4 are folded into the parent's size and class
  probabilities, which are features themselves);
- whether the children agree with each other and with the parent (the share of the
  children's points whose predicted class is the children's most common class, and the
  parent's; the children's mean probability of the parent's class), and how many of them
  are elements;
- how regular the cuts are (an arcade's bays repeat; the spacing's coefficient of
  variation) and the children's size spread;
- the parent's extent and HollowNet's probabilities of the parent and, weighted by size,
  of the children; the sequence (S1, S2, S3 or the storeys) and the node's depth.

The model is a small ensemble of regression trees (gradient boosting, sklearn's
``GradientBoostingClassifier``), stored as plain arrays in a versioned JSON file
(``tree/data/split-v1.json``) and evaluated here with NumPy, so running the tree needs
neither sklearn nor pickles. A node keeps its proposal of highest probability when that
probability reaches the model's threshold. :mod:`tree.fit_split` makes the file.
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

from hollowtree.arrays import FloatArray
from hollowtree.classes import CLASS_NAMES, ELEMENT_CLASSES, NUM_CLASSES
from hollowtree.errors import ConfigError

__all__ = ["DEFAULT_SPLIT_PATH", "FEATURE_NAMES", "N_PROBS", "SplitModel", "file_stamp", "load_split_model",
           "split_features"]

#: The split model shipped with the package.
DEFAULT_SPLIT_PATH = Path(__file__).resolve().parent / "data" / "split-v1.json"

_ELEMENT_IDS = np.asarray(sorted(int(c) for c in ELEMENT_CLASSES))
#: Width of the classifier's probability rows: HollowNet predicts every class but
#: "unclassified" (``hollownet.model.OUTPUT_CLASSES``, in id order).
N_PROBS = NUM_CLASSES - 1

#: Names of the columns of :func:`split_features`, in order.
FEATURE_NAMES: tuple[str, ...] = (
    ("log10_n_parent", "n_children", "e1", "e3", "size_cv", "parent_score", "e5", "min_child_score",
     "children_agree", "children_element", "children_as_parent", "children_p_parent_class",
     "cut_spacing_cv", "log10_extent_long", "log10_extent_short", "log10_extent_z", "depth",
     "seq_s1", "seq_s2", "seq_s3", "seq_storeys")
    + tuple(f"p_parent_{name}" for name in CLASS_NAMES[1:])
    + tuple(f"p_children_{name}" for name in CLASS_NAMES[1:])
)


def split_features(
    *,
    n_parent: int,
    extent: npt.ArrayLike,
    depth: int,
    key: int,
    parent_class: int,
    parent_probs: npt.ArrayLike,
    child_sizes: npt.ArrayLike,
    child_classes: npt.ArrayLike,
    child_probs: npt.ArrayLike,
    cuts: npt.ArrayLike,
) -> FloatArray:
    """The feature vector of one proposal (:data:`FEATURE_NAMES`).

    Parameters
    ----------
    n_parent : int
        Points of the node.
    extent : array-like of 3 floats
        The node's extent along x, y and z (metres).
    depth : int
        The node's depth in the tree (the root is 0).
    key : int
        The proposal: 1, 2, 3 (S1, S2, S3) or 4 (the storeys, :func:`tree.sequences.storeys`).
    parent_class : int
        The classifier's class id of the node.
    parent_probs : array-like of shape (K,)
        The classifier's probabilities of the node, K = :data:`N_PROBS` (HollowNet's
        outputs, every class but "unclassified" in id order).
    child_sizes : array-like of shape (s,)
    child_classes : array-like of shape (s,)
        Class ids of the children.
    child_probs : array-like of shape (s, K)
    cuts : array-like
        The proposal's cut positions.

    Examples
    --------
    >>> wall, arch = np.eye(8)[1], np.eye(8)[3]          # class ids 2 and 4
    >>> f = split_features(n_parent=3000, extent=[10, 1, 5], depth=0, key=2, parent_class=2,
    ...                    parent_probs=wall, child_sizes=[1000, 1000, 1000], child_classes=[4, 4, 4],
    ...                    child_probs=np.tile(arch, (3, 1)), cuts=[3.3, 6.6])
    >>> len(f) == len(FEATURE_NAMES), float(dict(zip(FEATURE_NAMES, f))["children_element"])
    (True, 1.0)
    """
    sizes = np.asarray(child_sizes, dtype=np.float64)
    pp = np.asarray(parent_probs, dtype=np.float64).reshape(-1)
    cp = np.asarray(child_probs, dtype=np.float64).reshape(len(sizes), -1)
    if len(pp) != N_PROBS or cp.shape[1] != N_PROBS:
        raise ValueError(f"split_features needs probability rows of {N_PROBS} classes; got {len(pp)} and {cp.shape[1]}")
    n = float(n_parent)
    s = len(sizes)
    wts = sizes / sizes.sum()
    cls = np.asarray(child_classes, dtype=np.int64).reshape(-1)
    cmax = cp.max(axis=1)
    mode = np.bincount(cls, weights=wts, minlength=NUM_CLASSES)
    pcls = int(parent_class)
    pcol = int(pp.argmax())
    ref = float(np.std([1.0, n - 1.0]))
    e1 = 1.0 - float(np.std(sizes)) / ref if ref > 0 else 1.0
    gaps = np.diff(np.sort(np.asarray(cuts, dtype=np.float64)))
    cv_gap = float(gaps.std() / gaps.mean()) if len(gaps) >= 2 and gaps.mean() > 0 else -1.0
    ext = np.asarray(extent, dtype=np.float64)
    hz = np.sort(ext[:2])
    seq = np.zeros(4)
    seq[int(key) - 1] = 1.0
    head = [math.log10(n), s, e1, 1.0 - math.exp(-0.5 * (s - 1) ** 2), float(sizes.std() / sizes.mean()),
            float(pp.max()), float(wts @ cmax), float(cmax.min()), float(mode.max()),
            float(wts @ np.isin(cls, _ELEMENT_IDS)), float(wts[cls == pcls].sum()), float(wts @ cp[:, pcol]),
            cv_gap, math.log10(hz[1] + 1e-3), math.log10(hz[0] + 1e-3), math.log10(ext[2] + 1e-3),
            float(depth)]
    return np.concatenate([head, seq, pp, wts @ cp])


@dataclass(frozen=True, kw_only=True, eq=False)
class SplitModel:
    """Gradient-boosted regression trees giving P(split is right | features).

    ``raw = init + learning_rate * sum(tree(x))``, ``P = 1 / (1 + exp(-raw))``; each tree
    is sklearn's ``tree_`` arrays (``feature`` -2 marks a leaf; ``x[feature] <=
    threshold`` goes left).
    """

    #: The feature columns the model must have been fitted on, and how to refit it.
    FEATURES: ClassVar[tuple[str, ...]] = FEATURE_NAMES
    REFIT: ClassVar[str] = "refit it with `hollowtree fit-split`"

    init: float
    learning_rate: float
    trees: tuple[dict[str, np.ndarray], ...]
    threshold: float = 0.5
    feature_names: tuple[str, ...] = ()
    version: int = 1
    info: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not self.feature_names:
            object.__setattr__(self, "feature_names", self.FEATURES)
        if not self._known_features(tuple(self.feature_names)):
            raise ValueError(f"this {type(self).__name__} was made for other features "
                             f"({len(self.feature_names)} columns); {self.REFIT}")
        # All trees as one set of arrays (children as global node indices), walked together.
        sizes = [len(t["feature"]) for t in self.trees]
        offsets = np.r_[0, np.cumsum(sizes)].astype(np.int64)
        def cat(key: str, dtype: type) -> np.ndarray:
            if not self.trees:
                return np.zeros(0, dtype=dtype)
            return np.concatenate([np.asarray(t[key], dtype=dtype) for t in self.trees])

        shift = np.repeat(offsets[:-1], sizes)
        left, right = cat("left", np.int64), cat("right", np.int64)
        flat = {"feature": cat("feature", np.int64), "threshold": cat("threshold", np.float64),
                "left": np.where(left >= 0, left + shift, -1), "right": np.where(right >= 0, right + shift, -1),
                "value": cat("value", np.float64), "roots": offsets[:-1]}
        object.__setattr__(self, "_flat", flat)

    @classmethod
    def _known_features(cls, names: tuple[str, ...]) -> bool:
        """Whether a model of these feature columns can be used (here: exactly :attr:`FEATURES`)."""
        return names == cls.FEATURES

    def probability(self, x: npt.ArrayLike) -> FloatArray:
        """P(right) for each row of ``x`` (shape (n, n_features) or (n_features,)).

        >>> leaf = dict(feature=np.array([-2]), threshold=np.array([0.0]), left=np.array([-1]),
        ...             right=np.array([-1]), value=np.array([0.0]))
        >>> SplitModel(init=0.0, learning_rate=0.1, trees=(leaf,)).probability(np.zeros(37)).tolist()
        [0.5]
        """
        a = np.atleast_2d(np.asarray(x, dtype=np.float64))
        t = self._flat  # type: ignore[attr-defined]
        at = np.broadcast_to(t["roots"], (len(a), len(t["roots"]))).copy()  # (rows, trees)
        rows = np.arange(len(a))[:, None]
        while at.size:
            f = t["feature"][at]
            inner = f >= 0
            if not inner.any():
                break
            go_left = a[rows, np.maximum(f, 0)] <= t["threshold"][at]
            at = np.where(inner, np.where(go_left, t["left"][at], t["right"][at]), at)
        raw = self.init + self.learning_rate * t["value"][at].sum(axis=1)
        return 1.0 / (1.0 + np.exp(-raw))

    def to_dict(self) -> dict[str, Any]:
        return {
            "version": self.version, "init": self.init, "learning_rate": self.learning_rate,
            "threshold": self.threshold, "feature_names": list(self.feature_names), "info": self.info,
            "trees": [{k: v.tolist() for k, v in t.items()} for t in self.trees],
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Any:
        unknown = set(d) - {"version", "init", "learning_rate", "threshold", "feature_names", "info", "trees"}
        if unknown:
            raise ValueError(f"unknown keys in a {cls.__name__}: {sorted(unknown)}")
        trees = tuple(
            {"feature": np.asarray(t["feature"], dtype=np.int64), "threshold": np.asarray(t["threshold"], dtype=np.float64),
             "left": np.asarray(t["left"], dtype=np.int64), "right": np.asarray(t["right"], dtype=np.int64),
             "value": np.asarray(t["value"], dtype=np.float64)}
            for t in d["trees"])
        return cls(init=float(d["init"]), learning_rate=float(d["learning_rate"]), trees=trees,
                   threshold=float(d.get("threshold", 0.5)), feature_names=tuple(d["feature_names"]),
                   version=int(d.get("version", 1)), info=dict(d.get("info", {})))

    @classmethod
    def from_sklearn(cls, model: Any, *, threshold: float = 0.5, info: dict[str, Any] | None = None) -> Any:
        """From a fitted binary ``sklearn.ensemble.GradientBoostingClassifier``."""
        p0 = float(model.init_.class_prior_[1]) if hasattr(model.init_, "class_prior_") else float("nan")
        if not 0.0 < p0 < 1.0:
            raise ValueError("the gradient boosting model must be fitted with the default prior init")
        trees = []
        for est in model.estimators_[:, 0]:
            t = est.tree_
            trees.append({"feature": np.where(t.children_left < 0, -2, t.feature).astype(np.int64),
                          "threshold": t.threshold.astype(np.float64), "left": t.children_left.astype(np.int64),
                          "right": t.children_right.astype(np.int64), "value": t.value[:, 0, 0].astype(np.float64)})
        return cls(init=math.log(p0 / (1.0 - p0)), learning_rate=float(model.learning_rate), trees=tuple(trees),
                   threshold=threshold, info=dict(info or {}))

    def save(self, path: str | Path) -> None:
        Path(path).write_text(json.dumps(self.to_dict(), separators=(",", ":")) + "\n")


def load_split_model(path: str | Path | None = None) -> SplitModel:
    """Read a split model; the package's ``split-v1.json`` by default (read once per
    process while the file's size and modification time stay the same: every tree task
    asks for it)."""
    p = DEFAULT_SPLIT_PATH if path is None else Path(path).resolve()
    return _load(str(p), file_stamp(p))


def file_stamp(path: Path) -> tuple[int, int]:
    """A file's size and modification time (ns): the part of a loader's cache key that has
    a file rewritten in place read again; (-1, -1) where it cannot be read (the loader then
    says why)."""
    try:
        st = path.stat()
    except OSError:
        return -1, -1
    return st.st_size, st.st_mtime_ns


@functools.lru_cache(maxsize=4)
def _load(path: str, stamp: tuple[int, int]) -> SplitModel:
    """The split model in ``path``; ``stamp`` (size, mtime) is part of the cache key only."""
    try:
        return SplitModel.from_dict(json.loads(Path(path).read_text()))
    except (OSError, ValueError, KeyError, TypeError, IndexError) as e:
        reason = e.strerror if isinstance(e, OSError) and e.strerror else e
        raise ConfigError(f"{path} is not a readable split model: {reason}") from None
