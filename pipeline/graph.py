"""Running units of work as Dask tasks: the only module (with tasks) that imports Dask.

:func:`task_runner` yields a ``runner(fn, args_list, desc) -> results`` for the stage
drivers (e.g. :func:`tiling.ingest.ingest`). Schedulers:

- ``None``: a local Dask cluster of worker processes (``workers`` of them, one thread
  each), started for the command and closed after it; its dashboard address is printed
  once and serves the dashboard for the whole command;
- ``"sync"``: every task in this process, one after another (tests, debugging);
- an address (``tcp://host:8786``): an existing Dask scheduler; the store must be a path
  or URL that every worker reaches.

Only small arguments travel in the graph (store URL, unit descriptions, attributes);
each task reads and writes its own data in the store. A stage whose tasks should hand all
their memory back when they end wraps them in :class:`in_child` (the coarse stage): each
then runs in a child process forked from its worker.
"""

from __future__ import annotations

import contextlib
import functools
import heapq
import logging
import os
import pickle
import signal
import sys
import time
import traceback
import uuid
import warnings
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any

from tqdm import tqdm

from hollowtree.errors import PipelineError

__all__ = ["Task", "fresh_workers", "in_child", "run_graph", "task_runner", "task_seconds", "timed_stage",
           "tune_process_for_streaming"]

logger = logging.getLogger(__name__)

Runner = Callable[[Callable[..., Any], Sequence[tuple[Any, ...]], str], list[Any]]


@dataclass(frozen=True)
class Task:
    """One task of :func:`run_graph`: ``fn(*args)``; ``priority``: higher runs first among
    the tasks ready at once; ``tag``: what ``then`` gets back with its result; ``desc``:
    the progress bar of a runner that runs the graph wave by wave (a plain callable)."""

    fn: Callable[..., Any]
    args: tuple[Any, ...]
    priority: int = 0
    tag: Any = None
    desc: str = ""


Then = Callable[[Any, Any], Sequence[Task]]


class _Ready:
    """The tasks of a graph made and not started, the highest priority first (then the
    first made), with the progress bar that counts every task made."""

    def __init__(self, tasks: Sequence[Task], bar: tqdm) -> None:
        self.heap = [(-t.priority, i, t) for i, t in enumerate(tasks)]
        heapq.heapify(self.heap)
        self.made, self.bar = len(self.heap), bar

    def __bool__(self) -> bool:
        return bool(self.heap)

    def pop(self) -> Task:
        return heapq.heappop(self.heap)[2]

    def ended(self, follow: Sequence[Task]) -> None:
        """A task ended and made ``follow``."""
        for f in follow:
            heapq.heappush(self.heap, (-f.priority, self.made, f))
            self.made += 1
        if follow:
            self.bar.total += len(follow)
            self.bar.refresh()
        self.bar.update(1)


def run_graph(runner: Runner, tasks: Sequence[Task], then: Then, desc: str) -> None:
    """Run ``tasks``, and as each ends, the tasks ``then(tag, result)`` returns (tasks that
    depend on it: the coarse stage's block tasks on their tile's plan, a tile's join on
    its blocks), until none is left. A task starts as soon as it is made and a worker is
    free, beside the others still running, instead of after a whole wave: a wave of a few
    long units no longer keeps the other workers waiting.

    The runners of :func:`task_runner` run the graph as it grows (``then`` in this process,
    between two tasks' ends); any other runner (a plain callable) runs it wave by wave,
    the tasks of a wave grouped by function and ``Task.desc``.
    """
    graph = getattr(runner, "graph", None)
    if graph is not None:
        graph(tasks, then, desc)
        return
    while tasks:
        groups: dict[tuple[int, str], list[Task]] = {}
        for t in sorted(tasks, key=lambda t: -t.priority):
            groups.setdefault((id(t.fn), t.desc or desc), []).append(t)
        follow: list[Task] = []
        for (_, d), group in groups.items():
            for t, result in zip(group, runner(group[0].fn, [t.args for t in group], d), strict=True):
                follow.extend(then(t.tag, result))
        tasks = follow


@functools.lru_cache(maxsize=1)
def _glibc() -> Any:
    """glibc, with the allocator calls used here, or None where it is not the C library."""
    import ctypes

    try:
        libc = ctypes.CDLL("libc.so.6")
        libc.mallopt, libc.malloc_trim  # noqa: B018  (both must exist)
    except (OSError, AttributeError):
        return None
    return libc


