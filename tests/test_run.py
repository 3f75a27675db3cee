"""``hollowtree run`` with real processes: local cluster, a CLI-started Dask cluster, a
SIGKILLed run, a dying worker, a store on S3 (moto server). Every variant must give
labels identical to the plain local run of the same workflow."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import laspy
import numpy as np
import pytest
from moto_s3 import free_port, moto_server

from hollowtree.classes import ClassId
from hollowtree.pipeline.coarse import COARSE_ALGORITHM
from hollowtree.pipeline.export import LAS_CLASSIFICATION
from hollowtree.pipeline.labels import LABEL_DTYPES
from hollowtree.tiling.lock import StoreLock
from hollowtree.tiling.store import RunStore

pytestmark = [pytest.mark.slow, pytest.mark.cluster]
REPO = Path(__file__).resolve().parents[1]
POINTS = 150_000


def _cli(*args: str, env: dict[str, str] | None = None, cwd: Path | None = None, **kw) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "hollowtree", *args], capture_output=True, text=True,
                          env=env, cwd=cwd, **kw)


def _workflow(dir_: Path, scan: Path, store: str, *, extra: str = "") -> Path:
    path = dir_ / f"wf-{abs(hash(store)) % 10**8}.yaml"
    path.write_text(f"""\
input:
  files: [{scan}]
