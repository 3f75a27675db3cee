"""The ``hollowtree`` command.

Logging handlers and progress bars are set up here and nowhere else. Every expected
failure (a :class:`hollowtree.errors.PipelineError`) becomes one line on stderr and exit
code 2; nothing is written in that case.
"""

from __future__ import annotations

import argparse
import logging
import sys
from collections.abc import Sequence
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Any

from hollowtree.errors import PipelineError
from hollowtree.pipeline.cli_args import (
    _bbox,
    _cluster_args,
    _float,
    _int_list,
    _param_flag,
    _positive_int,
    _procedural_points,
    _procedural_points_flag,
    _section,
    _set_flag,
    _stage_flag,
    _tile_size,
    _units,
    _workers_flag,
)

__all__ = ["main", "build_parser"]

logger = logging.getLogger("hollowtree")
#: The logger ``--verbose`` turns to DEBUG: every module logs under its name, below ``hollowtree``.
OWN_LOGGERS = ("hollowtree",)


def _version() -> str:
    try:
        return version("hollowtree")
    except PackageNotFoundError:  # running from a source tree that is not installed
        return "unknown (not installed)"


class _Parser(argparse.ArgumentParser):
    """argparse with exit code 2 and a one-line message for usage errors.

    ``late_description``: a callable that makes the description when help is shown, for
    descriptions whose making imports heavy modules (every command builds the parser).
    """

    late_description: Any = None

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {message}\n")

    def format_help(self) -> str:
        if self.late_description is not None:
            self.description = self.late_description()
        return super().format_help()


def _synth_description() -> str:
    from hollowtree.scenes.sites import (  # scenes are slow to import: only for this help
        GENERATED,
        SITES,
        TEST_SCENES,
    )

    return (
        "Scan a synthetic site with a virtual terrestrial laser scanner and write a "
        "LAS 1.4 / LAZ file with per-point ground truth, plus a Parquet table of the "
        f"elements. Sites: {', '.join(SITES)}. Test scenes: {', '.join(TEST_SCENES)}. Procedural sites "
        f"(a new site for every --seed): {', '.join(GENERATED)}."
    )


