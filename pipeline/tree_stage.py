"""The tree stage: the hierarchical tree with HollowNet for every element group.

Orchestration only (the recursion is ``tree/build.py``, the classifier
``hollownet/predict.py``). An element group is a run of consecutive global coarse
segments that touch (``coarse.group_gap``, docs/method.md); with grouping off it is one
segment. Groups are taken in CSR order and cut into batches of about ``batch_points``
points: small groups share a batch, a large one is a batch of its own and is never split
(sizes vary by 1000x). One Dask task per batch reads its
segments' points with one read of ``coarse/csr/xyz``, builds each tree, and writes, after
its data, its completion record. HollowNet is loaded once per worker process.

Store layout written here (``docs/store.md``)::

    tree/batches/<b>/leaf      uint64 (n,)  node id of each point's leaf (CSR order)
    tree/batches/<b>/class     uint8  (n,)  class of each point
    tree/batches/<b>/instance  uint32 (n,)  instance, numbered within the batch; 0 = none: element
                                            instances of the tree, and one instance per planar
                                            class (ground, wall, roof) and element group
    tree/batches/<b>/score     float32(n,)  the classifier's score of the leaf
    tree/sampled/<b>                        a group above max_group_points: the sample its tree
                                            was built on, with its labels; spread to the group's
                                            points by chunk-aligned spread units (then deleted)
    tree/tables/<b>.parquet                 the batch's tree nodes (``segment``: the first
                                            global segment of the node's group)
    tree/nodes.parquet                      every node of every segment, instances numbered globally
    tree/samples/<b>                        a sample of each arch, dome and wall instance (rows, frames)
    tree/merge/{instance_map, class_map}    the merge across groups, rows and frames
    tree/rows/cells                         the rows' and frames' cells, applied by the labels stage
"""

from __future__ import annotations

import functools
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from hollowtree.classes import PLANAR_CLASSES, ClassId
from hollowtree.errors import ConfigError, PipelineError
from hollowtree.pipeline.graph import in_child
from hollowtree.pipeline.timing import UNIT_BALANCE
from hollowtree.pipeline.tree_params import DEVICES, TreeStageParams
from hollowtree.threads import task_threads
from hollowtree.tiling.stage import Stage, params_hash
from hollowtree.tiling.store import CHUNK_POINTS, RunStore
from hollowtree.tree.tall import short_minarets, size_rules, slender_domes
from hollowtree.tree.verify import SHAPE_FEATURES, local_shape

__all__ = ["TreeStageParams", "tree_batch", "run_tree", "TreeReport", "plan_batches", "group_starts"]

STAGE = "tree"
SPREAD_STAGE = "tree.spread"
#: Version of the tree's algorithm (tree/): part of the stage's parameters hash and of the
#: workflow parameters a run records, so a store made by an older version is redone. What
#: each version changed is in CHANGELOG.md (and git).
TREE_ALGORITHM = "tree-v47"
#: Points sampled from each wall instance for the frames (tree/frames.py): a pier's face
#: beside a bay's jamb is a strip a few tenths of a metre wide in a facade's wall.
WALL_SAMPLE_POINTS = 16384


def _greedy_batches(sizes: list[int], target: int, alone: int | None) -> list[tuple[int, int]]:
    out: list[tuple[int, int]] = []
    lo, acc = 0, 0
    for g, n in enumerate(sizes):
        if acc and (acc + n > target or (alone and (n > alone or sizes[lo] > alone))):
            out.append((lo, g))
            lo, acc = g, 0
        acc += n
    if len(sizes) > lo:
        out.append((lo, len(sizes)))
    return out


