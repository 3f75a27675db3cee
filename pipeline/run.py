"""``hollowtree run``: one workflow, every stage, resumable, one run per store at a time.

Stages in order: input (a synthetic scan is made on first use) -> ingest -> coarse
(+ stitch) -> tree (+ HollowNet) -> labels -> outputs. Each stage runs as Dask tasks per
unit (map chunk, tile, segment batch, output range) on the workflow's cluster, and every
unit records completion in the store after its data, so a rerun skips what is recorded.
Parameters are chained: a stage's parameter hash includes the one of the stage before
it, so changing a parameter redoes exactly that stage and the ones after it; the run
says which before it starts. The store's workflow parameters are kept in the root
attribute ``workflow`` for ``hollowtree status``.
"""

from __future__ import annotations

import contextlib
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hollowtree.classes import CLASS_NAMES
from hollowtree.errors import ConfigError
from hollowtree.pipeline.coarse import COARSE_ALGORITHM
from hollowtree.pipeline.graph import timed_stage
from hollowtree.pipeline.tree_params import TreeStageParams
from hollowtree.pipeline.tree_stage import TREE_ALGORITHM, model_fingerprints
from hollowtree.pipeline.workflow import Workflow

__all__ = ["run_workflow", "RunReport", "STAGE_ORDER", "changed_stages", "make_synthetic_input"]

#: Stages whose parameters a workflow sets, upstream first.
STAGE_ORDER = ("ingest", "coarse", "tree", "labels")


@dataclass(kw_only=True)
class RunReport:
    store: str
    lines: list[str] = field(default_factory=list)
    class_counts: dict[str, int] = field(default_factory=dict)
    nothing_to_do: bool = False
    seconds: float = 0.0


def _input_points(wf: Workflow) -> int:
    """Points in the workflow's input files, from their headers."""
    from hollowtree.tiling.readers import probe

    return sum(probe(p).point_count for p in wf.input.paths())


def _stage_params(wf: Workflow) -> dict[str, dict[str, Any]]:
    """Per stage, the workflow parameters that decide its result."""
    return {
        "ingest": {"inputs": [str(p) for p in wf.input.paths()], **wf.ingest.model_dump(mode="json")},
        "coarse": {**wf.coarse.model_dump(mode="json"), "algorithm": COARSE_ALGORITHM},
        # the algorithm's version too: a rerun after a change of the tree's code redoes it
        # what the tree's files hold too: one refitted under the same path redoes the tree
        "tree": {**wf.tree.model_dump(mode="json", exclude={"device"}), "algorithm": TREE_ALGORITHM,
                 **(model_fingerprints(TreeStageParams.from_workflow(wf.tree)) if wf.tree.enabled
                    else {"check": None})},
        "labels": {},
    }


def changed_stages(old: dict[str, Any] | None, new: dict[str, dict[str, Any]]) -> tuple[list[str], list[str]]:
    """The stages to redo because a parameter changed, and what changed. A stage ``old``
    does not record has not run to its end with any parameters (a run interrupted before
    it): nothing of it changed.

    >>> old = {"ingest": {"voxel": None}, "coarse": {"epsilon": 0.03}, "tree": {}, "labels": {}}
    >>> new = {"ingest": {"voxel": None}, "coarse": {"epsilon": 0.05}, "tree": {}, "labels": {}}
    >>> changed_stages(old, new)
    (['coarse', 'tree', 'labels'], ['coarse.epsilon: 0.03 -> 0.05'])
    >>> changed_stages({"ingest": {"voxel": None}}, new)  # interrupted after the ingest
    ([], [])
    >>> changed_stages({"ingest": {}, "coarse": {"epsilon": 0.05}}, new)  # voxel: added later, at None
    ([], [])
    """
    if not old:
        return [], []
    for i, stage in enumerate(STAGE_ORDER):
        if stage not in old:
            continue
        a, b = old[stage], new.get(stage, {})
        # a key the store does not record was added since it was made: at None, no change
        diffs = [f"{stage}.{k}: {a.get(k)!r} -> {b.get(k)!r}" for k in sorted(set(a) | set(b)) if a.get(k) != b.get(k)]
        if diffs:
            return list(STAGE_ORDER[i:]), diffs
    return [], []