def _command(sub: Any, name: str, func: Any, *, help: str, description: str | None = None) -> _Parser:
    """Add the subcommand ``name``, run by ``func(args)``, to the subparsers ``sub``."""
    parser: _Parser = sub.add_parser(name, help=help, description=description)
    parser.set_defaults(func=func)
    return parser


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``hollowtree`` and its subcommands."""
    parser = _Parser(
        prog="hollowtree",
        description="Labelled architectural elements from terrestrial laser scans.",
    )
    parser.add_argument("--version", action="version", version=f"hollowtree {_version()}")
    parser.add_argument("-v", "--verbose", action="store_true", help="log hollowtree's debug messages")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)

    from hollowtree.scenes.scan_params import DEFAULT_POINTS, ScanParams

    s = _command(sub, "synth", _cmd_synth,
                 help="make a labelled synthetic scan of a site (LAS/LAZ with gt_class, gt_instance)")
    s.late_description = _synth_description
    s.add_argument("site", help="site or test scene name")
    s.add_argument("--out", required=True, type=Path, help="output .laz or .las file")
    size = s.add_mutually_exclusive_group()
    size.add_argument("--points", type=_positive_int, help=f"aim at about N points (default {DEFAULT_POINTS:,})")
    size.add_argument("--step", type=_float, help="angular step of the scanner, degrees")
    s.add_argument("--stations", type=_positive_int, help="use the first K stations of the site")
    _param_flag(s, ScanParams, "seed", "noise", "registration_error")
    s.add_argument("--crs", help="coordinate reference system to record, e.g. EPSG:32643")
    s.add_argument("--overwrite", action="store_true", help="replace an existing output")
    s.add_argument("--no-progress", action="store_true", help="no progress bar")

    g = _command(sub, "ingest", _cmd_ingest, help="stream point files into a tiled, chunked Zarr run store",
                 description="Tile LAS/LAZ/PLY/E57 files of one registered site into a Zarr v3 run store: "
                             "points routed to tiles with a buffer, Morton-sorted, original indices kept. "
                             "Rerunning the same command resumes an interrupted ingest.")
    g.add_argument("inputs", nargs="+", type=Path, help="input files (one registered site)")
    g.add_argument("--store", required=True, help="run store: a folder path or an fsspec URL")
    from hollowtree.pipeline.workflow import CoarseSection, IngestSection, TreeSection

    _stage_flag(g, IngestSection, "tile_size", type=_tile_size)
    _stage_flag(g, IngestSection, "buffer", "voxel")
    _stage_flag(g, IngestSection, "bbox", type=_bbox, metavar="XMIN,YMIN,XMAX,YMAX")
    _stage_flag(g, IngestSection, "tiles", type=_int_list, metavar="ID,ID,...")
    _stage_flag(g, IngestSection, "units", type=_units, metavar="UNIT")
    _stage_flag(g, IngestSection, "chunk_size")
    _set_flag(g, "ingest")
    g.add_argument("--scheduler", help="Dask scheduler address; 'sync' runs in this process; "
                   "default: a local cluster of worker threads in this process")
    _workers_flag(g)
    g.add_argument("--processes", action="store_true",
                   help="make the local cluster's workers processes, not threads (starts about 1.5 s slower)")
    g.add_argument("--no-progress", action="store_true", help="no progress bars")

    c = _command(sub, "coarse", _cmd_coarse,
                 help="coarse segments per tile (normals, Efficient RANSAC, DBSCAN), stitched across tiles",
                 description="Run the paper's first stage on an ingested run store: PCA normals, Efficient "
                             "RANSAC primitives and DBSCAN per tile as Dask tasks, then join the tiles' "
                             "segments over their shared buffer points. Rerunning resumes: recorded tiles "
                             "are skipped.")
    c.add_argument("store", help="run store made by `hollowtree ingest`")
    _stage_flag(c, CoarseSection, "epsilon", "alpha", "cluster_epsilon", "min_support", "eps", "min_samples")
    c.add_argument("--no-free-segments", action="store_true",
                   help="leave points that no primitive explains unsegmented (default: DBSCAN them too)")
    _stage_flag(c, CoarseSection, "free_min_points", "free_min_cells", "block_points", "block_margin", "sparse_factor", "group_gap",
                "seed")
    _set_flag(c, "coarse")
    _cluster_args(c)

    from hollowtree.pipeline.hollownet_cmd import add_labelled_args
    from hollowtree.pipeline.hollownet_cmd import add_parsers as add_hollownet_parsers

    add_hollownet_parsers(sub)  # train, classify

    tr = _command(sub, "tree", _cmd_tree,
                  help="the hierarchical tree with HollowNet for every coarse segment of a store",
                  description="Build the paper's hierarchical tree (three projection sequences, the five-term "
                              "energy, greedy recursion) for every global coarse segment of a store, one Dask "
                              "task per batch of segments. Rerunning resumes: recorded batches are skipped.")
    tr.add_argument("store", help="run store after `hollowtree coarse`")
    _stage_flag(tr, TreeSection, "max_depth", "decision", "threshold", "batch_points", "max_group_points", "weights",
                "device", "seed")
    _set_flag(tr, "tree")
    _cluster_args(tr)

    lb = _command(sub, "labels", _cmd_labels, help="per-point labels of a store from its tree (or its coarse segments)",
                  description="Write the per-point class, instance, segment and score arrays of a store after "
                              "`hollowtree coarse` and `hollowtree tree`, as `hollowtree run` does, so that "
                              "`hollowtree export` can follow. Without a complete tree stage (or with --no-tree) "
                              "the labels are the coarse segments', each classified whole. Rerunning resumes.")
    lb.add_argument("store", help="run store after `hollowtree coarse` (and `hollowtree tree`)")
    lb.add_argument("--no-tree", action="store_true", help="label from the coarse segments even when the tree ran")
    _cluster_args(lb)

    fe = _command(sub, "fit-energy", _cmd_fit_energy,
                  help="refit the tree's energy weights w and prior W on synthetic scenes",
                  description="Scan the training scenes, collect split proposals with known targets and fit "
                              "xi = w . e by linear regression (docs/method.md). Same seed, same model.")
    fe.add_argument("--seed", type=int, default=0)
    fe.add_argument("--out", type=Path, default=Path("energy-v1.json"),
                    help="output JSON (default energy-v1.json; the shipped one is tree/data/energy-v1.json)")
    fe.add_argument("--overwrite", action="store_true", help="replace an existing output")

    fs = _command(sub, "fit-split", _cmd_fit_split,
                  help="refit the tree's split model on the element groups of random scenes",
                  description="Scan 52 random training scenes, run ingest and the coarse stage on each, collect "
                              "the split proposals of their element groups with known targets and fit the "
                              "gradient-boosted split model (docs/method.md). About 30 minutes on 2 cores; the "
                              "scenes' groups are kept in --work, so a stopped fit goes on where it stopped.")
    fs.add_argument("--work", type=Path, default=Path("out/split-fit"),
                    help="folder for the scenes' element groups (default out/split-fit)")
    fs.add_argument("--seed", type=int, default=0)
    fs.add_argument("--threshold", type=_float, default=0.5,
                    help="decision threshold stored in the model (default 0.5)")
    fs.add_argument("--out", type=Path, default=Path("split-v1.json"),
                    help="output JSON (default split-v1.json; the shipped one is tree/data/split-v1.json)")
    fs.add_argument("--overwrite", action="store_true", help="replace an existing output")
    fs.add_argument("--no-progress", action="store_true", help="no progress bar")
    fs.add_argument("--procedural", type=int, default=0, metavar="N",
                    help="add the first N procedural training sites (scenes/procedural.py; training seeds only)")
    _procedural_points_flag(fs, 600_000)
    add_labelled_args(fs, "element groups")

    r = _command(sub, "run", _cmd_run, help="run a workflow YAML: ingest -> coarse -> tree -> labels -> outputs",
                 description="Run every stage of a workflow file on a local Dask cluster or a scheduler. "
                             "Rerunning resumes: recorded units are skipped; a changed parameter redoes its "
                             "stage and the ones after it. One run at a time per store.")
    r.add_argument("workflow", nargs="?", type=Path, help="workflow YAML (see docs/workflows.md)")
    r.add_argument("--scheduler", help="Dask scheduler address (overrides cluster.scheduler)")
    r.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY.PATH=VALUE",
                   help="override a workflow value, e.g. --set coarse.epsilon=0.05 (repeatable)")
    r.add_argument("--schema", action="store_true", help="print the workflow JSON Schema and exit")
    r.add_argument("--job-script", action="store_true",
                   help="print the batch script of one job of cluster.jobqueue and exit (nothing is submitted)")
    r.add_argument("--no-progress", action="store_true", help="no progress bars")

    ev = _command(sub, "evaluate", _cmd_evaluate,
                  help="score the pipeline and two baselines against ground truth (the paper's Table 1)",
                  description="For each INPUT (a synthetic site name, a LAS/LAZ with gt_class and gt_instance, or a "
                              "run store of such a scan) run the workflow (or read the store) and score RANSAC alone, "
                              "RANSAC + DBSCAN and the full tree: per class GT, found (IoU >= 0.5), accuracy, "
                              "precision and point IoU. Writes a JSON file and a four-panel PNG per input.")
    ev.add_argument("inputs", nargs="+", metavar="INPUT", help="site name, LAS/LAZ file or run store")
    ev.add_argument("--workflow", type=Path, help="workflow YAML (default: workflows/local.yaml)")
    ev.add_argument("--store-dir", default="out/evaluate",
                    help="folder for the run stores, one <name>.zarr per input (default out/evaluate)")
    ev.add_argument("--json", type=Path, help="JSON output (default: beside the stores, NAME.json for one input, "
                    "evaluate.json for several)")
    ev.add_argument("--png-dir", type=Path, help="folder for the <name>.png figures (default: beside the JSON)")
    ev.add_argument("--scheduler", help="Dask scheduler address (overrides cluster.scheduler); 'sync' = in process")
    ev.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY.PATH=VALUE",
                    help="override a workflow value, e.g. --set input.synth.points=200000 (repeatable)")
    ev.add_argument("--seeds", type=int, default=1, metavar="N",
                    help="run every input N times, coarse.seed and tree.seed raised by 0..N-1 (a store per "
                    "seed), and report the spread of the scores (default 1)")
    ev.add_argument("--no-progress", action="store_true", help="no progress bars")

    it = _command(sub, "init", _cmd_init, help="write the example workflows into a folder, to edit and run",
                  description="Copy the shipped example workflows (local.yaml: the whole pipeline on "
                              "this machine; laptop.yaml: one downsampled tile; cluster.yaml: a Dask "
                              "cluster and an object store) and their JSON schema into DIR.")
    it.add_argument("dir", type=Path, help="folder to write them into (made if missing)")
    it.add_argument("--overwrite", action="store_true", help="replace files of the same names")

    st = _command(sub, "status", _cmd_status, help="per stage: units done / total and the parameters used",
                  description="Show what a run store holds: per stage, units done / total and parameters.")
    st.add_argument("store", help="run store")

    e = _command(sub, "export", _cmd_export,
                 help="write labelled points (LAS/LAZ), tables (Parquet) or views (PNG) of a run",
                 description="Export the labels of a finished run: every input point in input order with "
                             "class_id, instance_id, segment_id, score, primitive_id and the LAS classification; "
                             "beside the LAS/LAZ, class styles for QGIS (.qml) and CloudCompare (.cc-classes.xml).")
    e.add_argument("store", help="run store")
    e.add_argument("--las", type=Path, help="output .las or .laz")
    e.add_argument("--parquet", type=Path, help="folder for segments.parquet (and tree.parquet)")
    e.add_argument("--png", type=Path, help="top and side views coloured by class")
    e.add_argument("--no-progress", action="store_true", help="no progress bar")
    from hollowtree.pipeline.view import add_parser as add_view_parser

    add_view_parser(sub)  # view: the store in the browser
    return parser


def _store_scheduler(args: argparse.Namespace, store: Any) -> str | None:
    """``--scheduler``, or ``"sync"`` where it is not given and the store's inputs hold
    fewer points than ``cluster.in_process_below`` (the rule of ``hollowtree run``)."""
    from hollowtree.pipeline.workflow import ClusterSection

    if args.scheduler is not None:
        return args.scheduler
    points = sum(int(s.get("point_count", 0)) for s in store.attrs.get("sources", []))
    return "sync" if points < ClusterSection.model_fields["in_process_below"].default else None


def _cmd_tree(args: argparse.Namespace) -> int:
    from hollowtree.pipeline.graph import task_runner, timed_stage
    from hollowtree.pipeline.tree_stage import TreeStageParams, run_tree
    from hollowtree.pipeline.workflow import TreeSection
    from hollowtree.tiling.store import RunStore

    scheduler = _store_scheduler(args, RunStore.open(args.store))
    section = _section(TreeSection, args, "tree")
    with task_runner(scheduler, workers=args.workers, progress=not args.no_progress) as run:
        with timed_stage(str(args.store), "tree", run):
            report = run_tree(args.store, TreeStageParams.from_workflow(section), runner=run, device=section.device)
    print(report.summary())
    return 0


def _cmd_labels(args: argparse.Namespace) -> int:
    from hollowtree.pipeline.graph import task_runner, timed_stage
    from hollowtree.pipeline.labels import run_labels
    from hollowtree.tiling.store import RunStore

    store = RunStore.open(args.store)
    stages = store.attrs.get("stages", {})

    def complete(stage: str) -> bool:
        st = stages.get(stage)
        return bool(st) and st.get("done") == st.get("units")

    if not complete("coarse"):
        raise PipelineError(f"store {args.store} has no complete coarse stage; run `hollowtree coarse` on it first")
    use_tree = not args.no_tree and complete("tree")
    if not args.no_tree and not use_tree:
        print(f"{args.store}: no complete tree stage; labels from the coarse segments", file=sys.stderr)
    with task_runner(_store_scheduler(args, store), workers=args.workers, progress=not args.no_progress) as run:
        with timed_stage(str(args.store), "labels", run):
            report = run_labels(args.store, use_tree=use_tree, runner=run)
    print(report.summary())
    return 0


def _check_out(out: Path, overwrite: bool) -> None:
    """Fail before any work where the output file ``out`` could not be written."""
    from hollowtree.errors import ConfigError

    if out.exists() and not overwrite:
        raise ConfigError(f"{out} exists; pass --overwrite to replace it")
    if not out.parent.is_dir():
        raise ConfigError(f"{out}: folder {out.parent} does not exist")


def _cmd_fit_energy(args: argparse.Namespace) -> int:
    from hollowtree.tree.fit import fit_energy_from_scenes

    _check_out(args.out, args.overwrite)
    model = fit_energy_from_scenes(args.seed)
    model.save(args.out)
    w = ", ".join(f"e{i + 1} {v:.3f}" for i, v in enumerate(model.w))
    print(f"{args.out}: R^2 {model.r2:.3f}; w = ({w}); threshold {model.threshold:.3f}")
    return 0


def _cmd_fit_split(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from hollowtree.errors import ConfigError
    from hollowtree.pipeline.hollownet_cmd import class_map_of
    from hollowtree.pipeline.split_fit import TRAINING_SCENES, fit_split_from_scenes
    from hollowtree.scenes.procedural import split_seeds

    _check_out(args.out, args.overwrite)
    if not 0.0 < args.threshold < 1.0:
        raise ConfigError(f"--threshold must be between 0 and 1 (a probability); got {args.threshold}")
    if args.procedural < 0:
        raise ConfigError(f"--procedural must be a count >= 0; got {args.procedural}")
    if args.no_synthetic and not args.labelled and not args.procedural:
        raise ConfigError("--no-synthetic needs at least one --from FILE or --procedural N")
    procedural = tuple(split_seeds("train", args.procedural)) if args.procedural else ()
    pts = _procedural_points(args)
    for f in args.labelled:
        if not f.is_file():
            raise ConfigError(f"--from {f}: file does not exist")
    scenes = () if args.no_synthetic else TRAINING_SCENES
    with tqdm(total=len(scenes) + len(procedural) + len(args.labelled), unit="scene", desc="fit-split",
              disable=True if args.no_progress else None) as bar:
        model = fit_split_from_scenes(args.work, scenes=scenes, seed=args.seed, threshold=args.threshold,
                                      on_scene=lambda i: bar.update(1), files=tuple(args.labelled),
                                      class_dim=args.class_dim, instance_dim=args.instance_dim,
                                      class_map=class_map_of(args.class_map), procedural=procedural,
                                      procedural_points=pts)
    model.save(args.out)
    info = model.info
    print(f"{args.out}: {info['samples']} proposals ({info['right']} right) from {info['scenes']} scenes, "
          f"{len(info.get('procedural', []))} procedural sites and {len(info.get('files', []))} labelled scans; "
          f"cross-validated AUC {info.get('cv_auc', float('nan'))}; threshold {model.threshold}")
    return 0


def _cmd_run(args: argparse.Namespace) -> int:
    from hollowtree.pipeline.workflow import WorkflowError, load_workflow, schema_text

    if args.schema:
        sys.stdout.write(schema_text())
        return 0
    if args.workflow is None:
        raise WorkflowError("give a workflow file, e.g. hollowtree run workflows/local.yaml")
    overrides = list(args.overrides)
    if args.scheduler:
        overrides.append(f"cluster.scheduler={args.scheduler}")
    wf = load_workflow(args.workflow, overrides)
    if args.job_script:
        if wf.cluster.jobqueue is None:
            raise WorkflowError(f"{args.workflow}: cluster.jobqueue: --job-script needs a jobqueue section")
        from hollowtree.pipeline.clusters import job_script

        sys.stdout.write(job_script(wf.cluster.jobqueue))
        return 0
    from hollowtree.pipeline.run import run_workflow

    try:
        report = run_workflow(wf, progress=not args.no_progress)
    except OSError as exc:
        sched = wf.cluster.scheduler
        if sched not in (None, "sync") and "scheduler" not in str(exc).lower():
            raise WorkflowError(f"cannot reach the Dask scheduler {sched}: {exc}") from None
        raise
    if report.class_counts:
        total = sum(report.class_counts.values())
        print(f"{'class':<14}{'points':>14}{'share':>9}")
        for name, n in report.class_counts.items():
            print(f"{name:<14}{n:>14,}{100 * n / total:>8.1f}%")
    print(f"{report.store}: done in {report.seconds:.1f} s")
    return 0


def _cmd_evaluate(args: argparse.Namespace) -> int:
    from hollowtree.pipeline.evaluate import evaluate_inputs

    overrides = list(args.overrides)
    if args.scheduler:
        overrides.append(f"cluster.scheduler={args.scheduler}")
    evaluate_inputs(args.inputs, workflow=args.workflow, overrides=overrides, store_dir=args.store_dir,
                    json_path=args.json, png_dir=args.png_dir, seeds=args.seeds, progress=not args.no_progress,
                    say=lambda line: print(line, flush=True))
    return 0


def _cmd_init(args: argparse.Namespace) -> int:
    import shutil

    from hollowtree.errors import ConfigError, OutputExistsError
    from hollowtree.pipeline.workflow import shipped_workflows

    src = sorted(p for p in shipped_workflows().iterdir() if p.suffix in (".yaml", ".json"))
    if args.dir.exists() and not args.dir.is_dir():
        raise ConfigError(f"{args.dir}: exists and is not a folder")
    clash = [p.name for p in src if (args.dir / p.name).exists()]
    if clash and not args.overwrite:
        raise OutputExistsError(f"{args.dir}: {', '.join(clash)} exist; pass --overwrite to replace them")
    args.dir.mkdir(parents=True, exist_ok=True)
    for p in src:
        shutil.copyfile(p, args.dir / p.name)
    print(f"{args.dir}: {', '.join(p.name for p in src)}; run one with `hollowtree run {args.dir / 'local.yaml'}`")
    return 0


def _cmd_status(args: argparse.Namespace) -> int:
    import json

    from hollowtree.pipeline.timing import WAVES, waves
    from hollowtree.tiling.lock import StoreLock
    from hollowtree.tiling.store import RunStore

    store = RunStore.open(args.store)
    attrs = store.attrs
    stages = attrs.get("stages", {})
    holder = StoreLock(args.store).holder()
    print(f"store {args.store} (schema {attrs.get('schema_version')})"
          + (f"; in use by pid {holder.get('pid')} on {holder.get('host')}" if holder else ""))
    expected = {"ingest": len(attrs.get("ingest", {}).get("tiles", []))}
    units = {"ingest": "tiles", "coarse": "tiles", "tree": "batches", "labels": "ranges"}
    wf = attrs.get("workflow", {})
    timed = waves({name: store.records(name) for name in {n for _, _, n in WAVES}})
    for stage in ("ingest", "coarse", "tree", "labels"):
        recs = store.records(stage)
        info = stages.get(stage, {})
        h = info.get("params_hash") or attrs.get(stage, {}).get("params_hash")
        done = sum(1 for v in recs.values() if h is None or v.get("params_hash") == h)
        total = info.get("units", expected.get(stage, expected["ingest"] if stage == "coarse" else "?"))
        if not recs and not info:
            print(f"  {stage:<8} not run")
            continue
        params = wf.get(stage) or info.get("params") or attrs.get(stage, {}).get("params") or {}
        print(f"  {stage:<8} {done}/{total} {units[stage]} done; parameters: {json.dumps(params, sort_keys=True)}")
        if "wall_s" in info:
            print(f"           {info['wall_s']:.1f} s, of which {info['driver_s']:.1f} s in the driver alone")
        for w in timed:
            if w.stage == stage:
                print("           " + _wave_line(w))
    return 0


def _wave_line(w: Any) -> str:
    """One line of ``hollowtree status`` about a wave of units (:class:`pipeline.timing.Wave`)."""
    import statistics

    from hollowtree.pipeline.timing import balance

    pts = sorted(w.points)
    med = statistics.median(pts) if pts else 0
    ratio = balance(pts)
    spread = f" (largest {ratio:.1f}x the median)" if ratio else ""
    return (f"{w.name}: {len(w.wall)} units on {w.workers} workers; unit seconds total {sum(w.wall):.1f}, "
            f"median {statistics.median(w.wall):.2f}, max {max(w.wall):.2f}; CPU {sum(w.cpu):.1f} s; "
            f"points per unit median {med:,.0f}, max {pts[-1] if pts else 0:,}{spread}")


def _cmd_export(args: argparse.Namespace) -> int:
    from hollowtree.errors import ConfigError
    from hollowtree.pipeline.export import export_las, export_parquet, export_png, style_paths
    from hollowtree.tiling.store import RunStore

    if not (args.las or args.parquet or args.png):
        raise ConfigError("give at least one of --las, --parquet, --png")
    store = RunStore.open(args.store)
    if args.las:
        n = export_las(store, args.las, progress=not args.no_progress)
        print(f"{args.las}: {n:,} points")
        qml, cc = style_paths(args.las)
        print(f"{qml}: QGIS style\n{cc}: CloudCompare colour scale")
    if args.parquet:
        for path in export_parquet(store, args.parquet):
            print(path)
    if args.png:
        print(export_png(store, args.png))
    return 0


def _cmd_coarse(args: argparse.Namespace) -> int:
    from hollowtree.pipeline.coarse import CoarseParams, run_coarse
    from hollowtree.pipeline.graph import task_runner, timed_stage
    from hollowtree.pipeline.workflow import CoarseSection
    from hollowtree.tiling.store import RunStore

    # a missing store or another schema fails before any cluster starts
    scheduler = _store_scheduler(args, RunStore.open(args.store))
    section = _section(CoarseSection, args, "coarse", {"free_segments": False} if args.no_free_segments else None)
    with task_runner(scheduler, workers=args.workers, progress=not args.no_progress) as run:
        with timed_stage(str(args.store), "coarse", run):
            report = run_coarse(args.store, CoarseParams.from_workflow(section), runner=run)
    print(report.summary())
    return 0


def _cmd_ingest(args: argparse.Namespace) -> int:
    import gc

    from hollowtree.errors import ConfigError
    from hollowtree.pipeline.graph import task_runner, timed_stage, tune_process_for_streaming
    from hollowtree.pipeline.workflow import IngestSection
    from hollowtree.tiling.ingest import IngestParams, ingest

    params = IngestParams.from_workflow(_section(IngestSection, args, "ingest"))
    try:
        in_process = args.scheduler == "sync" or (args.scheduler is None and not args.processes)
        if in_process:  # the tasks run in this process: before its worker threads exist
            tune_process_for_streaming()
        with task_runner(args.scheduler, workers=args.workers, progress=not args.no_progress,
                         processes=args.processes) as run:
            if in_process:
                gc.freeze()  # the cluster's own long-lived objects too
            with timed_stage(str(args.store), "ingest", run):
                report = ingest([str(p) for p in args.inputs], args.store, params, runner=run)
    except OSError as exc:
        if args.scheduler not in (None, "sync") and "scheduler" not in str(exc).lower():
            raise ConfigError(f"cannot reach the Dask scheduler {args.scheduler}: {exc}") from None
        raise
    print(report.summary())
    return 0


def _cmd_synth(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from hollowtree.scenes.synth import synth

    bars: list[tqdm] = []

    def on_total(n: int) -> None:
        # Called once the arguments are checked and the scene is built: no bar before.
        bars.append(
            tqdm(total=n, unit="ray", unit_scale=True, desc=f"scanning {args.site}",
                 disable=True if args.no_progress else None, leave=False)
        )

    def on_rays(n: int) -> None:
        bars[-1].update(n)

    # the scan's settings given (the others: ScanParams' defaults)
    scan = {k: v for k in ("seed", "noise", "registration_error") if (v := getattr(args, k)) is not None}
    try:
        result = synth(
            args.site,
            args.out,
            n_points=args.points,
            step_deg=args.step,
            n_stations=args.stations,
            crs=args.crs,
            overwrite=args.overwrite,
            on_rays=on_rays,
            on_total=on_total,
            **scan,
        )
    finally:
        for bar in bars:
            bar.close()
    print(result.summary())
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``hollowtree`` console script."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help, --version, usage errors (exit 2, one line)
        return int(exc.code or 0) if not isinstance(exc.code, str) else 2
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    for name in ("distributed", "dask"):  # dask configures its own loggers at INFO
        logging.getLogger(name).setLevel(logging.WARNING)
    if args.verbose:  # our own loggers only, not every library's
        for name in OWN_LOGGERS:
            logging.getLogger(name).setLevel(logging.DEBUG)
    if args.command is None:
        parser.print_help()
        return 2
    try:
        return int(args.func(args))
    except PipelineError as exc:
        print(f"hollowtree {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        what = ("rerun with --resume to continue" if args.command == "train"
                else "rerun the same command to resume")
        print(f"hollowtree {args.command}: interrupted; {what}", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
