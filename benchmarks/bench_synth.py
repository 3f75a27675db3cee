"""Speed and memory of ``hollowtree synth`` at growing point counts, side by side.

Each size runs in its own process (so peak memory is that run's own) and the script
prints points per second and peak resident memory per size, then the ratios that matter:
peak memory of the largest over the smallest scan (flat = about 1) and throughput of the
largest over the smallest. Run: ``python benchmarks/bench_synth.py [--site S] [--sizes ...]
[--json PATH]`` (default ``benchmarks/results/synth.json``).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

from _results import add_json, write

CHILD = r"""
import json, resource, sys, time
from pathlib import Path
from hollowtree.scenes.synth import synth
site, n, out = sys.argv[1], int(sys.argv[2]), Path(sys.argv[3])
t0 = time.perf_counter()
r = synth(site, out, n_points=n, overwrite=True)
dt = time.perf_counter() - t0
print(json.dumps({"points": r.n_points, "rays": r.n_rays, "seconds": dt,
                  "scan_seconds": r.seconds, "step": r.step_deg,
                  "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                  "bytes": out.stat().st_size}))
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--site", default="wazir_khan")
    ap.add_argument("--sizes", type=int, nargs="+", default=[1_000_000, 10_000_000, 100_000_000])
    add_json(ap, "synth")
    args = ap.parse_args()
    repo = Path(__file__).resolve().parents[1]
    env = dict(os.environ, PYTHONPATH=str(repo))
    print(f"machine: {os.cpu_count()} cores, "
          f"{os.sysconf('SC_PAGE_SIZE') * os.sysconf('SC_PHYS_PAGES') / 2**30:.0f} GiB")
    print(f"{'points':>12} {'wall s':>8} {'Mpts/s':>8} {'Mrays/s':>8} {'peak MB':>8} {'MB on disk':>10}")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for n in args.sizes:
            out = Path(tmp) / f"{args.site}-{n}.laz"
            res = subprocess.run([sys.executable, "-c", CHILD, args.site, str(n), str(out)],
                                 env=env, capture_output=True, text=True, check=True)
            row = json.loads(res.stdout.strip().splitlines()[-1])
            row |= {"m_points_per_s": row["points"] / row["seconds"] / 1e6,
                    "m_rays_per_s": row["rays"] / row["seconds"] / 1e6, "laz_mb": row["bytes"] / 1e6}
            rows.append(row)
            print(f"{row['points']:>12,} {row['seconds']:>8.1f} {row['m_points_per_s']:>8.2f} "
                  f"{row['m_rays_per_s']:>8.2f} {row['peak_rss_mb']:>8.0f} {row['laz_mb']:>10.1f}", flush=True)
            out.unlink()
    small, large = rows[0], rows[-1]
    ratios = {"peak_largest_over_smallest": large["peak_rss_mb"] / small["peak_rss_mb"],
              "throughput_largest_over_smallest": large["m_points_per_s"] / small["m_points_per_s"]}
    print(f"peak memory ratio (largest / smallest): {ratios['peak_largest_over_smallest']:.2f}")
    if len(rows) > 2:
        prev = rows[-2]
        ratios["peak_largest_over_previous"] = large["peak_rss_mb"] / prev["peak_rss_mb"]
        print(f"peak memory ratio ({large['points'] / 1e6:.0f} M / {prev['points'] / 1e6:.0f} M points): "
              f"{ratios['peak_largest_over_previous']:.2f}")
    print(f"throughput ratio (largest / smallest): {ratios['throughput_largest_over_smallest']:.2f}")
    print(f"largest run: {large['m_points_per_s']:.2f} M points/s "
          f"({'meets' if large['m_points_per_s'] >= 1 else 'misses'} the 1 M points/s target)")
    write(args.json, "bench_synth", args, rows=rows, ratios=ratios)


if __name__ == "__main__":
    main()