store: {store}
ingest: {{tile_size: 50.0, buffer: 2.0}}
coarse: {{min_support: 300}}
tree: {{batch_points: 40000}}
{extra}""")
    return path


def _labels(url: str) -> dict[str, np.ndarray]:
    store = RunStore.open(url)
    return {k: store.read_slice(f"labels/{k}") for k in LABEL_DTYPES}


def _same(a: dict[str, np.ndarray], b: dict[str, np.ndarray]) -> None:
    """Equal labels; HollowNet's scores to float32 rounding (a worker runs torch on one
    thread, a plain process on several, which sums a convolution in another order)."""
    for k in LABEL_DTYPES:
        if np.issubdtype(a[k].dtype, np.floating):
            np.testing.assert_allclose(a[k], b[k], rtol=1e-5, atol=1e-6, err_msg=k)
        else:
            np.testing.assert_array_equal(a[k], b[k], err_msg=k)


@pytest.fixture(scope="module")
def scan(tmp_path_factory):
    from hollowtree.scenes.synth import synth

    path = tmp_path_factory.mktemp("scan") / "wk.laz"
    synth("wazir_khan", path, n_points=POINTS, seed=3)
    return path


@pytest.fixture(scope="module")
def reference(scan, tmp_path_factory):
    """The plain local run (a LocalCluster of 2 processes), with every output."""
    d = tmp_path_factory.mktemp("ref")
    store = str(d / "ref.zarr")
    wf = _workflow(d, scan, store, extra=f"outputs: {{las: {d / 'out.laz'}, parquet: {d / 'tables'}, png: {d / 'v.png'}}}\n"
                                        "cluster: {in_process_below: 0}\n")
    proc = _cli("run", str(wf), "--no-progress")
    assert proc.returncode == 0, proc.stderr
    return {"store": store, "workflow": wf, "dir": d, "stdout": proc.stdout, "labels": _labels(store)}


def test_local_run_labels_every_point(reference, scan):
    lab = reference["labels"]
    n = laspy.open(scan).header.point_count
    assert all(len(v) == n for v in lab.values())
    # every point of the scan lies in an ingested tile and the run labels its coarse segment
    seg = lab["segment"]
    assert (seg > 0).mean() > 0.5
    assert set(np.unique(lab["class"]).tolist()) <= {int(c) for c in ClassId}
    assert (lab["class"][seg > 0] > 0).all()
    assert "class" in reference["stdout"]
    assert "done in" in reference["stdout"]


def test_small_scan_runs_in_process_with_the_cluster_labels(reference, scan, tmp_path):
    """Under ``cluster.in_process_below`` points a local run starts no cluster (no dashboard
    address) and gives the labels of the run on a LocalCluster; each stage and unit
    record says how long it took."""
    store = str(tmp_path / "s.zarr")
    wf = _workflow(tmp_path, scan, store, extra="cluster: {in_process_below: 100000000}\n")
    proc = _cli("run", str(wf))
    assert proc.returncode == 0, proc.stderr
    assert "dask dashboard" not in proc.stderr  # printed where a cluster starts
    _same(_labels(store), reference["labels"])
    st = RunStore.open(store)
    assert all({"wall_s", "driver_s"} <= set(st.attrs["stages"][s]) for s in ("ingest", "coarse", "tree", "labels"))
    recs = [r for s in ("ingest", "coarse", "tree", "labels") for r in st.records(s).values()]
    assert all(r["wall_s"] > 0 and r["cpu_s"] >= 0 for r in recs)
    assert len({r["worker"] for r in recs}) == 1  # every unit in the one process


def test_rerun_after_completion_does_nothing(reference):
    proc = _cli("run", str(reference["workflow"]), "--no-progress")
    assert proc.returncode == 0, proc.stderr
    assert "nothing to do" in proc.stdout


def test_export_las_keeps_input_order_dims_and_labels(reference, scan):
    out = laspy.read(reference["dir"] / "out.laz")
    src = laspy.read(scan)
    assert len(out) == len(src)
    np.testing.assert_array_equal(out.X * out.header.scales[0] + out.header.offsets[0], src.x)
    for dim in ("intensity", "gps_time", "gt_class", "gt_instance", "red"):
        np.testing.assert_array_equal(np.asarray(out[dim]), np.asarray(src[dim]), err_msg=dim)
    lab = reference["labels"]
    np.testing.assert_array_equal(np.asarray(out["class_id"]), lab["class"])
    np.testing.assert_array_equal(np.asarray(out["segment_id"]), lab["segment"])
    np.testing.assert_array_equal(np.asarray(out["instance_id"]), lab["instance"])
    mapping = np.array([LAS_CLASSIFICATION[ClassId(c)] for c in range(len(ClassId))])
    np.testing.assert_array_equal(np.asarray(out.classification), mapping[lab["class"]])
    assert (reference["dir"] / "tables" / "segments.parquet").is_file()
    assert (reference["dir"] / "v.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_store_of_an_older_coarse_algorithm_is_redone(reference, scan, tmp_path):
    """A store whose workflow records an older coarse code (another eps rule) redoes its
    coarse stage and everything after it, not "nothing to do"."""
    store = tmp_path / "old.zarr"
    shutil.copytree(reference["store"], store)
    s = RunStore.open(str(store), mode="a")
    wf_attrs = s.attrs["workflow"]
    s.update_attrs({"workflow": {**wf_attrs, "coarse": {**wf_attrs["coarse"], "algorithm": "coarse-v1"}}})
    proc = _cli("run", str(_workflow(tmp_path, scan, str(store))), "--no-progress")
    assert proc.returncode == 0, proc.stderr
    assert "redoing coarse, tree, labels" in proc.stdout
    assert f"coarse.algorithm: 'coarse-v1' -> '{COARSE_ALGORITHM}'" in proc.stdout
    assert RunStore.open(str(store)).attrs["workflow"]["coarse"]["algorithm"] == COARSE_ALGORITHM
    _same(_labels(str(store)), reference["labels"])


def test_second_run_on_a_store_in_use_is_refused(reference):
    with StoreLock(reference["store"]):
        proc = _cli("run", str(reference["workflow"]), "--no-progress")
    assert proc.returncode == 2
    assert "in use by another run" in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1


def test_status_reports_every_stage(reference):
    proc = _cli("status", reference["store"])
    assert proc.returncode == 0, proc.stderr
    for stage in ("ingest", "coarse", "tree", "labels"):
        line = next(x for x in proc.stdout.splitlines() if x.strip().startswith(stage))
        done, total = line.split()[1].split("/")
        assert done == total


def _n_records(stage_dir: Path) -> int:
    """Units recorded under ``records/<stage>`` (sub-groups; the stage's own zarr.json is not one)."""
    return sum(1 for u in stage_dir.iterdir() if (u / "zarr.json").is_file())


def _wait_for_records(store: Path, stage: str, n: int, proc: subprocess.Popen, timeout: float = 240) -> None:
    t0 = time.time()
    while time.time() - t0 < timeout:
        d = store / "records" / stage
        if d.is_dir() and _n_records(d) >= n:
            return
        if proc.poll() is not None:
            pytest.fail(f"the run ended before {n} {stage} records: {proc.stderr.read() if proc.stderr else ''}")
        time.sleep(0.05)
    pytest.fail(f"no {n} {stage} records after {timeout} s")


def test_sigkill_mid_run_then_resume(reference, scan, tmp_path):
    store = tmp_path / "k.zarr"
    wf = _workflow(tmp_path, scan, str(store))
    proc = subprocess.Popen([sys.executable, "-m", "hollowtree", "run", str(wf), "--no-progress"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        _wait_for_records(store, "coarse", 2, proc)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)  # the run and its local cluster, no cleanup
        proc.wait()
    n_done = _n_records(store / "records" / "coarse")
    again = _cli("run", str(wf), "--no-progress")
    assert again.returncode == 0, again.stderr
    assert "parameters changed" not in again.stdout  # nobody changed any
    assert "map units 0 run" in again.stdout  # ingest finished before the kill
    coarse_line = next(x for x in again.stdout.splitlines() if x.startswith("coarse:"))
    assert f"{n_done} skipped" in coarse_line
    _same(_labels(str(store)), reference["labels"])


@pytest.fixture
def dask_cluster(tmp_path):
    """`dask scheduler` and two `dask worker` processes on 127.0.0.1."""
    port = free_port()
    env = dict(os.environ, PYTHONPATH=str(REPO))
    procs = [subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
                               "--port", str(port), "--no-dashboard"], env=env, cwd=tmp_path,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)]
    address = f"tcp://127.0.0.1:{port}"
    for i in range(2):
        procs.append(subprocess.Popen(
            [sys.executable, "-m", "distributed.cli.dask_worker", address, "--nthreads", "1", "--no-nanny",
             "--no-dashboard", "--name", f"w{i}"], env=env, cwd=tmp_path,
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True))
    from distributed import Client

    with Client(address, timeout="30s") as c:
        c.wait_for_workers(2, timeout=60)
    yield address, procs
    for p in procs:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
        p.wait()


