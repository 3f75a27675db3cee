"""``hollowtree evaluate``: the paper's Table 1 on labelled scans, with two baselines.

For every input (a synthetic site name, a LAS/LAZ with ``gt_class``/``gt_instance``, or
an existing run store of such a scan) the driver runs the workflow (resuming what the
store holds) or reads the store, then scores three methods on the same points:

``ransac``
    Efficient RANSAC primitives alone (the paper's Fig. 1 (b)). The store does not keep
    per-point RANSAC primitive ids; it keeps each tile's coarse segments with their
    primitive's fit parameters. A tile's segments with the same kind and parameters come
    from one fit, so they are one primitive; tile primitives are joined across tiles
    through the stitched (global) coarse segments ("stitched primitive groups"). Points no
    primitive explains ("free" segments) are unlabelled here, and so are the few RANSAC
    inliers that DBSCAN then left as noise (they are not recoverable from the store).
``ransac+dbscan``
    The global coarse segments (Fig. 1 (c)), free segments included.
``tree``
    The full pipeline's per-point class and instance (``labels/``).

The baselines have no classes of their own: each of their segments is classified as a
whole by HollowNet (:meth:`hollownet.predict.Classifier.get`, the weights the tree used)
and is one instance of that class. Ground truth is streamed from the input files (1 M
records at a time, in input order) beside the store's label arrays and scored with the
kernels of :mod:`scenes.metrics`; the driver never holds more than one chunk of points
plus per-segment tables.
"""

from __future__ import annotations

import datetime as _dt
import json
import os
import platform
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from hollowtree.classes import ELEMENT_CLASSES
from hollowtree.errors import ConfigError, InputFileError
from hollowtree.pipeline.labels import LEAF_BITS, require_labels
from hollowtree.pipeline.workflow import shipped_workflows
from hollowtree.scenes.metrics import Evaluation, LabelCounts, count_labels, score_counts
from hollowtree.tiling.readers import SUFFIXES, probe, read_blocks
from hollowtree.tiling.store import RunStore

__all__ = ["METHODS", "GT_DIMS", "DEFAULT_WORKFLOW", "SiteResult", "evaluate_inputs", "evaluate_store", "machine",
           "format_table", "primitive_groups", "draw_panels", "seed_spread", "format_spread"]

#: The three methods, in the order of the paper's Fig. 1 (b), (c), (d).
METHODS = ("ransac", "ransac+dbscan", "tree")
GT_DIMS = ("gt_class", "gt_instance")
DEFAULT_WORKFLOW = shipped_workflows() / "local.yaml"
_CHUNK = 1_000_000
#: Largest segment handed to HollowNet whole; bigger ones are classified from a seeded
#: random subset of this many points (its hollow-voxel grid hardly changes).
MAX_CLASSIFY_POINTS = 2_000_000
NOTES = {
    "ransac": "stitched RANSAC primitives (tile segments with identical fits, joined across tiles through the "
              "global coarse segments); points of no primitive and RANSAC inliers that DBSCAN left as noise "
              "are unlabelled; each primitive classified whole by HollowNet (ground or roof by height, as in the tree "
              "stage) and taken as one instance",
    "ransac+dbscan": "global coarse segments (free segments included), each classified whole by HollowNet "
                     "(ground or roof by height, as in the tree stage) and taken as one instance",
    "tree": "labels/class and labels/instance of the full pipeline",
}


@dataclass(frozen=True, kw_only=True)
class SiteResult:
    """The scores of the three methods on one scan."""

    name: str
    input: str
    store: str
    n_points: int
    pipeline_seconds: float | None
    evaluate_seconds: float
    methods: dict[str, Evaluation]
    n_segments: int
    n_primitives: int
    pipeline_log: tuple[str, ...] = ()
    #: ``{"coarse": coarse.seed, "tree": tree.seed}`` of the run, where evaluate ran it
    seeds: dict[str, int] | None = None

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "input": self.input, "store": self.store, "n_points": self.n_points,
                "seeds": self.seeds,
                "pipeline_seconds": None if self.pipeline_seconds is None else round(self.pipeline_seconds, 2),
                "evaluate_seconds": round(self.evaluate_seconds, 2), "pipeline_log": list(self.pipeline_log),
                "n_segments": self.n_segments, "n_primitives": self.n_primitives,
                "methods": {m: {**ev.to_dict(), "note": NOTES[m]} for m, ev in self.methods.items()}}


