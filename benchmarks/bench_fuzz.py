"""The never-crash harness at scale (issue 43): random scans through every stage.

Draws ``--scans`` specs from ``scenes.fuzz.fuzz_specs()`` (random scene compositions of
10 k to 300 k points and degenerate point sets: a lone point, one point per tile, a
1 x 200 strip, identical points, uniform noise, only ground, only walls, a 1 cm cube;
any of them duplicated, at survey coordinates, cut into 1 to 12 tiles across, with or
without the density cap) and runs each through every stage of ``workflows/local.yaml``
in process (``pipeline.fuzz.run_fuzz``): ingest, coarse + stitch, tree + HollowNet,
labels and the LAZ / Parquet / PNG outputs, then checks that every input point has a
label and the LAZ holds every point in order.

Hypothesis draws the specs (generation only, no shrinking, no example database), seeded
by ``--seed``, so a run is repeatable. Any exception or failed check is a bug: the
script prints each with its spec and traceback, keeps its work folder under ``--work``,
and exits 1. A file with no point at all may be refused with a one-line message.

Prints a table per kind (scans, points, bugs, seconds) and writes the outcomes as JSON
(``--json``, default ``benchmarks/results/fuzz.json``).

Run: ``python benchmarks/bench_fuzz.py [--scans 500] [--seed 0] [--max-points 300000]
[--work out/fuzz] [--json PATH]``.
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from hypothesis import HealthCheck, Phase, given, settings  # noqa: E402
from hypothesis import seed as hseed  # noqa: E402
from tqdm import tqdm  # noqa: E402

from hollowtree.pipeline.fuzz import FuzzOutcome, run_fuzz  # noqa: E402
from hollowtree.scenes.fuzz import fuzz_specs  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scans", type=int, default=500)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--max-points", type=int, default=300_000)
    ap.add_argument("--work", type=Path, default=REPO / "out" / "fuzz")
    ap.add_argument("--json", type=Path, default=REPO / "benchmarks" / "results" / "fuzz.json")
    args = ap.parse_args(argv)
    if args.scans < 1:
        ap.error("--scans must be positive")
    outcomes: list[FuzzOutcome] = []
    bar = tqdm(total=args.scans, desc="fuzz scans", unit="scan", file=sys.stderr,
               disable=not sys.stderr.isatty())
    t0 = time.perf_counter()

    @hseed(args.seed)
    @settings(max_examples=args.scans, database=None, phases=[Phase.generate], deadline=None,
              suppress_health_check=list(HealthCheck))
    @given(fuzz_specs(max_points=args.max_points))
    def one(spec):
        out = run_fuzz(spec, args.work / f"scan-{len(outcomes):04d}")
        outcomes.append(out)
        bar.update(1)
        if out.status == "bug":
            print(f"BUG {spec.describe()}\n{out.error}", file=sys.stderr, flush=True)

    one()
    bar.close()
    wall = time.perf_counter() - t0
    kinds = sorted({o.spec.kind for o in outcomes})
    print(f"{'kind':<10}{'scans':>7}{'points':>12}{'ok':>6}{'refused':>9}{'bugs':>6}{'seconds':>9}")
    for k in kinds:
        os_ = [o for o in outcomes if o.spec.kind == k]
        print(f"{k:<10}{len(os_):>7}{sum(o.n_points for o in os_):>12,}"
              f"{sum(o.status == 'ok' for o in os_):>6}{sum(o.status == 'refused' for o in os_):>9}"
              f"{sum(o.status == 'bug' for o in os_):>6}{sum(o.seconds for o in os_):>9.0f}")
    bugs = [o for o in outcomes if o.status == "bug"]
    multi = sum(1 for o in outcomes if o.spec.tiles_across and o.spec.tiles_across > 1)
    print(f"{len(outcomes)} scans ({multi} cut into several tiles), {len(bugs)} bugs, {wall:.0f} s")
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps({
        "benchmark": "bench_fuzz", "scans": len(outcomes), "seed": args.seed, "max_points": args.max_points,
        "bugs": len(bugs), "seconds": round(wall, 1), "machine": platform.processor() or platform.machine(),
        "outcomes": [o.to_dict() for o in outcomes],
    }, indent=1) + "\n")
    print(f"outcomes: {args.json}")
    return 1 if bugs else 0


if __name__ == "__main__":
    sys.exit(main())