def plan_batches(offsets: np.ndarray, batch_points: int, *, alone: int | None = None,
                 balance: float | None = None) -> list[tuple[int, int]]:
    """Consecutive segment ranges ``[lo, hi)`` (0-based rows of ``offsets``) of about
    ``batch_points`` points; a segment larger than that is a range of its own, and so is
    one above ``alone`` (``max_group_points``: built on a sample).

    With ``balance``, the batches are made larger than ``batch_points`` where needed
    (in steps of a tenth) until the largest holds at most ``balance`` times the median
    batch's points (issue 44): one large element group, which is never split, then no
    longer stands beside many batches far smaller than it. They grow to ``alone`` at most
    (or to every point, without it): a group above it is built on a sample of that many
    points, so a batch larger than that would take longer than the group beside it.

    >>> plan_batches(np.array([0, 10, 20, 100, 105, 110]), 25)
    [(0, 2), (2, 3), (3, 5)]
    >>> plan_batches(np.array([0, 10, 20, 100, 105, 110]), 25, alone=50, balance=3.0)
    [(0, 2), (2, 3), (3, 5)]
    >>> plan_batches(np.array([0, 10, 20, 100, 105, 110]), 200, alone=50)
    [(0, 2), (2, 3), (3, 5)]
    >>> plan_batches(np.array([0, 5, 10, 15, 20, 25, 30, 90]), 5, balance=3.0)
    [(0, 4), (4, 6), (6, 7)]
    >>> plan_batches(np.array([0, 5, 10, 15, 20, 25, 30, 90]), 5, alone=10, balance=3.0)
    [(0, 2), (2, 4), (4, 6), (6, 7)]
    """
    sizes = np.diff(offsets).tolist()
    target = max(int(batch_points), 1)
    out = _greedy_batches(sizes, target, alone)
    if balance is None:
        return out
    most = min(int(offsets[-1]), alone) if alone else int(offsets[-1])
    while len(out) > 1 and target < most:
        pts = np.asarray([offsets[hi] - offsets[lo] for lo, hi in out])
        if pts.max() <= balance * float(np.median(pts)):
            break
        target = min(max(target + 1, int(target * 1.1)), most)
        out = _greedy_batches(sizes, target, alone)
    return out


def _worker_threads() -> int | None:
    """One torch thread inside a Dask worker (its cores are shared with the other
    workers); the classifier's default in a plain process."""
    try:
        from distributed import get_worker

        get_worker()
    except (ImportError, ValueError):
        return None
    return 1


def _device(device: str) -> str:
    """``device`` with ``auto`` resolved in this process."""
    if device != "auto":
        return device
    import torch

    return "cuda" if torch.cuda.is_available() else "cpu"


def _load_classifier(weights: str | None, device: str = "cpu") -> None:
    """Load HollowNet in this process as :func:`tree_batch` will use it (the worker's, before
    it forks a batch's child: ``pipeline.graph.in_child``)."""
    from hollowtree.hollownet.predict import Classifier

    Classifier.get(weights, device=_device(device), num_threads=_worker_threads())


_PLANAR = np.array([int(c) for c in PLANAR_CLASSES], dtype=np.uint8)
_NODE_COLUMNS = ("segment", "node_id", "parent", "depth", "sequence", "e1", "e2", "e3", "e4", "e5", "xi",
                 "class_id", "score", "n_points", "xmin", "ymin", "zmin", "xmax", "ymax", "zmax",
                 "is_leaf", "instance", *SHAPE_FEATURES)


_BOX = ("xmin", "ymin", "zmin", "xmax", "ymax", "zmax")
#: The instance map of the merge across element groups (:mod:`tree.merge`): entry ``i``
#: is the instance that batch-global instance ``i`` belongs to (0 stays 0).
MERGE_MAP = "tree/merge/instance_map"
#: The class of each batch-global instance after the merge (:func:`tree.merge.merged_classes`:
#: a piece that joined an instance of another class takes that class); 0 = as the tree said.
MERGE_CLASS_MAP = "tree/merge/class_map"
#: The arcade cells (tree/rows.py, :class:`tree.rows.ArcadeCells`), applied by the labels stage.
ROWS = "tree/rows/cells"


def group_starts(store: RunStore) -> np.ndarray:
    """0-based row of the first segment of every element group, and the segment count
    last (``coarse/segments.parquet``'s ``group`` column; one group per segment in a
    store made before element groups)."""
    t = store.read_table("coarse/segments.parquet")
    n = t.num_rows
    if "group" not in t.column_names or n == 0:
        return np.arange(n + 1, dtype=np.int64)
    seg = np.asarray(t.column("segment").to_numpy(), dtype=np.int64)
    grp = np.asarray(t.column("group").to_numpy(), dtype=np.int64)[np.argsort(seg, kind="stable")]
    return np.r_[np.flatnonzero(np.r_[True, grp[1:] != grp[:-1]]), n].astype(np.int64)