def make_synthetic_input(wf: Workflow, *, progress: bool) -> Path | None:
    """Make the workflow's synthetic scan if it names one that does not exist yet."""
    spec = wf.input.synth
    if spec is None or spec.path().exists():
        return None
    from tqdm import tqdm

    from hollowtree.scenes.synth import synth

    path = spec.path()
    path.parent.mkdir(parents=True, exist_ok=True)
    bars: list[Any] = []
    try:
        synth(spec.site, path, n_points=spec.points, seed=spec.seed,
              on_total=lambda n: bars.append(tqdm(total=n, unit="ray", unit_scale=True, leave=False,
                                                  desc=f"input: scanning {spec.site}", disable=None if progress else True,
                                                  file=sys.stderr)),
              on_rays=lambda n: bars[-1].update(n))
    finally:
        for bar in bars:
            bar.close()
    return path


def _class_counts(store: Any) -> dict[str, int]:
    from hollowtree.pipeline.labels import STAGE as LABELS

    counts = np.zeros(len(CLASS_NAMES), dtype=np.int64)
    for info in store.records(LABELS).values():
        counts[: len(info.get("class_counts", []))] += np.asarray(info.get("class_counts", []), dtype=np.int64)
    return {CLASS_NAMES[i]: int(c) for i, c in enumerate(counts) if c}


def _complete(store: Any, wf: Workflow) -> bool:
    """Whether the store records every stage of ``wf`` as done and its outputs exist."""
    stages = store.attrs.get("stages", {})
    needed = ["ingest", "coarse", "labels"] + (["tree"] if wf.tree.enabled else [])
    if any(stages.get(s, {}).get("done") != stages.get(s, {}).get("units", -1) or s not in stages for s in needed):
        return False
    if stages["labels"].get("tree") != wf.tree.enabled:
        return False
    return all(Path(p).exists() for p in (wf.outputs.las, wf.outputs.parquet, wf.outputs.png) if p)


def _remove_if_empty(folder: Path) -> None:
    """Remove ``folder`` when nothing is in it (the lock file gone with its run)."""
    with contextlib.suppress(OSError):
        if folder.is_dir() and not any(folder.iterdir()):
            folder.rmdir()


