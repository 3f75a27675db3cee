"""Algorithm 1 of the paper: the greedy hierarchical tree of one coarse segment.

At every node the sequences propose splits (:func:`tree.sequences.propose`); the
classifier scores every proposal's children; each proposal gets ``xi = w . e``
(:mod:`tree.energy`) or, with a split model (:mod:`tree.split`, the pipeline's default),
the model's probability that it is right; the best is kept if that score reaches the
threshold and the recursion goes on in its children down to ``max_depth``. An explicit
stack replaces the paper's recursion. A storeys cut is judged one level further (its
storeys' own proposals: ``look_ahead``), and its bands are cut into storeys again only
where no bay cut (S2, S3) reaches the threshold.

Element instances (``../shared/METHOD.md``, "Classes"): the largest node whose class is an
element class (arch, dome, minaret, pillar) and whose ancestors are not; every point below
it takes its class and instance. A split node counts as an element only when its children
mostly share its class, and never when it was split at gaps (:func:`tree.sequences.gaps`:
its parts do not touch).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.spatial import cKDTree

from hollowtree.arrays import FloatArray, IntArray
from hollowtree.classes import ELEMENT_CLASSES, ClassId
from hollowtree.columns import column_max, column_min, column_span
from hollowtree.tree.build_params import BuildParams
from hollowtree.tree.energy import Classifier, EnergyModel, energy_terms, load_energy_model
from hollowtree.tree.operators import RngLike, h
from hollowtree.tree.posts import posts
from hollowtree.tree.sequences import (
    GAP_SEQUENCE,
    PART_SEQUENCE,
    POST_SEQUENCE,
    Proposal,
    SequenceParams,
    gaps,
    parts,
    propose,
)
from hollowtree.tree.split import N_PROBS, SplitModel, split_features

__all__ = ["NodeTable", "TreeResult", "build_tree"]

_WALL = int(ClassId.WALL)
#: ``propose``'s keys of the storeys and of the cuts into bays (S2, S3).
_STOREYS = 4
_BAYS = (2, 3)
#: A storey is looked into (``build_tree(look_ahead=)``) when under this share of its wall
#: projection's cells is occupied (:func:`_solid_share`): it has a row of openings.
OPEN_STOREY = 0.8
#: A root is cut into its parts apart (:func:`tree.sequences.parts`) only when HollowNet
#: calls one part one of these, and that part is at least :data:`PART_MIN_HEIGHT` tall: a
#: chattri or a small dome standing beside a minaret or a wall. Pieces of an arcade apart
#: (a bay's two jambs, seen without the arch over them) are one thing whatever HollowNet
#: calls each, and a strip of a bastion beside its curtain wall, called minaret, is a piece
#: of a minaret in another group (docs/method.md, tree-v13).
PART_CLASSES = (int(ClassId.DOME),)
#: Metres; HollowNet's smallest training dome, a chattri, is about 3.3 m tall.
PART_MIN_HEIGHT = 2.0
#: A root HollowNet calls one of these is not cut into parts apart: a dome or a minaret is
#: a standalone element itself, and clutter (``other``) in pieces is clutter. On Wazir Khan
#: such roots were rows of arcade bays seen in pieces (docs/method.md, tree-v13).
WHOLE_ROOT_CLASSES = (int(ClassId.DOME), int(ClassId.MINARET), int(ClassId.OTHER))

#: A root HollowNet calls one of these that no proposal splits gives up its posts
#: (:func:`tree.posts.posts`) when HollowNet calls at least two of them pillars: a
#: pavilion's or a colonnade's columns under their slab or beam, which touch through it.
#: A root called clutter too (``tree-v35``): HollowNet calls a whole pavilion (dome, slab
#: and columns) other more often than dome, and the element check (:mod:`tree.verify`)
#: judges each post after (a scaffold's poles, people side by side). Chosen on the
#: validation split (docs/generalize.md).
POSTS_FROM = (int(ClassId.DOME), int(ClassId.PILLAR), int(ClassId.OTHER))
_PILLAR = int(ClassId.PILLAR)


@dataclass(frozen=True, kw_only=True, eq=False)
class NodeTable:
    """The nodes of one tree as parallel arrays (sklearn's ``tree_``), in creation order.

    Attributes
    ----------
    node_id : ndarray of int64, shape (n_nodes,)
        0..n_nodes-1; the root is 0.
    parent : ndarray of int64
        -1 for the root.
    depth : ndarray of int64
    sequence : ndarray of int8
        The sequence (1, 2, 3) whose split produced the node; 0 for the root, 5
        (``tree.sequences.GAP_SEQUENCE``) for a cut at gaps, 6
        (``tree.sequences.PART_SEQUENCE``) for a root's parts apart.
    terms : ndarray of float64, shape (n_nodes, 5)
        e1..e5 of the split that produced the node (NaN for the root).
    xi : ndarray of float64
        ``w . e`` of that split (NaN for the root).
    class_id : ndarray of uint8
    score : ndarray of float32
    n_points : ndarray of int64
    bbox : ndarray of float64, shape (n_nodes, 6)
        ``xmin, ymin, zmin, xmax, ymax, zmax``.
    is_leaf : ndarray of bool
    """

    node_id: IntArray
    parent: IntArray
    depth: IntArray
    sequence: npt.NDArray[np.int8]
    terms: FloatArray
    xi: FloatArray
    class_id: npt.NDArray[np.uint8]
    score: npt.NDArray[np.float32]
    n_points: IntArray
    bbox: FloatArray
    is_leaf: npt.NDArray[np.bool_]

    def __len__(self) -> int:
        return len(self.node_id)

    def children(self, node: int) -> IntArray:
        """Ids of the children of ``node``."""
        return np.flatnonzero(self.parent == node).astype(np.int64)

    def to_dict(self) -> dict[str, npt.NDArray[Any]]:
        """Flat columns (one per energy term and bbox side), ready for a Parquet table."""
        cols: dict[str, npt.NDArray[Any]] = {
            "node_id": self.node_id, "parent": self.parent, "depth": self.depth,
            "sequence": self.sequence,
        }
        for k in range(5):
            cols[f"e{k + 1}"] = self.terms[:, k]
        cols |= {"xi": self.xi, "class_id": self.class_id, "score": self.score,
                 "n_points": self.n_points, "is_leaf": self.is_leaf}
        for k, name in enumerate(["xmin", "ymin", "zmin", "xmax", "ymax", "zmax"]):
            cols[name] = self.bbox[:, k]
        return cols


@dataclass(frozen=True, kw_only=True, eq=False)
class TreeResult:
    """The tree of one segment and what it says about each point.

    Attributes
    ----------
    nodes : NodeTable
    leaf : ndarray of int64, shape (n_points,)
        Node id of each point's leaf.
    class_id : ndarray of uint8, shape (n_points,)
        The element instance's class inside an element instance, else the leaf's class.
    instance : ndarray of int64, shape (n_points,)
        Element instance within this segment, 1..M; 0 outside every element instance
        (planar classes and ``other``: the caller makes them one instance per segment).
    score : ndarray of float32, shape (n_points,)
        The leaf's classification score.
    instance_node : ndarray of int64, shape (M,)
        Node id of each element instance (``instance_node[i - 1]`` for instance ``i``).
    """

    nodes: NodeTable
    leaf: IntArray
    class_id: npt.NDArray[np.uint8]
    instance: IntArray
    score: npt.NDArray[np.float32]
    instance_node: IntArray


def _bbox(xyz: FloatArray) -> FloatArray:
    if len(xyz) == 0:
        return np.full(6, np.nan)
    # Column by column: NumPy's axis-0 reductions of an (n, 3) array are ten times slower.
    cols = [xyz[:, k] for k in range(3)]
    return np.array([c.min() for c in cols] + [c.max() for c in cols], dtype=np.float64)


def _classify(classifier: Classifier, parts: list[FloatArray]) -> tuple[IntArray, FloatArray, FloatArray]:
    cls, score, prob = classifier.predict(parts)
    return (np.asarray(cls, dtype=np.int64).reshape(-1), np.asarray(score, dtype=np.float64).reshape(-1),
            np.asarray(prob, dtype=np.float64).reshape(len(parts), -1))


def _is_flat(pts: FloatArray, params: SequenceParams) -> bool:
    """Whether a node is a flat horizontal patch (``SequenceParams.flat_ratio``).

    >>> g = np.random.default_rng(0).random((1000, 3)) * [40.0, 20.0, 0.05]
    >>> _is_flat(g, SequenceParams()), _is_flat(g * [1, 1, 200], SequenceParams())
    (True, False)
    """
    z_lo, z_hi = np.percentile(pts[:, 2], [1.0, 99.0])
    horizontal = max(float(np.ptp(pts[:, 0])), float(np.ptp(pts[:, 1])))
    return bool(z_hi - z_lo < max(params.flat_height, params.flat_ratio * horizontal))


def _solid_share(pts: FloatArray, params: SequenceParams) -> float:
    """The share of occupied cells in the bounding box of a node's wall projection (``h``:
    along its footprint's principal axis, and height): about 0.6 for a storey of arched
    bays, above 0.85 for a plain wall seen from one side. The cells are ``params.cell``
    wide, or twice the mean point spacing in that box where that is larger (a sparse
    plain wall is still solid).

    >>> rng = np.random.default_rng(0)
    >>> wall = np.c_[rng.uniform(0, 10, 40000), np.zeros(40000), rng.uniform(0, 5, 40000)]
    >>> bays = wall[(wall[:, 0] % 2.5 < 0.8) | (wall[:, 2] > 4.0)]
    >>> round(_solid_share(wall, SequenceParams()), 2), round(_solid_share(bays, SequenceParams()), 2)
    (1.0, 0.49)
    >>> round(_solid_share(wall[:500], SequenceParams()), 2)  # sparse: 0.63 m cells
    0.98
    """
    tz = h(pts)
    ext = column_span(tz)
    # Cells of twice the mean point spacing at least, so a sparse plain wall fills them too.
    cell = max(params.cell if params.cell > 0 else 0.1, 2.0 * float(np.sqrt(ext[0] * ext[1] / max(len(pts), 1))))
    k = np.floor((tz - column_min(tz)) * (1.0 / cell)).astype(np.int64)
    n = column_max(k) + 1
    return len(np.unique(k[:, 0] * n[1] + k[:, 1])) / float(n[0] * n[1])


def build_tree(
    xyz: npt.ArrayLike,
    classifier: Classifier,
    *,
    model: EnergyModel | None = None,
    max_depth: int = BuildParams.max_depth,
    threshold: float | None = BuildParams.threshold,
    params: SequenceParams | None = None,
    rng: RngLike = None,
    split: SplitModel | None = None,
    look_ahead: bool = BuildParams.look_ahead,
) -> TreeResult:
    """Build the hierarchical tree of one segment (Algorithm 1).

    Not in the paper: before any proposal the root is cut at its gaps
    (:func:`tree.sequences.gaps`), and a root that no proposal splits is cut into its parts
    apart (:func:`tree.sequences.parts`) when HollowNet calls one of them a dome
    (:data:`PART_CLASSES`; docs/method.md).

    Parameters
    ----------
    xyz : array-like of shape (n_points, 3)
        The segment's points (float64, local metres preferred: subtract an origin from
        UTM coordinates first).
    classifier : Classifier
        ``predict(list of (n_i, 3) arrays) -> (class_ids, scores, probabilities)``.
    model : EnergyModel, optional
        ``w``, ``W``, ``Nmin`` and the threshold; default the package's ``energy-v1.json``.
    max_depth : int
        The paper's ``d``: nodes at this depth are not split.
    threshold : float, optional
        Overrides the threshold of ``split`` (when given) or of ``model``.
    params : SequenceParams, optional
    rng : int, Generator or None
        Seeds the RANSAC fits: one base seed is drawn from it and node ``i`` uses
        ``SeedSequence([base, i])``, so the same input and seed give the same tree.
    split : SplitModel, optional
        Decide by this split model (``load_split_model()``) instead of the energy: the
        proposal of highest probability is kept when it reaches the threshold. The
        classifier's probability rows must then be HollowNet's (8 classes). The energy's
        terms are still computed and recorded.
    look_ahead : bool
        When no proposal of a node above ``max_depth - 1`` reaches the threshold and one of
        them is a storeys cut, each storey (cut at the bands' middles,
        as the proposal was scored) with a row of openings (under :data:`OPEN_STOREY` of
        its wall projection occupied) gets its cuts into bays (S2, S3) scored; the storeys
        cut is kept when one of those reaches the threshold. Whatever HollowNet calls the
        node: it sees shape without size, and a curved arcade facade seen whole is called
        wall, minaret or dome by its scan.
        A storey cut rarely changes a class (a wall over a row of arches leaves a wall and
        a band of bays that HollowNet calls wall); what it is for is the bays below it.
        The node table's ``xi`` stays the cut's own score, so a split child whose ``xi``
        is under the threshold was kept by this look-ahead.

    Returns
    -------
    TreeResult

    Notes
    -----
    Memory: the points once, one index array per live node, and the proposals of one
    node at a time (three sets of child indices, O(n_points)).

    Examples
    --------
    >>> class Const:  # a stand-in classifier: everything is "wall" with score 0.5
    ...     def predict(self, segments):
    ...         n = len(segments)
    ...         return np.full(n, 2), np.full(n, 0.5), np.full((n, 9), 1 / 9)
    >>> r = build_tree(np.zeros((3, 3)), Const())
    >>> len(r.nodes), r.leaf.tolist(), r.instance.tolist()
    (1, [0, 0, 0], [0, 0, 0])
    """
    a = np.asarray(xyz, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"The 'xyz' parameter of build_tree must be an array of shape (n_points, 3). "
                         f"Got shape {a.shape} instead.")
    if max_depth < 0:
        raise ValueError(f"The 'max_depth' parameter of build_tree must be an int >= 0. Got {max_depth} instead.")
    model = model if model is not None else load_energy_model()
    thr = model.threshold if threshold is None else float(threshold)
    params = params or SequenceParams()
    base = int(np.random.default_rng(rng).integers(2**62))  # per-node seeds below
    prior = model.W

    n = len(a)
    cls0, sc0, pr0 = _classify(classifier, [a]) if n else (np.array([0]), np.array([0.0]), np.zeros((1, N_PROBS)))
    probs: list[FloatArray] = [pr0[0]]
    parent, depth, seq, xi, cls, score, npts = [-1], [0], [0], [np.nan], [int(cls0[0])], [float(sc0[0])], [n]
    terms: list[FloatArray] = [np.full(5, np.nan)]
    bbox = [_bbox(a)]
    leaf_of = np.zeros(n, dtype=np.int64)
    is_leaf = [True]
    stack: list[tuple[int, IntArray]] = [(0, np.arange(n, dtype=np.int64))]
    unjoined: dict[int, tuple[float, float]] = {}  # the rest of a posts split: its posts' heights

    def _add_children(node: int, idx: IntArray, children: Any, sequence: int, e: FloatArray, x: float,
                      c_cls: IntArray, c_sc: FloatArray, c_pr: FloatArray) -> None:
        """Make ``children`` (index arrays into ``idx``, the node's points) children of ``node``."""
        is_leaf[node] = False
        for j, child in enumerate(children):
            cid = len(parent)
            gidx = idx[child]
            parent.append(node)
            depth.append(depth[node] + 1)
            seq.append(sequence)
            terms.append(e)
            xi.append(x)
            cls.append(int(c_cls[j]))
            score.append(float(c_sc[j]))
            probs.append(c_pr[j])
            npts.append(len(gidx))
            bbox.append(_bbox(a[gidx]))
            is_leaf.append(True)
            leaf_of[gidx] = cid
            stack.append((cid, gidx))

    thr_split = split.threshold if split is not None and threshold is None else thr

    def _scored(pts: FloatArray, node_depth: int, node_cls: int, node_probs: FloatArray,
                node_rng: np.random.Generator, keys: tuple[int, ...] = (1, 2, 3, _STOREYS),
                ) -> list[tuple[float, int, Any]]:
        """The node's proposals of ``keys``, each ``(score, key, (proposal, e, classes, scores, probs))``."""
        props = [(key, pr) for key, pr in propose(pts, params=params, rng=node_rng).items()
                 if pr is not None and key in keys]
        if not props:
            return []
        parts = [pts[c] for _, pr in props for c in pr.children]
        all_cls, all_sc, all_pr = _classify(classifier, parts)
        cand: list[tuple[Proposal, FloatArray, IntArray, FloatArray, FloatArray]] = []
        feats: list[FloatArray] = []
        k = 0
        extent = column_span(pts) if split is not None else None
        for key, pr in props:
            s = pr.n_children
            c_cls, c_sc, c_pr = all_cls[k:k + s], all_sc[k:k + s], all_pr[k:k + s]
            k += s
            sizes = [len(c) for c in pr.children]
            e = energy_terms(sizes, n_min=model.n_min, prior=prior,
                             parent_class=node_cls, sequence=pr.sequence, scores=c_sc)
            cand.append((pr, e, c_cls, c_sc, c_pr))
            if split is not None:
                feats.append(split_features(n_parent=len(pts), extent=extent, depth=node_depth, key=key,
                                            parent_class=node_cls, parent_probs=node_probs, child_sizes=sizes,
                                            child_classes=c_cls, child_probs=c_pr, cuts=pr.cuts))
        # One call of the split model for all proposals of the node (its trees are walked per call).
        scores = split.probability(np.vstack(feats)) if split is not None else [model.xi(c[1]) for c in cand]
        return [(float(x), key, c) for x, (key, _), c in zip(scores, props, cand, strict=True)]

    def _bays_first(node: int, scored: list[tuple[float, int, Any]]) -> list[tuple[float, int, Any]]:
        # a storeys proposal's band is cut into storeys again only where no bay cut passes
        if node in banded and any(x >= thr_split for x, k, _ in scored if k in _BAYS):
            return [t for t in scored if t[1] != _STOREYS]
        return scored

    def _best(scored: list[tuple[float, int, Any]]) -> tuple[float, int, Any]:
        return scored[int(np.argmax([x for x, _, _ in scored]))]  # the first of equal scores, as before

    def _split_posts(node: int, idx: IntArray, pts: FloatArray) -> bool:
        """A root of :data:`POSTS_FROM` that nothing split: the posts HollowNet calls
        pillars each a child (:func:`tree.posts.posts`), the rest of the root one."""
        if depth[node] != 0 or cls[node] not in POSTS_FROM:
            return False
        found = posts(pts, params=params)
        if found is None:
            return False
        p_cls, p_sc, p_pr = _classify(classifier, [pts[c] for c in found])
        pillar = np.flatnonzero(p_cls == _PILLAR)
        if len(pillar) < 2:
            return False
        children = [found[j] for j in pillar]
        c_cls, c_sc, c_pr = p_cls[pillar], p_sc[pillar], p_pr[pillar]
        part = np.full(len(pts), len(children), dtype=np.int64)
        for j, c in enumerate(children):
            part[c] = j
        rest = part == len(children)
        if 0 < rest.sum() < max(params.min_points, 2):  # a few points: with the nearest post
            _, near = cKDTree(pts[~rest]).query(pts[rest])
            part[rest] = part[~rest][near]
            children = [np.flatnonzero(part == j).astype(np.int64) for j in range(len(children))]
            c_cls, c_sc, c_pr = _classify(classifier, [pts[c] for c in children])
        elif rest.any():  # the rest: one more child, classified alone (the posts already are)
            children.append(np.flatnonzero(rest).astype(np.int64))
            r_cls, r_sc, r_pr = _classify(classifier, [pts[children[-1]]])
            c_cls, c_sc, c_pr = np.r_[c_cls, r_cls], np.r_[c_sc, r_sc], np.vstack([c_pr, r_pr])
        _add_children(node, idx, children, POST_SEQUENCE, np.full(5, np.nan), np.nan, c_cls, c_sc, c_pr)
        if len(children) > len(pillar):  # the rest: what the posts joined falls apart
            z = [pts[c, 2] for c in children[:len(pillar)]]
            unjoined[len(parent) - 1] = (float(np.median([v.min() for v in z])), float(np.median([v.max() for v in z])))
        return True

    def _split_parts(node: int, idx: IntArray, pts: FloatArray) -> None:
        """A root that nothing split: into its parts apart (:func:`tree.sequences.parts`)
        when HollowNet calls them different classes, one of them of :data:`PART_CLASSES`
        and at least :data:`PART_MIN_HEIGHT` tall, and the root none of
        :data:`WHOLE_ROOT_CLASSES`."""
        if depth[node] != 0 or cls[node] in WHOLE_ROOT_CLASSES:
            return
        part = parts(pts, params=params)
        if part is None:
            return
        c_cls, c_sc, c_pr = _classify(classifier, [pts[c] for c in part.children])
        height = np.array([np.ptp(pts[c, 2]) for c in part.children])
        if len(np.unique(c_cls)) > 1 and (np.isin(c_cls, PART_CLASSES) & (height >= PART_MIN_HEIGHT)).any():
            _add_children(node, idx, part.children, part.sequence, np.full(5, np.nan), np.nan, c_cls, c_sc, c_pr)

    banded: set[int] = set()  # nodes that are a storeys proposal's bands
    while stack:
        node, idx = stack.pop()
        if depth[node] >= max_depth or len(idx) < max(params.min_points, 2):
            continue
        pts = a[idx]
        if _is_flat(pts, params):
            continue
        if node in unjoined:  # the rest of a posts split, in its parts apart whatever they are
            gap = parts(pts, params=params, stacked=True, posts_z=unjoined[node])
        else:
            gap = gaps(pts, params=params) if depth[node] == 0 else None
        if gap is not None:  # parts that do not touch: split, whatever the classifier says
            c_cls, c_sc, c_pr = _classify(classifier, [pts[c] for c in gap.children])
            _add_children(node, idx, gap.children, gap.sequence, np.full(5, np.nan), np.nan, c_cls, c_sc, c_pr)
            continue
        node_rng = np.random.default_rng(np.random.SeedSequence([base, node]))
        scored = _bays_first(node, _scored(pts, depth[node], cls[node], probs[node], node_rng))
        if not scored:
            if not _split_posts(node, idx, pts):
                _split_parts(node, idx, pts)
            continue
        x, key, (pr, e, c_cls, c_sc, c_pr) = _best(scored)
        keep = x >= thr_split
        storey = [t for t in scored if t[1] == _STOREYS]
        if not keep and storey and look_ahead and depth[node] + 1 < max_depth:
            # A storey cut is judged by what its storeys split into (the bays): the
            # storeys as the proposal was scored (cut at the bands' middles), their cuts into bays.
            st, _, k_cls, _, k_pr = storey[0][2]
            for j, child in enumerate(st.children):
                if len(child) < max(params.min_points, 2) or _is_flat(pts[child], params) \
                        or _solid_share(pts[child], params) >= OPEN_STOREY:
                    continue
                k_rng = np.random.default_rng(np.random.SeedSequence([base, node, j, _STOREYS]))
                inner = _scored(pts[child], depth[node] + 1, int(k_cls[j]), k_pr[j], k_rng, keys=_BAYS)
                if inner and _best(inner)[0] >= thr_split:
                    keep = True
                    x, key, (pr, e, c_cls, c_sc, c_pr) = storey[0]
                    break
        if not keep:
            if not _split_posts(node, idx, pts):
                _split_parts(node, idx, pts)
            continue
        children = pr.children
        if pr.kept_children is not None:  # the storeys' bands, each a child (tree/sequences.py)
            children = pr.kept_children
            c_cls, c_sc, c_pr = _classify(classifier, [pts[c] for c in children])
            for j in pr.kept_bands:  # solid across the wall's length: wall, whatever its look
                c_cls[j] = _WALL
                c_sc[j] = c_pr[j, _WALL - 1] if c_pr.shape[1] >= _WALL else c_sc[j]
        first = len(parent)
        _add_children(node, idx, children, pr.sequence, e, x, c_cls, c_sc, c_pr)
        if key == _STOREYS:
            banded.update(range(first, len(parent)))
    m = len(parent)
    nodes = NodeTable(
        node_id=np.arange(m, dtype=np.int64), parent=np.asarray(parent, dtype=np.int64),
        depth=np.asarray(depth, dtype=np.int64), sequence=np.asarray(seq, dtype=np.int8),
        terms=np.vstack(terms), xi=np.asarray(xi, dtype=np.float64),
        class_id=np.asarray(cls, dtype=np.uint8), score=np.asarray(score, dtype=np.float32),
        n_points=np.asarray(npts, dtype=np.int64), bbox=np.vstack(bbox),
        is_leaf=np.asarray(is_leaf, dtype=bool))
    return _per_point(nodes, leaf_of)


def _per_point(nodes: NodeTable, leaf_of: IntArray) -> TreeResult:
    """Per-point class, instance and score from the leaves and the element instances."""
    m = len(nodes)
    element = np.isin(nodes.class_id, np.asarray([int(c) for c in ELEMENT_CLASSES]))
    owner = np.full(m, -1, dtype=np.int64)  # element-instance node of each node, or -1
    # A split node is an element only when its children (by points) mostly agree with it.
    same = np.zeros(m, dtype=np.int64)
    for i in range(1, m):
        par = int(nodes.parent[i])
        if nodes.class_id[i] == nodes.class_id[par]:
            same[par] += int(nodes.n_points[i])
    element &= nodes.is_leaf | (2 * same >= nodes.n_points)
    # Parts cut at gaps or apart do not touch: they are different things whatever their classes.
    gap_parent = nodes.parent[np.isin(nodes.sequence, (GAP_SEQUENCE, PART_SEQUENCE, POST_SEQUENCE))
                              & (nodes.parent >= 0)]
    element[gap_parent] = False
    inst_nodes: list[int] = []
    for i in range(m):  # parents come before children (creation order)
        par = int(nodes.parent[i])
        if par >= 0 and owner[par] >= 0:
            owner[i] = owner[par]
        elif element[i]:
            owner[i] = i
            inst_nodes.append(i)
    inst_of_node = np.zeros(m, dtype=np.int64)
    for k, i in enumerate(inst_nodes):
        inst_of_node[i] = k + 1
    point_owner = owner[leaf_of]
    inside = point_owner >= 0
    instance = np.where(inside, inst_of_node[np.maximum(point_owner, 0)], 0)
    class_id = np.where(inside, nodes.class_id[np.maximum(point_owner, 0)], nodes.class_id[leaf_of])
    return TreeResult(nodes=nodes, leaf=leaf_of, class_id=class_id.astype(np.uint8),
                      instance=instance.astype(np.int64), score=nodes.score[leaf_of].astype(np.float32),
                      instance_node=np.asarray(inst_nodes, dtype=np.int64))