def _group_tree(pts: np.ndarray, s: int, params: TreeStageParams, clf: Any, ground_level: float | None,
                n_inst: int) -> tuple[dict[str, np.ndarray], dict[str, list[Any]], int]:
    """The tree of one element group (its points ``pts``, store-local metres; ``s``: its
    first segment, 0-based): per-point leaf, class, instance (numbered from ``n_inst + 1``)
    and score, the node table's columns and the new instance count."""
    from hollowtree.tree.build import build_tree
    from hollowtree.tree.ground import ground_or_roof
    from hollowtree.tree.split import load_split_model

    center = pts.mean(axis=0)
    # The size rules of tree/tall.py, with the local ground in the tree's (centred) coordinates.
    clf = size_rules(clf, pillar_max_height=params.pillar_max_height, other_max_base=params.other_max_base,
                     other_max_size=params.other_max_size,
                     ground=None if ground_level is None else ground_level - center[2])
    res = build_tree(pts - center, clf, max_depth=params.max_depth, threshold=params.threshold,
                     look_ahead=params.look_ahead,
                     rng=np.random.SeedSequence([params.seed, s + 1]),
                     split=load_split_model(params.split_model) if params.decision == "split-model" else None)
    if params.roof_min_height is not None and ground_level is not None:
        res_class = ground_or_roof(res.class_id, pts[:, 2], res.leaf, ground_level, params.roof_min_height)
    else:
        res_class = res.class_id
    node_class = res.nodes.class_id
    if params.pillar_max_height is not None and len(res.instance_node):
        # A tall slender dome is a minaret, and a minaret instance not taller than a
        # pillar is a pillar (tree/tall.py).
        box = res.nodes.bbox[res.instance_node]
        height, width = box[:, 5] - box[:, 2], np.maximum(box[:, 3] - box[:, 0], box[:, 4] - box[:, 1])
        inst_class = short_minarets(slender_domes(node_class[res.instance_node], height, width,
                                                  params.pillar_max_height), height, params.pillar_max_height)
        node_class = node_class.copy()
        node_class[res.instance_node] = inst_class
        res_class = np.where(res.instance > 0, inst_class[np.maximum(res.instance, 1) - 1], res_class)
    inst = np.where(res.instance > 0, res.instance + n_inst, 0).astype(np.uint32)
    node_inst = np.zeros(len(res.nodes), np.int64)
    node_inst[res.instance_node] = np.arange(1, len(res.instance_node) + 1) + n_inst
    n_inst += len(res.instance_node)
    # Planar classes are one instance per class and element group (one tree; METHOD.md, "Classes").
    planar = np.isin(res_class, _PLANAR) & (res.instance == 0)
    for c in np.unique(res_class[planar]).tolist():
        n_inst += 1
        inst[planar & (res_class == c)] = n_inst
    d = res.nodes.to_dict()
    m = len(res.nodes)
    # The element check's shape features (tree/verify.py) of every instance node's points.
    shape = np.full((m, len(SHAPE_FEATURES)), np.nan)
    if len(res.instance_node):
        order = np.argsort(res.instance, kind="stable")
        ends = np.searchsorted(res.instance[order], np.arange(len(res.instance_node) + 2))
        for i, node in enumerate(res.instance_node.tolist()):
            shape[node] = local_shape(pts[order[ends[i + 1]:ends[i + 2]]])
    cols: dict[str, list[Any]] = {"segment": [s + 1] * m}
    for c in _NODE_COLUMNS[1:]:
        if c in SHAPE_FEATURES:
            cols[c] = shape[:, SHAPE_FEATURES.index(c)].tolist()
        elif c == "instance":
            cols[c] = node_inst.tolist()
        elif c == "class_id":
            cols[c] = node_class.tolist()
        elif c in _BOX:
            j = _BOX.index(c)
            cols[c] = (res.nodes.bbox[:, j] + center[j % 3]).tolist()
        else:
            cols[c] = np.asarray(d[c]).tolist()
    values = {"leaf": res.leaf.astype(np.uint64), "class": res_class.astype(np.uint8), "instance": inst,
              "score": res.score.astype(np.float32)}
    return values, cols, n_inst


def _sampled_group_tree(store: RunStore, b: int, lo: int, hi: int, s: int, scale: np.ndarray,
                        params: TreeStageParams, clf: Any, ground_level: float | None
                        ) -> tuple[dict[str, list[Any]], int, int]:
    """The tree of one element group above ``max_group_points``, in bounded memory: built
    on a seeded random sample of about ``max_group_points`` of its points (read chunk by
    chunk). The sample and its labels go to ``tree/sampled/<b>`` and the batch's arrays are
    made at the group's length: :func:`spread_labels` units then give every point the
    labels of its nearest sampled point and count the leaves' points (the node table's
    ``n_points``, set by :func:`_spread_counts`; its bounding boxes are the sample's).
    Returns the node columns, the instance count and the sample's size."""
    n = hi - lo
    step = max(params.max_group_points, 1_000_000)
    rng = np.random.default_rng(np.random.SeedSequence([params.seed, s + 1, 1]))
    keep = params.max_group_points / n
    parts = []
    for a in range(lo, hi, step):
        chunk = store.read_slice("coarse/csr/xyz", a, min(a + step, hi))
        parts.append(chunk[rng.random(len(chunk)) < keep])
    sample = np.concatenate(parts).astype(np.float64) * scale
    values, cols, n_inst = _group_tree(sample, s, params, clf, ground_level, 0)
    store.write_unit(f"tree/sampled/{b}", {"xyz": sample, **values})
    for k, v in values.items():
        store.create_array(f"tree/batches/{b}/{k}", shape=(n,), dtype=v.dtype)
    _write_samples(store, b, sample, values, params.seed, [(0, len(sample), s)])
    return cols, n_inst, len(sample)


