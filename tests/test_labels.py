"""The labels stage in one process: input order, voxel-dropped points, bbox runs, export."""

from __future__ import annotations

import laspy
import numpy as np
import pytest

from pipeline.labels import LABEL_DTYPES, LEAF_BITS
from pipeline.run import run_workflow
from pipeline.workflow import load_workflow
from tiling.grid import TileGrid
from tiling.store import RunStore


@pytest.fixture(scope="module")
def scan(tmp_path_factory):
    from scenes.synth import synth

    path = tmp_path_factory.mktemp("lab") / "wk.laz"
    synth("wazir_khan", path, n_points=80_000, seed=5)
    return path


def _run(tmp_path, scan, extra=""):
    wf_path = tmp_path / "wf.yaml"
    wf_path.write_text(f"""\
input: {{files: [{scan}]}}
store: {tmp_path / 's.zarr'}
ingest: {{tile_size: 50.0}}
coarse: {{min_support: 300}}
tree: {{enabled: false}}
cluster: {{scheduler: sync}}
{extra}""")
    run_workflow(load_workflow(wf_path), progress=False, say=lambda _: None)
    store = RunStore.open(tmp_path / "s.zarr")
    return store, {k: store.read_slice(f"labels/{k}") for k in LABEL_DTYPES}


def test_labels_follow_the_input_order(tmp_path, scan):
    store, lab = _run(tmp_path, scan)
    src = laspy.read(scan)
    assert len(lab["segment"]) == len(src)
    # the coarse stage's own per-row answers, mapped back by original index, must agree
    for t in store.attrs["ingest"]["tiles"]:
        d = store.read_unit(f"tiles/{t}", ["index", "core"])
        c = store.read_unit(f"coarse/tiles/{t}", ["primitive", "global"])
        core = d["core"]
        idx = d["index"][core].astype(np.int64)
        np.testing.assert_array_equal(lab["primitive"][idx], c["primitive"][core])
        np.testing.assert_array_equal(lab["segment"][idx] >> np.uint64(LEAF_BITS), c["global"][core])


def test_bbox_run_labels_only_its_tiles(tmp_path, scan):
    src = laspy.read(scan)
    x0, y0 = float(src.x.min()), float(src.y.min())
    wf_path = tmp_path / "wf.yaml"
    wf_path.write_text(f"""\
input: {{files: [{scan}]}}
store: {tmp_path / 's.zarr'}
ingest: {{tile_size: 50.0, voxel: 0.1, bbox: [{x0 + 1}, {y0 + 1}, {x0 + 2}, {y0 + 2}]}}
coarse: {{min_support: 300}}
tree: {{enabled: false}}
cluster: {{scheduler: sync}}
outputs: {{las: {tmp_path / 'o.las'}}}
""")
    run_workflow(load_workflow(wf_path), progress=False, say=lambda _: None)
    store = RunStore.open(tmp_path / "s.zarr")
    lab = {k: store.read_slice(f"labels/{k}") for k in LABEL_DTYPES}
    grid = TileGrid.from_dict(store.attrs["grid"])
    (tile,) = store.attrs["ingest"]["tiles"]
    xyz = np.c_[src.x, src.y, src.z]
    inside = grid.core_tile(xyz, outside="flag") == tile
    assert inside.any() and (~inside).any()
    assert (lab["segment"][~inside] == 0).all() and (lab["primitive"][~inside] == 0).all()
    assert (lab["segment"][inside] > 0).mean() > 0.3
    # voxel-dropped points carry exactly their representative's labels
    d = store.read_unit(f"tiles/{tile}", ["voxel_dropped", "voxel_representative"])
    assert len(d["voxel_dropped"]) > 0
    drop, rep = d["voxel_dropped"].astype(np.int64), d["voxel_representative"].astype(np.int64)
    for k in LABEL_DTYPES:
        np.testing.assert_array_equal(lab[k][drop], lab[k][rep], err_msg=k)
    out = laspy.read(tmp_path / "o.las")
    assert len(out) == len(src)
    np.testing.assert_array_equal(np.asarray(out["segment_id"]), lab["segment"])
