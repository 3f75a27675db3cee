"""Fitting the split model (:mod:`tree.split`) on the element groups the tree meets.

Training data (made by ``hollowtree fit-split``, :mod:`pipeline.split_fit`): random scenes
(the five HollowNet recipes of :mod:`hollownet._scenes` and two- or three-storey arcades,
:func:`hollownet._scenes.storeyed_arcades`) are scanned and run through ingest and the
coarse stage of ``workflows/local.yaml``; every element group of at least ``min_node``
points is a node, and so is every ground-truth instance inside it (a node the tree should
leave whole). Each node gets the proposals of its sequences under ``n_seeds`` seeds (S1
and S3 depend on ``psi``'s RANSAC; identical proposals are kept once), HollowNet scores
the node and every child, and :func:`proposal_target` says how right each proposal is.
The children of a right proposal (first seed) are nodes too, down to ``max_depth``, so a
storey of bays is met as it is at run time.

A proposal is right (:data:`GOOD_TARGET`) when at least half of its children, beyond the
first, are right: a child matches one ground-truth instance (IoU >= 0.5, one to one) or is
a union of whole instances (each >= 90 % inside it, together >= 90 % of it), so cutting a
facade into storeys of bays is right and cutting a dome in half is not.

The fit is sklearn's ``GradientBoostingClassifier`` (150 trees of depth 3, learning rate
0.05, subsample 0.8, seeded); scenes are grouped in a 5-fold cross-validation whose AUC,
and the node decisions at the threshold, are stored with the model (``info``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from hollowtree.arrays import FloatArray, IntArray
from hollowtree.columns import column_span
from hollowtree.tree.build import _is_flat
from hollowtree.tree.build_params import BuildParams
from hollowtree.tree.energy import Classifier
from hollowtree.tree.sequences import SequenceParams, propose
from hollowtree.tree.split import FEATURE_NAMES, SplitModel, split_features

__all__ = ["GOOD_TARGET", "THRESHOLDS", "SplitSamples", "fit_split_model", "proposal_samples", "proposal_target"]


#: A proposal is right when its target reaches this.
GOOD_TARGET = 0.5


def _parts(gt_class: npt.ArrayLike, gt_instance: npt.ArrayLike) -> IntArray:
    """Dense ids of the (class, instance) pairs."""
    key = np.asarray(gt_class, dtype=np.int64) * 1_000_000_007 + np.asarray(gt_instance, dtype=np.int64)
    return np.unique(key, return_inverse=True)[1].reshape(-1).astype(np.int64)


def proposal_target(children: Sequence[IntArray], parts: IntArray, *, whole: float = 0.9) -> float:
    """``(right children - 1) / (children - 1)``, 0 for a single child.

    A child is right when it matches a part not matched yet (IoU >= 0.5) or is a union of
    at least two whole parts not used yet (each at least ``whole`` inside it, together at
    least ``whole`` of it).

    Examples
    --------
    >>> parts = np.repeat([0, 1, 2, 3], 10)
    >>> proposal_target([np.arange(0, 20), np.arange(20, 40)], parts)   # two pairs of parts
    1.0
    >>> proposal_target([np.arange(0, 5), np.arange(5, 40)], parts)     # half a part
    0.0
    """
    s = len(children)
    if s < 2:
        return 0.0
    part_size = np.bincount(parts)
    used: set[int] = set()
    right = 0
    for c in children:
        inter = np.bincount(parts[c], minlength=len(part_size))
        iou = inter / (part_size + len(c) - inter)
        q = int(np.argmax(iou))
        if iou[q] >= 0.5 and q not in used:
            used.add(q)
            right += 1
            continue
        inside = np.flatnonzero((inter >= whole * part_size) & (inter > 0))
        cover = inter[inside].sum() / max(len(c), 1)
        if len(inside) >= 2 and cover >= whole and not (set(inside.tolist()) & used):
            used.update(inside.tolist())
            right += 1
    return max(right - 1, 0) / (s - 1)


@dataclass(frozen=True, kw_only=True, eq=False)
class SplitSamples:
    """Proposals with their features and targets.

    Attributes
    ----------
    features : ndarray of float64, shape (n, n_features)
    target : ndarray of float64, shape (n,)
    node : ndarray of str
        The node a proposal was made at (``scene/group/node``): the node decisions of
        :func:`fit_split_model`'s report pick one proposal per node.
    scene : ndarray of str
        Cross-validation groups.
    """

    features: FloatArray
    target: FloatArray
    node: npt.NDArray[np.str_]
    scene: npt.NDArray[np.str_]

    def __len__(self) -> int:
        return len(self.target)

    @staticmethod
    def concat(parts: Sequence[SplitSamples]) -> SplitSamples:
        parts = [p for p in parts if len(p)]
        if not parts:
            raise ValueError("no proposals to fit the split model on")
        return SplitSamples(features=np.vstack([p.features for p in parts]),
                            target=np.concatenate([p.target for p in parts]),
                            node=np.concatenate([p.node for p in parts]),
                            scene=np.concatenate([p.scene for p in parts]))


def proposal_samples(
    xyz: npt.ArrayLike,
    gt_class: npt.ArrayLike,
    gt_instance: npt.ArrayLike,
    starts: npt.ArrayLike,
    classifier: Classifier,
    *,
    scene: str,
    params: SequenceParams | None = None,
    n_seeds: int = 3,
    min_node: int = 2000,
    max_depth: int = BuildParams.max_depth,
    max_group_points: int = 0,
) -> SplitSamples:
    """The proposals of one scene's element groups (module docstring).

    ``xyz`` are the coarse segments' points in group order, ``starts`` the first row of
    every group and the row count last; ``gt_class`` and ``gt_instance`` each point's
    ground truth. A group of more than ``max_group_points`` points (0: none) is met as the
    tree stage meets it: as a seeded random sample of about that many points.
    """
    params = params or SequenceParams()
    a = np.asarray(xyz, dtype=np.float64)
    gs = np.asarray(starts, dtype=np.int64)
    gc = np.asarray(gt_class)
    gi = np.asarray(gt_instance)
    feats: list[FloatArray] = []
    target: list[float] = []
    node_of: list[str] = []
    for g in range(len(gs) - 1):
        lo, hi = int(gs[g]), int(gs[g + 1])
        if hi - lo < min_node:
            continue
        rows = np.arange(lo, hi)
        if max_group_points and hi - lo > max_group_points:
            keep = np.random.default_rng(np.random.SeedSequence([g, 1])).random(hi - lo) < max_group_points / (hi - lo)
            rows = rows[keep]
        pts = a[rows] - a[rows].mean(axis=0)
        parts = _parts(gc[rows], gi[rows])
        queue: list[tuple[int, IntArray, int]] = [(0, np.arange(len(rows), dtype=np.int64), 0)]
        if parts.max() > 0:
            queue += [(q + 1, np.flatnonzero(parts == q), 0) for q in range(int(parts.max()) + 1)]
        n_nodes = len(queue)
        while queue:
            k, idx, depth = queue.pop()
            if len(idx) < min_node or depth >= max_depth:
                continue
            sub = pts[idx]
            if _is_flat(sub, params):
                continue
            props, seen = [], set()
            for rs in range(n_seeds):
                for key, p in propose(sub, params=params, rng=np.random.SeedSequence([rs, g, k])).items():
                    sig = None if p is None else (key, p.n_children, tuple(np.round(p.cuts, 3).tolist()))
                    if p is not None and sig not in seen:
                        seen.add(sig)
                        props.append((key, p, rs))
            if not props:
                continue
            pcls, _, pprob = classifier.predict([sub])
            ccls, _, cprob = classifier.predict([sub[c] for _, p, _ in props for c in p.children])
            pp = np.asarray(pprob, dtype=np.float64).reshape(1, -1)[0]
            cp = np.asarray(cprob, dtype=np.float64).reshape(-1, len(pp))
            pc = int(np.asarray(pcls).reshape(-1)[0])
            cc = np.asarray(ccls, dtype=np.int64).reshape(-1)
            sp = np.unique(parts[idx], return_inverse=True)[1].reshape(-1).astype(np.int64)
            ext = column_span(sub)
            j = 0
            for key, p, rs in props:
                s = p.n_children
                t = proposal_target(p.children, sp)
                feats.append(split_features(n_parent=len(idx), extent=ext, depth=depth, key=key, parent_class=pc,
                                            parent_probs=pp, child_sizes=[len(c) for c in p.children],
                                            child_classes=cc[j:j + s], child_probs=cp[j:j + s], cuts=p.cuts))
                target.append(t)
                node_of.append(f"{scene}/{g}/{k}")
                j += s
                if rs == 0 and t >= GOOD_TARGET and (k == 0 or depth > 0):
                    for c in p.children:
                        queue.append((n_nodes, idx[c], depth + 1))
                        n_nodes += 1
    return SplitSamples(features=np.asarray(feats, dtype=np.float64).reshape(-1, len(FEATURE_NAMES)),
                        target=np.asarray(target, dtype=np.float64), node=np.asarray(node_of, dtype=str),
                        scene=np.full(len(target), scene, dtype=object).astype(str))


def _node_decisions(p: FloatArray, good: npt.NDArray[np.bool_], node: npt.NDArray[np.str_],
                    threshold: float) -> dict[str, int]:
    """Per node: the best proposal split when ``p >= threshold``; right when it splits with a
    good proposal or keeps a node that has none."""
    order = np.argsort(node, kind="stable")
    bounds = np.flatnonzero(np.r_[True, node[order][1:] != node[order][:-1], True])
    out = {"nodes": 0, "need_split": 0, "right": 0, "false_split": 0, "missed": 0}
    for lo, hi in zip(bounds[:-1], bounds[1:], strict=True):
        m = order[lo:hi]
        j = m[int(np.argmax(p[m]))]
        any_good = bool(good[m].any())
        split = bool(p[j] >= threshold)
        out["nodes"] += 1
        out["need_split"] += any_good
        out["right"] += (split and bool(good[j])) or (not split and not any_good)
        out["false_split"] += split and not bool(good[j])
        out["missed"] += (not split) and any_good
    return out


#: Thresholds the cross-validation tries when none is given.
THRESHOLDS: tuple[float, ...] = (0.2, 0.25, 0.3, 0.35, 0.4, 0.45, 0.5, 0.55, 0.6, 0.65, 0.7)


def fit_split_model(samples: SplitSamples, *, threshold: float = 0.5, seed: int = 0, folds: int = 5,
                    info: dict[str, Any] | None = None) -> SplitModel:
    """Fit the split model; ``info`` gets the sample counts, the grouped cross-validation's
    AUC (by scene, ``folds`` folds), its node decisions at ``threshold`` and how many node
    decisions are right at each of :data:`THRESHOLDS`."""
    from sklearn.ensemble import GradientBoostingClassifier
    from sklearn.metrics import roc_auc_score
    from sklearn.model_selection import GroupKFold

    x, good = samples.features, samples.target >= GOOD_TARGET
    if good.all() or not good.any():
        raise ValueError("the split model needs both right and wrong proposals to fit on")

    def make() -> GradientBoostingClassifier:
        return GradientBoostingClassifier(n_estimators=150, max_depth=3, learning_rate=0.05, subsample=0.8,
                                          random_state=seed)

    report: dict[str, Any] = {"samples": int(len(good)), "right": int(good.sum()),
                              "scenes": int(len(np.unique(samples.scene)))}
    if len(np.unique(samples.scene)) >= folds:
        p = np.zeros(len(good))
        for tr, te in GroupKFold(n_splits=folds).split(x, good, samples.scene):
            p[te] = make().fit(x[tr], good[tr]).predict_proba(x[te])[:, 1]
        report["cv_auc"] = round(float(roc_auc_score(good, p)), 4)
        report["cv_right_by_threshold"] = {str(t): _node_decisions(p, good, samples.node, t)["right"]
                                           for t in THRESHOLDS}
        report["cv_nodes"] = _node_decisions(p, good, samples.node, threshold)
    model = make().fit(x, good)
    return SplitModel.from_sklearn(model, threshold=threshold, info={**report, **(info or {})})