def spread_labels(url: str, b: int, j: int, rows: tuple[int, int], csr: tuple[int, int], scale: list[float],
                  h: str) -> list[int]:
    """Spread task: rows ``rows = (first, end)`` of batch ``b`` (a sampled group at CSR rows
    ``csr``; ``first`` on a chunk boundary) take the labels of their nearest sampled point
    (``tree/sampled/<b>``). Returns and records the points per leaf node."""
    from scipy.spatial import cKDTree

    store = RunStore.open(url, mode="a")
    sampled = store.read_unit(f"tree/sampled/{b}")
    sample = sampled.pop("xyz")
    kd = cKDTree(sample, balanced_tree=False)  # as the tree's own: the same nearest points
    counts = np.zeros(int(sampled["leaf"].max(initial=0)) + 1, np.int64)
    step = 4 * CHUNK_POINTS
    for a in range(rows[0], rows[1], step):
        z = min(a + step, rows[1])
        pts = store.read_slice("coarse/csr/xyz", csr[0] + a, csr[0] + z).astype(np.float64) * np.asarray(scale)
        _, near = kd.query(pts, workers=task_threads(rows=len(pts)))
        for k, v in sampled.items():
            store.write_slice(f"tree/batches/{b}/{k}", a, v[near])
        counts += np.bincount(sampled["leaf"][near].astype(np.int64), minlength=len(counts))
    store.record(SPREAD_STAGE, f"{b}.{j}", {"params_hash": h, "n_points": rows[1] - rows[0],
                                             "rows": list(rows), "leaf_points": counts.tolist()})
    return counts.tolist()


def _spread_counts(store: RunStore, b: int, table: pa.Table, leaf_points: list[list[int]]) -> pa.Table:
    """A sampled batch's node table with ``n_points``: every node counts the group's points
    in its leaves (children come after their parent)."""
    parent = np.asarray(table.column("parent").to_numpy(), dtype=np.int64)
    n_leaf = np.zeros(len(parent), np.int64)
    for c in leaf_points:
        n_leaf[:len(c)] += np.asarray(c[:len(parent)], dtype=np.int64)
    for k in range(len(parent) - 1, 0, -1):
        n_leaf[parent[k]] += n_leaf[k]
    return table.set_column(table.schema.get_field_index("n_points"), "n_points",
                            pa.array(n_leaf, type=table.schema.field("n_points").type))


def _write_samples(store: RunStore, b: int, xyz: np.ndarray, values: dict[str, np.ndarray], seed: int,
                   groups: list[tuple[int, int, int]]) -> None:
    """A seeded sample of every arch and dome instance's points of batch ``b``, and of
    every wall instance's (``WALL_SAMPLE_POINTS``) (``tree/samples/<b>``: batch-local
    instance, store-local metres, points per sampled point, class), for the arcade rows
    (tree/rows.py) and the frames (tree/frames.py). ``groups``: ``(first row, end row,
    first segment)`` of each element group; each is drawn with a generator of its own, so
    a group's sample does not depend on the batch that holds it."""
    from hollowtree.tree.rows import instance_sample

    parts = []
    for a, z, s in groups:
        rng = np.random.default_rng(np.random.SeedSequence([seed, s + 1, 2]))
        inst, cls = values["instance"][a:z], values["class"][a:z]
        parts += [instance_sample(xyz[a:z], inst, cls, rng),
                  instance_sample(xyz[a:z], inst, cls, rng, n=WALL_SAMPLE_POINTS, classes=(int(ClassId.WALL),))]
    inst, pts, weight, cls = (np.concatenate([p[k] for p in parts]) for k in range(4))
    store.write_unit(f"tree/samples/{b}", {"instance": inst, "xyz": pts, "weight": weight, "class": cls})


