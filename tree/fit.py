"""Fitting the energy: ``w`` by linear regression, the prior ``W`` by counting.

Training proposals come from synthetic scenes whose parts are known
(:func:`fit_energy_from_scenes`): each element's points are a segment, the segment's
parts are its ground-truth pieces (an arcade's bays, a minaret's stages between the
balconies; a dome, a wall, a pillar, a chattri, a bastion or a portal is one part), and
every part is itself a node whose proposals should be refused. The target of a proposal
is how well its children match the parts (:func:`proposal_target`): 1 for a split along
the parts, 0 for any split of a single part.

- ``W[k, n]``: the share of proposals of sequence ``n`` on parents of class ``k`` that
  took the right path (:func:`right_paths`: good, target >= :data:`GOOD_TARGET`, and
  the best proposal made at their node, equal targets ranked by how closely the matched
  children cover their parts), shrunk towards the overall share by two pseudo-proposals
  (a class never seen gets the overall share). It is the paper's "prior probability of
  observing a certain projection sequence given the class", counted where the sequence
  applies (S1 and S3 exist only where ``psi`` finds a transport curve).
- ``w``: least squares of the targets on ``[e1..e5]``, no intercept (``xi = w . e`` as in
  the paper); R^2 against the targets' mean.
- threshold: the ``xi`` that best separates good from bad proposals (balanced accuracy).

By default the fit scores children with an oracle stand-in: class = the majority
ground-truth class, score = the share of that class (the shipped ``energy-v1.json``; see
docs/method.md for why the HollowNet refit is not shipped yet). Refit with a real
classifier by passing it as ``classifier``.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from hollowtree.arrays import FloatArray, IntArray
from hollowtree.classes import NUM_CLASSES, ClassId
from hollowtree.scenes.scanner import ScanParams, scan
from hollowtree.scenes.sites import build_scene
from hollowtree.tree.energy import Classifier, EnergyModel, energy_terms
from hollowtree.tree.sequences import SequenceParams, propose

__all__ = [
    "GOOD_TARGET",
    "EnergySamples",
    "fit_energy",
    "fit_energy_from_scenes",
    "minaret_stage_cuts",
    "proposal_quality",
    "proposal_target",
    "right_paths",
]


#: A proposal is good when its target (:func:`proposal_target`) reaches this.
GOOD_TARGET = 0.5
#: Training segments: (scene, element class of the segment's points, how parts are made).
TRAINING_SEGMENTS: tuple[tuple[str, ClassId, str], ...] = tuple((scene, cls, how) for scenes, cls, how in (
    ("minaret octagonal_minaret", ClassId.MINARET, "stages"),
    ("arcade pointed_arcade curved_arcade", ClassId.ARCH, "instances"),
    ("dome onion_dome pointed_dome chattri", ClassId.DOME, "one"),
    ("bastion", ClassId.MINARET, "one"),
    ("pillar", ClassId.PILLAR, "one"),
    ("portal", ClassId.ARCH, "one"),
    ("plane_wall", ClassId.WALL, "one"),
) for scene in scenes.split())


def minaret_stage_cuts(
    *,
    height: float = 30.0,
    base_radius: float = 2.0,
    n_stages: int = 8,
    taper: float = 0.05,
    setback: float = 0.04,
    balcony_thickness: float = 0.35,
    parapet_height: float = 1.0,
    plinth_height: float = 1.5,
) -> tuple[FloatArray, FloatArray]:
    """Balcony height ranges and stage cut heights of :func:`scenes.elements.minaret`.

    Returns ``(balconies, cuts)``: ``balconies`` of shape (n_stages - 1, 2), from the foot
    of the corbel to the top of the parapet; ``cuts`` the middles of the balconies (a
    stage runs from one balcony's middle to the next, the first from the ground, the last
    to the top). Defaults are the ``minaret`` test scene's nominal geometry (cupola on
    posts).

    Examples
    --------
    >>> b, c = minaret_stage_cuts(n_stages=3, height=20.0)
    >>> b.shape, bool(np.all(np.diff(c) > 0))
    ((2, 2), True)
    """
    r = base_radius
    r_top_est = r * ((1 - taper) * (1 - setback)) ** n_stages
    cup_r = 1.05 * r_top_est
    finial = 0.5 * cup_r + 0.4
    post_h = 1.6 * cup_r + 0.3
    cup_h = 0.25 + post_h + 0.3 + 0.25 + cup_r + finial - 0.05
    shaft = height - plinth_height - cup_h
    w = 0.8 ** np.arange(n_stages)
    stage_h = (shaft - (n_stages - 1) * balcony_thickness) * w / w.sum()
    z = plinth_height
    out = []
    for i in range(n_stages - 1):
        z += stage_h[i]
        corbel = min(0.9, 0.5 * stage_h[i])
        out.append((z - corbel, z + balcony_thickness + parapet_height))
        z += balcony_thickness
    b = np.asarray(out, dtype=np.float64).reshape(-1, 2)
    return b, b.mean(axis=1)


def _oracle(labels: Sequence[npt.NDArray[Any]]) -> tuple[IntArray, FloatArray]:
    """The fit's stand-in classifier: majority ground-truth class and its share."""
    cls = np.zeros(len(labels), dtype=np.int64)
    score = np.zeros(len(labels))
    for i, lab in enumerate(labels):
        counts = np.bincount(np.asarray(lab, dtype=np.int64), minlength=NUM_CLASSES)
        cls[i] = int(np.argmax(counts))
        score[i] = counts[cls[i]] / max(int(counts.sum()), 1)
    return cls, score


