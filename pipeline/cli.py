"""The ``hollowtree`` command.

Logging handlers and progress bars are set up here and nowhere else. Every expected
failure (a :class:`tiling.errors.PipelineError`) becomes one line on stderr and exit
code 2; nothing is written in that case.
"""

from __future__ import annotations

import argparse
import logging
import sys
from collections.abc import Sequence
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

from tiling.errors import PipelineError

__all__ = ["main", "build_parser"]

logger = logging.getLogger("hollowtree")


def _version() -> str:
    try:
        return version("hollowtree")
    except PackageNotFoundError:  # running from a source tree that is not installed
        return "unknown (not installed)"


class _Parser(argparse.ArgumentParser):
    """argparse with exit code 2 and a one-line message for usage errors."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {message}\n")


def _positive_int(text: str) -> int:
    try:
        value = int(text.replace("_", ""))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if value <= 0:
        raise argparse.ArgumentTypeError(f"must be a positive integer; got {value}")
    return value


def _float(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None


def _non_negative(text: str) -> float:
    value = _float(text)
    if not value >= 0:
        raise argparse.ArgumentTypeError(f"must be a non-negative number; got {text}")
    return value


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``hollowtree`` and its subcommands."""
    parser = _Parser(
        prog="hollowtree",
        description="Labelled architectural elements from terrestrial laser scans.",
    )
    parser.add_argument("--version", action="version", version=f"hollowtree {_version()}")
    parser.add_argument("-v", "--verbose", action="store_true", help="log debug messages")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)

    from scenes.sites import SITES, TEST_SCENES

    s = sub.add_parser(
        "synth",
        help="make a labelled synthetic scan of a site (LAS/LAZ with gt_class, gt_instance)",
        description=(
            "Scan a synthetic site with a virtual terrestrial laser scanner and write a "
            "LAS 1.4 / LAZ file with per-point ground truth, plus a Parquet table of the "
            f"elements. Sites: {', '.join(SITES)}. Test scenes: {', '.join(TEST_SCENES)}."
        ),
    )
    s.add_argument("site", help="site or test scene name")
    s.add_argument("--out", required=True, type=Path, help="output .laz or .las file")
    size = s.add_mutually_exclusive_group()
    size.add_argument(
        "--points", type=_positive_int, help="aim at about N points (default 1,000,000)"
    )
    size.add_argument("--step", type=_float, help="angular step of the scanner, degrees")
    s.add_argument("--stations", type=_positive_int, help="use the first K stations of the site")
    s.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    s.add_argument(
        "--noise", type=_non_negative, default=0.0025,
        help="range noise standard deviation at 10 m, metres (default 0.0025)",
    )
    s.add_argument(
        "--registration-error", type=_non_negative, default=0.0,
        help="per-station registration error, metres (default 0)",
    )
    s.add_argument("--crs", help="coordinate reference system to record, e.g. EPSG:32643")
    s.add_argument("--overwrite", action="store_true", help="replace an existing output")
    s.add_argument("--no-progress", action="store_true", help="no progress bar")
    s.set_defaults(func=_cmd_synth)

    g = sub.add_parser(
        "ingest",
        help="stream point files into a tiled, chunked Zarr run store",
        description=(
            "Tile LAS/LAZ/PLY/E57 files of one registered site into a Zarr v3 run store: "
            "points routed to tiles with a buffer, Morton-sorted, original indices kept. "
            "Rerunning the same command resumes an interrupted ingest."
        ),
    )
    g.add_argument("inputs", nargs="+", type=Path, help="input files (one registered site)")
    g.add_argument("--store", required=True, help="run store: a folder path or an fsspec URL")
    g.add_argument("--tile-size", type=_tile_size, default=None,
                   help="tile core side, metres, or 'auto' (default: about 2 M points per tile)")
    g.add_argument("--buffer", type=_float, default=2.0, help="buffer width, metres (default 2)")
    g.add_argument("--voxel", type=_float, help="keep one point per voxel of this size, metres")
    g.add_argument("--bbox", type=_bbox, help="only tiles meeting XMIN,YMIN,XMAX,YMAX")
    g.add_argument("--tiles", type=_int_list, help="only these tile ids, e.g. 0,1,5")
    g.add_argument("--chunk-size", type=_positive_int, default=1_000_000,
                   help="records per map task (default 1,000,000)")
    g.add_argument("--scheduler", help="Dask scheduler address; 'sync' runs in this process; "
                   "default: a local cluster of processes")
    g.add_argument("--workers", type=_positive_int, default=2, help="local cluster workers (default 2)")
    g.add_argument("--no-progress", action="store_true", help="no progress bars")
    g.set_defaults(func=_cmd_ingest)

    c = sub.add_parser(
        "coarse",
        help="coarse segments per tile (normals, Efficient RANSAC, DBSCAN), stitched across tiles",
        description=(
            "Run the paper's first stage on an ingested run store: PCA normals, Efficient "
            "RANSAC primitives and DBSCAN per tile as Dask tasks, then join the tiles' "
            "segments over their shared buffer points. Rerunning resumes: recorded tiles "
            "are skipped."
        ),
    )
    c.add_argument("store", help="run store made by `hollowtree ingest`")
    c.add_argument("--epsilon", type=_float, default=0.03, help="RANSAC distance, metres (default 0.03)")
    c.add_argument("--alpha", type=_float, default=20.0, help="RANSAC normal angle, degrees (default 20)")
    c.add_argument("--cluster-epsilon", type=_float,
                   help="RANSAC bitmap cell, metres (default: max(0.15, 2 x point spacing))")
    c.add_argument("--min-support", type=_positive_int, default=1000,
                   help="smallest primitive, points (default 1000)")
    c.add_argument("--eps", type=_float, help="DBSCAN radius, metres (default: 3 x point spacing)")
    c.add_argument("--min-samples", type=_positive_int, default=10, help="DBSCAN core threshold")
    c.add_argument("--seed", type=int, default=0)
    c.add_argument("--scheduler", help="Dask scheduler address; 'sync' runs in this process")
    c.add_argument("--workers", type=_positive_int, default=2, help="local cluster workers (default 2)")
    c.add_argument("--no-progress", action="store_true", help="no progress bars")
    c.set_defaults(func=_cmd_coarse)
    return parser


