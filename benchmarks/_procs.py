"""Memory of a process and everything below it (the local Dask cluster's workers), for the
end-to-end benchmarks (bench_workflow.py, bench_scale.py)."""

from __future__ import annotations

import psutil


def tree_rss(proc: psutil.Process) -> tuple[int, int]:
    """Resident memory of ``proc`` and its descendants: (largest single process, sum), bytes."""
    try:
        procs = [proc, *proc.children(recursive=True)]
    except psutil.NoSuchProcess:
        return 0, 0
    rss = []
    for p in procs:
        try:
            rss.append(p.memory_info().rss)
        except psutil.NoSuchProcess:
            pass
    return (max(rss) if rss else 0), sum(rss)
