"""Segmentation scores against per-point ground truth: the paper's Table 1 and more.

Pure NumPy (no dask, zarr, laspy or yaml): the labels arrive as plain arrays, in the same
point order for the ground truth and for the prediction.

* **Instances** are ``(class, instance id)`` pairs with an id > 0; id 0 means "no
  instance". A predicted instance whose points carry several classes counts as one
  instance per class.
* **Found** (the paper's AG): a ground-truth instance of class ``c`` is found when a
  predicted instance of class ``c`` covers it with point IoU
  ``|G & P| / |G | P| >= iou_threshold`` (0.5, ``../shared/METHOD.md``). Matching is
  one-to-one and **greedy by IoU** (highest IoU pair first, each ground-truth and each
  predicted instance used at most once). At a threshold of 0.5 this equals Hungarian
  matching: predicted instances are disjoint point sets, so a ground-truth instance can
  have two candidates above 0.5 only in the tie IoU == 0.5 exactly.
* **Accuracy %** = found / GT (None, printed NA, when GT = 0); **precision %** = matched
  predicted instances / predicted instances of the class (None when there are none): every
  unmatched predicted instance, however small, is a false instance.
* **Point IoU %** per class is the semantic IoU over points, ``TP / (TP + FP + FN)`` from
  the confusion matrix; the **mean IoU** averages it over the classes present in the
  ground truth (class 0, unclassified, excluded).

Large scans are scored in pieces: :func:`count_labels` reduces a chunk of points to
:class:`LabelCounts` (a confusion matrix and instance and overlap counts, whose size
depends on the number of instances, not of points), :meth:`LabelCounts.merge` adds the
counts of two chunks, and :func:`score_counts` turns the total into an
:class:`Evaluation`. :func:`evaluate_labels` does all three for arrays in memory.

Examples
--------
>>> gt_c = np.array([5, 5, 5, 6, 6, 2])
>>> gt_i = np.array([1, 1, 1, 2, 2, 3])
>>> ev = evaluate_labels(gt_c, gt_i, gt_c, gt_i)
>>> ev.score("dome").n_found, ev.score("dome").accuracy_pct, ev.mean_iou_pct
(1, 100.0, 100.0)
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from hollowtree.classes import CLASS_NAMES, NUM_CLASSES, class_id

__all__ = ["LOSS_BUCKETS", "VISIBLE_POINTS", "LabelCounts", "ClassScore", "Evaluation", "count_labels", "evaluate_labels", "loss_buckets",
           "score_counts"]

_U64 = npt.NDArray[np.uint64]
_I64 = npt.NDArray[np.int64]
#: A ground-truth element of fewer points than this is one the scan hardly shows
#: (:func:`loss_buckets` calls it tiny); :class:`ClassScore` also counts the others apart.
VISIBLE_POINTS = 100
#: Instance ids must stay below this so that ``id * num_classes + class`` fits in uint64.
_MAX_INSTANCE = 2**58


def _sum_by(keys: _U64, counts: _I64) -> tuple[_U64, _I64]:
    """Unique keys (sorted) and the sum of ``counts`` of each."""
    if not len(keys):
        return np.zeros(0, np.uint64), np.zeros(0, np.int64)
    uk, inv = np.unique(keys, return_inverse=True)
    return uk, np.bincount(inv.reshape(-1), weights=counts, minlength=len(uk)).astype(np.int64)


def _sum_pairs(a: _U64, b: _U64, counts: _I64) -> tuple[_U64, _U64, _I64]:
    """Unique ``(a, b)`` pairs and the sum of ``counts`` of each (np.unique on pair codes)."""
    if not len(a):
        return np.zeros(0, np.uint64), np.zeros(0, np.uint64), np.zeros(0, np.int64)
    ua, ia = np.unique(a, return_inverse=True)
    ub, ib = np.unique(b, return_inverse=True)
    code = ia.reshape(-1).astype(np.int64) * len(ub) + ib.reshape(-1)
    uc, inv = np.unique(code, return_inverse=True)
    total = np.bincount(inv.reshape(-1), weights=counts, minlength=len(uc)).astype(np.int64)
    return ua[uc // len(ub)], ub[uc % len(ub)], total


@dataclass(frozen=True, kw_only=True, eq=False)
class LabelCounts:
    """What scoring needs from a set of points; chunks of a scan add up with :meth:`merge`.

    Instance keys are ``instance_id * num_classes + class`` (uint64), sorted and unique.

    Attributes
    ----------
    num_classes : int
    n_points : int
    confusion : ndarray of shape (num_classes, num_classes), int64
        ``confusion[g, p]`` points of ground-truth class ``g`` predicted as ``p``.
    gt_keys, gt_sizes : ndarray of shape (n_gt,)
        Ground-truth instances and their point counts.
    pred_keys, pred_sizes : ndarray of shape (n_pred,)
        Predicted instances and their point counts.
    pair_gt, pair_pred, pair_count : ndarray of shape (n_pairs,)
        Points shared by a ground-truth and a predicted instance of the same class.
    """

    num_classes: int
    n_points: int
    confusion: _I64
    gt_keys: _U64
    gt_sizes: _I64
    pred_keys: _U64
    pred_sizes: _I64
    pair_gt: _U64
    pair_pred: _U64
    pair_count: _I64

    @classmethod
    def empty(cls, num_classes: int = NUM_CLASSES) -> LabelCounts:
        """Counts of no points (the start of a sum over chunks)."""
        z64, zu = np.zeros(0, np.int64), np.zeros(0, np.uint64)
        return cls(num_classes=num_classes, n_points=0, confusion=np.zeros((num_classes, num_classes), np.int64),
                   gt_keys=zu, gt_sizes=z64, pred_keys=zu, pred_sizes=z64, pair_gt=zu, pair_pred=zu, pair_count=z64)

    def merge(self, other: LabelCounts) -> LabelCounts:
        """The counts of both sets of points (disjoint sets: chunks of one scan)."""
        if other.num_classes != self.num_classes:
            raise ValueError(f"cannot merge counts of {self.num_classes} and {other.num_classes} classes")
        gk, gs = _sum_by(np.r_[self.gt_keys, other.gt_keys], np.r_[self.gt_sizes, other.gt_sizes])
        pk, ps = _sum_by(np.r_[self.pred_keys, other.pred_keys], np.r_[self.pred_sizes, other.pred_sizes])
        a, b, c = _sum_pairs(np.r_[self.pair_gt, other.pair_gt], np.r_[self.pair_pred, other.pair_pred],
                             np.r_[self.pair_count, other.pair_count])
        return LabelCounts(num_classes=self.num_classes, n_points=self.n_points + other.n_points,
                           confusion=self.confusion + other.confusion, gt_keys=gk, gt_sizes=gs,
                           pred_keys=pk, pred_sizes=ps, pair_gt=a, pair_pred=b, pair_count=c)


def _as_labels(name: str, a: npt.ArrayLike, n: int | None) -> npt.NDArray[Any]:
    arr = np.asarray(a)
    if arr.ndim != 1 or (n is not None and len(arr) != n):
        want = "(n_points,)" if n is None else f"({n},) like gt_class"
        raise ValueError(f"The '{name}' parameter of count_labels must be an array of shape {want}. "
                         f"Got shape {arr.shape} instead.")
    if arr.dtype.kind not in "iub":
        raise ValueError(f"The '{name}' parameter of count_labels must hold integers. Got {arr.dtype} instead.")
    if len(arr) and arr.dtype.kind == "i" and int(arr.min()) < 0:
        raise ValueError(f"The '{name}' parameter of count_labels must be >= 0. Got {int(arr.min())} instead.")
    return arr


def count_labels(
    gt_class: npt.ArrayLike, gt_instance: npt.ArrayLike, pred_class: npt.ArrayLike, pred_instance: npt.ArrayLike,
    *, num_classes: int = NUM_CLASSES,
) -> LabelCounts:
    """Reduce per-point labels to the counts that :func:`score_counts` needs.

    Parameters
    ----------
    gt_class, pred_class : array-like of shape (n_points,), integers in [0, num_classes)
    gt_instance, pred_instance : array-like of shape (n_points,), integers >= 0
        0 = no instance. Ids are per scan; they need not be consecutive.
    num_classes : int

    Returns
    -------
    LabelCounts

    Notes
    -----
    O(n log n) (``np.unique`` on uint64 keys and on pair codes), no Python loop over points.
    Memory: about 40 bytes per point for the temporary keys; call it on chunks of a few
    million points and :meth:`LabelCounts.merge` the results for larger scans.

    Examples
    --------
    >>> c = count_labels([5, 5, 6], [1, 1, 2], [5, 6, 6], [7, 8, 8])
    >>> c.confusion[5, 6], c.gt_sizes.tolist(), c.pair_count.tolist()
    (np.int64(1), [2, 1], [1, 1])
    """
    gc = _as_labels("gt_class", gt_class, None)
    n = len(gc)
    gi = _as_labels("gt_instance", gt_instance, n)
    pc = _as_labels("pred_class", pred_class, n)
    pi = _as_labels("pred_instance", pred_instance, n)
    k = int(num_classes)
    for name, arr in (("gt_class", gc), ("pred_class", pc)):
        if len(arr) and int(arr.max()) >= k:
            raise ValueError(f"The '{name}' parameter of count_labels must be in the range [0, {k}). "
                             f"Got {int(arr.max())} instead.")
    for name, arr in (("gt_instance", gi), ("pred_instance", pi)):
        if len(arr) and int(arr.max()) >= _MAX_INSTANCE:
            raise ValueError(f"The '{name}' parameter of count_labels must be < 2**58. Got {int(arr.max())} instead.")
    gc64, pc64 = gc.astype(np.int64), pc.astype(np.int64)
    confusion = np.bincount(gc64 * k + pc64, minlength=k * k).reshape(k, k).astype(np.int64)
    kk = np.uint64(k)
    gkey = gi.astype(np.uint64) * kk + gc64.astype(np.uint64)
    pkey = pi.astype(np.uint64) * kk + pc64.astype(np.uint64)
    g_in, p_in = gi > 0, pi > 0
    gk, gs = np.unique(gkey[g_in], return_counts=True)
    pk, ps = np.unique(pkey[p_in], return_counts=True)
    both = g_in & p_in & (gc64 == pc64)
    a, b, cnt = _sum_pairs(gkey[both], pkey[both], np.ones(int(both.sum()), np.int64))
    return LabelCounts(num_classes=k, n_points=n, confusion=confusion, gt_keys=gk.astype(np.uint64),
                       gt_sizes=gs.astype(np.int64), pred_keys=pk.astype(np.uint64), pred_sizes=ps.astype(np.int64),
                       pair_gt=a, pair_pred=b, pair_count=cnt)


def _pct(num: int, den: int) -> float | None:
    return None if den == 0 else 100.0 * num / den


@dataclass(frozen=True, kw_only=True)
class ClassScore:
    """The scores of one class (percentages; None where undefined, printed NA).

    ``n_gt``/``n_found``/``accuracy_pct`` are the paper's GT/AG/Acc columns;
    ``n_gt_visible``/``n_found_visible`` count only the ground-truth instances of at least
    :data:`VISIBLE_POINTS` points (None in scores saved before they were counted).
    """

    class_id: int
    name: str
    n_gt: int
    n_found: int
    accuracy_pct: float | None
    n_pred: int
    n_pred_matched: int
    precision_pct: float | None
    gt_points: int
    pred_points: int
    iou_pct: float | None
    n_gt_visible: int | None = None
    n_found_visible: int | None = None

    def to_dict(self) -> dict[str, Any]:
        return {k: getattr(self, k) for k in self.__dataclass_fields__}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> ClassScore:
        return cls(**dict(data))


@dataclass(frozen=True, kw_only=True)
class Evaluation:
    """Scores of one prediction against the ground truth of one scan.

    Attributes
    ----------
    classes : tuple of ClassScore
        Classes 1 .. num_classes - 1, in id order.
    mean_iou_pct : float or None
        Mean point IoU over the classes present in the ground truth.
    iou_threshold : float
    n_points : int
    matching : str
    """

    classes: tuple[ClassScore, ...]
    mean_iou_pct: float | None
    iou_threshold: float
    n_points: int
    matching: str = "greedy one-to-one by IoU"

    def score(self, name: str | int) -> ClassScore:
        """The :class:`ClassScore` of a class given by name or id."""
        cid = int(class_id(name)) if isinstance(name, str) else int(name)
        for c in self.classes:
            if c.class_id == cid:
                return c
        raise KeyError(f"class {name!r} is not in this evaluation")

    def to_dict(self) -> dict[str, Any]:
        return {"n_points": self.n_points, "iou_threshold": self.iou_threshold, "matching": self.matching,
                "mean_iou_pct": self.mean_iou_pct, "classes": {c.name: c.to_dict() for c in self.classes}}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Evaluation:
        return cls(classes=tuple(ClassScore.from_dict(c) for c in data["classes"].values()),
                   mean_iou_pct=data["mean_iou_pct"], iou_threshold=float(data["iou_threshold"]),
                   n_points=int(data["n_points"]), matching=str(data["matching"]))


def _greedy_matches(pair_gt: _U64, pair_pred: _U64, iou: npt.NDArray[np.float64], threshold: float) -> _I64:
    """Indices of the pairs kept by one-to-one matching, highest IoU first."""
    cand = np.flatnonzero(iou >= threshold)
    cand = cand[np.argsort(-iou[cand], kind="stable")]
    used_g: set[int] = set()
    used_p: set[int] = set()
    keep = []
    for j in cand.tolist():  # a loop over candidate pairs (about one per found instance)
        g, p = int(pair_gt[j]), int(pair_pred[j])
        if g in used_g or p in used_p:
            continue
        used_g.add(g)
        used_p.add(p)
        keep.append(j)
    return np.asarray(keep, dtype=np.int64)


def score_counts(counts: LabelCounts, *, iou_threshold: float = 0.5) -> Evaluation:
    """Per-class instance and point scores from :class:`LabelCounts` (see the module notes).

    Examples
    --------
    >>> ev = score_counts(count_labels([4, 4, 4, 4], [1, 1, 1, 1], [4, 4, 4, 4], [1, 1, 2, 2]))
    >>> a = ev.score("arch")
    >>> a.n_gt, a.n_found, a.n_pred, a.precision_pct, a.iou_pct
    (1, 1, 2, 50.0, 100.0)
    >>> a.n_gt_visible, a.n_found_visible  # an arch of 4 points: under VISIBLE_POINTS
    (0, 0)
    """
    if not 0.0 < iou_threshold <= 1.0:
        raise ValueError(f"The 'iou_threshold' parameter of score_counts must be a float in the range (0.0, 1.0]. "
                         f"Got {iou_threshold!r} instead.")
    k = counts.num_classes
    kk = np.uint64(k)
    g_size = counts.gt_sizes[np.searchsorted(counts.gt_keys, counts.pair_gt)] if len(counts.pair_gt) else np.zeros(0)
    p_size = counts.pred_sizes[np.searchsorted(counts.pred_keys, counts.pair_pred)] if len(counts.pair_gt) else np.zeros(0)
    inter = counts.pair_count.astype(np.float64)
    iou = inter / np.maximum(g_size + p_size - inter, 1.0)
    kept = _greedy_matches(counts.pair_gt, counts.pair_pred, iou, iou_threshold)
    matched_class = (counts.pair_gt[kept] % kk).astype(np.int64)
    found = np.bincount(matched_class, minlength=k)
    n_gt = np.bincount((counts.gt_keys % kk).astype(np.int64), minlength=k)
    visible = counts.gt_sizes >= VISIBLE_POINTS
    n_gt_vis = np.bincount((counts.gt_keys[visible] % kk).astype(np.int64), minlength=k)
    g_vis = counts.gt_sizes[np.searchsorted(counts.gt_keys, counts.pair_gt[kept])] >= VISIBLE_POINTS
    found_vis = np.bincount(matched_class[g_vis], minlength=k)
    n_pred = np.bincount((counts.pred_keys % kk).astype(np.int64), minlength=k)
    conf = counts.confusion
    tp = np.diag(conf)
    gt_pts, pred_pts = conf.sum(axis=1), conf.sum(axis=0)
    union = gt_pts + pred_pts - tp
    rows = []
    for c in range(1, k):
        rows.append(ClassScore(
            class_id=c, name=CLASS_NAMES[c] if c < len(CLASS_NAMES) else str(c), n_gt=int(n_gt[c]),
            n_found=int(found[c]), accuracy_pct=_pct(int(found[c]), int(n_gt[c])), n_pred=int(n_pred[c]),
            n_pred_matched=int(found[c]), precision_pct=_pct(int(found[c]), int(n_pred[c])),
            gt_points=int(gt_pts[c]), pred_points=int(pred_pts[c]), iou_pct=_pct(int(tp[c]), int(union[c])),
            n_gt_visible=int(n_gt_vis[c]), n_found_visible=int(found_vis[c])))
    present = [r.iou_pct for r in rows if r.gt_points > 0 and r.iou_pct is not None]
    mean = float(np.mean(present)) if present else None
    return Evaluation(classes=tuple(rows), mean_iou_pct=mean, iou_threshold=float(iou_threshold),
                      n_points=counts.n_points)


def evaluate_labels(
    gt_class: npt.ArrayLike, gt_instance: npt.ArrayLike, pred_class: npt.ArrayLike, pred_instance: npt.ArrayLike,
    *, iou_threshold: float = 0.5, num_classes: int = NUM_CLASSES,
) -> Evaluation:
    """Score per-point predicted labels against the ground truth (arrays in memory).

    Parameters
    ----------
    gt_class, gt_instance, pred_class, pred_instance : array-like of shape (n_points,)
        As in :func:`count_labels`, in the same point order.
    iou_threshold : float
        A ground-truth instance is found by a predicted one of its class with IoU >= this.

    Returns
    -------
    Evaluation

    Examples
    --------
    Three minarets merged into one predicted instance (IoU 1/3 with each): none found.

    >>> ev = evaluate_labels([6] * 6, [1, 1, 2, 2, 3, 3], [6] * 6, [9] * 6)
    >>> m = ev.score("minaret")
    >>> m.n_gt, m.n_found, m.accuracy_pct, m.precision_pct, m.iou_pct
    (3, 0, 0.0, 0.0, 100.0)
    """
    counts = count_labels(gt_class, gt_instance, pred_class, pred_instance, num_classes=num_classes)
    return score_counts(counts, iou_threshold=iou_threshold)


#: Where :func:`loss_buckets` puts a ground-truth element, in the order it tries them.
LOSS_BUCKETS: tuple[str, ...] = ("found", "tiny", "wrong class", "leaves, not grouped", "coarse fragments",
                                 "not cut out")


def _best_overlap(keys: npt.NDArray[np.int64], member: npt.NDArray[np.bool_],
                  size_of: Mapping[int, int]) -> tuple[float, int]:
    """Best IoU of the ``member`` points with any group of ``keys`` (key 0 is no group)."""
    k, n = np.unique(keys[member], return_counts=True)
    m = int(member.sum())
    best, arg = 0.0, 0
    for key, inter in zip(k.tolist(), n.tolist(), strict=True):
        if key:
            iou = inter / (m + size_of[key] - inter)
            if iou > best:
                best, arg = iou, int(key)
    return best, arg


def _sizes(keys: npt.NDArray[np.int64]) -> dict[int, int]:
    """Points per key."""
    k, c = np.unique(keys, return_counts=True)
    return dict(zip(k.tolist(), c.tolist(), strict=True))


def _instances(cls: npt.NDArray[np.int64], inst: npt.NDArray[np.int64],
               classes: tuple[int, ...]) -> Iterator[tuple[int, int, npt.NDArray[np.bool_], int]]:
    """Every instance of ``classes`` (instance 0 is none): its class, its id, the mask of its
    points and their count."""
    for c in classes:
        for e in np.unique(inst[(cls == c) & (inst > 0)]).tolist():
            member = (cls == c) & (inst == e)
            yield c, e, member, int(member.sum())


def loss_buckets(
    gt_class: npt.ArrayLike, gt_instance: npt.ArrayLike, pred_class: npt.ArrayLike,
    pred_instance: npt.ArrayLike, coarse: npt.ArrayLike, leaf: npt.ArrayLike, *,
    classes: tuple[int, ...], tiny: int = VISIBLE_POINTS, iou_threshold: float = 0.5,
) -> list[dict[str, Any]]:
    """Where each ground-truth element of ``classes`` was lost, if it was.

    Each element goes to the first of :data:`LOSS_BUCKETS` that holds:

    ``found``
        a predicted instance of its class covers it (IoU >= ``iou_threshold``);
    ``tiny``
        it has fewer than ``tiny`` points;
    ``wrong class``
        a predicted instance or a tree leaf of any class covers it: the pieces were cut
        right, the class (or an ancestor's class the leaf inherited) was wrong;
    ``leaves, not grouped``
        leaves lying mostly (over half their points) inside it cover half of it: it was
        cut out in pieces that were never joined;
    ``coarse fragments``
        no coarse segment holds half of its points;
    ``not cut out``
        one coarse segment holds most of it, and nothing separated it from the rest.

    Parameters
    ----------
    gt_class, gt_instance : array-like of int, shape (n_points,)
        Ground truth; instance 0 is no instance.
    pred_class, pred_instance : array-like of int, shape (n_points,)
        The run's labels (instance ids are per class space; 0 is none).
    coarse, leaf : array-like of int, shape (n_points,)
        The coarse segment (0: none) and a key unique per tree leaf (0: none).
    classes : tuple of int
        The element classes to look at.

    Returns
    -------
    list of dict
        One per element: ``class``, ``instance``, ``points``, ``bucket``, the best IoU
        with an instance of its class, of any class and with a leaf, the predicted class
        of the best instance (or of most of its points), the share of it in its main
        coarse segment and its share of that segment.

    Examples
    --------
    >>> gc = np.r_[np.full(4, 4), np.full(6, 2)]; gi = np.r_[np.ones(4, int), np.zeros(6, int)]
    >>> [r["bucket"] for r in loss_buckets(gc, gi, gc, gi, np.ones(10), np.ones(10), classes=(4,), tiny=1)]
    ['found']
    >>> [r["bucket"] for r in loss_buckets(gc, gi, np.full(10, 2), np.zeros(10), np.ones(10), np.ones(10),
    ...                                    classes=(4,), tiny=1)]
    ['not cut out']
    """
    gcls, ginst = np.asarray(gt_class, np.int64), np.asarray(gt_instance, np.int64)
    pcls, pinst = np.asarray(pred_class, np.int64), np.asarray(pred_instance, np.int64)
    seg, lf = np.asarray(coarse, np.int64), np.asarray(leaf, np.int64)
    pkey = np.where(pinst > 0, pinst * 256 + pcls, 0)

    s_pkey, s_leaf, s_seg = _sizes(pkey), _sizes(lf), _sizes(seg)
    out: list[dict[str, Any]] = []
    for c, e, member, m in _instances(gcls, ginst, classes):
        iou_same, _ = _best_overlap(np.where(pcls == c, pkey, 0), member, s_pkey)
        iou_any, key_any = _best_overlap(pkey, member, s_pkey)
        iou_leaf, _ = _best_overlap(lf, member, s_leaf)
        sk, sn = np.unique(seg[member], return_counts=True)
        main, share = int(sk[np.argmax(sn)]), float(sn.max() / m)
        lk, ln = np.unique(lf[member], return_counts=True)
        inside = sum(x for k, x in zip(lk.tolist(), ln.tolist(), strict=True) if k and x > 0.5 * s_leaf[k])
        if iou_same >= iou_threshold:
            bucket = "found"
        elif m < tiny:
            bucket = "tiny"
        elif max(iou_any, iou_leaf) >= iou_threshold:
            bucket = "wrong class"
        elif inside >= 0.5 * m:
            bucket = "leaves, not grouped"
        elif share < 0.5 or main == 0:
            bucket = "coarse fragments"
        else:
            bucket = "not cut out"
        got = key_any % 256 if key_any else int(np.bincount(pcls[member]).argmax())
        out.append({"class": int(c), "instance": int(e), "points": m, "bucket": bucket,
                    "iou_same": round(iou_same, 3), "iou_any": round(iou_any, 3), "iou_leaf": round(iou_leaf, 3),
                    "predicted": int(got), "coarse_share": round(share, 3),
                    "share_of_segment": round(float(sn.max()) / s_seg[main], 3) if main else 0.0})
    return out


def false_positives(
    gt_class: npt.ArrayLike, gt_instance: npt.ArrayLike, pred_class: npt.ArrayLike,
    pred_instance: npt.ArrayLike, *, classes: tuple[int, ...], iou_threshold: float = 0.5,
) -> list[dict[str, Any]]:
    """What each predicted element instance that matches no element of its class holds.

    Parameters
    ----------
    gt_class, gt_instance, pred_class, pred_instance : array-like of int, shape (n_points,)
        Ground truth and the run's labels, as in :func:`loss_buckets`.
    classes : tuple of int
        The element classes whose predictions are looked at.

    Returns
    -------
    list of dict
        One per unmatched prediction: ``class``, ``points``, ``truth`` (the ground-truth
        class of most of its points), ``share`` (the share of its points in the one
        ground-truth instance it overlaps most; 0 where that is no instance), ``instance``
        (that instance, 0 for none) and ``kind``:
        ``piece`` (most of it lies in one element of its own class: a fragment or a
        duplicate), ``other element`` (most of it lies in one element of another class),
        ``no element`` (most of it is wall, roof, ground, clutter or unlabelled) or
        ``mixed``.

    Examples
    --------
    >>> gc = np.r_[np.full(4, 4), np.full(6, 8)]; gi = np.r_[np.ones(4, int), np.zeros(6, int)]
    >>> [(r["kind"], r["truth"]) for r in false_positives(gc, gi, np.full(10, 4), np.r_[np.ones(4), np.full(6, 2)],
    ...                                                  classes=(4,))]
    [('no element', 8)]
    """
    gcls, ginst = np.asarray(gt_class, np.int64), np.asarray(gt_instance, np.int64)
    pcls, pinst = np.asarray(pred_class, np.int64), np.asarray(pred_instance, np.int64)
    gkey = np.where(ginst > 0, ginst * 256 + gcls, 0)
    gsize = _sizes(gkey)
    out: list[dict[str, Any]] = []
    for c, _, member, m in _instances(pcls, pinst, classes):
        iou_same, _ = _best_overlap(np.where(gcls == c, gkey, 0), member, gsize)
        if iou_same >= iou_threshold:
            continue
        k, n = np.unique(gkey[member], return_counts=True)
        top = int(np.argmax(n))
        key, share = int(k[top]), float(n[top] / m)
        truth = int(np.bincount(gcls[member]).argmax())
        if key and share > 0.5:
            kind = "piece" if key % 256 == c else "other element"
        elif float(np.mean(gkey[member] == 0)) > 0.5:
            kind = "no element"
        else:
            kind = "mixed"
        out.append({"class": int(c), "points": m, "truth": truth, "share": round(share if key else 0.0, 3),
                    "kind": kind, "instance": key // 256})
    return out
