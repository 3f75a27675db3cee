"""Wall time and peak memory of ``hollowtree run`` on a workflow, sampled from outside.

Runs the workflow as a child command and samples, every 0.2 s, the resident memory of the
command and every process below it (the local Dask cluster's workers included), printing
the peak of the largest single process and the peak of their sum, per stage line as the
run prints it. The synthetic input of the workflow is made first (not timed), so the
figures are those of the pipeline.

Run: ``python benchmarks/bench_workflow.py workflows/laptop.yaml [--set key=value ...] [--json PATH]``
(default ``benchmarks/results/workflow.json``: per stage the time of its last line and the peaks so far).
Target of ``workflows/laptop.yaml`` (issue 7): one downsampled tile of a 20 M-point
synthetic site within 4 GiB peak memory.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import threading
import time
from pathlib import Path

import psutil
from _procs import tree_rss
from _results import add_json, write

#: The lines of ``hollowtree run`` that end a stage (the last of each is kept in the JSON).
STAGES = ("ingest", "coarse", "tree", "labels", "outputs")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("workflow", type=Path)
    ap.add_argument("--set", dest="overrides", action="append", default=[])
    ap.add_argument("--keep-store", action="store_true", help="do not delete the store first (measure a resume)")
    add_json(ap, "workflow")
    args = ap.parse_args()
    repo = Path(__file__).resolve().parents[1]
    sys.path.insert(0, str(repo))
    from hollowtree.pipeline.run import make_synthetic_input
    from hollowtree.pipeline.workflow import load_workflow

    wf = load_workflow(args.workflow, args.overrides)
    t0 = time.perf_counter()
    made = make_synthetic_input(wf, progress=False)
    if made:
        print(f"input made in {time.perf_counter() - t0:.1f} s (not counted): {made}")
    if not args.keep_store and "://" not in wf.store and Path(wf.store).exists():
        shutil.rmtree(wf.store)
    for out in (wf.outputs.las, wf.outputs.png):
        if out and Path(out).exists():
            os.remove(out)
    cmd = [sys.executable, "-m", "hollowtree", "run", str(args.workflow), "--no-progress"]
    for o in args.overrides:
        cmd += ["--set", o]
    t0 = time.perf_counter()
    child = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                             env=dict(os.environ, PYTHONPATH=str(repo)))
    ps = psutil.Process(child.pid)
    peak = {"max": 0, "sum": 0}
    stage_peaks: list[tuple[str, float, int, int]] = []
    stop = threading.Event()

    def sample() -> None:
        while not stop.is_set():
            m, s = tree_rss(ps)
            peak["max"], peak["sum"] = max(peak["max"], m), max(peak["sum"], s)
            time.sleep(0.2)

    th = threading.Thread(target=sample, daemon=True)
    th.start()
    assert child.stdout is not None
    for line in child.stdout:
        print(line.rstrip())
        stage_peaks.append((line.split(":")[0], time.perf_counter() - t0, peak["max"], peak["sum"]))
    child.wait()
    stop.set()
    th.join()
    wall = time.perf_counter() - t0
    print()
    print(f"machine: {os.cpu_count()} cores, {psutil.virtual_memory().total / 2**30:.0f} GiB")
    print(f"{'after line':<14}{'t s':>8}{'peak process MB':>17}{'peak sum MB':>13}")
    for name, t, m, s in stage_peaks:
        print(f"{name[:13]:<14}{t:>8.1f}{m / 2**20:>17.0f}{s / 2**20:>13.0f}")
    print(f"exit {child.returncode}; wall {wall:.1f} s; peak single process {peak['max'] / 2**20:.0f} MB; "
          f"peak sum over processes {peak['sum'] / 2**20:.0f} MB ({peak['sum'] / 2**30:.2f} GiB)")
    outputs = ", ".join(Path(str(o)).suffix[1:].upper() or "Parquet" for o in
                        (wf.outputs.las, wf.outputs.parquet, wf.outputs.png) if o)
    write(args.json, "bench_workflow", args, exit=child.returncode, wall_s=wall, outputs=outputs,
          rows=list({name: {"line": name, "t_s": t, "peak_process_mb": m / 2**20, "peak_sum_mb": s / 2**20}
                     for name, t, m, s in stage_peaks if name in STAGES}.values()),
          peak_process_mb=peak["max"] / 2**20, peak_sum_gib=peak["sum"] / 2**30)


if __name__ == "__main__":
    main()
