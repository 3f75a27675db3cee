"""``cluster.jobqueue`` and ``cluster.kubernetes``: validated like every key; the job script
and the Kubernetes resource they make, checked without a batch system or a cluster."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from hollowtree.errors import ConfigError
from hollowtree.pipeline.clusters import job_script, kubernetes_spec
from hollowtree.pipeline.workflow import WorkflowError, load_workflow

BASE = "input: {files: [scan.laz]}\nstore: out/s.zarr\n"
SLURM = """cluster:
  jobqueue:
    system: slurm
    jobs: 4
    cores: 8
    memory: 32GiB
    walltime: "02:00:00"
    queue: normal
    account: survey
    job_extra: ["--gres=gpu:1"]
    prologue: ["module load python/3.11"]
"""


def _wf(tmp_path: Path, text: str) -> Path:
    (tmp_path / "scan.laz").write_bytes(b"")
    path = tmp_path / "wf.yaml"
    path.write_text(BASE.replace("scan.laz", str(tmp_path / "scan.laz")) + text)
    return path


def test_a_slurm_job_script_asks_for_what_the_section_says(tmp_path):
    wf = load_workflow(_wf(tmp_path, SLURM))
    script = job_script(wf.cluster.jobqueue)
    for line in ("#SBATCH -p normal", "#SBATCH -A survey", "#SBATCH --cpus-per-task=8", "#SBATCH -t 02:00:00",
                 "#SBATCH --gres=gpu:1", "module load python/3.11"):
        assert line in script, line
    assert "#SBATCH --mem=" in script
    assert "distributed.cli.dask_worker" in script
    assert sys.executable in script  # the workers run this environment's Python


def test_a_pbs_job_script(tmp_path):
    wf = load_workflow(_wf(tmp_path, "cluster: {jobqueue: {system: pbs, cores: 4, memory: 16GiB, queue: workq}}\n"))
    script = job_script(wf.cluster.jobqueue)
    assert "#PBS -q workq" in script
    assert "ncpus=4" in script


def test_the_cli_prints_the_job_script_and_submits_nothing(tmp_path):
    path = _wf(tmp_path, SLURM)
    r = subprocess.run([sys.executable, "-m", "hollowtree", "run", str(path), "--job-script"],
                       capture_output=True, text=True, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith("#!/usr/bin/env bash")
    assert not (tmp_path / "out").exists()
    plain = _wf(tmp_path, "")
    r = subprocess.run([sys.executable, "-m", "hollowtree", "run", str(plain), "--job-script"],
                       capture_output=True, text=True, cwd=tmp_path)
    assert r.returncode == 2
    assert r.stderr.strip().count("\n") == 0
    assert "cluster.jobqueue" in r.stderr


@pytest.mark.parametrize(("text", "expect"), [
    ("cluster: {scheduler: 'tcp://h:8786', jobqueue: {system: slurm, cores: 2, memory: 4GiB}}\n",
     "at most one of cluster.scheduler, cluster.jobqueue and cluster.kubernetes"),
    ("cluster: {jobqueue: {system: condor, cores: 2, memory: 4GiB}}\n", "cluster.jobqueue.system"),
    ("cluster: {jobqueue: {system: slurm, memory: 4GiB}}\n", "cluster.jobqueue.cores"),
    ("cluster: {jobqueue: {system: slurm, cores: 0, memory: 4GiB}}\n", "cluster.jobqueue.cores"),
    ("cluster: {kubernetes: {workers: 3}}\n", "cluster.kubernetes.image"),
    ("cluster: {kubernetes: {image: x, cpu: -1}}\n", "cluster.kubernetes.cpu"),
])
def test_bad_cluster_sections_are_one_line(tmp_path, text, expect):
    with pytest.raises(WorkflowError, match=expect.replace(".", r"\.")) as info:
        load_workflow(_wf(tmp_path, text))
    assert "\n" not in str(info.value)


def test_the_kubernetes_resource(tmp_path):
    wf = load_workflow(_wf(tmp_path, "cluster: {kubernetes: {image: 'registry.example/hollowtree:0.1', workers: 6, "
                                     "cpu: 4, memory: 16Gi, env: {AWS_REGION: eu-west-1}}}\n"))
    spec = kubernetes_spec(wf.cluster.kubernetes)
    assert spec["kind"] == "DaskCluster"
    worker = spec["spec"]["worker"]
    assert worker["replicas"] == 6
    container = worker["spec"]["containers"][0]
    assert container["image"] == "registry.example/hollowtree:0.1"
    assert container["resources"]["limits"] == {"cpu": "4", "memory": "16Gi"}
    assert container["args"][container["args"].index("--nthreads") + 1] == "4"
    assert {"name": "AWS_REGION", "value": "eu-west-1"} in container["env"]
    assert spec["spec"]["scheduler"]["service"]["selector"]["dask.org/cluster-name"] == spec["metadata"]["name"]


def test_the_kubernetes_resource_has_the_operators_layout(tmp_path):
    """Where dask-kubernetes is installed: the same keys as its own ``make_cluster_spec``."""
    op = pytest.importorskip("dask_kubernetes.operator", reason="dask-kubernetes is optional (hollowtree[kubernetes])")
    wf = load_workflow(_wf(tmp_path, "cluster: {kubernetes: {image: img}}\n"))
    ours, theirs = kubernetes_spec(wf.cluster.kubernetes), op.make_cluster_spec(name="hollowtree", image="img")

    def keys(d, prefix=""):
        out = set()
        for k, v in d.items():
            out.add(prefix + k)
            if isinstance(v, dict):
                out |= keys(v, prefix + k + ".")
        return out

    assert keys(ours) == keys(theirs)


def test_a_missing_package_is_one_line(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "dask_jobqueue", None)  # as if it were not installed
    wf = load_workflow(_wf(tmp_path, SLURM))
    with pytest.raises(ConfigError, match=r"cluster\.jobqueue needs dask-jobqueue: pip install 'hollowtree\[jobqueue\]'"):
        job_script(wf.cluster.jobqueue)


def test_a_workflow_with_a_jobqueue_section_runs_on_that_cluster(tmp_path, monkeypatch):
    """``run_workflow`` opens the section's cluster, runs every stage on its client and
    closes it (here a cluster of threads stands in for the batch jobs)."""
    import contextlib

    from distributed import Client, LocalCluster

    import hollowtree.pipeline.clusters as clusters
    from hollowtree.pipeline.run import run_workflow
    from hollowtree.scenes.synth import synth

    opened: list[object] = []

    @contextlib.contextmanager
    def fake_open(section):
        opened.append(section.jobqueue.system)
        with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=":0") as c, \
                Client(c) as client:
            yield client
            opened.append(sorted(client.run_on_scheduler(lambda dask_scheduler: list(dask_scheduler.task_prefixes))))

    monkeypatch.setattr(clusters, "open_cluster", fake_open)
    scan = tmp_path / "scan.laz"
    synth("wazir_khan", scan, n_points=20_000, seed=3)
    path = tmp_path / "wf.yaml"
    path.write_text(f"input: {{files: [{scan}]}}\nstore: {tmp_path / 's.zarr'}\ntree: {{enabled: false}}\n"
                    "cluster: {jobqueue: {system: slurm, cores: 1, memory: 2GiB}}\n")
    run_workflow(load_workflow(path), progress=False, say=lambda _: None)
    assert opened[0] == "slurm"
    assert {"map_chunk", "labels_range"} <= set(opened[1])
    assert (tmp_path / "s.zarr").is_dir()