def tune_process_for_streaming() -> None:
    """Tune this process for tasks that stream large arrays (the ingest's), run in it.

    - glibc's allocator keeps freed memory for reuse (one arena, no trimming, no separate
      mappings for large blocks) instead of returning it to the kernel after every array:
      a 10 M-point ingest otherwise spends about 13 % of its CPU time in the kernel
      zeroing fresh pages (perf); the peak resident memory stays that of the largest
      working set;
    - the objects that exist now (the imported modules) are moved out of the cyclic
      garbage collector's view (``gc.freeze``): its full passes, triggered by the many
      small objects of Zarr's asynchronous writes, otherwise revisit them each time.

    Call it before any worker thread starts: glibc gives each thread an arena when it
    first allocates, and large blocks of a thread's own arena are always separate
    mappings. Only the allocator part is a no-op where glibc is not the C library.
    """
    import ctypes
    import gc

    gc.freeze()
    libc = _glibc()
    if libc is None:
        return
    mallopt = libc.mallopt
    m_trim_threshold, m_mmap_threshold, m_arena_max = -1, -3, -8
    mallopt.argtypes = [ctypes.c_int, ctypes.c_int]  # the value is a C int: 1 GiB fits
    mallopt(m_arena_max, 1)
    mallopt(m_mmap_threshold, 1 << 30)
    mallopt(m_trim_threshold, 1 << 30)


