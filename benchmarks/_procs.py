"""Memory of a process and everything below it (the local Dask cluster's workers), for the
end-to-end benchmarks (bench_workflow.py, bench_scale.py)."""

from __future__ import annotations

import psutil


def tree_rss(proc: psutil.Process) -> tuple[int, int]:
    """Resident memory of ``proc`` and its descendants: (largest single process, sum), bytes.

    A task's child process forked from its worker (``pipeline.graph.in_child``: the same
    command line as its parent) counts with that worker, as the worker's resident memory
    plus the child's own pages (USS): the rest of the child's resident pages are the
    worker's, shared copy-on-write, and would be counted twice (or, the shared library
    pages the child has not touched, not at all in the child's RSS). So "a process" here
    is a worker with the task it runs, whether the task runs in it or in its child.
    """
    try:
        procs = [proc, *proc.children(recursive=True)]
    except psutil.NoSuchProcess:
        return 0, 0
    cmd: dict[int, tuple[int, list[str]]] = {}
    for p in procs:
        try:
            cmd[p.pid] = (p.ppid(), p.cmdline())
        except psutil.Error:
            pass
    mem: dict[int, int] = {}
    for p in procs:
        if p.pid not in cmd:
            continue
        ppid, line = cmd[p.pid]
        forked = ppid in cmd and cmd[ppid][1] == line and p.pid != proc.pid
        try:
            if forked:
                mem[ppid] = mem.get(ppid, 0) + p.memory_full_info().uss
            else:
                mem[p.pid] = mem.get(p.pid, 0) + p.memory_info().rss
        except psutil.Error:
            pass
    return (max(mem.values()) if mem else 0), sum(mem.values())