def _matches(children: Sequence[IntArray], parts: npt.ArrayLike) -> list[float]:
    """IoU of each child matched one-to-one to a part with IoU >= 0.5 (``parts``: a part
    label per point of the parent)."""
    lab = np.asarray(parts)
    _, inv = np.unique(lab, return_inverse=True)
    part_size = np.bincount(inv)
    matched: dict[int, float] = {}
    for c in children:
        inter = np.bincount(inv[c], minlength=len(part_size))
        iou = inter / (part_size + len(c) - inter)
        q = int(np.argmax(iou))
        if iou[q] >= 0.5 and q not in matched:  # IoU >= 0.5 makes the match unique
            matched[q] = float(iou[q])
    return list(matched.values())


def proposal_target(children: Sequence[IntArray], parts: npt.ArrayLike) -> float:
    """What a split is worth against the ground-truth parts: ``(m - 1) / (s - 1)``.

    ``s`` children, ``m`` of them matched one-to-one to a part with IoU >= 0.5 (``parts``:
    a part label per point of the parent). A split along the parts scores 1; any split of
    a single part scores 0 (at most one child can cover half of it); an over-split
    scores in between.

    Examples
    --------
    >>> parts = np.array([0, 0, 1, 1])
    >>> proposal_target([np.array([0, 1]), np.array([2, 3])], parts)
    1.0
    >>> proposal_target([np.array([0]), np.array([1, 2, 3])], np.zeros(4, int))
    0.0
    """
    s = len(children)
    if s < 2:
        return 0.0
    return max(len(_matches(children, parts)) - 1, 0) / (s - 1)


def proposal_quality(children: Sequence[IntArray], parts: npt.ArrayLike) -> float:
    """How closely the matched children cover their parts: the mean IoU of the children
    matched as in :func:`proposal_target` (0 when none is). It ranks proposals of one
    node that match the same number of parts (:func:`fit_energy`'s "right path").

    Examples
    --------
    >>> parts = np.array([0, 0, 0, 1, 1, 1])
    >>> proposal_quality([np.array([0, 1, 2]), np.array([3, 4, 5])], parts)
    1.0
    >>> round(proposal_quality([np.array([0, 1]), np.array([2, 3, 4, 5])], parts), 4)
    0.7083
    """
    m = _matches(children, parts)
    return float(np.mean(m)) if m else 0.0


@dataclass(frozen=True, kw_only=True, eq=False)
class EnergySamples:
    """Training proposals: terms, targets and what the prior needs.

    Attributes
    ----------
    sizes : list of ndarray
        Children's point counts of each proposal.
    n_parent, parent_class, sequence : ndarray of int64, shape (n,)
    scores : list of ndarray
        Children's classification scores.
    target : ndarray of float64, shape (n,)
    origin : list of str
        ``scene/step/node`` of each proposal (node 0 is the segment, k > 0 its part k);
        proposals with the same origin compete at one node. Empty: each its own node.
    quality : ndarray of float64, optional
        :func:`proposal_quality` of each proposal (ranks equal targets at one node).
    """

    sizes: list[IntArray]
    n_parent: IntArray
    parent_class: IntArray
    sequence: IntArray
    scores: list[FloatArray]
    target: FloatArray
    origin: list[str] = field(default_factory=list)
    quality: FloatArray | None = None

    def __len__(self) -> int:
        return len(self.target)