def tree_batch(url: str, b: int, segs: tuple[int, int], cfg: dict[str, Any],
               ground: np.ndarray | None = None, starts: list[int] | None = None) -> dict[str, Any]:
    """Dask task: the trees of global segments ``segs[0] + 1 .. segs[1]`` (one batch).

    ``starts``: the 0-based first segment of every element group in the batch (one tree
    per group, built on the points of all its segments); None = one tree per segment.
    ``ground``: the local ground level of each of these segments, in the store's
    coordinates (``tree.ground.ground_levels``); used when ``roof_min_height`` or ``other_max_base`` is set
    (a group takes its segments' lowest). A batch of one group above ``max_group_points``
    is built on a sample of it (:func:`_sampled_group_tree`).
    """
    from hollowtree.hollownet.predict import Classifier

    store = RunStore.open(url, mode="a")
    params = TreeStageParams(**cfg["params"])
    scale = np.asarray(store.attrs["coords"]["scale"])
    offsets = store.read_unit("coarse/csr", ["offsets"])["offsets"]
    lo, hi = int(offsets[segs[0]]), int(offsets[segs[1]])
    n = hi - lo
    clf = Classifier.get(params.weights, device=_device(cfg.get("device", "cpu")), num_threads=_worker_threads())
    bounds = list(range(segs[0], segs[1] + 1)) if starts is None else [*starts, segs[1]]

    def ground_level(s: int, s_end: int) -> float | None:
        if ground is None:
            return None
        return float(np.min(ground[s - segs[0]:s_end - segs[0]]))

    sampled = 0
    if len(bounds) == 2 and params.max_group_points and n > params.max_group_points:
        cols, n_inst, sampled = _sampled_group_tree(store, b, lo, hi, segs[0], scale, params, clf,
                                                    ground_level(segs[0], segs[1]))
        cols["n_points"] = [0] * len(cols["node_id"])  # the spread units count them
    else:
        xyz = store.read_slice("coarse/csr/xyz", lo, hi).astype(np.float64) * scale
        out = {"leaf": np.zeros(n, np.uint64), "class": np.zeros(n, np.uint8), "instance": np.zeros(n, np.uint32),
               "score": np.zeros(n, np.float32)}
        cols = {c: [] for c in _NODE_COLUMNS}
        n_inst = 0
        groups = []
        for s, s_end in zip(bounds[:-1], bounds[1:], strict=True):
            a, z = int(offsets[s]) - lo, int(offsets[s_end]) - lo
            groups.append((a, z, s))
            values, group_cols, n_inst = _group_tree(xyz[a:z], s, params, clf, ground_level(s, s_end), n_inst)
            for k, v in values.items():
                out[k][a:z] = v
            for c in _NODE_COLUMNS:
                cols[c] += group_cols[c]
        store.write_unit(f"tree/batches/{b}", out)
        _write_samples(store, b, xyz, out, params.seed, groups)
    store.write_table(f"tree/tables/{b}.parquet", pa.table(cols))
    # a sampled group's unit holds its sample; the spread units hold its points
    info = {"params_hash": cfg["params_hash"], "n_segments": segs[1] - segs[0], "n_points": sampled or n,
            "n_nodes": len(cols["segment"]), "n_instances": n_inst, "csr": [lo, hi], "sampled": sampled}
    store.record(STAGE, str(b), info)
    return info


@dataclass(frozen=True, kw_only=True)
class TreeReport:
    n_segments: int
    n_groups: int
    n_batches: int
    batches_run: int
    n_nodes: int
    n_instances: int
    seconds: float
    n_merged: int = 0

    def summary(self) -> str:
        return (f"tree: {self.n_segments:,} segments in {self.n_groups:,} element groups, {self.n_batches} batches ({self.batches_run} run, "
                f"{self.n_batches - self.batches_run} skipped); {self.n_nodes:,} nodes, "
                f"{self.n_instances:,} instances ({self.n_merged:,} merged across groups); {self.seconds:.1f} s")


def _ground_levels(store: RunStore) -> np.ndarray:
    """Local ground level of every global segment (row g-1 for segment g), in the
    store's coordinates, from the coarse segment table's bounding boxes."""
    from hollowtree.tree.ground import ground_levels

    t = store.read_table("coarse/segments.parquet")
    cols = {c: np.asarray(t.column(c).to_numpy(), dtype=np.float64)
            for c in ("segment", "xmin", "ymin", "zmin", "xmax", "ymax", "zmax", "n_points")}
    order = np.argsort(cols["segment"], kind="stable")
    bbox = np.stack([cols[c][order] for c in ("xmin", "ymin", "zmin", "xmax", "ymax", "zmax")], axis=1)
    z0 = float(store.attrs["coords"]["offset"][2])
    return ground_levels(bbox, n_points=cols["n_points"][order], min_points=200) - z0


