"""End-to-end scaling of ``hollowtree run``: wall time and peak memory per stage at several sizes.

For each size N it makes (once, not timed) a synthetic Wazir Khan scan of about N points,
then runs ``hollowtree run`` on the bundled default workflow with the input, the store
and the outputs overridden, as a child command whose processes (the local Dask cluster's
workers included) are sampled every 0.2 s. Per stage (the lines the run prints as each
stage ends) it reports seconds, input points per second per core, the peak resident
memory of the largest single process, of all processes together and of the driver (the
``hollowtree run`` process itself, which stitches), and how busy the machine's cores were
(the share of all CPU time that was not idle; the benchmark should run alone, so this is
how well the run keeps its cores fed). At the end it prints
the issue's two ratios, measured side by side in this one run:

- time per point at the largest size over time per point at the smallest (linear = 1);
- peak single-process memory at each size over that at the size before it, the smallest
  left out (flat = 1; ``--sizes 1e6 1e7 1e8`` prints 100 M over 10 M).

The machine's own speed is printed beside the figures: its CPU model, and before each run
and after the last, a **reference read** (the same LAZ scan, the one nearest 10 M points,
decoded by laspy on every core: raw points/s, no pipeline; ``--reference PATH`` names
another, e.g. the 10 M-point scan when only ``--sizes 1e8`` runs). Our machines are shared and
change kind between sessions; the end-to-end rate over the reference read rate taken just
before the run is a ratio that stays comparable where absolute rates do not.

After each run it reads the store's unit records and stage times and prints what they
predict for 1, 2, 4, 16 and 64 workers and for ``--target`` points (1.36 B) on 64
workers (:mod:`pipeline.timing`: every wave list-scheduled, plus the driver's seconds,
plus the run's other seconds as measured), and per wave its units, seconds and largest
unit over the median in points, and the worst of those waves (``unit_balance``; issue 44
asks for 3x at most). ``--workers 1 2`` runs every size once per worker count
and prints the wall of the fewest over that of the most.

A "process" is a worker with the task it runs: a task's child process forked from its
worker (``pipeline.graph.in_child``) counts with the worker, as its own pages (USS) on top
of the worker's resident memory (``_procs.tree_rss``).

Run: ``python benchmarks/bench_scale.py [--sizes 1e6 1e7 1e8] [--workflow workflows/local.yaml]
[--set key=value ...] [--workers 1 2] [--target 1.36e9] [--json FILE]``. Scans are cached in ``out/`` by the workflow's
``input.synth.out`` pattern; stores are written to ``out/scale-<N>.zarr`` and deleted
first (kept after the run with ``--keep``).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import psutil
from _procs import tree_rss
from _results import cpu_model

REPO = Path(__file__).resolve().parents[1]
STAGES = ("ingest", "coarse", "tree", "labels", "outputs")


def _busy(a: Any, b: Any) -> float:
    """Fraction of the machine's CPU time between two ``psutil.cpu_times()`` that was not idle."""
    idle = (b.idle - a.idle) + (getattr(b, "iowait", 0.0) - getattr(a, "iowait", 0.0))
    # Linux counts guest time inside user time as well: leave it out of the total.
    total = sum(b) - sum(a) - sum(getattr(b, f, 0.0) - getattr(a, f, 0.0) for f in ("guest", "guest_nice"))
    return 1.0 - idle / total if total > 0 else 0.0