def right_paths(samples: EnergySamples) -> npt.NDArray[np.bool_]:
    """Which proposals took the right path: good (target >= :data:`GOOD_TARGET`) and the
    best of the proposals made at their node, ranked by target, then by
    :func:`proposal_quality` (ties all count).

    On a curved arcade S2 and S3 may both match every arch (target 1) while S3's bays
    are the closer ones: S3 took the right path there, S2 did not.

    Examples
    --------
    >>> s = EnergySamples(sizes=[np.array([5, 5])] * 3, n_parent=np.full(3, 10),
    ...                   parent_class=np.full(3, 4), sequence=np.array([1, 2, 3]),
    ...                   scores=[np.ones(2)] * 3, target=np.array([0.0, 1.0, 1.0]),
    ...                   origin=["a/0", "a/0", "a/0"], quality=np.array([0.0, 0.76, 0.96]))
    >>> right_paths(s).tolist()
    [False, False, True]
    """
    good = samples.target >= GOOD_TARGET
    n = len(samples)
    quality = samples.quality if samples.quality is not None else np.zeros(n)
    origin = samples.origin if len(samples.origin) == n else [str(i) for i in range(n)]
    right = np.zeros(n, dtype=bool)
    nodes: dict[str, list[int]] = {}
    for i, o in enumerate(origin):
        nodes.setdefault(o, []).append(i)
    for members in nodes.values():
        keys = [(float(samples.target[i]), float(quality[i])) for i in members]
        top = max(keys)
        for i, key in zip(members, keys, strict=True):
            right[i] = bool(good[i]) and key == top
    return right


def fit_energy(samples: EnergySamples, *, n_min: int = 20_000, seed: int = 0,
               info: dict[str, Any] | None = None) -> EnergyModel:
    """Fit ``W`` (counting), then ``w`` (least squares, no intercept) and the threshold.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> n = 40
    >>> sizes = [rng.integers(100, 1000, size=rng.integers(2, 6)) for _ in range(n)]
    >>> seq = rng.integers(1, 4, size=n)
    >>> tgt = np.where(seq == 1, 0.9, 0.3)
    >>> s = EnergySamples(sizes=sizes, n_parent=np.array([x.sum() for x in sizes]),
    ...                   parent_class=np.full(n, 6), sequence=seq,
    ...                   scores=[np.ones(len(x)) for x in sizes], target=tgt)
    >>> m = fit_energy(s, n_min=500)
    >>> bool(m.W[6, 0] > 0.8 > 0.2 > m.W[6, 1]), bool(m.r2 > 0.9)
    (True, True)
    """
    good = samples.target >= GOOD_TARGET
    right = right_paths(samples)
    # Shrunk towards the overall rate of right proposals (2 pseudo-proposals).
    p0 = float(right.mean()) if len(right) else 0.5
    num = np.full((NUM_CLASSES, 3), 2.0 * p0)
    den = np.full((NUM_CLASSES, 3), 2.0)
    for k, n, g in zip(samples.parent_class, samples.sequence, right, strict=True):
        num[k, n - 1] += float(g)
        den[k, n - 1] += 1.0
    prior = num / den
    e = np.vstack([
        energy_terms(sz, n_min=n_min, prior=prior, parent_class=int(k), sequence=int(n), scores=sc)
        for sz, k, n, sc in zip(samples.sizes, samples.parent_class, samples.sequence, samples.scores,
                                strict=True)
    ])
    w = np.linalg.lstsq(e, samples.target, rcond=None)[0]
    pred = e @ w
    ss_res = float(((samples.target - pred) ** 2).sum())
    ss_tot = float(((samples.target - samples.target.mean()) ** 2).sum())
    r2 = 1.0 - ss_res / ss_tot if ss_tot > 0 else float("nan")
    # Threshold: best balanced accuracy of "xi >= t" for "good".
    best_t, best_acc = GOOD_TARGET, -1.0
    for t in np.unique(pred):
        split = pred >= t
        tpr = float((split & good).sum()) / max(int(good.sum()), 1)
        tnr = float((~split & ~good).sum()) / max(int((~good).sum()), 1)
        if 0.5 * (tpr + tnr) > best_acc:
            best_t, best_acc = float(t), 0.5 * (tpr + tnr)
    # Midway between the chosen cut and the highest xi below it (a margin both ways).
    below = pred[pred < best_t]
    thr = 0.5 * (best_t + float(below.max())) if len(below) else best_t
    meta = {"n_samples": len(samples), "n_good": int(good.sum()), "n_right": int(right.sum()),
            "balanced_accuracy": best_acc, "good_target": GOOD_TARGET} | (info or {})
    return EnergyModel(weights=tuple(float(x) for x in w), prior=tuple(tuple(float(x) for x in r) for r in prior),
                       n_min=n_min, threshold=thr, r2=r2, seed=seed, info=meta)


def _scan_points(name: str, *, step: float, seed: int) -> tuple[FloatArray, npt.NDArray[Any], npt.NDArray[Any]]:
    sc = build_scene(name)
    chunks = list(scan(sc, ScanParams(step_deg=step, seed=seed), workers=1))
    return (np.concatenate([c.xyz for c in chunks]), np.concatenate([c.gt_class for c in chunks]),
            np.concatenate([c.gt_instance for c in chunks]))