#: Dask settings of the local cluster's worker processes. Dask's nanny starts each worker
#: with ``MALLOC_TRIM_THRESHOLD_=65536``: glibc then hands memory back to the kernel after
#: nearly every large array and the next array's pages fault in zeroed again, which makes
#: coarse block tasks much slower at about the same peak (measured in
#: docs/decisions/speed-and-memory.md, "Workers without Dask's trim threshold"). ``None``
#: unsets it; a value in the environment still wins.
_LOCAL_WORKER_CONFIG: dict[str, Any] = {"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None}


def _trim_heap() -> None:
    """Hand the C heap's free memory back to the kernel (glibc's ``malloc_trim``; a no-op
    elsewhere)."""
    libc = _glibc()
    if libc is not None:
        libc.malloc_trim(0)


def _run_and_trim(fn: Callable[..., Any], *args: Any) -> Any:
    """Run one task, then trim the heap: a worker keeps its freed memory for reuse during a
    task (no page-fault storm, see ``_LOCAL_WORKER_CONFIG``) but not from one task to the
    next, so a long-lived worker's footprint is that of its largest task, not the sum of
    what every stage left in its heap."""
    try:
        return fn(*args)
    finally:
        _trim_heap()


class in_child:  # noqa: N801  (used like a function: ``runner(in_child(fn), ...)``)
    """A task that runs in a child process of its worker, one child per task.

    ``in_child(fn, prepare)(*args)`` is ``fn(*args)``, run in a process forked from the
    worker for this one call; the child sends the result (or the exception) back and
    exits, so the kernel gets all of its memory back. Without it a worker's heap keeps
    what earlier tasks left behind (the C allocator's fragments, scattered small objects):
    a coarse block task of 2.2 M points peaked at 789, 864 and 875 MB as the first,
    second and third task of one process, for the same +570 MB working set
    (docs/decisions/speed-and-memory.md, "A child process per task"). ``prepare()`` runs in the
    worker before each fork (cheap after its first call): what it loads there, such as
    compiled kernels, the children share copy-on-write instead of loading it each.

    Runs ``fn`` in place (no child) where it cannot fork or should not: outside a Dask
    worker (``scheduler: sync``, tests), in a worker without a nanny (the threads of the
    ingest's in-process cluster), or where ``os.fork`` does not exist (Windows).
    """

    def __init__(self, fn: Callable[..., Any], prepare: Callable[[], Any] | None = None) -> None:
        self.fn, self.prepare = fn, prepare
        self.__name__ = getattr(fn, "__name__", "task")  # what the dashboard shows

    def __call__(self, *args: Any) -> Any:
        if not _forks_here():
            return self.fn(*args)
        if self.prepare is not None:
            self.prepare()
        return _run_in_child(self.fn, args, limit=_memory_limit())


def _memory_limit() -> int | None:
    """Bytes this worker and its task's child may hold together before the child is
    stopped: Dask's ``distributed.worker.memory.terminate`` fraction of the worker's memory
    limit, the line at which Dask's nanny kills a worker (whose monitor sees the worker's
    own memory, not its children's). None where either is off or not in a worker."""
    try:
        import dask
        from distributed import get_worker

        limit = get_worker().memory_manager.memory_limit
        fraction = dask.config.get("distributed.worker.memory.terminate")
    except (ImportError, ValueError, AttributeError, KeyError):
        return None
    if not limit or not fraction:
        return None
    return int(limit * float(fraction))


def _forks_here() -> bool:
    """Whether this thread runs in a Dask worker process of its own (started by a nanny)."""
    if not hasattr(os, "fork"):
        return False
    try:
        from distributed import get_worker

        return get_worker().nanny is not None
    except (ImportError, ValueError):  # not in a worker
        return False


def _die_with_parent() -> None:
    """Linux: the child gets SIGKILL when the worker thread that forked it ends (a
    cancelled run, a killed worker), so no orphan keeps writing to the store."""
    try:
        import ctypes

        pr_set_pdeathsig = 1
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(pr_set_pdeathsig, signal.SIGKILL)
    except (OSError, AttributeError):
        pass


def _run_in_child(fn: Callable[..., Any], args: tuple[Any, ...], *, limit: int | None = None) -> Any:
    """``fn(*args)`` in a forked child; its result, or its exception raised here with the
    child's traceback as a note. With ``limit`` (bytes), the child is killed, and the task
    fails saying so, once its own pages (USS) and the worker's resident memory add up to
    more: the memory a nanny would stop the worker at (:func:`_memory_limit`)."""
    name = getattr(fn, "__name__", "task")
    parent = os.getpid()
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: never returns
        status = 1
        try:
            os.close(r)
            _die_with_parent()
            if os.getppid() != parent:  # the worker ended before prctl took effect
                os._exit(1)
            try:
                payload = pickle.dumps((True, fn(*args), ""), protocol=pickle.HIGHEST_PROTOCOL)
            except BaseException as exc:  # noqa: BLE001  (sent to the worker, raised there)
                tb = traceback.format_exc()
                try:
                    payload = pickle.dumps((False, exc, tb), protocol=pickle.HIGHEST_PROTOCOL)
                except Exception:  # noqa: BLE001  (an exception pickle cannot carry)
                    payload = pickle.dumps((False, RuntimeError(f"{type(exc).__name__}: {exc}"), tb))
            with os.fdopen(w, "wb") as f:
                f.write(payload)
            status = 0
        finally:
            # What the task created through multiprocessing (tqdm's lock, a named
            # semaphore) is released as a multiprocessing child would; the worker's own
            # finalizers do not run here (each belongs to the process that made it).
            try:
                from multiprocessing import util

                util._run_finalizers()
            finally:
                os._exit(status)
    os.close(w)
    payload, used = _read_result(r, pid, limit)
    _, status = os.waitpid(pid, 0)
    if used is not None:
        raise PipelineError(
            f"task {name}: its child process was stopped at {used / 2**20:,.0f} MB (with its worker's), over "
            f"the worker's memory limit ({(limit or 0) / 2**20:,.0f} MB: distributed.worker.memory.terminate of "
            "its memory_limit); give each worker more memory, or make the tasks smaller "
            "(coarse.block_points, tree.batch_points)")
    if os.WIFSIGNALED(status) or os.WEXITSTATUS(status) != 0 or not payload:
        if os.WIFSIGNALED(status):
            sig = os.WTERMSIG(status)
            why = f"was killed by signal {sig} ({signal.Signals(sig).name})"
            if sig == signal.SIGKILL:
                why += "; out of memory?"
        else:
            why = f"exited with status {os.WEXITSTATUS(status)}"
        raise PipelineError(f"task {name}: its child process {why} before sending a result")
    ok, value, tb = pickle.loads(payload)
    if ok:
        return value
    value.add_note(f"in the task's child process (pid {pid}):\n{tb.rstrip()}")
    raise value


#: Seconds between two looks at a task's child's memory (when the worker has a limit).
_MEMORY_POLL_S = 0.25


def _read_result(fd: int, pid: int, limit: int | None) -> tuple[bytes, int | None]:
    """Everything the child writes to ``fd`` until it closes it, and None; or, with
    ``limit``, whatever came before the child (``pid``) and its worker held more than
    ``limit`` bytes together, and that figure (the child is then killed)."""
    if limit is None:
        with os.fdopen(fd, "rb") as f:
            return f.read(), None
    import select

    import psutil

    child, worker = psutil.Process(pid), psutil.Process()
    chunks: list[bytes] = []
    with os.fdopen(fd, "rb", buffering=0) as f:
        while True:
            ready, _, _ = select.select([f], [], [], _MEMORY_POLL_S)
            if ready:
                data = f.read(1 << 20)
                if not data:
                    return b"".join(chunks), None
                chunks.append(data)
                continue
            try:
                # The child's resident memory first (O(1) to read): its own pages (USS)
                # are at most that, so only a sum over the limit needs the USS, whose
                # page-table walk cost about 1 % of a run's CPU when taken every poll.
                base = worker.memory_info().rss
                used = child.memory_info().rss + base
                if used > limit:
                    used = child.memory_full_info().uss + base
            except psutil.Error:  # the child is gone: its pipe ends at once
                continue
            if used > limit:
                with contextlib.suppress(ProcessLookupError):
                    os.kill(pid, signal.SIGKILL)
                return b"".join(chunks), used


@contextlib.contextmanager
def timed_stage(url: str, stage: str, runner: Callable[..., Any]) -> Iterator[None]:
    """Time the stage run inside the block and keep it in the store's ``stages`` attribute:
    ``wall_s`` (the whole stage) and ``driver_s`` (the part spent outside its task waves:
    planning, stitching, reading tables, in this process alone). A stage that ran no task
    (every unit already recorded) keeps the times of the run that made it."""
    from hollowtree.tiling.store import RunStore

    t0, busy0 = time.perf_counter(), task_seconds(runner)
    yield
    wall, busy = time.perf_counter() - t0, task_seconds(runner) - busy0
    if busy <= 0:
        return
    store = RunStore.open(url, mode="a")
    stages = store.attrs.get("stages", {})
    if stage in stages:
        stages[stage] = {**stages[stage], "wall_s": round(wall, 3), "driver_s": round(max(wall - busy, 0.0), 3)}
        store.update_attrs({"stages": stages})


def fresh_workers(runner: Runner) -> None:
    """Replace the worker processes of a runner's local cluster by new ones (a no-op for
    the in-process runner and for a cluster this command did not start).

    What a stage leaves in a worker it does not hand back: the tree stage imports torch
    and loads HollowNet, about 0.5 GB that a labels task would otherwise carry on top of
    its own working set, and the ingest's and coarse stage's heaps are not all handed back
    by ``malloc_trim`` (a coarse task peaked 70-120 MB higher, a tree task 150-250 MB
    higher, in workers that had run the stage before; docs/decisions/speed-and-memory.md, "Fresh workers
    after every stage").
    ``hollowtree run`` calls it after every stage that ran tasks; the dashboard keeps its
    address (:class:`_LocalClient`).
    """
    restart = getattr(runner, "restart_workers", None)
    if restart is not None:
        restart()


class _LocalClient:
    """A local cluster of this command and its client; :meth:`renew` replaces both, so the
    next stage runs in new worker processes. Every cluster after the first serves its
    dashboard on the first one's port, so the address printed at the start stays the
    address of the run's dashboard (a browser reloads the page after a stage).

    A new cluster rather than new workers under the same scheduler: a nanny restart
    (``client.restart()``, ``Client.restart_workers``) left runs waiting for workers that
    never came back (at 4 M points, 3 restarts of 7 waited out a 60 s timeout), and scaling
    the workers to none and back raced the cluster's own bookkeeping (a ``KeyError`` in
    ``SpecCluster._update_worker_status`` when the cluster closed; dask/distributed#5407,
    #5919). Closing a cluster and starting one takes about as long as a restart (median
    0.80 s against 0.81 s, 2 workers). Where the port is taken meanwhile, the new
    cluster's address is printed.
    """

    def __init__(self, workers: int, processes: bool, progress: bool = False) -> None:
        self.workers, self.processes, self.progress = workers, processes, progress
        self.port: int | None = None
        self._start()

    def _start(self) -> None:
        from urllib.parse import urlparse

        from distributed import Client, LocalCluster

        # CRITICAL: a worker's heartbeat racing the scheduler's close logs an ERROR traceback
        # at the end of a successful run (dask/distributed#7891); a task's own error reaches
        # the client as its exception, one line from the CLI.
        with warnings.catch_warnings():  # a taken port: said below, in one line
            warnings.filterwarnings("ignore", message="Port .* is already in use")
            self.cluster = LocalCluster(n_workers=self.workers, threads_per_worker=1, processes=self.processes,
                                        dashboard_address=f":{self.port or 0}", silence_logs=logging.CRITICAL)
        self.client = Client(self.cluster)
        port = urlparse(self.client.dashboard_link).port
        if self.port is None:
            self.port = port
        elif port != self.port and self.progress:
            print(f"dask dashboard (port {self.port} was taken): {self.client.dashboard_link}", file=sys.stderr)

    def renew(self) -> None:
        self.close()
        self._start()

    def close(self) -> None:
        try:
            self.client.close()
        finally:
            self.cluster.close()


def _bar(total: int, desc: str, progress: bool) -> tqdm:
    return tqdm(total=total, desc=desc, unit="task", disable=True if not progress or total == 0 else None,
                leave=False, file=sys.stderr)


def _timed(run: Callable[..., list[Any]], graph: Callable[[Sequence[Task], Then, str], None]) -> Runner:
    """``run`` (and its ``graph``, :func:`run_graph`) that also count the wall seconds
    spent in them (``task_seconds()``): the time a stage's driver waited on its tasks,
    the rest of the stage being its own."""
    spent = [0.0]

    def timed(fn: Callable[..., Any], args_list: Sequence[tuple[Any, ...]], desc: str) -> list[Any]:
        t0 = time.perf_counter()
        try:
            return run(fn, args_list, desc)
        finally:
            spent[0] += time.perf_counter() - t0

    def timed_graph(tasks: Sequence[Task], then: Then, desc: str) -> None:
        t0 = time.perf_counter()
        try:
            graph(tasks, then, desc)
        finally:
            spent[0] += time.perf_counter() - t0

    timed.task_seconds = lambda: spent[0]  # type: ignore[attr-defined]
    timed.graph = timed_graph  # type: ignore[attr-defined]
    return timed


def task_seconds(runner: Runner) -> float:
    """Wall seconds ``runner`` has spent running tasks so far (0 for a plain callable)."""
    get = getattr(runner, "task_seconds", None)
    return float(get()) if get is not None else 0.0


def _sync_runner(progress: bool) -> Runner:
    def run(fn: Callable[..., Any], args_list: Sequence[tuple[Any, ...]], desc: str) -> list[Any]:
        out = []
        with _bar(len(args_list), desc, progress) as bar:
            for args in args_list:
                out.append(fn(*args))
                bar.update(1)
        return out

    def graph(tasks: Sequence[Task], then: Then, desc: str) -> None:
        with _bar(len(tasks), desc, progress) as bar:
            ready = _Ready(tasks, bar)
            while ready:
                t = ready.pop()
                ready.ended(then(t.tag, t.fn(*t.args)))

    runner = _timed(run, graph)
    runner.serial = True  # type: ignore[attr-defined]  # one task at a time: nothing runs beside another
    return runner


def _client_runner(client_of: Callable[[], Any], progress: bool) -> Runner:
    from distributed import as_completed

    def run(fn: Callable[..., Any], args_list: Sequence[tuple[Any, ...]], desc: str) -> list[Any]:
        if not args_list:
            return []
        client = client_of()  # the local cluster's current client (fresh_workers renews it)
        name = getattr(fn, "__name__", "task")  # the dashboard shows the stage's function
        futures = [client.submit(_run_and_trim, fn, *args, key=f"{name}-{uuid.uuid4().hex}")
                   for args in args_list]
        try:
            with _bar(len(futures), desc, progress) as bar:
                for fut in as_completed(futures):
                    if fut.status == "error":
                        fut.result()  # raises the task's own exception
                    bar.update(1)
            return [f.result() for f in futures]
        finally:
            client.cancel([f for f in futures if not f.done()])

    def graph(tasks: Sequence[Task], then: Then, desc: str) -> None:
        # The driver is the list scheduler here: a task is submitted only when a worker
        # thread is free for it, the ready task of the highest priority first. Dask would
        # otherwise place a task made later (a block after its plan) on a busy worker whose
        # task it expects to end soon (it estimates a task's seconds by its function's
        # average), where it waits while another worker idles.
        from distributed import wait

        if not tasks:
            return
        client = client_of()
        live: dict[str, tuple[Any, Any]] = {}  # key -> (future, tag) of the tasks submitted, not ended
        try:
            with _bar(len(tasks), desc, progress) as bar:
                ready = _Ready(tasks, bar)
                while ready or live:
                    free = max(sum(client.nthreads().values()), 1) - len(live)
                    while ready and free > 0:
                        t = ready.pop()
                        name = getattr(t.fn, "__name__", "task")
                        fut = client.submit(_run_and_trim, t.fn, *t.args, key=f"{name}-{uuid.uuid4().hex}",
                                            priority=t.priority)
                        live[fut.key] = (fut, t.tag)
                        free -= 1
                    try:  # a second at most: a worker that joins meanwhile gets a task
                        ended = wait([f for f, _ in live.values()], timeout=1.0, return_when="FIRST_COMPLETED").done
                    except TimeoutError:
                        continue
                    for fut in ended:
                        if fut.status == "error":
                            fut.result()  # raises the task's own exception
                        _, tag = live.pop(fut.key)
                        ready.ended(then(tag, fut.result()))
        finally:
            client.cancel([f for f, _ in live.values() if not f.done()])

    return _timed(run, graph)


@contextlib.contextmanager
def task_runner(
    scheduler: str | None = None, *, workers: int = 2, progress: bool = True, processes: bool = True,
    client: Any = None,
) -> Iterator[Runner]:
    """Context manager yielding a runner on the chosen scheduler (see module notes).

    ``client``: a ``distributed.Client`` the caller made (a notebook's, one of a
    dask-jobqueue or dask-kubernetes cluster): its cluster runs the tasks and stays open
    after the block; ``scheduler`` and ``workers`` are then not used.

    ``processes=False`` makes the local cluster (``scheduler=None``) one of ``workers``
    threads in this process: it starts in milliseconds instead of about 1.5 s, for stages
    whose tasks spend their time in code that releases the GIL (the ingest's).
    """
    if client is not None:
        if progress:
            print(f"dask dashboard: {client.dashboard_link}", file=sys.stderr)
        yield _client_runner(lambda: client, progress)
        return
    if scheduler == "sync":
        yield _sync_runner(progress)
        return
    import dask
    from distributed import Client

    # distributed sets its loggers to INFO when imported; keep them quiet unless the
    # caller's root logger asks for DEBUG (``--verbose`` turns on hollowtree's own only).
    if logging.getLogger().level > logging.DEBUG:
        for name in ("distributed", "distributed.scheduler", "distributed.nanny",
                     "distributed.core", "distributed.http.proxy", "distributed.worker"):
            logging.getLogger(name).setLevel(logging.WARNING)

    if scheduler is None:
        # In-process workers share the GIL with their tasks: no statistical profiler
        # sampling every worker thread every 10 ms there.
        quiet = contextlib.nullcontext() if processes else dask.config.set(
            {"distributed.worker.profile.enabled": False})
        with quiet, dask.config.set(_LOCAL_WORKER_CONFIG):
            local = _LocalClient(workers, processes, progress)
            try:
                if progress:
                    print(f"dask dashboard: {local.client.dashboard_link}", file=sys.stderr)
                run = _client_runner(lambda: local.client, progress)
                run.dashboard_link = lambda: local.client.dashboard_link  # type: ignore[attr-defined]
                if processes:  # our own worker processes: fresh_workers may replace them
                    run.restart_workers = local.renew  # type: ignore[attr-defined]
                run.serial = workers == 1  # type: ignore[attr-defined]  # one thread: nothing runs beside a task
                yield run
            finally:
                local.close()
        return
    with Client(scheduler, timeout="10s") as client:
        if progress:
            print(f"dask dashboard: {client.dashboard_link}", file=sys.stderr)
        yield _client_runner(lambda: client, progress)
