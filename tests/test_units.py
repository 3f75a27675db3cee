"""Units balanced by points (issue 44): on a deliberately uneven scan, the coarse stage's
blocks, the tree's batches and the labels stage's tile slices hold no unit above
``UNIT_BALANCE`` times its wave's median (the tree's batches of an uneven spread of
element groups: ``plan_batches`` below)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hollowtree.pipeline.coarse import CoarseParams, balanced_block_points, run_coarse
from hollowtree.pipeline.graph import task_runner
from hollowtree.pipeline.labels import run_labels
from hollowtree.pipeline.timing import UNIT_BALANCE, WAVES, balance, waves
from hollowtree.pipeline.tree_stage import TreeStageParams, plan_batches, run_tree
from hollowtree.scenes.synth import synth
from hollowtree.tiling.ingest import IngestParams, ingest
from hollowtree.tiling.store import RunStore


@pytest.fixture(scope="module")
def uneven(tmp_path_factory) -> Path:
    """A minaret on 10 m tiles: its tiles hold 61 to 12 240 points (10.4x the median). The
    labels' slices may hold as few as 500 rows here (``MIN_SLICE_ROWS`` is for real scans)."""
    import hollowtree.pipeline.labels as labels

    d = tmp_path_factory.mktemp("units")
    synth("minaret", d / "m.laz", n_points=60_000, seed=2)
    store = d / "s"
    with task_runner("sync", progress=False) as run:
        ingest([str(d / "m.laz")], str(store), IngestParams(tile_size=10.0, buffer=2.0), runner=run)
        run_coarse(str(store), CoarseParams(eps=0.3, block_points=20_000), runner=run)
        run_tree(str(store), TreeStageParams(batch_points=2_000), runner=run)
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(labels, "MIN_SLICE_ROWS", 500)
            run_labels(str(store), use_tree=True, runner=run)
    return store


def _ratios(store: Path) -> dict[str, float | None]:
    s = RunStore.open(store)
    return {f"{w.stage}.{w.name}": balance(w.points) for w in waves({n: s.records(n) for _, _, n in WAVES})}


def test_coarse_blocks_tree_batches_and_label_slices_are_balanced_by_points(uneven):
    ratios = _ratios(uneven)
    assert ratios["ingest.tiles"] > 3 * UNIT_BALANCE  # the scan is uneven
    assert ratios["coarse.tiles"] <= UNIT_BALANCE
    assert ratios["tree.batches"] <= UNIT_BALANCE
    assert ratios["labels.tiles"] <= UNIT_BALANCE


def test_alike_tiles_keep_block_points_and_one_large_group_stays_alone():
    assert balanced_block_points([900_000, 1_000_000, 1_100_000], 2_200_000) == 2_200_000
    # one group of 90 points above max_group_points (50) beside many of 5: alone, the others batched
    offsets = np.r_[0, np.cumsum([5] * 40 + [90] + [5] * 40)]
    plan = plan_batches(offsets, 5, alone=50, balance=UNIT_BALANCE)
    sizes = [int(offsets[b] - offsets[a]) for a, b in plan]
    assert 90 in sizes
    assert (40, 41) in plan
    assert max(sizes) <= UNIT_BALANCE * np.median(sizes)
    assert plan_batches(offsets, 5) == [(g, g + 1) for g in range(81)]  # without balance: one group a batch


def test_a_sampled_group_is_spread_by_units_and_resumes(uneven, tmp_path, monkeypatch):
    """A group above max_group_points: its batch builds the tree on the sample, spread
    units of whole chunks label its points; a run stopped among them resumes to the same
    labels as one that was not."""
    import shutil

    import hollowtree.pipeline.tree_stage as tree_stage

    monkeypatch.setattr(tree_stage, "CHUNK_POINTS", 1_024)  # several spread units per group
    params = TreeStageParams(batch_points=2_000, max_group_points=1_000)
    stores = {k: tmp_path / k for k in ("whole", "stopped")}
    for p in stores.values():
        shutil.copytree(uneven, p)
        s = RunStore.open(p, mode="a")  # a tree stage never run (another one would be redone whole)
        s.update_attrs({"stages": {k: v for k, v in s.attrs["stages"].items() if k != "tree"}})

    class Stop(Exception):
        pass

    with task_runner("sync", progress=False) as run:
        run_tree(str(stores["whole"]), params, runner=run)

        def dies_in_spread(fn, args, desc):
            if desc == "tree: spread":
                run(fn, args[: len(args) // 2], desc)
                raise Stop
            return run(fn, args, desc)

        with pytest.raises(Stop):
            run_tree(str(stores["stopped"]), params, runner=dies_in_spread)
        seen = []

        def counting(fn, args, desc):
            seen.append((desc, len(args)))
            return run(fn, args, desc)

        run_tree(str(stores["stopped"]), params, runner=counting)
    a, b = RunStore.open(stores["whole"]), RunStore.open(stores["stopped"])
    spread = a.records("tree.spread")
    assert len(spread) > len({u.split(".")[0] for u in spread})  # groups of several units
    assert ("tree: batches", 0) in seen
    assert ("tree: spread", len(spread) - len(spread) // 2) in seen
    for bb in a.records("tree"):
        for k in ("leaf", "class", "instance", "score"):
            assert np.array_equal(a.read_slice(f"tree/batches/{bb}/{k}"), b.read_slice(f"tree/batches/{bb}/{k}"))
    na, nb = a.read_table("tree/nodes.parquet"), b.read_table("tree/nodes.parquet")
    for c in na.column_names:  # NaN == NaN here
        np.testing.assert_array_equal(na.column(c).to_numpy(), nb.column(c).to_numpy())
    assert not a.has("tree/sampled")
    assert not b.has("tree/sampled")
