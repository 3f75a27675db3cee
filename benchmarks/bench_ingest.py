"""Ingest throughput against the physical limit, and its memory, side by side in one run.

For each size: a synthetic scan is written as LAZ (and, up to 20 M points, as LAS), then
(1) a plain laspy chunked read of the same file (scaled x, y, z of every point: the
limit any ingest has to read through; laspy's default LAZ backend decompresses on every
core) and (2) ``hollowtree ingest`` of it with its defaults (a local Dask cluster of 2
worker threads in the command's process; ``--processes``: of 2 worker processes) run as
a separate command, timed end to end. With ``--repeats N`` the pair runs N times, one
after the other, and the medians are compared (the machine may be shared). Prints points
per second of both, their ratio (target: ingest at least 0.5 of the raw read), the
peak resident memory of the ingest command (its largest process; target: flat in the
point count, under 2 GiB at the default chunk size), and the CPU seconds of both (all
threads and processes) with their ratio: a figure that other jobs on the machine bend
much less than wall times.

First it measures the fixed cost every ingest pays whatever its size: the interpreter's
start, importing what ``hollowtree ingest`` imports, and a whole ingest of a 1 000-point
file (imports, numba's start, the local cluster, planning, one map and one reduce task).

Run: ``python benchmarks/bench_ingest.py [--sizes 10000000 100000000] [--site S]
[--repeats N] [--processes] [--json PATH]`` (default ``benchmarks/results/ingest.json``).
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import laspy
from _results import add_json, write


def _cpu() -> float:
    t = os.times()
    return t.user + t.system


def raw_read(path: Path) -> tuple[float, float]:
    """Points per second of a plain chunked read, and its CPU seconds (all threads)."""
    t0, c0 = time.perf_counter(), _cpu()
    n = 0
    with laspy.open(path) as reader:
        for chunk in reader.chunk_iterator(1_000_000):
            _ = (chunk.x, chunk.y, chunk.z)
            n += len(chunk)
    return n / (time.perf_counter() - t0), _cpu() - c0


def run_command(argv: list[str], env: dict[str, str]) -> tuple[float, float, float]:
    """Run ``argv``; return its wall seconds, the peak resident MB of its largest
    process and its CPU seconds (its own rusage, children included, from ``wait4``)."""
    with tempfile.TemporaryFile() as out:
        t0 = time.perf_counter()
        proc = subprocess.Popen(argv, env=env, stdout=out, stderr=subprocess.STDOUT)
        _, status, usage = os.wait4(proc.pid, 0)
        seconds = time.perf_counter() - t0
        proc.returncode = os.waitstatus_to_exitcode(status)
        if proc.returncode:
            out.seek(0)
            sys.exit(f"{' '.join(argv)} failed ({proc.returncode}):\n{out.read().decode()[-2000:]}")
    return seconds, usage.ru_maxrss / 1024, usage.ru_utime + usage.ru_stime


def ingest_argv(path: Path, store: Path, processes: bool) -> list[str]:
    return [sys.executable, "-m", "hollowtree", "ingest", str(path), "--store", str(store),
            "--no-progress", *(["--processes"] if processes else [])]


def fixed_cost(tmp: Path, env: dict[str, str], processes: bool) -> None:
    from hollowtree.scenes.synth import synth

    start = min(run_command([sys.executable, "-c", "pass"], env)[0] for _ in range(3))
    imports = min(run_command([sys.executable, "-c", "import pipeline.cli, tiling.ingest, distributed, numba"],
                              env)[0] for _ in range(3))
    tiny = tmp / "tiny.laz"
    synth("dome", tiny, n_points=1_000, seed=1)
    runs = []
    for _ in range(3):
        store = tmp / "tiny.zarr"
        runs.append(run_command(ingest_argv(tiny, store, processes), env)[0])
        shutil.rmtree(store)
    print(f"fixed cost (best of 3): interpreter start {start:.2f} s; imports of `hollowtree ingest` "
          f"{imports:.2f} s; ingest of a 1,000-point LAZ {min(runs):.2f} s", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--site", default="wazir_khan")
    ap.add_argument("--sizes", type=int, nargs="+", default=[10_000_000, 100_000_000])
    ap.add_argument("--las-up-to", type=int, default=20_000_000)
    ap.add_argument("--repeats", type=int, default=1, help="raw read + ingest pairs per file (medians)")
    ap.add_argument("--processes", action="store_true", help="ingest on a local cluster of processes")
    add_json(ap, "ingest")
    args = ap.parse_args()
    repo = Path(__file__).resolve().parents[1]
    env = dict(os.environ, PYTHONPATH=str(repo))
    sys.path.insert(0, str(repo))
    from hollowtree.scenes.synth import synth

    print(f"machine: {os.cpu_count()} cores, "
          f"{os.sysconf('SC_PAGE_SIZE') * os.sysconf('SC_PHYS_PAGES') / 2**30:.0f} GiB; "
          f"load average {os.getloadavg()[0]:.2f}; workers: {'processes' if args.processes else 'threads'}")
    peaks, rows = {}, []
    with tempfile.TemporaryDirectory(dir=os.environ.get("BENCH_TMP")) as tmp:
        fixed_cost(Path(tmp), env, args.processes)
        print(f"{'file':>22} {'points':>12} {'raw Mpts/s':>10} {'ingest s':>9} {'ingest Mpts/s':>13} "
              f"{'ratio':>6} {'peak MB':>8} {'raw CPU s':>9} {'ingest CPU s':>12} {'CPU ratio':>9}")
        for n in args.sizes:
            suffixes = [".las", ".laz"] if n <= args.las_up_to else [".laz"]
            for suffix in suffixes:
                path = Path(tmp) / f"{args.site}-{n}{suffix}"
                res = synth(args.site, path, n_points=n, seed=1)
                store = Path(tmp) / "store.zarr"
                raws, times, mems, raw_cpus, cpus = [], [], [], [], []
                for _ in range(args.repeats):
                    rate, cpu = raw_read(path)
                    raws.append(rate)
                    raw_cpus.append(cpu)
                    seconds, peak, cpu = run_command(ingest_argv(path, store, args.processes), env)
                    times.append(seconds)
                    mems.append(peak)
                    cpus.append(cpu)
                    shutil.rmtree(store)
                raw, seconds, peak = statistics.median(raws), statistics.median(times), max(mems)
                raw_cpu, cpu = statistics.median(raw_cpus), statistics.median(cpus)
                rate = res.n_points / seconds
                peaks[(n, suffix)] = peak
                detail = ""
                if args.repeats > 1:
                    detail = (f"   (raw {' '.join(f'{r / 1e6:.2f}' for r in raws)}; "
                              f"ingest s {' '.join(f'{t:.1f}' for t in times)})")
                rows.append({"file": suffix[1:].upper(), "points": res.n_points, "raw_m_points_per_s": raw / 1e6,
                             "ingest_s": seconds, "ingest_m_points_per_s": rate / 1e6, "ingest_over_raw": rate / raw,
                             "peak_mb": peak, "raw_cpu_s": raw_cpu, "ingest_cpu_s": cpu})
                print(f"{path.name:>22} {res.n_points:>12,} {raw / 1e6:>10.2f} {seconds:>9.1f} "
                      f"{rate / 1e6:>13.2f} {rate / raw:>6.2f} {peak:>8.0f} {raw_cpu:>9.1f} {cpu:>12.1f} "
                      f"{raw_cpu / cpu:>9.2f}{detail}", flush=True)
                path.unlink()
                path.with_name(path.stem + ".elements.parquet").unlink()
    laz = sorted((n, p) for (n, s), p in peaks.items() if s == ".laz")
    ratios = {}
    if len(laz) > 1:
        ratios["peak_laz_largest_over_smallest"] = laz[-1][1] / laz[0][1]
        print(f"peak memory ratio LAZ {laz[-1][0] / 1e6:.0f} M / {laz[0][0] / 1e6:.0f} M points: "
              f"{ratios['peak_laz_largest_over_smallest']:.2f}")
    write(args.json, "bench_ingest", args, rows=rows, ratios=ratios)


if __name__ == "__main__":
    main()