def _parts(name: str, how: str, xyz: FloatArray, instance: npt.NDArray[Any]) -> IntArray:
    if how == "instances":
        return np.asarray(instance, dtype=np.int64)
    if how == "stages":
        n_stages = 4 if name == "octagonal_minaret" else 8
        _, cuts = minaret_stage_cuts(n_stages=n_stages)
        return np.searchsorted(cuts, xyz[:, 2]).astype(np.int64)
    return np.zeros(len(xyz), dtype=np.int64)


def collect_samples(
    *,
    seed: int = 0,
    steps: Sequence[float] = (0.2, 0.3),
    segments: Sequence[tuple[str, ClassId, str]] = TRAINING_SEGMENTS,
    classifier: Classifier | None = None,
    params: SequenceParams | None = None,
) -> EnergySamples:
    """Proposals on every training segment and on each of its parts, with their targets."""
    params = params or SequenceParams()
    sizes, npar, pcls, seqs, scores, target, origin, quality = [], [], [], [], [], [], [], []
    for i, (name, cls, how) in enumerate(segments):
        for j, step in enumerate(steps):
            xyz, gcls, ginst = _scan_points(name, step=step, seed=seed + 7 * i + j)
            keep = gcls == cls
            pts, part = xyz[keep], _parts(name, how, xyz[keep], ginst[keep])
            lab = gcls[keep]
            nodes = [np.arange(len(pts))]
            if len(np.unique(part)) > 1:
                nodes += [np.flatnonzero(part == q) for q in np.unique(part)]
            for k, idx in enumerate(nodes):
                if len(idx) < params.min_points:
                    continue
                sub = pts[idx]
                props = propose(sub, params=params, rng=np.random.SeedSequence([seed, i, j, k]))
                if classifier is None:
                    pc = int(_oracle([lab[idx]])[0][0])
                else:
                    pc_cls, _, _ = classifier.predict([sub])  # unpacked: HollowNet's Prediction
                    pc = int(np.asarray(pc_cls).reshape(-1)[0])
                for pr in props.values():
                    if pr is None:
                        continue
                    if classifier is None:
                        sc = _oracle([lab[idx][c] for c in pr.children])[1]
                    else:
                        _, c_sc, _ = classifier.predict([sub[c] for c in pr.children])
                        sc = np.asarray(c_sc, dtype=np.float64)
                    sizes.append(np.array([len(c) for c in pr.children]))
                    npar.append(len(idx))
                    pcls.append(int(pc))
                    seqs.append(pr.sequence)
                    scores.append(np.asarray(sc, dtype=np.float64))
                    target.append(proposal_target(pr.children, part[idx]))
                    quality.append(proposal_quality(pr.children, part[idx]))
                    origin.append(f"{name}/{step}/{k}")
    return EnergySamples(sizes=sizes, n_parent=np.asarray(npar, dtype=np.int64),
                         parent_class=np.asarray(pcls, dtype=np.int64),
                         sequence=np.asarray(seqs, dtype=np.int64), scores=scores,
                         target=np.asarray(target, dtype=np.float64), origin=origin,
                         quality=np.asarray(quality, dtype=np.float64))


def fit_energy_from_scenes(
    seed: int = 0,
    *,
    steps: Sequence[float] = (0.2, 0.3),
    n_min: int = 20_000,
    classifier: Classifier | None = None,
    params: SequenceParams | None = None,
) -> EnergyModel:
    """Scan the training scenes, collect proposals and fit the energy (a few minutes on 2
    cores). Same seed, same model.

    Parameters
    ----------
    seed : int
        Seeds the scans (noise) and the RANSAC fits.
    steps : sequence of float
        Scanner angular steps (degrees): each scene is scanned once per step.
    n_min : int
        ``Nmin`` of ``e2``.
    classifier : Classifier, optional
        Scores the children; default the oracle stand-in (majority ground-truth class,
        its share as the score).
    params : SequenceParams, optional
    """
    t0 = time.perf_counter()
    samples = collect_samples(seed=seed, steps=steps, classifier=classifier, params=params)
    info = {"classifier": "oracle (majority ground-truth class, its share as score)"
            if classifier is None else type(classifier).__name__,
            "target": "(m - 1) / (s - 1): s children, m matched to a part with IoU >= 0.5",
            "prior": "W[k, n]: share of sequence n's proposals on class-k parents that took the right "
                     "path (good and best at their node; equal targets ranked by the matched "
                     "children's mean IoU), shrunk by 2 pseudo-proposals",
            "scenes": [s[0] for s in TRAINING_SEGMENTS], "steps_deg": list(steps),
            "seconds": round(time.perf_counter() - t0, 1)}
    return fit_energy(samples, n_min=n_min, seed=seed, info=info)
