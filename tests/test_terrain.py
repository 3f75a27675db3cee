"""A sparse (airborne-like) scan takes its ground from the terrain filter (SMRF)."""

from __future__ import annotations

import laspy
import numpy as np

from hollowtree.classes import ClassId
from hollowtree.pipeline.run import run_workflow
from hollowtree.pipeline.workflow import load_workflow
from hollowtree.primitives.terrain import smrf_ground
from hollowtree.tiling.store import RunStore


def _airborne(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """About one point per m^2 over 150 x 150 m of gently sloping ground, with two flat-roofed
    buildings (25 x 40 m, 7 m; 12 x 12 m, 4 m) and a row of trees; True where ground."""
    g = rng.uniform(0, 150, (22_000, 2))
    ground = np.c_[g, 0.04 * g[:, 0] + 0.5 * np.sin(g[:, 1] / 20) + rng.normal(0, 0.03, len(g))]
    parts = [ground]
    for (x0, y0, w, d, h) in ((30, 40, 25, 40, 7.0), (100, 100, 12, 12, 4.0)):
        r = rng.uniform(0, 1, (int(w * d), 2)) * (w, d) + (x0, y0)
        parts.append(np.c_[r, 0.04 * r[:, 0] + 0.5 * np.sin(r[:, 1] / 20) + h + rng.normal(0, 0.03, len(r))])
    t = rng.uniform(0, 1, (1500, 2)) * (100, 6) + (20, 120)
    parts.append(np.c_[t, 0.04 * t[:, 0] + rng.uniform(2, 12, len(t))])
    xyz = np.concatenate(parts)
    keep = np.ones(len(xyz), bool)
    for (x0, y0, w, d, _) in ((30, 40, 25, 40, 0), (100, 100, 12, 12, 0)):  # no ground under roofs
        keep[:len(ground)] &= ~((ground[:, 0] > x0) & (ground[:, 0] < x0 + w) & (ground[:, 1] > y0)
                                & (ground[:, 1] < y0 + d))
    is_ground = np.r_[np.ones(len(ground), bool), np.zeros(len(xyz) - len(ground), bool)]
    return xyz[keep], is_ground[keep]


def test_smrf_separates_ground_from_roofs_and_trees():
    xyz, truth = _airborne(np.random.default_rng(1))
    g = smrf_ground(xyz)
    assert g[truth].mean() > 0.97
    assert g[~truth].mean() < 0.05


def test_a_sparse_scan_gets_its_ground_from_the_terrain_filter(tmp_path):
    xyz, truth = _airborne(np.random.default_rng(2))
    header = laspy.LasHeader(point_format=3, version="1.2")
    header.scales, header.offsets = np.array([0.01, 0.01, 0.01]), np.zeros(3)
    las = laspy.LasData(header)
    las.x, las.y, las.z = xyz.T
    las.write(tmp_path / "als.las")
    wf = tmp_path / "wf.yaml"
    wf.write_text(f"input: {{files: [{tmp_path / 'als.las'}]}}\nstore: {tmp_path / 'runs' / 's.zarr'}\n"
                  "tree: {enabled: false}\ncluster: {scheduler: sync}\n")
    run_workflow(load_workflow(wf), progress=False, say=lambda _: None)
    store = RunStore.open(tmp_path / "runs" / "s.zarr")  # the run made its folder
    assert store.attrs["stages"]["coarse"]["spacing"] > 0.5
    cls = store.read_slice("labels/class")
    assert (cls[truth] == ClassId.GROUND).mean() > 0.97
    assert (cls[~truth] == ClassId.GROUND).mean() < 0.05
