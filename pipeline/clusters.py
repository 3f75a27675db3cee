"""Clusters a workflow can ask for besides a scheduler address: batch jobs on SLURM, PBS,
SGE or LSF (dask-jobqueue) and pods on Kubernetes (dask-kubernetes' operator).

Both are optional dependencies (``pip install 'hollowtree[jobqueue]'`` or
``'hollowtree[kubernetes]'``); a workflow that names one without it installed gets one
line, exit 2. :func:`open_cluster` starts the cluster and returns a ``distributed.Client``
on it, which the run uses like a notebook's client (``run_workflow(client=...)``).
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from typing import Any

from hollowtree.errors import ConfigError

__all__ = ["JOBQUEUE_SYSTEMS", "job_script", "kubernetes_spec", "open_cluster"]

#: ``cluster.jobqueue.system`` -> the dask-jobqueue class.
JOBQUEUE_SYSTEMS = {"slurm": "SLURMCluster", "pbs": "PBSCluster", "sge": "SGECluster", "lsf": "LSFCluster"}


def _need(module: str, extra: str, key: str) -> Any:
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError:
        raise ConfigError(f"cluster.{key} needs {module.split('.')[0].replace('_', '-')}: "
                          f"pip install 'hollowtree[{extra}]'") from None


def _jobqueue_cluster(jq: Any) -> Any:
    """The dask-jobqueue cluster object of a ``cluster.jobqueue`` section (no job submitted)."""
    mod = _need("dask_jobqueue", "jobqueue", "jobqueue")
    cls = getattr(mod, JOBQUEUE_SYSTEMS[jq.system])
    kwargs: dict[str, Any] = {"cores": jq.cores, "memory": jq.memory, "processes": jq.processes,
                              "walltime": jq.walltime, "job_extra_directives": list(jq.job_extra),
                              "job_script_prologue": list(jq.prologue)}
    if jq.queue is not None:
        kwargs["queue"] = jq.queue
    if jq.account is not None:
        kwargs["account" if jq.system != "lsf" else "project"] = jq.account
    if jq.log_directory is not None:
        kwargs["log_directory"] = jq.log_directory
    return cls(**kwargs)


def job_script(jq: Any) -> str:
    """The batch script one job of a ``cluster.jobqueue`` section submits (what ``hollowtree
    run --job-script`` prints)."""
    cluster = _jobqueue_cluster(jq)
    try:
        return str(cluster.job_script())
    finally:
        cluster.close()


def kubernetes_spec(k8s: Any, name: str = "hollowtree") -> dict[str, Any]:
    """The ``DaskCluster`` resource (``kubernetes.dask.org/v1``, the Dask operator's) of a
    ``cluster.kubernetes`` section: ``workers`` worker pods of the image, each one worker
    process with a thread per CPU and the section's CPU and memory as request and limit,
    and a scheduler pod (1 CPU, 2 GiB). The layout is that of dask-kubernetes'
    ``make_cluster_spec``; built here, so it needs no Kubernetes package to check."""
    env = [{"name": key, "value": value} for key, value in k8s.env.items()]
    cpu = f"{k8s.cpu:g}"
    worker = {
        "name": "worker", "image": k8s.image, "env": env,
        "args": ["dask-worker", "--name", "$(DASK_WORKER_NAME)", "--nthreads", str(max(1, int(k8s.cpu))),
                 "--memory-limit", k8s.memory, "--dashboard", "--dashboard-address", "8788"],
        "resources": {"requests": {"cpu": cpu, "memory": k8s.memory}, "limits": {"cpu": cpu, "memory": k8s.memory}},
        "ports": [{"name": "http-dashboard", "containerPort": 8788, "protocol": "TCP"}],
    }
    health = {"httpGet": {"port": "http-dashboard", "path": "/health"}}
    scheduler = {
        "name": "scheduler", "image": k8s.image, "env": env, "args": ["dask-scheduler", "--host", "0.0.0.0"],
        "resources": {"requests": {"cpu": "1", "memory": "2Gi"}, "limits": {"cpu": "1", "memory": "2Gi"}},
        "ports": [{"name": "tcp-comm", "containerPort": 8786, "protocol": "TCP"},
                  {"name": "http-dashboard", "containerPort": 8787, "protocol": "TCP"}],
        "readinessProbe": {**health, "initialDelaySeconds": 0, "periodSeconds": 1, "timeoutSeconds": 300},
        "livenessProbe": {**health, "initialDelaySeconds": 15, "periodSeconds": 20},
    }
    service = {
        "type": "ClusterIP",
        "selector": {"dask.org/cluster-name": name, "dask.org/component": "scheduler"},
        "ports": [{"name": "tcp-comm", "protocol": "TCP", "port": 8786, "targetPort": "tcp-comm"},
                  {"name": "http-dashboard", "protocol": "TCP", "port": 8787, "targetPort": "http-dashboard"}],
    }
    return {"apiVersion": "kubernetes.dask.org/v1", "kind": "DaskCluster", "metadata": {"name": name},
            "spec": {"idleTimeout": 0, "worker": {"replicas": k8s.workers, "spec": {"containers": [worker]}},
                     "scheduler": {"spec": {"containers": [scheduler]}, "service": service}}}


@contextlib.contextmanager
def open_cluster(section: Any) -> Iterator[Any]:
    """A ``distributed.Client`` on the cluster a workflow's ``cluster:`` section names
    (``jobqueue`` or ``kubernetes``); the cluster is closed (its jobs or pods ended) after."""
    from distributed import Client

    if section.jobqueue is not None:
        cluster = _jobqueue_cluster(section.jobqueue)
        cluster.scale(jobs=section.jobqueue.jobs)
    else:
        op = _need("dask_kubernetes.operator", "kubernetes", "kubernetes")
        cluster = op.KubeCluster(custom_cluster_spec=kubernetes_spec(section.kubernetes),
                                 namespace=section.kubernetes.namespace)
    try:
        with Client(cluster) as client:
            yield client
    finally:
        cluster.close()