# ------------------------------------------------------------------------------ baselines
def primitive_groups(store: RunStore) -> tuple[np.ndarray, int]:
    """Stitched RANSAC primitive of every global coarse segment (0 for free segments).

    Returns ``(group_of, n_groups)``: ``group_of[g]`` for global segment ``g`` (index 0 is
    "no segment"), groups numbered 1..n_groups in order of their lowest global segment.
    """
    from hollowtree.primitives.stitch import UnionFind

    n_seg = int(store.attrs["stages"]["coarse"]["n_segments"])
    kinds = store.read_table("coarse/segments.parquet").column("kind").to_pylist()
    keys: dict[tuple[int, str, str], int] = {}
    a_list, b_list = [], []
    for t in (int(t) for t in store.attrs["ingest"]["tiles"]):
        table = store.read_table(f"coarse/tables/{t}.parquet").to_pydict()
        arrays = store.read_unit(f"coarse/tiles/{t}", ["segment", "global"])
        has = arrays["global"] > 0
        if not has.any():
            continue
        code = np.unique(arrays["segment"][has].astype(np.int64) * (n_seg + 1) + arrays["global"][has].astype(np.int64))
        key_of = {s: (t, k, p) for s, k, p in zip(table["segment"], table["kind"], table["params"], strict=True)}
        for local, glob in zip((code // (n_seg + 1)).tolist(), (code % (n_seg + 1)).tolist(), strict=True):
            key = key_of[local]
            if key[1] == "free":
                continue
            a_list.append(glob)
            b_list.append(n_seg + 1 + keys.setdefault(key, len(keys)))
    uf = UnionFind(n_seg + 1 + len(keys))
    if a_list:
        uf.union_pairs(np.asarray(a_list), np.asarray(b_list))
    roots = uf.find(np.arange(n_seg + 1))
    primitive = np.array([False] + [k != "free" for k in kinds], dtype=bool)
    group_of = np.zeros(n_seg + 1, dtype=np.int64)
    if primitive.any():
        _, first, inv = np.unique(roots[primitive], return_index=True, return_inverse=True)
        rank = np.argsort(np.argsort(first))  # number groups by their lowest segment id
        group_of[primitive] = rank[inv.reshape(-1)] + 1
    return group_of, int(group_of.max(initial=0))


def _classify_groups(store: RunStore, group_of: np.ndarray, n_groups: int, clf: Any, *, seed: int = 0,
                     ground: np.ndarray | None = None, roof_min_height: float | None = None,
                     sizes: dict[str, float | None] | None = None) -> np.ndarray:
    """HollowNet class of every group of global segments (index 0: class 0).

    With ``ground`` (the local ground level of every global segment, index 0 unused,
    store coordinates) and ``roof_min_height``, a group classed ground or roof is
    decided by its median height as the tree stage decides a leaf
    (``tree.ground.ground_or_roof``), so the baselines get the same correction.
    ``sizes``: the bounds of ``tree.tall.size_rules`` (``pillar_max_height``,
    ``other_max_base``, ``other_max_size``), applied to every group as the tree stage
    applies them to every part (the base test needs ``ground``); None: HollowNet's class.
    """
    from hollowtree.tree.ground import ground_or_roof
    from hollowtree.tree.tall import size_rules

    offsets = store.read_unit("coarse/csr", ["offsets"])["offsets"]
    scale = np.asarray(store.attrs["coords"]["scale"])
    order = np.argsort(group_of, kind="stable")
    bounds = np.searchsorted(group_of[order], np.arange(n_groups + 2))
    out = np.zeros(n_groups + 1, dtype=np.uint8)
    rng = np.random.default_rng(seed)
    batch: list[np.ndarray] = []
    ids: list[int] = []
    batch_z: list[np.ndarray] = []
    batch_ground: list[float] = []
    batch_mean_z: list[float] = []

    def flush() -> None:
        if batch:
            ruled = clf
            if sizes is not None:
                # Each part is centred: its ground in its own coordinates.
                g = None if ground is None else np.array(batch_ground) - np.array(batch_mean_z)
                ruled = size_rules(clf, ground=g, **sizes)
            cls = np.asarray(ruled.predict(batch).class_id, dtype=np.uint8)
            if ground is not None and roof_min_height is not None:
                for j in range(len(ids)):
                    z = batch_z[j]
                    if len(z):
                        cls[j] = ground_or_roof(cls[j:j + 1], np.array([np.median(z)]), np.zeros(1, np.int64),
                                                float(batch_ground[j]), roof_min_height)[0]
            out[np.asarray(ids)] = cls
            batch.clear()
            ids.clear()
            batch_z.clear()
            batch_ground.clear()
            batch_mean_z.clear()

    for gid in range(1, n_groups + 1):
        segs = order[bounds[gid]:bounds[gid + 1]]
        parts = [store.read_slice("coarse/csr/xyz", int(offsets[s - 1]), int(offsets[s])) for s in segs.tolist()]
        xyz = np.concatenate(parts) if parts else np.zeros((0, 3), np.int32)
        if len(xyz) > MAX_CLASSIFY_POINTS:
            xyz = xyz[np.sort(rng.choice(len(xyz), MAX_CLASSIFY_POINTS, replace=False))]
        pts = xyz.astype(np.float64) * scale
        mean = pts.mean(axis=0) if len(pts) else np.zeros(3)
        batch.append(pts - mean)
        batch_mean_z.append(float(mean[2]))
        ids.append(gid)
        batch_z.append(pts[:, 2])
        batch_ground.append(float(ground[segs].min()) if ground is not None and len(segs) else 0.0)
        if sum(len(b) for b in batch) >= MAX_CLASSIFY_POINTS:
            flush()
    flush()
    return out


# ------------------------------------------------------------------------------ scoring
def _check_gt(path: str) -> None:
    info = probe(path)
    for dim in GT_DIMS:
        if dim not in info.extra_dims:
            raise ConfigError(f"{path}: no {dim} dimension; evaluate needs per-point ground truth "
                              f"({' and '.join(GT_DIMS)})")


def evaluate_store(
    store: RunStore, *, name: str, input_: str = "", pipeline_seconds: float | None = None,
    pipeline_log: Sequence[str] = (), iou_threshold: float = 0.5, n_sample: int = 200_000,
    say: Callable[[str], None] = print,
) -> tuple[SiteResult, dict[str, np.ndarray]]:
    """Score the three methods on a finished run store against its inputs' ground truth.

    Returns the :class:`SiteResult` and a sample of at most ``n_sample`` points for the
    figure (``xyz``, ``intensity`` and each method's per-point colour key).
    """
    from hollowtree.hollownet.predict import Classifier

    t0 = time.perf_counter()
    require_labels(store)
    attrs = store.attrs
    sources = attrs["sources"]
    for s in sources:
        if not Path(s["path"]).is_file():
            raise InputFileError(f"input {s['path']} of store {store.url} is gone; cannot read its ground truth")
        _check_gt(s["path"])
    n_total = int(sum(int(s["point_count"]) for s in sources))
    group_of, n_groups = primitive_groups(store)
    n_seg = len(group_of) - 1
    clf = Classifier.get((attrs.get("workflow", {}).get("tree") or {}).get("weights"))
    tree_cfg = attrs.get("workflow", {}).get("tree") or {}
    # The baselines get the tree stage's size rules on every part too (tree/tall.py; a store
    # written before a rule existed has no key for it and gets the rule's default), but for
    # the base test of the clutter rule: it holds for whole objects, and a baseline's
    # segment is a piece (a tree's crown, above its trunk, does not stand on the ground).
    from hollowtree.pipeline.tree_stage import TreeStageParams

    defaults = TreeStageParams()
    sizes = {k: tree_cfg.get(k, getattr(defaults, k)) for k in ("pillar_max_height", "other_max_size")}
    sizes["other_max_base"] = None
    say(f"evaluate: {name}: classifying {n_seg:,} coarse segments and {n_groups:,} RANSAC primitives with HollowNet")
    roof_min_height = tree_cfg.get("roof_min_height")
    ground = None
    if roof_min_height is not None:
        from hollowtree.pipeline.tree_stage import _ground_levels

        ground = np.r_[np.inf, _ground_levels(store)]  # index 0: no segment
    seg_class = _classify_groups(store, np.arange(n_seg + 1), n_seg, clf, ground=ground,
                                 roof_min_height=roof_min_height, sizes=sizes)
    prim_class = _classify_groups(store, group_of, n_groups, clf, ground=ground, roof_min_height=roof_min_height,
                                  sizes=sizes)
    say(f"evaluate: {name}: scoring {n_total:,} points")
    acc = {m: LabelCounts.empty() for m in METHODS}
    rng = np.random.default_rng(0)
    p_keep = min(1.0, n_sample / max(n_total, 1))
    sample: dict[str, list[np.ndarray]] = {k: [] for k in ("xyz", "intensity", "ransac", "ransac+dbscan", "tree")}
    base = 0
    for s in sources:
        for block in read_blocks(s["path"], chunk_size=_CHUNK):
            if not len(block):
                continue
            idx = block.index.astype(np.int64) + base
            lo, hi = int(idx[0]), int(idx[-1]) + 1
            at = idx - lo
            lab = {k: store.read_slice(f"labels/{k}", lo, hi)[at] for k in ("class", "instance", "segment")}
            coarse = (lab["segment"] >> np.uint64(LEAF_BITS)).astype(np.int64)
            prim = group_of[coarse]
            pred = {"ransac": (prim_class[prim], prim), "ransac+dbscan": (seg_class[coarse], coarse),
                    "tree": (lab["class"], lab["instance"])}
            gc, gi = block.extra["gt_class"], block.extra["gt_instance"]
            for m in METHODS:
                acc[m] = acc[m].merge(count_labels(gc, gi, *pred[m]))
            keep = rng.random(len(idx)) < p_keep
            sample["xyz"].append(block.xyz[keep])
            sample["intensity"].append(block.intensity[keep] if block.intensity is not None
                                       else np.zeros(int(keep.sum()), np.uint16))
            sample["ransac"].append(prim[keep])
            sample["ransac+dbscan"].append(coarse[keep])
            sample["tree"].append(lab["class"][keep].astype(np.int64))
        base += int(s["point_count"])
    methods = {m: score_counts(acc[m], iou_threshold=iou_threshold) for m in METHODS}
    result = SiteResult(name=name, input=input_ or ", ".join(s["path"] for s in sources), store=store.url,
                        n_points=n_total, pipeline_seconds=pipeline_seconds,
                        evaluate_seconds=time.perf_counter() - t0, methods=methods, n_segments=n_seg,
                        n_primitives=n_groups, pipeline_log=tuple(pipeline_log))
    return result, {k: np.concatenate(v) if v else np.zeros(0) for k, v in sample.items()}


# ------------------------------------------------------------------------------ output
def _fmt(v: float | None, width: int) -> str:
    return f"{'NA':>{width}}" if v is None else f"{v:>{width}.1f}"


def format_table(result: SiteResult) -> str:
    """The paper's Table 1 columns (GT, AG, Acc %) plus predicted, precision and point IoU."""
    ran = "not run" if result.pipeline_seconds is None else f"{result.pipeline_seconds:.1f} s"
    lines = [f"{result.name}: {result.n_points:,} points; pipeline {ran}, evaluation {result.evaluate_seconds:.1f} s",
             f"  {'method':<15}{'class':<9}{'GT':>5}{'AG':>5}{'Acc %':>8}{'pred':>6}{'prec %':>8}{'IoU %':>8}"]
    for m, ev in result.methods.items():
        for i, c in enumerate(ELEMENT_CLASSES):
            s = ev.score(int(c))
            lines.append(f"  {m if i == 0 else '':<15}{s.name:<9}{s.n_gt:>5}{s.n_found:>5}{_fmt(s.accuracy_pct, 8)}"
                         f"{s.n_pred:>6}{_fmt(s.precision_pct, 8)}{_fmt(s.iou_pct, 8)}")
        n_present = sum(1 for c in ev.classes if c.gt_points > 0)
        lines.append(f"  {'':<15}mean point IoU over {n_present} classes: {_fmt(ev.mean_iou_pct, 0).strip()} %")
    return "\n".join(lines)


def _write_json(path: Path, payload: dict[str, Any]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.partial")
    tmp.write_text(json.dumps(payload, indent=2) + "\n")
    os.replace(tmp, path)


def _oblique(xyz: np.ndarray, *, azimuth_deg: float = -35.0, elevation_deg: float = 30.0) -> tuple[np.ndarray, np.ndarray]:
    """Screen coordinates (u, v) of an oblique parallel view and the far-to-near drawing order."""
    a, e = np.radians(azimuth_deg), np.radians(elevation_deg)
    x, y, z = (xyz - xyz.min(axis=0)).T if len(xyz) else np.zeros((3, 0))
    u = x * np.cos(a) - y * np.sin(a)
    depth = x * np.sin(a) + y * np.cos(a)
    v = z * np.cos(e) + depth * np.sin(e)
    return np.c_[u, v], np.argsort(-(depth * np.cos(e) - z * np.sin(e)), kind="stable")


def _id_colours(ids: np.ndarray) -> np.ndarray:
    """A distinct colour per segment id (golden-ratio hues); id 0 light grey."""
    from matplotlib.colors import hsv_to_rgb

    ids = np.asarray(ids, dtype=np.int64)
    h = (ids * 0.6180339887) % 1.0
    sv = np.c_[h, 0.55 + 0.4 * ((ids * 7) % 3) / 2, 0.95 - 0.25 * ((ids * 5) % 2)]
    rgb = hsv_to_rgb(sv)
    rgb[ids == 0] = (0.85, 0.85, 0.85)
    return rgb


def draw_panels(sample: dict[str, np.ndarray], out: Path, *, title: str) -> Path:
    """The paper's result figure: (a) cloud by height, (b) RANSAC, (c) DBSCAN, (d) ours by class."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch

    from hollowtree.classes import CLASS_NAMES
    from hollowtree.pipeline.export import CLASS_COLOURS

    uv, order = _oblique(sample["xyz"])
    span = np.ptp(uv, axis=0) if len(uv) else np.ones(2)
    w = 8.0
    h = float(np.clip(w * span[1] / max(span[0], 1e-6), 2.0, 12.0))
    fig, axes = plt.subplots(2, 2, figsize=(2 * w, 2 * h + 1.2), dpi=90)
    z = sample["xyz"][:, 2] if len(uv) else np.zeros(0)
    colours = [plt.get_cmap("viridis")((z - z.min()) / max(np.ptp(z), 1e-6)) if len(z) else np.zeros((0, 4)),
               _id_colours(sample["ransac"]), _id_colours(sample["ransac+dbscan"]),
               CLASS_COLOURS[sample["tree"].astype(np.int64)]]
    titles = ["(a) point cloud, coloured by height", f"(b) RANSAC primitives ({len(np.unique(sample['ransac'])) - 1} drawn)",
              f"(c) RANSAC + DBSCAN segments ({len(np.unique(sample['ransac+dbscan'])) - 1} drawn)",
              "(d) ours: hierarchical tree + HollowNet, by class"]
    for ax, col, t in zip(axes.ravel(), colours, titles, strict=True):
        ax.scatter(uv[order, 0], uv[order, 1], c=col[order], s=0.4, linewidths=0)
        ax.set_aspect("equal")
        ax.set_axis_off()
        ax.set_title(t, fontsize=11)
    present = sorted(set(np.unique(sample["tree"]).tolist()))
    fig.legend(handles=[Patch(color=CLASS_COLOURS[c], label=CLASS_NAMES[c]) for c in present],
               loc="lower center", ncol=len(present), frameon=False)
    fig.suptitle(f"{title}: {len(uv):,} of the points, oblique view")
    fig.tight_layout(rect=(0, 0.04, 1, 0.97))
    tmp = out.with_name(f".{out.stem}.partial.png")
    fig.savefig(tmp)
    plt.close(fig)
    os.replace(tmp, out)
    return out


# ------------------------------------------------------------------------------ seeds
#: The element classes the spread reports (the paper's Table 1 columns, and pillars).
SPREAD_CLASSES = tuple(c.label for c in ELEMENT_CLASSES)


def _stats(values: Sequence[float]) -> dict[str, Any]:
    v = [float(x) for x in values]
    return {"values": v, "mean": sum(v) / len(v), "min": min(v), "max": max(v)}


def seed_spread(runs: Sequence[Sequence[SiteResult]]) -> dict[str, Any]:
    """How much the scores move when only the seeds move.

    ``runs[k]`` holds the results of seed offset ``k`` (the same inputs, in the same
    order). Per site and over all sites (the mean of the sites' mean IoU; elements found
    summed): the tree's mean point IoU, that of RANSAC + DBSCAN and their difference, and
    per element class the instances found and the tree's precision, each as
    ``{"values": [per seed], "mean", "min", "max"}``; over all sites the precision is
    pooled (matched over predicted instances of the sites whose ground truth has the
    class). Classes absent from a site's ground truth and precisions that are undefined
    (no predicted instance) are left out.
    """
    if not runs or not runs[0]:
        raise ValueError("seed_spread needs at least one run of at least one input")
    names = [r.name for r in runs[0]]
    for k, run in enumerate(runs):
        if [r.name for r in run] != names:
            raise ValueError(f"run {k} scores {[r.name for r in run]}, run 0 {names}: the same inputs are needed")

    def one(results: Sequence[SiteResult]) -> dict[str, Any]:
        tree = [r.methods["tree"] for r in results]
        base = [r.methods["ransac+dbscan"] for r in results]
        out: dict[str, Any] = {
            "tree_mean_iou_pct": _stats([e.mean_iou_pct or 0.0 for e in tree]),
            "ransac+dbscan_mean_iou_pct": _stats([e.mean_iou_pct or 0.0 for e in base]),
            "tree_minus_ransac+dbscan": _stats([(t.mean_iou_pct or 0.0) - (b.mean_iou_pct or 0.0)
                                                for t, b in zip(tree, base, strict=True)]),
            "found": {}, "precision_pct": {},
        }
        for c in SPREAD_CLASSES:
            n_gt = tree[0].score(c).n_gt
            if n_gt:
                out["found"][c] = {"n_gt": n_gt, **_stats([e.score(c).n_found for e in tree])}
            prec = [e.score(c).precision_pct for e in tree]
            if n_gt and all(p is not None for p in prec):
                out["precision_pct"][c] = _stats([p for p in prec if p is not None])
        return out

    sites = {n: one([run[i] for run in runs]) for i, n in enumerate(names)}
    over: dict[str, Any] = {}
    for key in ("tree_mean_iou_pct", "ransac+dbscan_mean_iou_pct", "tree_minus_ransac+dbscan"):
        per_seed = [sum(sites[n][key]["values"][k] for n in names) / len(names) for k in range(len(runs))]
        over[key] = _stats(per_seed)
    over["found"], over["precision_pct"] = {}, {}
    for c in SPREAD_CLASSES:
        with_c = [i for i, n in enumerate(names) if c in sites[n]["found"]]
        if with_c:
            over["found"][c] = {"n_gt": sum(sites[names[i]]["found"][c]["n_gt"] for i in with_c),
                                **_stats([sum(sites[names[i]]["found"][c]["values"][k] for i in with_c)
                                          for k in range(len(runs))])}
            # pooled: matched predicted instances over predicted instances, all sites with the class
            scores = [[run[i].methods["tree"].score(c) for i in with_c] for run in runs]
            if all(sum(x.n_pred for x in per) for per in scores):
                over["precision_pct"][c] = _stats([100.0 * sum(x.n_pred_matched for x in per)
                                                   / sum(x.n_pred for x in per) for per in scores])
    return {"n_seeds": len(runs), "sites": sites, "all": over}


def _range(s: dict[str, Any], signed: bool = False) -> str:
    f = "+.1f" if signed else ".1f"
    return f"{s['mean']:{f}} ({s['min']:{f}} to {s['max']:{f}})"


def format_spread(spread: dict[str, Any]) -> str:
    """The spread as a table: mean (min to max) over the seeds."""
    n = spread["n_seeds"]
    plural = {"arch": "arches"}
    lines = [f"evaluate: over {n} seeds, mean (min to max)",
             f"  {'site':<12}{'tree mean IoU %':<24}{'tree - ransac+dbscan':<24}"
             + "".join(f"{plural.get(c, c + 's') + ' found':<30}" for c in SPREAD_CLASSES[:3])]
    rows = [*spread["sites"].items(), (f"all {len(spread['sites'])}", spread["all"])]
    for name, s in rows:
        found = []
        for c in SPREAD_CLASSES[:3]:
            f = s["found"].get(c)
            found.append("-" if f is None else f"{_range(f)} / {f['n_gt']}")
        lines.append(f"  {name:<12}{_range(s['tree_mean_iou_pct']):<24}"
                     f"{_range(s['tree_minus_ransac+dbscan'], signed=True):<24}"
                     + "".join(f"{x:<30}" for x in found))
    return "\n".join(line.rstrip() for line in lines)


# ------------------------------------------------------------------------------ driver
def _algorithms() -> dict[str, str]:
    """The tree's, coarse stage's and grid's algorithm labels (every store of a run carries them)."""
    from hollowtree.pipeline.coarse import COARSE_ALGORITHM
    from hollowtree.pipeline.tree_stage import TREE_ALGORITHM
    from hollowtree.tiling.grid import GRID_ALGORITHM

    return {"tree_algorithm": TREE_ALGORITHM, "coarse_algorithm": COARSE_ALGORITHM, "grid_algorithm": GRID_ALGORITHM}


#: The packages whose versions can move labels at the margin (numeric kernels, HollowNet,
#: the ray caster of the synthetic scans): :func:`machine` names them.
NUMERIC_PACKAGES = ("numpy", "scipy", "numba", "llvmlite", "torch", "scikit-learn", "embreex")


def machine() -> dict[str, Any]:
    """The machine a result was measured on: cores, platform, CPU model and the versions of
    :data:`NUMERIC_PACKAGES`. Labels can differ at the margin between CPU types and between
    package versions (the numeric kernels differ), so variants are compared in one
    environment (``benchmarks/choose.py``)."""
    from importlib.metadata import PackageNotFoundError, version

    cpu = platform.processor()
    try:
        cpu = next((line.split(":", 1)[1].strip() for line in Path("/proc/cpuinfo").read_text().splitlines()
                    if line.startswith("model name")), cpu)
    except OSError:
        pass
    packages = {}
    for name in NUMERIC_PACKAGES:
        try:
            packages[name] = version(name)
        except PackageNotFoundError:
            packages[name] = None
    return {"cpus": os.cpu_count(), "platform": platform.platform(), "cpu": cpu or platform.machine(),
            "packages": packages}


def _is_store(text: str) -> bool:
    return (Path(text) / "zarr.json").is_file() or ("://" in text and Path(text).suffix.lower() not in SUFFIXES
                                                   and RunStore.exists(text))


def _join(folder: str, name: str) -> str:
    return f"{folder.rstrip('/')}/{name}" if "://" in folder else str(Path(folder) / name)


def _plan(text: str, store_dir: str) -> tuple[str, str, list[str]]:
    """``(name, store, workflow overrides)`` for one INPUT; no overrides for a run store."""
    from hollowtree.scenes.sites import scene_names

    p = Path(text)
    if _is_store(text):
        return p.name.removesuffix(".zarr") or text, text, []
    if p.suffix.lower() in (".las", ".laz"):
        if not p.is_file():
            raise InputFileError(f"{text}: file does not exist")
        _check_gt(text)
        return p.stem, _join(store_dir, f"{p.stem}.zarr"), [f"input.files={json.dumps([str(p)])}", "input.synth=null"]
    if text in scene_names():
        return text, _join(store_dir, f"{text}.zarr"), ["input.files=[]", f"input.synth.site={text}"]
    raise ConfigError(f"{text}: not a site name ({', '.join(scene_names()[:5])}, ...), a LAS/LAZ file with "
                      f"{' and '.join(GT_DIMS)}, or a run store")


def _seed_store(store: str, k: int) -> str:
    """The store of seed offset ``k``: the input's own store for 0, ``<name>-seed<k>.zarr`` beside it after."""
    return store if k == 0 else f"{store.removesuffix('.zarr')}-seed{k}.zarr"


def evaluate_inputs(
    inputs: Sequence[str], *, workflow: str | Path | None = None, overrides: Sequence[str] = (),
    store_dir: str = "out/evaluate", json_path: str | Path | None = None, png_dir: str | Path | None = None,
    seeds: int = 1, progress: bool = True, say: Callable[[str], None] = print,
) -> tuple[list[SiteResult], Path]:
    """Run (or read) and score every input; print the tables; write the JSON and PNGs.

    With ``seeds`` = N > 1 every input is run N times, with the workflow's ``coarse.seed``
    and ``tree.seed`` raised by 0 .. N-1 (a store per seed: ``<name>.zarr``, then
    ``<name>-seed<k>.zarr``), and the JSON gets the other runs (``repeats``) and the
    spread of the scores over the seeds (``spread``, :func:`seed_spread`). The figures
    are drawn for the first seed. Returns the first seed's results.
    """
    from hollowtree.pipeline.run import run_workflow
    from hollowtree.pipeline.workflow import load_workflow

    if isinstance(seeds, bool) or not isinstance(seeds, int) or seeds < 1:
        raise ConfigError(f"--seeds must be a whole number >= 1; got {seeds!r}")
    wf_path = Path(workflow) if workflow is not None else DEFAULT_WORKFLOW
    plans = [_plan(t, store_dir) for t in inputs]  # every input checked before anything runs
    names = [p[0] for p in plans]
    if len(set(names)) < len(names):
        twice = sorted({n for n in names if names.count(n) > 1})
        raise ConfigError(f"inputs {', '.join(twice)} appear twice (or share a file name); give each input once")
    if seeds > 1:
        stores = [t for t, (_, _, extra) in zip(inputs, plans, strict=True) if not extra]
        if stores:
            raise ConfigError(f"{stores[0]}: a run store is scored as it is; --seeds {seeds} needs inputs it can "
                              "run (a site name or a LAS/LAZ file)")
    wfs: dict[tuple[str, int], Any] = {}
    seeds_of: dict[tuple[str, int], dict[str, int]] = {}
    for text, (_, store, extra) in zip(inputs, plans, strict=True):
        if not extra:
            continue
        fixed = [*overrides, *extra, "outputs.las=null", "outputs.parquet=null", "outputs.png=null"]
        base = load_workflow(wf_path, [*fixed, f"store={json.dumps(store)}"])
        for k in range(seeds):
            c, t = base.coarse.seed + k, base.tree.seed + k
            wfs[text, k] = base if k == 0 else load_workflow(wf_path, [
                *fixed, f"store={json.dumps(_seed_store(store, k))}", f"coarse.seed={c}", f"tree.seed={t}"])
            seeds_of[text, k] = {"coarse": c, "tree": t}
    first_store = plans[0][1]
    default_dir = Path(first_store).parent if "://" not in first_store else Path(".")
    default_name = f"{plans[0][0]}.json" if len(plans) == 1 else "evaluate.json"
    json_out = Path(json_path) if json_path is not None else default_dir / default_name
    png_out = Path(png_dir) if png_dir is not None else json_out.parent
    runs: list[list[SiteResult]] = []
    for k in range(seeds):
        results: list[SiteResult] = []
        runs.append(results)
        for i, (text, (name, store, _)) in enumerate(zip(inputs, plans, strict=True)):
            step = f"{i + 1}/{len(inputs)}" if seeds == 1 else f"{k * len(inputs) + i + 1}/{seeds * len(inputs)}"
            seed_note = "" if seeds == 1 else f" (seeds +{k})"
            say(f"evaluate: [{step}] {name}{seed_note}")
            seconds, log = None, []
            store_k = _seed_store(store, k)
            if (text, k) in wfs:
                if "://" not in store_k:
                    Path(store_k).parent.mkdir(parents=True, exist_ok=True)

                def say_site(line: str, n: str = name) -> None:
                    say(f"  {n}: {line}")

                report = run_workflow(wfs[text, k], progress=progress, say=say_site)
                seconds, log = (None if report.nothing_to_do else report.seconds), report.lines
            result, sample = evaluate_store(RunStore.open(store_k), name=name, input_=text, pipeline_seconds=seconds,
                                            pipeline_log=log, say=say)
            result = replace(result, seeds=seeds_of.get((text, k)))
            say(format_table(result))
            if k == 0:
                png_out.mkdir(parents=True, exist_ok=True)
                png = draw_panels(sample, png_out / f"{name}.png", title=name)
                say(f"evaluate: {name}: figure {png}")
            results.append(result)
            complete = [r for r in runs if len(r) == len(inputs)]
            payload: dict[str, Any] = {
                "hollowtree_evaluate": 1, "date": _dt.datetime.now().isoformat(timespec="seconds"),
                "workflow": str(wf_path), "overrides": list(overrides), **_algorithms(), "machine": machine(),
                "iou_threshold": 0.5, "matching": "greedy one-to-one by IoU (equals Hungarian at IoU >= 0.5)",
                "seeds": seeds, "sites": [r.to_dict() for r in runs[0]]}
            if seeds > 1:
                payload["repeats"] = [[r.to_dict() for r in run] for run in runs[1:]]
                if len(complete) > 1:
                    payload["spread"] = seed_spread(complete)
            _write_json(json_out, payload)
    if seeds > 1:
        say(format_spread(seed_spread(runs)))
    say(f"evaluate: {json_out}")
    return runs[0], json_out
