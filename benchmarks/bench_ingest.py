"""Ingest throughput against the physical limit, and its memory, side by side in one run.

For each size: a synthetic scan is written as LAZ (and, up to 20 M points, as LAS), then
(1) a plain laspy chunked read of the same file (scaled x, y, z of every point: the
limit any ingest has to read through) and (2) ``hollowtree ingest`` of it on the default
local Dask cluster (2 worker processes) run as a separate command. Prints points per
second of both, their ratio (target: ingest at least 0.5 of the raw read), and the peak
resident memory of the largest process of the ingest command (target: flat in the point
count, under 2 GiB at the default chunk size).

Run: ``python benchmarks/bench_ingest.py [--sizes 10000000 100000000] [--site S]``.
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import laspy


def raw_read(path: Path) -> float:
    t0 = time.perf_counter()
    n = 0
    with laspy.open(path) as reader:
        for chunk in reader.chunk_iterator(1_000_000):
            _ = (chunk.x, chunk.y, chunk.z)
            n += len(chunk)
    return n / (time.perf_counter() - t0)


def run_ingest(path: Path, store: Path, env: dict[str, str]) -> tuple[float, float]:
    before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    t0 = time.perf_counter()
    subprocess.run(
        [sys.executable, "-m", "pipeline.cli", "ingest", str(path), "--store", str(store),
         "--no-progress"], env=env, check=True, capture_output=True, text=True,
    )
    seconds = time.perf_counter() - t0
    peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    return seconds, max(peak, before) / 1024


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--site", default="wazir_khan")
    ap.add_argument("--sizes", type=int, nargs="+", default=[10_000_000, 100_000_000])
    ap.add_argument("--las-up-to", type=int, default=20_000_000)
    args = ap.parse_args()
    repo = Path(__file__).resolve().parents[1]
    env = dict(os.environ, PYTHONPATH=str(repo))
    sys.path.insert(0, str(repo))
    from scenes.synth import synth

    print(f"machine: {os.cpu_count()} cores, "
          f"{os.sysconf('SC_PAGE_SIZE') * os.sysconf('SC_PHYS_PAGES') / 2**30:.0f} GiB")
    print(f"{'file':>22} {'points':>12} {'raw Mpts/s':>10} {'ingest s':>9} {'ingest Mpts/s':>13} "
          f"{'ratio':>6} {'peak MB':>8}")
    peaks = {}
    with tempfile.TemporaryDirectory(dir=os.environ.get("BENCH_TMP")) as tmp:
        for n in args.sizes:
            suffixes = [".las", ".laz"] if n <= args.las_up_to else [".laz"]
            for suffix in suffixes:
                path = Path(tmp) / f"{args.site}-{n}{suffix}"
                res = synth(args.site, path, n_points=n, seed=1)
                raw = raw_read(path)
                store = Path(tmp) / "store.zarr"
                seconds, peak = run_ingest(path, store, env)
                rate = res.n_points / seconds
                peaks[(n, suffix)] = peak
                print(f"{path.name:>22} {res.n_points:>12,} {raw / 1e6:>10.2f} {seconds:>9.1f} "
                      f"{rate / 1e6:>13.2f} {rate / raw:>6.2f} {peak:>8.0f}", flush=True)
                shutil.rmtree(store)
                path.unlink()
                path.with_name(path.stem + ".elements.parquet").unlink()
    laz = sorted((n, p) for (n, s), p in peaks.items() if s == ".laz")
    if len(laz) > 1:
        print(f"peak memory ratio LAZ {laz[-1][0] / 1e6:.0f} M / {laz[0][0] / 1e6:.0f} M points: "
              f"{laz[-1][1] / laz[0][1]:.2f}")


if __name__ == "__main__":
    main()