def run_tree(url: str, params: TreeStageParams, *, runner: Any, device: str = "cpu") -> TreeReport:
    """Run the tree stage on a store whose coarse stage is complete (resumable per batch).

    ``device`` (:data:`DEVICES`) is where each worker runs HollowNet; it is not a
    parameter of the result (a store's batches may come from workers of either kind).
    On a GPU a batch runs in its worker, not in a forked child (CUDA does not survive a
    fork).
    """
    if device not in DEVICES:
        raise ConfigError(f"tree device must be one of {list(DEVICES)}; got {device!r}")
    t0 = time.perf_counter()
    store = RunStore.open(url, mode="a")
    attrs = store.attrs
    stages = attrs.get("stages", {})
    coarse = stages.get("coarse", {})
    if not coarse or coarse.get("done") != coarse.get("units"):
        raise PipelineError(f"store {url}: the coarse stage is not complete; run it first")
    h = params_hash([params.to_dict(), coarse["params_hash"], TREE_ALGORITHM, model_fingerprints(params)])
    cfg = {"params": params.to_dict(), "params_hash": h, "device": device}
    stage = Stage(store, STAGE, h, unit_stages=(SPREAD_STAGE,))
    completed = stage.last.get("params_hash") == h
    stage.clear_if_changed()
    offsets = store.read_unit("coarse/csr", ["offsets"])["offsets"]
    # Batches of whole element groups (a group is a run of consecutive segments).
    starts = group_starts(store)
    batches = [(int(starts[g0]), int(starts[g1])) for g0, g1 in
               plan_batches(offsets[starts], params.batch_points, alone=params.max_group_points or None,
                            balance=UNIT_BALANCE)]
    # A record counts only for the batch it was made for (batches planned otherwise before).
    done = {k: v for k, v in stage.done().items() if k.isdigit() and int(k) < len(batches)
            and v.get("csr") == [int(offsets[batches[int(k)][0]]), int(offsets[batches[int(k)][1]])]}
    todo = [b for b in range(len(batches)) if str(b) not in done]
    ground = _ground_levels(store) if todo and (params.roof_min_height is not None
                                                or params.other_max_base is not None) else None

    def starts_in(b: int) -> list[int]:
        lo, hi = batches[b]
        return starts[(starts >= lo) & (starts < hi)].tolist()

    # Each batch in a child process of its worker (in_child), HollowNet loaded once in the
    # worker before its first fork: a long-lived worker's later batches otherwise peak
    # above its first (what its heap and torch kept of the earlier ones).
    task = tree_batch if device != "cpu" else in_child(tree_batch, functools.partial(_load_classifier, params.weights))
    results = runner(task,
                     [(url, b, batches[b], cfg, None if ground is None else ground[slice(*batches[b])],
                       starts_in(b)) for b in todo], "tree: batches")
    for b, info in zip(todo, results, strict=True):
        done[str(b)] = info
    infos = [done[str(b)] for b in range(len(batches))]
    spread = _spread(store, infos, h, runner)
    inst_offsets = np.r_[0, np.cumsum([i["n_instances"] for i in infos])].astype(np.int64)
    if todo or not completed:
        tables = []
        for b in range(len(batches)):
            t = store.read_table(f"tree/tables/{b}.parquet")
            if b in spread:
                t = _spread_counts(store, b, t, spread[b])
                store.write_table(f"tree/tables/{b}.parquet", t)
            inst = np.asarray(t.column("instance").to_numpy(), dtype=np.int64)
            t = t.set_column(t.schema.get_field_index("instance"), "instance",
                             pa.array(np.where(inst > 0, inst + inst_offsets[b], 0)))
            tables.append(t)
        nodes = pa.concat_tables(tables) if tables else None
        imap, cmap = _merge_map(nodes, int(inst_offsets[-1]))
        if nodes is not None and params.verify:
            _check_elements(nodes, imap, cmap, _ground_levels(store), params.verify_model)
        cells = _arcade_rows(store, len(batches), inst_offsets, imap, cmap)
        store.write_unit(ROWS.rsplit("/", 1)[0], cells.to_arrays())
        if nodes is not None:
            inst = np.asarray(nodes.column("instance").to_numpy(), dtype=np.int64)
            nodes = nodes.set_column(nodes.schema.get_field_index("instance"), "instance",
                                     pa.array(imap[inst].astype(np.int64)))
            cls = np.asarray(nodes.column("class_id").to_numpy()).copy()
            cls[inst > 0] = np.where(cmap[inst[inst > 0]] > 0, cmap[inst[inst > 0]], cls[inst > 0])
            nodes = nodes.set_column(nodes.schema.get_field_index("class_id"), "class_id",
                                     pa.array(cls, type=nodes.schema.field("class_id").type))
            store.write_table("tree/nodes.parquet", nodes)
        store.write_unit("tree/merge", {"instance_map": imap, "class_map": cmap})
    n_merged = int(np.count_nonzero(store.read_slice(MERGE_MAP) != np.arange(int(inst_offsets[-1]) + 1))) \
        if store.has(MERGE_MAP) else 0
    n_nodes = sum(int(i["n_nodes"]) for i in infos)
    stage.finish(len(batches), params=params.to_dict(), batches=[i["csr"] for i in infos],
                 instance_offsets=inst_offsets[:-1].tolist())
    return TreeReport(n_segments=len(offsets) - 1, n_groups=len(starts) - 1, n_batches=len(batches), batches_run=len(todo),
                      n_nodes=n_nodes, n_instances=int(inst_offsets[-1]) - n_merged, n_merged=n_merged,
                      seconds=time.perf_counter() - t0)