def test_cli_started_dask_cluster_matches_local_when_a_worker_dies(reference, scan, tmp_path, dask_cluster):
    """The bundled cluster workflow on a CLI-started cluster of two workers, one of them
    killed mid-run: the run finishes on the other with the plain local run's labels."""
    address, procs = dask_cluster
    store = tmp_path / "c.zarr"
    wf = REPO / "workflows" / "cluster.yaml"
    run = subprocess.Popen([sys.executable, "-m", "hollowtree", "run", str(wf), "--no-progress", "--scheduler",
                            address, "--set", f"input.files=[{scan}]", "--set", f"store={store}",
                            "--set", "ingest.tile_size=50.0", "--set", "ingest.voxel=null",
                            "--set", "coarse.min_support=300", "--set", "tree.batch_points=40000",
                            "--set", f"outputs.parquet={tmp_path / 't'}"],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    _wait_for_records(store, "coarse", 1, run)
    os.killpg(procs[2].pid, signal.SIGKILL)  # one worker process, mid-run
    out, err = run.communicate(timeout=600)
    assert run.returncode == 0, err
    _same(_labels(str(store)), reference["labels"])
    assert (tmp_path / "t" / "segments.parquet").is_file()


def test_store_on_s3_moto_server_and_a_changed_parameter(reference, scan, tmp_path, monkeypatch):
    """A run store on S3 (moto server) gives the plain local run's labels; a rerun with the
    tree turned off redoes only the tree and labels (no coarse tile run again)."""
    pytest.importorskip("moto", reason="moto[server] is a dev dependency")
    pytest.importorskip("s3fs", reason="s3fs is a dev dependency")
    with moto_server() as aws:
        env = dict(os.environ, **aws)
        import s3fs

        fs = s3fs.S3FileSystem(key="test", secret="test", endpoint_url=env["AWS_ENDPOINT_URL"])
        fs.mkdir("hollowtree-test")
        wf = _workflow(tmp_path, scan, "s3://hollowtree-test/run.zarr")
        first = _cli("run", str(wf), "--no-progress", env=env)
        assert first.returncode == 0, first.stderr
        for k, v in env.items():
            if k.startswith("AWS_"):
                monkeypatch.setenv(k, v)
        _same(_labels("s3://hollowtree-test/run.zarr"), reference["labels"])
        proc = _cli("run", str(wf), "--no-progress", "--set", "tree.enabled=false", env=env)
        assert proc.returncode == 0, proc.stderr
        assert "redoing tree, labels" in proc.stdout
        assert "tiles 0 run" in proc.stdout.split("coarse:")[1].splitlines()[0]  # coarse skipped
        off = _labels("s3://hollowtree-test/run.zarr")
        assert not off["class"].any()
        np.testing.assert_array_equal(off["primitive"], reference["labels"]["primitive"])


def test_an_unreachable_object_store_is_one_line(scan, tmp_path):
    pytest.importorskip("s3fs", reason="s3fs is a dev dependency")
    env = dict(os.environ, AWS_ACCESS_KEY_ID="test", AWS_SECRET_ACCESS_KEY="test", AWS_DEFAULT_REGION="us-east-1",
               AWS_ENDPOINT_URL=f"http://127.0.0.1:{free_port()}", AWS_MAX_ATTEMPTS="1")
    wf = _workflow(tmp_path, scan, "s3://nowhere/run.zarr")
    r = _cli("run", str(wf), "--no-progress", env=env)
    assert r.returncode == 2
    assert len(r.stderr.strip().splitlines()) == 1
    assert "s3://nowhere/run.zarr cannot be reached" in r.stderr


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


def test_fresh_workers_replaces_only_our_own_worker_processes():
    """After the tree stage the run replaces its local cluster's workers (torch and
    HollowNet stay in a worker otherwise); the in-process runner has none to replace."""
    from hollowtree.pipeline.graph import fresh_workers, task_runner

    with task_runner("sync", progress=False) as run:
        fresh_workers(run)
        assert run(os.getpid, [()], "pid") == [os.getpid()]
    with task_runner(None, workers=1, progress=False) as run:
        assert run.serial  # one worker thread: nothing runs beside a task
        link = run.dashboard_link()
        before = run(os.getpid, [()], "pid")
        fresh_workers(run)
        after = run(os.getpid, [()], "pid")
        fresh_workers(run)  # a second time too (a new local cluster each time)
        again = run(os.getpid, [()], "pid")
        assert not _alive(before[0])
        assert not _alive(after[0])
        # the address printed at the start stays the dashboard's
        assert run.dashboard_link() == link
    assert len({*before, *after, *again}) == 3
    assert os.getpid() not in before + after


def test_a_new_cluster_whose_dashboard_port_is_taken_says_where_it_is(capsys):
    """Where another process took the dashboard's port between two stages, the next
    cluster serves it elsewhere and prints that address."""
    import socket
    from urllib.parse import urlparse

    from hollowtree.pipeline.graph import _LocalClient

    local = _LocalClient(1, True, progress=True)
    try:
        port = urlparse(local.client.dashboard_link).port
        local.close()
        with socket.socket() as s:
            s.bind(("", port))
            s.listen()
            local._start()
            assert urlparse(local.client.dashboard_link).port != port
            assert local.client.submit(os.getpid).result() != os.getpid()
    finally:
        local.close()
    assert f"port {port} was taken" in capsys.readouterr().err


_PREPARED: list[int] = []


def _prepare() -> None:
    _PREPARED.append(os.getpid())


def _prepared() -> list[int]:
    return list(_PREPARED)


def _pids() -> tuple[int, int]:
    return os.getpid(), os.getppid()


def _rss_mb() -> float:
    import psutil

    return psutil.Process().memory_info().rss / 2**20


def _hold_memory(mb: int) -> float:
    """Touch ``mb`` MB and return this process's resident MB while holding it."""
    block = np.ones(mb * 2**20 // 8)
    return _rss_mb() + 0 * float(block[-1])


def _fail(message: str) -> None:
    from hollowtree.errors import ConfigError

    raise ConfigError(message)


def _die() -> None:
    os.kill(os.getpid(), signal.SIGKILL)


def test_in_child_runs_each_task_in_a_child_of_its_worker_and_frees_its_memory():
    """``in_child`` tasks run in a process forked from their worker (``prepare`` first, in
    the worker): the worker gets the child's memory back, the child's result or exception
    comes back, and a child killed by a signal is a PipelineError that says so. Outside a
    worker process (the sync runner) the task runs in place."""
    from hollowtree.errors import ConfigError, PipelineError
    from hollowtree.pipeline.graph import in_child, task_runner

    with task_runner("sync", progress=False) as run:
        assert run(in_child(_pids), [()], "pids") == [_pids()]
    with task_runner(None, workers=1, progress=False) as run:
        [worker] = run(os.getpid, [()], "pid")
        [(pid, ppid)] = run(in_child(_pids, _prepare), [()], "pids")
        assert ppid == worker
        assert pid != worker
        assert not _alive(pid)  # waited for: no zombie, no orphan
        assert run(_prepared, [()], "prepared") == [[worker]]
        [base] = run(_rss_mb, [()], "rss")
        [held] = run(in_child(_hold_memory), [(400,)], "hold")
        assert held > 400  # the child held it (its RSS: what it touched of the worker, and the block)
        [after] = run(_rss_mb, [()], "rss")
        assert after < base + 50, (base, held, after)
        with pytest.raises(ConfigError, match="bad key x"):
            run(in_child(_fail), [("bad key x",)], "fail")
        with pytest.raises(PipelineError, match="task _die: its child process was killed by signal 9"):
            run(in_child(_die), [()], "die")
        assert run(os.getpid, [()], "pid") == [worker]  # the worker itself lives on


def test_in_child_task_over_the_worker_memory_limit_is_stopped():
    """Dask's nanny watches its worker's memory, not the worker's children: a task's child
    that takes the worker over the terminate line of its memory limit is killed, and the
    task fails saying so; the worker lives on, and smaller tasks run as before."""
    import logging

    from distributed import Client, LocalCluster

    from hollowtree.errors import PipelineError
    from hollowtree.pipeline.graph import in_child

    with LocalCluster(n_workers=1, threads_per_worker=1, memory_limit="700MB", dashboard_address=":0",
                      silence_logs=logging.ERROR) as cluster, Client(cluster) as client:
        worker = client.submit(os.getpid, pure=False).result()
        assert client.submit(in_child(_hold_memory), 100, pure=False).result() > 100
        with pytest.raises(PipelineError, match=r"task _hold_memory: its child process was stopped at [\d,]+ MB "
                                                r"\(with its worker's\), over the worker's memory limit \(634 MB"):
            client.submit(in_child(_hold_memory), 3000, pure=False).result()
        assert client.submit(os.getpid, pure=False).result() == worker
        assert client.submit(in_child(_hold_memory), 100, pure=False).result() > 100


def test_progress_bars_only_on_a_terminal(capsys):
    """Output that is no terminal (a log file, a pipe) gets no progress bar, only the
    stage lines; a bar's carriage returns would fill it."""
    from hollowtree.pipeline.graph import task_runner

    with task_runner("sync", progress=True) as run:
        assert run(abs, [(-1,), (-2,)], "a stage") == [1, 2]
    assert "\r" not in capsys.readouterr().err


def test_verbose_turns_on_our_own_loggers_only(tmp_path):
    """``-v``: hollowtree's modules log at DEBUG, other libraries stay at WARNING."""
    import logging

    from hollowtree.pipeline.cli import OWN_LOGGERS, main

    before = {n: logging.getLogger(n).level for n in (*OWN_LOGGERS, "fsspec")}
    try:
        assert main(["-v", "status", str(tmp_path / "none.zarr")]) == 2
        assert logging.getLogger("hollowtree.tiling.store").getEffectiveLevel() == logging.DEBUG
        assert logging.getLogger("fsspec").getEffectiveLevel() > logging.DEBUG
        assert logging.getLogger().level > logging.DEBUG
    finally:
        for n, level in before.items():
            logging.getLogger(n).setLevel(level)


def test_an_unreachable_scheduler_is_one_line_and_leaves_no_folder(scan, tmp_path):
    """The run would make the store's missing folders (out/...), but leaves none of them
    behind when it stops before writing anything."""
    store = tmp_path / "out" / "runs" / "never.zarr"
    wf = _workflow(tmp_path, scan, str(store), extra=f"cluster: {{scheduler: 'tcp://127.0.0.1:{free_port()}'}}\n")
    r = _cli("run", str(wf), "--no-progress")
    assert r.returncode == 2
    assert len(r.stderr.strip().splitlines()) == 1
    assert "cannot reach the Dask scheduler" in r.stderr
    assert not (tmp_path / "out").exists()


def test_step_commands_run_a_small_store_in_their_own_process(tmp_path, monkeypatch, capsys):
    """`hollowtree coarse` / `tree` / `labels` follow `run`'s rule: a store of under
    `cluster.in_process_below` input points runs in process unless --scheduler says otherwise."""
    from hollowtree.pipeline import graph
    from hollowtree.pipeline.cli import main
    from hollowtree.scenes.synth import synth

    scan = tmp_path / "m.laz"
    synth("minaret", scan, n_points=20_000, seed=1)
    assert main(["ingest", str(scan), "--store", str(tmp_path / "s"), "--scheduler", "sync", "--no-progress"]) == 0
    asked: list[str | None] = []
    real = graph.task_runner

    def recording(scheduler=None, **kw):
        asked.append(scheduler)
        return real("sync", **kw)  # no cluster in this test either way

    monkeypatch.setattr(graph, "task_runner", recording)
    assert main(["coarse", str(tmp_path / "s"), "--no-progress"]) == 0
    assert main(["labels", str(tmp_path / "s"), "--no-tree", "--no-progress"]) == 0
    assert main(["coarse", str(tmp_path / "s"), "--no-progress", "--scheduler", "tcp://nowhere:1"]) == 0
    assert asked == ["sync", "sync", "tcp://nowhere:1"]
    capsys.readouterr()
