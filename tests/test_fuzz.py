"""Never crash on a scan (issue 43): random and degenerate scans through every stage of the
default workflow. ``benchmarks/bench_fuzz.py`` runs 500+ of them; this file runs the
degenerate cases by name and a seeded sample of random ones."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, example, given, seed, settings

from hollowtree.pipeline.fuzz import run_fuzz, write_points
from hollowtree.scenes.fuzz import DEGENERATE_KINDS, FuzzSpec, fuzz_specs

pytestmark = pytest.mark.slow


def _assert_runs(spec: FuzzSpec, tmp_path) -> None:
    out = run_fuzz(spec, tmp_path / "scan")
    assert out.status == "ok", f"{spec.describe()}\n{out.error}"
    assert sum(out.class_counts.values()) == out.n_points


@pytest.mark.parametrize("kind", DEGENERATE_KINDS)
def test_degenerate_scan_runs_to_the_end(kind, tmp_path):
    _assert_runs(FuzzSpec(kind=kind, seed=7, n_points=3000, extent=60.0, tiles_across=3), tmp_path)


@pytest.mark.parametrize("spec", [
    # tiles with no rows at all between the walls: the stitch once crashed on them
    FuzzSpec(kind="vplanes", seed=18883096, n_points=385, extent=200.0, survey=True, tiles_across=4),
    # exact duplicates without the density cap: no spacing to measure
    FuzzSpec(kind="identical", seed=1, n_points=2000, density_cap=False),
    FuzzSpec(kind="plane", seed=2, n_points=4000, duplicate=12, density_cap=False, tiles_across=2),
    # one point per tile
    FuzzSpec(kind="sparse", seed=3, n_points=16, extent=30.0, tiles_across=6),
    # a scene with no ground, and an empty scene (one small wall)
    FuzzSpec(kind="scene", seed=4, n_points=20_000, parts=("minaret", "column", "dome")),
    FuzzSpec(kind="scene", seed=5, n_points=10_000, parts=()),
], ids=lambda s: s.describe().split(" n=")[0].replace(" ", "-"))
def test_named_corner_cases(spec, tmp_path):
    _assert_runs(spec, tmp_path)


def test_a_scan_that_cannot_be_labelled_says_so_in_one_line(tmp_path):
    out = run_fuzz(FuzzSpec(kind="single", seed=0, n_points=3), tmp_path / "scan")
    assert out.status == "ok"
    assert out.class_counts == {"unclassified": 3}
    said = [line for line in out.lines if "nothing could be labelled" in line]
    assert said == ["labels: nothing could be labelled in 3 points (no surface or element found: too few, too "
                    "sparse or too noisy points?); every point keeps class 0"]


def test_a_file_with_no_point_is_refused_in_one_line(tmp_path):
    scan = tmp_path / "empty.las"
    write_points(scan, {"xyz": np.zeros((0, 3)), "gt_class": np.zeros(0, np.uint8),
                        "gt_instance": np.zeros(0, np.uint32)})
    wf = tmp_path / "wf.yaml"
    wf.write_text(f"input: {{files: [{scan}]}}\nstore: {tmp_path / 's.zarr'}\ncluster: {{scheduler: sync}}\n")
    proc = subprocess.run([sys.executable, "-m", "hollowtree", "run", str(wf), "--no-progress"],
                          capture_output=True, text=True)
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [f"hollowtree run: error: {scan}: holds no points"]


@seed(43)
@settings(max_examples=5, database=None, phases=[Phase.explicit, Phase.generate], deadline=None,
          suppress_health_check=list(HealthCheck))
@given(spec=fuzz_specs(max_points=40_000))
@example(spec=FuzzSpec(kind="scene", seed=11, n_points=30_000, extent=40.0, tiles_across=6,
                       parts=("terrain", "wall_run", "arcade", "chattri", "minaret", "clutter")))
def test_random_scans_run_to_the_end(spec, tmp_path_factory):
    _assert_runs(spec, tmp_path_factory.mktemp("fuzz"))