def _cmd_coarse(args: argparse.Namespace) -> int:
    from pipeline.coarse import CoarseParams, run_coarse
    from pipeline.graph import task_runner
    from primitives.ransac import RansacParams
    from tiling.store import RunStore

    RunStore.open(args.store)  # a missing store or another schema fails before any cluster starts
    params = CoarseParams(
        ransac=RansacParams(epsilon=args.epsilon, alpha_deg=args.alpha, min_support=args.min_support),
        cluster_epsilon=args.cluster_epsilon, eps=args.eps, min_samples=args.min_samples, seed=args.seed,
    )
    with task_runner(args.scheduler, workers=args.workers, progress=not args.no_progress) as run:
        report = run_coarse(args.store, params, runner=run)
    print(report.summary())
    return 0


def _tile_size(text: str) -> float | None:
    return None if text.strip().lower() == "auto" else _float(text)


def _bbox(text: str) -> tuple[float, float, float, float]:
    parts = text.split(",")
    if len(parts) != 4:
        raise argparse.ArgumentTypeError(f"expected XMIN,YMIN,XMAX,YMAX; got {text!r}")
    vals = tuple(_float(p) for p in parts)
    return vals  # type: ignore[return-value]


def _int_list(text: str) -> tuple[int, ...]:
    try:
        return tuple(int(p) for p in text.split(",") if p.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected tile ids like 0,1,5; got {text!r}") from None


def _cmd_ingest(args: argparse.Namespace) -> int:
    from pipeline.graph import task_runner
    from tiling.errors import ConfigError
    from tiling.ingest import IngestParams, ingest

    params = IngestParams(
        tile_size=args.tile_size, buffer=args.buffer, voxel=args.voxel, bbox=args.bbox,
        tiles=args.tiles, chunk_size=args.chunk_size,
    )
    try:
        with task_runner(args.scheduler, workers=args.workers, progress=not args.no_progress) as run:
            report = ingest([str(p) for p in args.inputs], args.store, params, runner=run)
    except OSError as exc:
        if args.scheduler not in (None, "sync") and "scheduler" not in str(exc).lower():
            raise ConfigError(f"cannot reach the Dask scheduler {args.scheduler}: {exc}") from None
        raise
    print(report.summary())
    return 0


def _cmd_synth(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from scenes.synth import synth

    bars: list[tqdm] = []

    def on_total(n: int) -> None:
        # Called once the arguments are checked and the scene is built: no bar before.
        bars.append(
            tqdm(total=n, unit="ray", unit_scale=True, desc=f"scanning {args.site}",
                 disable=args.no_progress, leave=False)
        )

    def on_rays(n: int) -> None:
        bars[-1].update(n)

    try:
        result = synth(
            args.site,
            args.out,
            n_points=args.points,
            step_deg=args.step,
            n_stations=args.stations,
            seed=args.seed,
            noise=args.noise,
            registration_error=args.registration_error,
            crs=args.crs,
            overwrite=args.overwrite,
            on_rays=on_rays,
            on_total=on_total,
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
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.WARNING,
        format="%(levelname)s %(name)s: %(message)s",
    )
    if not args.verbose:  # dask configures its own loggers at INFO
        for name in ("distributed", "dask"):
            logging.getLogger(name).setLevel(logging.WARNING)
    if args.command is None:
        parser.print_help()
        return 2
    try:
        return int(args.func(args))
    except PipelineError as exc:
        print(f"hollowtree {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"hollowtree {args.command}: interrupted; nothing was written", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