def measure(cmd: list[str]) -> tuple[int, float, list[dict[str, float]]]:
    """Run ``cmd``; per stage line: name, seconds since the previous one, peaks (bytes)."""
    t0 = time.perf_counter()
    child = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                             env=dict(os.environ, PYTHONPATH=str(REPO)))
    ps = psutil.Process(child.pid)
    peak = {"max": 0, "sum": 0, "driver": 0}
    lock = threading.Lock()
    stop = threading.Event()

    def sample() -> None:
        while not stop.is_set():
            m, s = tree_rss(ps)
            try:
                d = ps.memory_info().rss
            except psutil.NoSuchProcess:
                d = 0
            with lock:
                peak["max"], peak["sum"] = max(peak["max"], m), max(peak["sum"], s)
                peak["driver"] = max(peak["driver"], d)
            time.sleep(0.2)

    th = threading.Thread(target=sample, daemon=True)
    th.start()
    rows: list[dict[str, float]] = []
    last = t0
    cpu_last = psutil.cpu_times()
    assert child.stdout is not None
    for line in child.stdout:
        sys.stdout.write("    " + line)
        name = line.split(":")[0].strip()
        if name in STAGES and (not rows or rows[-1]["stage"] != name):
            now, cpu = time.perf_counter(), psutil.cpu_times()
            with lock:
                rows.append({"stage": name, "seconds": now - last, "peak_process": peak["max"],
                             "peak_sum": peak["sum"], "peak_driver": peak["driver"],
                             "busy": _busy(cpu_last, cpu)})
                peak["max"], peak["sum"], peak["driver"] = 0, 0, 0
            last, cpu_last = now, cpu
        elif name in STAGES:  # a second line of the same stage (outputs)
            now, cpu = time.perf_counter(), psutil.cpu_times()
            with lock:
                rows[-1]["busy"] = ((rows[-1]["busy"] * rows[-1]["seconds"] + _busy(cpu_last, cpu) * (now - last))
                                    / (rows[-1]["seconds"] + now - last))
                rows[-1]["seconds"] += now - last
                rows[-1]["peak_process"] = max(rows[-1]["peak_process"], peak["max"])
                rows[-1]["peak_sum"] = max(rows[-1]["peak_sum"], peak["sum"])
                rows[-1]["peak_driver"] = max(rows[-1]["peak_driver"], peak["driver"])
                peak["max"], peak["sum"], peak["driver"] = 0, 0, 0
            last, cpu_last = now, cpu
    child.wait()
    stop.set()
    th.join()
    return child.returncode, time.perf_counter() - t0, rows


def reference_read(path: Path, min_seconds: float = 3.0) -> float:
    """Points per second of plain ``laspy.read`` of ``path`` (its default LAZ backend, on
    every core), reading it again until ``min_seconds`` have passed: the machine's speed
    at this moment, on a fixed job."""
    import laspy

    n, t0 = 0, time.perf_counter()
    while True:
        n += len(laspy.read(path).points)
        elapsed = time.perf_counter() - t0
        if elapsed >= min_seconds:
            return n / elapsed


PREDICT_WORKERS = (1, 2, 4, 16, 64)


def projection(store: Path, n_points: int, wall: float, stage_rows: list[dict[str, float]],
               target_points: float) -> dict[str, Any]:
    """What the recorded units of ``store`` predict (``pipeline.timing``): the makespan on
    1-64 workers, and ``target_points`` on 64 workers (the units repeated, the driver's
    and the outputs' seconds grown alike); the rest of the run (process and cluster
    starts, new workers between stages) is added as measured. Also each wave's largest
    unit over its median, in points."""
    from hollowtree.pipeline.timing import UNIT_BALANCE, WAVES, balance, predict_seconds, waves
    from hollowtree.tiling.store import RunStore

    st = RunStore.open(str(store))
    wl = waves({name: st.records(name) for name in {n for _, _, n in WAVES}})
    stages = st.attrs.get("stages", {})
    driver = {k: float(v.get("driver_s", 0.0)) for k, v in stages.items()}
    staged = sum(float(v.get("wall_s", 0.0)) for v in stages.values())
    outputs = sum(r["seconds"] for r in stage_rows if r["stage"] == "outputs")
    other = max(wall - staged - outputs, 0.0)
    pred = {w: predict_seconds(wl, driver, w) + outputs + other for w in PREDICT_WORKERS}
    repeat = target_points / n_points
    big = predict_seconds(wl, driver, 64, repeat=repeat) + outputs * repeat + other
    ratios = {f"{w.stage}.{w.name}": balance(w.points) for w in wl}
    worst = max(((r, k) for k, r in ratios.items() if r is not None), default=None)
    return {"predicted_s": pred, "speedup_16_over_2": pred[2] / pred[16], "target_points": target_points,
            "target_64_workers_s": big, "driver_s": driver, "outputs_s": outputs, "other_s": other,
            "largest_over_median_points": ratios,
            "unit_balance": {"worst_wave": worst[1] if worst else None, "largest_over_median": worst[0] if worst else None,
                             "limit": UNIT_BALANCE},
            "waves": [{"stage": w.stage, "wave": w.name, "units": len(w.wall), "unit_s": sum(w.wall),
                       "max_s": max(w.wall), "cpu_s": sum(w.cpu), "max_points": max(w.points)} for w in wl]}


