"""How many threads one task's multithreaded kernels may use."""

from __future__ import annotations

import os

__all__ = ["task_threads"]


def task_threads(cap: int | None = None) -> int:
    """Threads for one task's multithreaded kernels (k-d tree queries, torch).

    ``OMP_NUM_THREADS`` where it is set: a Dask nanny sets it to 1 in every worker process
    it starts (``distributed.nanny.pre-spawn-environ``), so a machine's workers, one
    thread each, run one thread per core instead of each spawning a thread per core
    (16 workers on 16 cores: 16 threads, not 256). Elsewhere (``hollowtree run`` in its
    own process, a notebook) the CPUs this process may use, at most ``cap``.

    >>> 1 <= task_threads(cap=2) <= 2
    True
    """
    env = os.environ.get("OMP_NUM_THREADS", "").strip()
    if env.isdigit() and int(env) > 0:
        return int(env)
    try:
        n = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        n = os.cpu_count() or 1
    return max(1, n if cap is None else min(cap, n))
