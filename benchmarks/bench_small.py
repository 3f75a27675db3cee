"""Small scans: ``hollowtree run`` end to end in process against on a local cluster.

For each scan it runs the bundled default workflow (``workflows/local.yaml``, every
output written: LAZ, tables, PNG) twice, back to back, as a child command timed from
outside (process start, imports and cluster start included): once with
``cluster.in_process_below=0`` (a local cluster of 2 worker processes) and once with
every task in the command's own process. It prints both walls and the ratio, cluster
over in process (above 1: in process is faster). The ratios choose
``cluster.in_process_below``; the 1 065-point ``laspy/simple.laz`` of
``../shared/data/external`` (when it is there) and the demo's 1 M points are the
targets of issue 44 (under 8 s and 45 s on an idle 2-core machine).

Run: ``python benchmarks/bench_small.py [--sizes 1e5 3e5 1e6 2e6 4e6] [--json FILE]`` (default
``benchmarks/results/small.json``).
Scans are synthetic Wazir Khan scans made once in ``out/`` (not timed).
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _results import add_json, write

REPO = Path(__file__).resolve().parents[1]
SIMPLE = REPO.parent / "shared" / "data" / "external" / "laspy" / "simple.laz"


def run_once(scan: Path, below: int, work: Path) -> float:
    """Seconds of one ``hollowtree run`` of ``scan``, outputs included; raises on failure."""
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir(parents=True)
    cmd = [sys.executable, "-m", "hollowtree", "run", str(REPO / "workflows" / "local.yaml"), "--no-progress"]
    for s in (f'input.files=["{scan}"]', "input.synth=null", f"store={work / 's.zarr'}",
              f"outputs.las={work / 'l.laz'}", f"outputs.parquet={work / 't'}", f"outputs.png={work / 'v.png'}",
              f"cluster.in_process_below={below}"):
        cmd += ["--set", s]
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, env=dict(os.environ, PYTHONPATH=str(REPO)))
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise SystemExit(f"{scan}: run failed ({proc.returncode}): {proc.stderr.strip()[-400:]}")
    return wall


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", nargs="+", type=float, default=[1e5, 3e5, 1e6, 2e6, 4e6])
    add_json(ap, "small")
    args = ap.parse_args()
    sys.path.insert(0, str(REPO))
    from hollowtree.scenes.synth import synth
    from hollowtree.tiling.readers import probe

    scans = [SIMPLE] if SIMPLE.is_file() else []
    for size in args.sizes:
        path = REPO / "out" / f"wazir_khan-{int(size)}.laz"
        if not path.is_file():
            path.parent.mkdir(exist_ok=True)
            synth("wazir_khan", path, n_points=int(size), seed=0)
        scans.append(path)
    rows = []
    with tempfile.TemporaryDirectory(dir=REPO / "out") as tmp:
        for scan in scans:
            n = probe(scan).point_count
            cluster = run_once(scan, 0, Path(tmp) / "c")
            inproc = run_once(scan, 2**62, Path(tmp) / "p")
            rows.append({"scan": scan.name, "points": n, "cluster_s": cluster, "in_process_s": inproc,
                         "cluster_over_in_process": cluster / inproc})
            print(f"{scan.name:<28}{n:>12,} points: cluster {cluster:6.1f} s, in process {inproc:6.1f} s, "
                  f"ratio {cluster / inproc:.2f}", flush=True)
    write(args.json, "bench_small", args, rows=rows)


if __name__ == "__main__":
    main()