def run_workflow(
    wf: Workflow, *, progress: bool = True, say: Callable[[str], None] = print, client: Any = None,
) -> RunReport:
    """Run every stage of ``wf`` (resuming what the store already records).

    ``client``: an existing ``distributed.Client`` (a notebook's, a dask-jobqueue or
    dask-kubernetes cluster's) to run the tasks on instead of ``wf.cluster``; it stays
    open. Its workers must import hollowtree and reach the store and the inputs.
    """
    from hollowtree.pipeline.coarse import CoarseParams, run_coarse
    from hollowtree.pipeline.graph import fresh_workers, task_runner
    from hollowtree.pipeline.labels import run_labels
    from hollowtree.tiling.ingest import IngestParams, ingest
    from hollowtree.tiling.lock import StoreLock
    from hollowtree.tiling.store import RunStore, check_writable

    if client is None and (wf.cluster.jobqueue is not None or wf.cluster.kubernetes is not None):
        from hollowtree.pipeline.clusters import open_cluster

        check_writable(wf.store, parents=True)  # before any job is submitted
        with open_cluster(wf.cluster) as cluster_client:
            return run_workflow(wf, progress=progress, say=say, client=cluster_client)
    t0 = time.perf_counter()
    url = wf.store
    report = RunReport(store=url)
    check_writable(url, parents=True)
    if wf.tree.enabled and wf.tree.device == "cuda" and client is None and wf.cluster.scheduler in (None, "sync"):
        import torch  # the workers are this machine's: say so before anything runs

        if not torch.cuda.is_available():
            raise ConfigError("tree.device is cuda but torch sees no CUDA device on this machine; use cpu or auto")
    new_params = _stage_params(wf)
    ingest_params = IngestParams.from_workflow(wf.ingest)
    coarse_params = CoarseParams.from_workflow(wf.coarse)
    made = make_synthetic_input(wf, progress=progress)
    if made is not None:
        say(f"input: made synthetic scan {made}")
    made_dirs: list[Path] = []  # the folders this run makes for its store, innermost first
    if "://" not in url:  # the lock lives inside the store folder
        folder = Path(url).absolute()
        while not folder.exists():
            made_dirs.append(folder)
            folder = folder.parent
        Path(url).mkdir(parents=True, exist_ok=True)
    try:
        with StoreLock(url):
            old = RunStore.open(url).attrs.get("workflow") if RunStore.exists(url) else None
            if old == new_params and _complete(RunStore.open(url), wf):
                report.nothing_to_do = True
                report.class_counts = _class_counts(RunStore.open(url))
                report.lines.append(f"nothing to do: every stage of {url} is recorded with these parameters "
                                    "and the outputs exist")
                say(report.lines[-1])
                report.seconds = time.perf_counter() - t0
                return report
            redo, diffs = changed_stages(old, new_params)
            if redo:
                say(f"parameters changed ({'; '.join(diffs)}): redoing {', '.join(redo)}")
            scheduler = wf.cluster.scheduler
            if client is None and scheduler is None and _input_points(wf) < wf.cluster.in_process_below:
                scheduler = "sync"  # a small scan: starting a cluster would take longer than its tasks
            with task_runner(scheduler, workers=wf.cluster.workers, progress=progress, client=client) as runner:
                with timed_stage(url, "ingest", runner):
                    rep = ingest([str(p) for p in wf.input.paths()], url, ingest_params, runner=runner,
                                 replace="ingest" in redo)
                RunStore.open(url, mode="a").update_attrs({"workflow": {**(old or {}), "ingest": new_params["ingest"]}})
                report.lines.append(f"ingest: {rep.n_tiles} tiles, {rep.n_points_in:,} input points; map units "
                                    f"{rep.maps_run} run, {rep.maps_skipped} skipped; tiles {rep.tiles_run} run, "
                                    f"{rep.tiles_skipped} skipped")
                say(report.lines[-1])
                unit = RunStore.open(url).attrs.get("coords", {}).get("unit")
                if unit:  # not metres
                    report.lines.append(f"ingest: input coordinates in {unit}; the store and every length "
                                        "parameter are in metres")
                    say(report.lines[-1])
                if rep.maps_run or rep.tiles_run:  # what the ingest's readers and writers left
                    fresh_workers(runner)
                with timed_stage(url, "coarse", runner):
                    crep = run_coarse(url, coarse_params, runner=runner)
                report.lines.append(f"coarse: {crep.n_segments:,} segments; tiles {crep.tiles_run} run, "
                                    f"{crep.tiles_skipped} skipped; DBSCAN eps {crep.eps:.3f} m; "
                                    f"{crep.seconds:.1f} s (stitch {crep.stitch_seconds:.1f} s)")
                say(report.lines[-1])
                use_tree = wf.tree.enabled
                if use_tree and crep.tiles_run:  # the coarse tasks' heaps, before torch and HollowNet
                    fresh_workers(runner)
                if use_tree:
                    from hollowtree.pipeline.tree_stage import TreeStageParams, run_tree

                    with timed_stage(url, "tree", runner):
                        trep = run_tree(url, TreeStageParams.from_workflow(wf.tree), runner=runner,
                                        device=wf.tree.device)
                    report.lines.append(trep.summary())
                    say(report.lines[-1])
                    if trep.batches_run:  # torch and HollowNet stay in the workers that ran the tree
                        fresh_workers(runner)
                with timed_stage(url, "labels", runner):
                    lrep = run_labels(url, use_tree=use_tree, runner=runner)
                report.lines.append(lrep.summary())
                say(report.lines[-1])
                store = RunStore.open(url, mode="a")
                store.update_attrs({"workflow": new_params})
                report.class_counts = _class_counts(store)
                if set(report.class_counts) <= {CLASS_NAMES[0]} and not use_tree:  # classes come from the tree
                    report.lines.append("labels: the tree is off (tree.enabled: false): every point keeps class 0, "
                                        "with its coarse segment and primitive (labels/segment, labels/primitive)")
                    say(report.lines[-1])
                elif set(report.class_counts) <= {CLASS_NAMES[0]}:  # nothing found: say so, once
                    report.lines.append(f"labels: nothing could be labelled in {report.class_counts.get(CLASS_NAMES[0], 0):,} "
                                        "points (no surface or element found: too few, too sparse or too noisy points?); "
                                        "every point keeps class 0")
                    say(report.lines[-1])
                from hollowtree.pipeline.export import write_outputs

                for line in write_outputs(store, wf, progress=progress):
                    report.lines.append(line)
                    say(line)
    finally:
        for folder in made_dirs:  # a run that wrote nothing (no scheduler, no input) leaves no folder behind
            _remove_if_empty(folder)
    report.seconds = time.perf_counter() - t0
    return report
