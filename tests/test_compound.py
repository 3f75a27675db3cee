"""A compound element in one element group: a pavilion gives up its columns.

The coarse stage joins a pavilion's dome, slab and columns into one element group
(they touch), which HollowNet calls dome and no proposal splits; the tree cuts out its
posts HollowNet calls pillars (``tree.posts.posts``, ``tree.build.POSTS_FROM``), so
each column is a pillar instance. Without that step the columns are part of the dome.
"""

from __future__ import annotations

import numpy as np
import pytest

from hollowtree.classes import ClassId
from hollowtree.pipeline.run import run_workflow
from hollowtree.pipeline.workflow import load_workflow
from hollowtree.scenes.metrics import count_labels, score_counts
from hollowtree.tiling.readers import PointBlock, read_blocks
from hollowtree.tiling.store import RunStore


@pytest.fixture(scope="module")
def pavilion(tmp_path_factory):
    from hollowtree.scenes.elements import ground
    from hollowtree.scenes.procedural import _pavilion, _Site
    from hollowtree.scenes.scanner import ScanParams
    from hollowtree.scenes.synth import write_scan

    s = _Site("pavilion", np.random.default_rng(11))
    _pavilion(s, 0.0, 0.0, "pavilion", size=2.0, z0=0.0)
    s.b.add(ground(-7.0, 7.0, -7.0, 7.0), ClassId.GROUND, "ground")
    for x, y in ((6.5, 1.0), (-6.5, -1.0), (1.0, 6.5), (-1.0, -6.5)):
        s.b.add_station((x, y, 1.6))
    path = tmp_path_factory.mktemp("pavilion") / "pavilion.laz"
    write_scan(s.b.build(), path, ScanParams(step_deg=0.3, seed=0, max_range=12.0), workers=1)
    return path


def _pillars_found(tmp_path, scan) -> tuple[int, int]:
    tmp_path.mkdir(parents=True, exist_ok=True)
    wf = tmp_path / "wf.yaml"
    wf.write_text(f"input: {{files: [{scan}]}}\nstore: {tmp_path / 's.zarr'}\ncluster: {{scheduler: sync}}\n")
    run_workflow(load_workflow(wf), progress=False, say=lambda _: None)
    store = RunStore.open(tmp_path / "s.zarr")
    b = PointBlock.concat(read_blocks(scan))
    n = len(b)
    counts = count_labels(b.extra["gt_class"], b.extra["gt_instance"], store.read_slice("labels/class", 0, n),
                          store.read_slice("labels/instance", 0, n))
    s = score_counts(counts).score(int(ClassId.PILLAR))
    return s.n_found, s.n_gt


def test_a_pavilion_gives_up_its_columns(tmp_path, pavilion, monkeypatch):
    import hollowtree.tree.build as build

    found, n_gt = _pillars_found(tmp_path / "posts", pavilion)
    assert n_gt >= 4
    monkeypatch.setattr(build, "POSTS_FROM", ())
    found_whole, _ = _pillars_found(tmp_path / "whole", pavilion)
    assert found >= n_gt // 2
    assert found > found_whole