def print_projection(n: int, workers: int, p: dict[str, Any]) -> None:
    print(f"{n:,} points, {workers} workers: recorded units predict "
          + ", ".join(f"{w} workers {s:.1f} s" for w, s in p["predicted_s"].items())
          + f"; 16 over 2: {p['speedup_16_over_2']:.2f}x; {p['target_points'] / 1e9:.2f} B points on 64 workers: "
          f"{p['target_64_workers_s'] / 60:.1f} min")
    for w in p["waves"]:
        ratio = p["largest_over_median_points"].get(f"{w['stage']}.{w['wave']}")
        print(f"    {w['stage']:<7}{w['wave']:<8}{w['units']:>5} units {w['unit_s']:>8.1f} s (max {w['max_s']:.1f} s)"
              f"{w['cpu_s']:>9.1f} CPU s; largest unit {w['max_points']:,} points"
              + (f" ({ratio:.1f}x the median)" if ratio else ""))
    ub = p["unit_balance"]
    if ub["worst_wave"]:
        print(f"    units: the largest holds {ub['largest_over_median']:.1f}x its wave's median in points at most "
              f"({ub['worst_wave']}; limit {ub['limit']:g}x)")
    print(f"    driver alone: {sum(p['driver_s'].values()):.1f} s "
          f"({', '.join(f'{k} {v:.1f}' for k, v in p['driver_s'].items())}); outputs {p['outputs_s']:.1f} s; "
          f"starts and new workers {p['other_s']:.1f} s")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", nargs="+", type=float, default=[1e6, 1e7, 1e8])
    ap.add_argument("--workflow", type=Path, default=REPO / "workflows" / "local.yaml")
    ap.add_argument("--set", dest="overrides", action="append", default=[])
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--workers", nargs="+", type=int, default=None,
                    help="run every size once per worker count (cluster.workers), side by side")
    ap.add_argument("--target", type=float, default=1.36e9,
                    help="points of the scan the recorded units project to on 64 workers (default 1.36e9)")
    ap.add_argument("--keep", action="store_true",
                    help="keep each run's store (out/scale-<N>.zarr) for `hollowtree status` and the predictor")
    ap.add_argument("--reference", type=Path, default=None,
                    help="LAZ/LAS file of the reference read (default: the scan nearest 10 M points)")
    args = ap.parse_args()
    if args.reference is not None and not args.reference.is_file():
        ap.error(f"--reference {args.reference}: no such file")
    sys.path.insert(0, str(REPO))
    from hollowtree.pipeline.run import make_synthetic_input
    from hollowtree.pipeline.workflow import load_workflow
    from hollowtree.tiling.readers import probe

    cores = os.cpu_count() or 1
    runs = []
    for size in args.sizes:  # every scan first (not timed), so the reference file exists
        n = int(size)
        store = REPO / "out" / f"scale-{n}.zarr"
        sets = [f"input.synth.points={n}", f"store={store}", "outputs.las=null", "outputs.png=null",
                "outputs.parquet=null", *args.overrides]
        wf = load_workflow(args.workflow, sets)
        t0 = time.perf_counter()
        made = make_synthetic_input(wf, progress=True)
        if made:
            print(f"{n:,} points: input made in {time.perf_counter() - t0:.1f} s (not counted)")
        runs.append((n, store, sets, wf))
    if args.reference is not None:
        ref = args.reference
    else:
        ref_wf = min(runs, key=lambda r: abs(math.log(r[0] / 1e7)))[3]
        ref = Path(ref_wf.input.paths()[0])
    print(f"reference read: {ref.name} (laspy, every core)")
    results = []
    for n, store, sets, wf in runs:
        for workers in args.workers or [wf.cluster.workers]:
            before = reference_read(ref)
            print(f"{n:,} points: reference read {before / 1e6:.2f} M points/s")
            if store.exists():
                shutil.rmtree(store)
            cmd = [sys.executable, "-m", "hollowtree", "run", str(args.workflow), "--no-progress"]
            for s in [*sets, *([f"cluster.workers={workers}"] if args.workers else [])]:
                cmd += ["--set", s]
            print(f"{n:,} points: {' '.join(cmd[2:])}")
            rc, wall, rows = measure(cmd)
            if rc != 0:
                raise SystemExit(f"run of {n:,} points failed with exit code {rc}")
            n_in = sum(probe(p).point_count for p in wf.input.paths())
            proj = projection(store, n_in, wall, rows, args.target)
            print_projection(n_in, workers, proj)
            results.append({"points": n_in, "workers": workers, "wall_s": wall, "stages": rows,
                            "reference_read": before, "projection": proj})
            if not args.keep:
                shutil.rmtree(store, ignore_errors=True)
    after = reference_read(ref)
    print(f"after the last run: reference read {after / 1e6:.2f} M points/s")

    print(f"\nmachine: {cpu_model()}, {cores} cores, {psutil.virtual_memory().total / 2**30:.0f} GiB")
    print(f"{'points':>12} {'stage':<8}{'s':>9}{'pts/s/core':>12}{'peak proc MB':>14}{'peak sum MB':>13}"
          f"{'driver MB':>11}{'busy %':>8}")
    for r in results:
        for row in r["stages"]:
            rate = r["points"] / row["seconds"] / cores if row["seconds"] > 0 else float("inf")
            print(f"{r['points']:>12,} {row['stage']:<8}{row['seconds']:>9.1f}{rate:>12,.0f}"
                  f"{row['peak_process'] / 2**20:>14.0f}{row['peak_sum'] / 2**20:>13.0f}"
                  f"{row['peak_driver'] / 2**20:>11.0f}{100 * row.get('busy', float('nan')):>8.0f}")
        peak = max(x["peak_process"] for x in r["stages"])
        rate = r["points"] / r["wall_s"]
        print(f"{r['points']:>12,} {'total':<8}{r['wall_s']:>9.1f}{rate:>12,.0f} pts/s "
              f"(all cores); peak process {peak / 2**20:.0f} MB; over the reference read "
              f"({r['reference_read'] / 1e6:.2f} M/s) {rate / r['reference_read']:.3f}")
    if args.workers and len(args.workers) >= 2:
        for n in sorted({r["points"] for r in results}):
            walls = {r["workers"]: r["wall_s"] for r in results if r["points"] == n}
            lo, hi = min(walls), max(walls)
            print(f"{n:,} points: wall with {lo} workers over {hi} workers: {walls[lo] / walls[hi]:.2f}")
    by_size = [r for r in results if r["workers"] == results[0]["workers"]]
    if len(by_size) >= 2:
        a, b = by_size[0], by_size[-1]
        lin = (b["wall_s"] / b["points"]) / (a["wall_s"] / a["points"])
        print(f"time per point, {b['points']:,} over {a['points']:,}: {lin:.2f} (linear = 1)")
        for c, b in zip(by_size[1:-1], by_size[2:], strict=True):  # each size over the one before (the smallest left out)
            pk = max(x["peak_process"] for x in b["stages"]) / max(x["peak_process"] for x in c["stages"])
            print(f"peak single-process memory, {b['points']:,} over {c['points']:,}: {pk:.2f} (flat = 1)")
        if len(by_size) == 2:
            c, b = by_size
            pk = max(x["peak_process"] for x in b["stages"]) / max(x["peak_process"] for x in c["stages"])
            print(f"peak single-process memory, {b['points']:,} over {c['points']:,}: {pk:.2f} (flat = 1)")
    if args.json:
        args.json.write_text(json.dumps({"cores": cores, "cpu": cpu_model(), "reference_file": ref.name,
                                         "reference_read_after": after, "results": results}, indent=1))


if __name__ == "__main__":
    main()
