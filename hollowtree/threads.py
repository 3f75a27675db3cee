"""How many threads one task's multithreaded kernels may use."""

from __future__ import annotations

import os

__all__ = ["ROWS_PER_THREAD", "task_threads"]

#: Rows a k-d tree query gives each thread at least (``task_threads(rows=...)``): a thread
#: costs about a millisecond to start, a query row a few microseconds, so a query of a few
#: hundred rows (a window of a small scan) runs faster on the calling thread alone.
ROWS_PER_THREAD = 4096


def task_threads(cap: int | None = None, *, rows: int | None = None) -> int:
    """Threads for one task's multithreaded kernels (k-d tree queries, torch).

    ``OMP_NUM_THREADS`` where it is set: a Dask nanny sets it to 1 in every worker process
    it starts (``distributed.nanny.pre-spawn-environ``), so a machine's workers, one
    thread each, run one thread per core instead of each spawning a thread per core
    (16 workers on 16 cores: 16 threads, not 256). Elsewhere (``hollowtree run`` in its
    own process, a notebook) the CPUs this process may use, at most ``cap``. ``rows``: the
    rows of the query the threads share; no more threads than ``rows //``
    :data:`ROWS_PER_THREAD` (at least one).

    >>> 1 <= task_threads(cap=2) <= 2
    True
    >>> task_threads(rows=500)
    1
    """
    env = os.environ.get("OMP_NUM_THREADS", "").strip()
    if env.isdigit() and int(env) > 0:
        n = int(env)
    else:
        try:
            n = len(os.sched_getaffinity(0))
        except AttributeError:  # not on Linux
            n = os.cpu_count() or 1
        n = n if cap is None else min(cap, n)
    if rows is not None:
        n = min(n, rows // ROWS_PER_THREAD)
    return max(1, n)
