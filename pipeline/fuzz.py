"""The never-crash harness: one random scan (:mod:`scenes.fuzz`) through every stage of the
default workflow, in process, and the checks every result must pass.

A scan may legitimately be refused only when its file holds no point at all (a
:class:`~hollowtree.errors.PipelineError`, one line). Every other scan, however degenerate, must
run to the end: every input point gets a label (class 0 where nothing could be said), the
LAZ output holds every input point in input order, and the run's tables and picture are
written. Anything else is a bug and is reported with its traceback.

Used by ``tests/test_fuzz.py`` (a seeded sample) and ``benchmarks/bench_fuzz.py`` (500+
scans).
"""

from __future__ import annotations

import shutil
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import laspy
import numpy as np
import yaml

from hollowtree.classes import NUM_CLASSES
from hollowtree.errors import PipelineError
from hollowtree.pipeline.workflow import shipped_workflows
from hollowtree.scenes.fuzz import FuzzSpec, fuzz_points

__all__ = ["DEFAULT_WORKFLOW", "FuzzOutcome", "run_fuzz", "write_points"]

#: The workflow whose stage parameters every fuzz scan runs with (only the input, the
#: store, the outputs and the scheduler are replaced; ``tile_size`` where a spec sets one).
DEFAULT_WORKFLOW = shipped_workflows() / "local.yaml"


@dataclass(kw_only=True)
class FuzzOutcome:
    """What one fuzz scan did: ``status`` is ``ok``, ``refused`` (a one-line refusal of an
    empty file) or ``bug`` (an exception or a failed check, with ``error``)."""

    spec: FuzzSpec
    status: str
    n_points: int = 0
    seconds: float = 0.0
    error: str = ""
    class_counts: dict[str, int] = field(default_factory=dict)
    lines: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return {"spec": self.spec.describe(), "status": self.status, "n_points": self.n_points,
                "seconds": round(self.seconds, 3), "error": self.error, "class_counts": self.class_counts}


def write_points(path: Path, pts: dict[str, np.ndarray]) -> None:
    """A LAS 1.4 file (point format 6, 1 mm scale) with ``gt_class``/``gt_instance``."""
    header = laspy.LasHeader(point_format=6, version="1.4")
    header.add_extra_dims([laspy.ExtraBytesParams("gt_class", np.uint8),
                           laspy.ExtraBytesParams("gt_instance", np.uint32)])
    xyz = pts["xyz"]
    header.scales = np.array([0.001, 0.001, 0.001])
    header.offsets = np.floor(xyz.min(axis=0)) if len(xyz) else np.zeros(3)
    las = laspy.LasData(header)
    las.x, las.y, las.z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    las.gt_class = pts["gt_class"]
    las.gt_instance = pts["gt_instance"]
    las.write(path)


#: Smallest tile a spec's ``tiles_across`` may give, metres (the default buffer is 2 m).
MIN_TILE = 2.5


def _workflow(spec: FuzzSpec, scan: Path, work: Path, base: Path, span: float) -> dict[str, Any]:
    data = yaml.safe_load(base.read_text())
    data["input"] = {"files": [str(scan)]}
    data["store"] = str(work / "store.zarr")
    data["cluster"] = {"scheduler": "sync"}
    data["outputs"] = {"las": str(work / "labelled.laz"), "parquet": str(work / "tables"),
                       "png": str(work / "view.png")}
    if spec.tiles_across is not None:
        data.setdefault("ingest", {})["tile_size"] = max(MIN_TILE, span / spec.tiles_across)
    if not spec.density_cap:
        data.setdefault("ingest", {})["voxel"] = None
    return data


def _check(work: Path, n_in: int, xyz_in: np.ndarray) -> None:
    """Raise AssertionError unless the outputs hold every input point with a valid label."""
    from hollowtree.tiling.store import RunStore

    store = RunStore.open(str(work / "store.zarr"))
    cls = store.read_slice("labels/class")
    assert len(cls) == n_in, f"labels/class has {len(cls)} rows for {n_in} input points"
    assert int(cls.max(initial=0)) < NUM_CLASSES, f"label class {int(cls.max())} out of range"
    out = laspy.read(work / "labelled.laz")
    assert len(out.points) == n_in, f"labelled.laz has {len(out.points)} points for {n_in}"
    back = np.stack([np.asarray(out.x), np.asarray(out.y), np.asarray(out.z)], axis=1)
    assert np.abs(back - xyz_in).max(initial=0.0) < 2e-3, "labelled.laz moved or reordered points"
    for name in ("tables", "view.png"):
        assert (work / name).exists(), f"output {name} was not written"


def run_fuzz(spec: FuzzSpec, work: Path, *, base: Path = DEFAULT_WORKFLOW, keep: bool = False) -> FuzzOutcome:
    """Make ``spec``'s scan in ``work``, run every stage of ``base`` on it, check the outputs.

    ``work`` is emptied first; unless ``keep``, it is emptied again after a scan that
    passed (a failed one stays for a look).
    """
    from hollowtree.pipeline.run import run_workflow
    from hollowtree.pipeline.workflow import Workflow

    t0 = time.perf_counter()
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir(parents=True)
    pts = fuzz_points(spec)
    scan = work / "scan.las"
    write_points(scan, pts)
    n = len(pts["xyz"])
    outcome = FuzzOutcome(spec=spec, status="ok", n_points=n)
    try:
        span = float(np.ptp(pts["xyz"][:, :2], axis=0).max()) if n else 0.0
        wf = Workflow.model_validate(_workflow(spec, scan, work, base, span))
        rep = run_workflow(wf, progress=False, say=lambda _line: None)
        outcome.lines = rep.lines
        outcome.class_counts = rep.class_counts
        if n:
            src = laspy.read(scan)
            _check(work, n, np.stack([np.asarray(src.x), np.asarray(src.y), np.asarray(src.z)], axis=1))
    except PipelineError as exc:
        msg = str(exc)
        if n == 0 and "\n" not in msg:
            outcome.status, outcome.error = "refused", msg
        else:
            outcome.status, outcome.error = "bug", f"{type(exc).__name__}: {msg}\n{traceback.format_exc()}"
    except Exception as exc:  # noqa: BLE001  (the harness's job is to catch every one)
        outcome.status, outcome.error = "bug", f"{type(exc).__name__}: {exc}\n{traceback.format_exc()}"
    outcome.seconds = time.perf_counter() - t0
    if outcome.status != "bug" and not keep:
        shutil.rmtree(work, ignore_errors=True)
    return outcome