def _spread(store: RunStore, infos: list[dict[str, Any]], h: str, runner: Any) -> dict[int, list[list[int]]]:
    """Run the spread units of the sampled batches (units of about the median batch's
    points, whole chunks; recorded ones skipped); their leaf counts by batch."""
    pts = sorted(int(i["n_points"]) for i in infos if int(i["n_points"]) > 0)
    step = max(1, round(pts[len(pts) // 2] / CHUNK_POINTS)) * CHUNK_POINTS if pts else CHUNK_POINTS
    done = Stage(store, STAGE, h).done(SPREAD_STAGE)
    scale = [float(v) for v in store.attrs["coords"]["scale"]]
    units, plan = [], {}
    for b, info in enumerate(infos):
        if not info.get("sampled"):
            continue
        lo, hi = info["csr"]
        n = hi - lo
        k = -(-n // step)
        width = -(-n // k)
        width = -(-width // CHUNK_POINTS) * CHUNK_POINTS  # whole chunks per unit
        plan[b] = [(j, (j * width, min((j + 1) * width, n))) for j in range(k) if j * width < n]
        units += [(store.url, b, j, r, (lo, hi), scale, h) for j, r in plan[b]
                  if done.get(f"{b}.{j}", {}).get("rows") != list(r)]
    if units:
        runner(spread_labels, units, "tree: spread")
        done = Stage(store, STAGE, h).done(SPREAD_STAGE)
    out = {b: [done[f"{b}.{j}"]["leaf_points"] for j, _ in p] for b, p in plan.items()}
    store.delete("tree/sampled")
    return out


def _arcade_rows(store: RunStore, n_batches: int, inst_offsets: np.ndarray, imap: np.ndarray,
                 cmap: np.ndarray) -> Any:
    """The arcade cells (tree/rows.py) from the batches' arch and dome samples, after the
    merge; an arch instance absorbed by a bay is folded into ``imap`` (in place), a dome
    instance absorbed by a row maps to 0 (no instance; its points in the cells join their
    bays). Then the frames (tree/frames.py) of the arch instances in no row: a face joins
    its passage (``imap``; a wall face takes class arch in ``cmap``), and a lone piece's
    cell follows the rows' cells."""
    from hollowtree.tree.frames import frame_cells
    from hollowtree.tree.rows import ArcadeCells, arcade_cells

    arch, dome, wall = int(ClassId.ARCH), int(ClassId.DOME), int(ClassId.WALL)
    parts: dict[int, dict[int, list[tuple[np.ndarray, np.ndarray]]]] = {arch: {}, dome: {}, wall: {}}
    for b in range(n_batches):
        if not store.has(f"tree/samples/{b}"):
            continue
        d = store.read_unit(f"tree/samples/{b}", ["instance", "xyz", "weight", "class"])
        inst = d["instance"].astype(np.int64) + inst_offsets[b]
        final = np.where(cmap[inst] > 0, cmap[inst], d["class"]).astype(np.int64)  # after the merge
        merged = imap[inst].astype(np.int64)
        for c in (arch, dome, wall):
            keep = final == c
            for i in np.unique(merged[keep]).tolist():
                m = keep & (merged == i)
                parts[c].setdefault(int(i), []).append((d["xyz"][m], d["weight"][m]))
    samples = {c: {i: (np.concatenate([p for p, _ in v]), np.concatenate([w for _, w in v])) for i, v in by.items()}
               for c, by in parts.items()}
    cells, absorbed = arcade_cells(samples[arch], int(inst_offsets[-1]) + 1, domes=samples[dome])
    for j, i in absorbed.items():
        imap[imap == j] = i
    skip = set(cells.instance.tolist()) | set(absorbed)
    next_id = max([int(inst_offsets[-1]) + 1, *(int(i) + 1 for i in cells.instance.tolist())])
    frames, joined = frame_cells(samples[arch], samples[wall], skip, next_id=next_id)
    for f, a in joined.items():
        members = np.flatnonzero(imap == f)
        imap[members] = a
        cmap[members] = arch
    if not len(frames):
        return cells
    return ArcadeCells(*(np.concatenate([x, y]) for x, y in ((cells.frame, frames.frame), (cells.box, frames.box),
                                                             (cells.instance, frames.instance),
                                                             (cells.take, frames.take), (cells.trim, frames.trim))))


def element_instances(nodes: pa.Table, imap: np.ndarray, cmap: np.ndarray,
                      ground: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`tree.verify.instance_features` of the element instances after the merge
    (``imap`` and ``cmap`` of :func:`_merge_map`; ``nodes`` with batch-global instances),
    each node on the ground of its segment (``ground``: :func:`_ground_levels`)."""
    from hollowtree.tree.verify import instance_features

    col = {c: np.asarray(nodes.column(c).to_numpy()) for c in ("instance", "class_id", "score", "n_points", "depth",
                                                                 "segment", *_BOX)}
    inst = col["instance"].astype(np.int64)
    cls = np.where((inst > 0) & (cmap[inst] > 0), cmap[inst], col["class_id"]).astype(np.int64)
    seg = col["segment"].astype(np.int64)
    known = (seg >= 1) & (seg <= len(ground))
    g = np.full(len(seg), np.nan)
    g[known] = ground[seg[known] - 1]
    names = set(nodes.column_names)
    shape = (np.column_stack([np.asarray(nodes.column(c).to_numpy(), dtype=np.float64) for c in SHAPE_FEATURES])
             if names.issuperset(SHAPE_FEATURES) else None)
    return instance_features(np.where(inst > 0, imap[inst], 0), cls, col["score"], col["n_points"],
                             np.column_stack([col[c] for c in _BOX]), col["depth"], seg, g, shape)


def _file_hash(path: Path) -> str:
    import hashlib

    return hashlib.sha256(path.read_bytes()).hexdigest()[:16]


def check_fingerprint(params: TreeStageParams) -> str | None:
    """What the element check's file holds (a hash), so a store reruns its tree when the
    check changes under the same path; None when the check is off."""
    from hollowtree.tree.verify import DEFAULT_VERIFY_PATH, load_verify_model

    if not params.verify:
        return None
    path = DEFAULT_VERIFY_PATH if params.verify_model is None else Path(params.verify_model)
    try:
        load_verify_model(path)  # a bad file is refused before any batch runs
    except ConfigError as e:
        raise ConfigError(f"tree.verify_model: {e}") from None
    return _file_hash(path)


def model_fingerprints(params: TreeStageParams) -> dict[str, str | None]:
    """Hashes of what the tree's files hold (HollowNet's weights, the split model when the
    decision uses it, the element check when it is on), so a file rewritten under the same
    path (a refit with ``--out`` over it) redoes the tree."""
    from hollowtree.hollownet import DEFAULT_WEIGHTS
    from hollowtree.tree.split import DEFAULT_SPLIT_PATH

    weights = DEFAULT_WEIGHTS if params.weights is None else Path(params.weights)
    split = DEFAULT_SPLIT_PATH if params.split_model is None else Path(params.split_model)
    try:
        hollownet = _file_hash(weights)
    except OSError as e:
        raise ConfigError(f"tree.weights: {weights} cannot be read: {e.strerror or e}") from None
    return {"check": check_fingerprint(params), "hollownet": hollownet,
            "split": _file_hash(split) if params.decision == "split-model" else None}


def _check_elements(nodes: pa.Table, imap: np.ndarray, cmap: np.ndarray, ground: np.ndarray,
                    model: str | None) -> None:
    """The element check (tree/verify.py) of every element instance after the merge: an
    instance it gives another class, ``other`` among them, takes it in ``cmap`` (in place)."""
    from hollowtree.tree.verify import load_verify_model

    ids, cls, feats = element_instances(nodes, imap, cmap, ground)
    if not len(ids):
        return
    new = load_verify_model(model).decide(feats)
    at = np.minimum(np.searchsorted(ids, imap), len(ids) - 1)
    changed = (ids[at] == imap) & (new[at] != cls[at])
    cmap[changed] = new[at[changed]]


def _merge_map(nodes: pa.Table | None, n_instances: int) -> tuple[np.ndarray, np.ndarray]:
    """The instance map of :func:`tree.merge.merge_instances` over every instance node, and
    the class of every instance after it (:func:`tree.merge.merged_classes`)."""
    from hollowtree.tree.merge import merge_instances, merged_classes

    if nodes is None or nodes.num_rows == 0:
        return np.arange(n_instances + 1, dtype=np.uint32), np.zeros(n_instances + 1, dtype=np.uint8)
    inst = np.asarray(nodes.column("instance").to_numpy(), dtype=np.int64)
    sel = np.flatnonzero(inst > 0)
    col = {c: np.asarray(nodes.column(c).to_numpy())[sel] for c in ("class_id", "segment", *_BOX)}
    imap = merge_instances(inst[sel], col["class_id"], col["segment"], np.column_stack([col[c] for c in _BOX]),
                           n_instances)
    return imap, merged_classes(inst[sel], col["class_id"], imap)
