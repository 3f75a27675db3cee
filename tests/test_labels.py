"""The labels stage in one process: input order, voxel-dropped points, bbox runs, export."""

from __future__ import annotations

import json

import laspy
import numpy as np
import pytest

from hollowtree.classes import ClassId
from hollowtree.pipeline.labels import LABEL_DTYPES, LEAF_BITS
from hollowtree.pipeline.run import run_workflow
from hollowtree.pipeline.workflow import load_workflow
from hollowtree.tiling.grid import TileGrid
from hollowtree.tiling.store import RunStore


@pytest.fixture(scope="module")
def scan(tmp_path_factory):
    from hollowtree.scenes.synth import synth

    path = tmp_path_factory.mktemp("lab") / "wk.laz"
    synth("wazir_khan", path, n_points=80_000, seed=5)
    return path


#: The tree of the tests that change one step of the tree stage and compare with the plain run.
SHALLOW = "{enabled: true, max_depth: 1}"


@pytest.fixture(scope="module")
def shallow_run(tmp_path_factory, scan):
    """The plain run with the SHALLOW tree, once for the tests that compare with it (read
    only): its folder, (store, labels) and how many times it replaced the workers."""
    import hollowtree.pipeline.graph as graph

    calls: list[int] = []
    path = tmp_path_factory.mktemp("shallow")
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(graph, "fresh_workers", lambda runner: calls.append(1))
        result = _run(path, scan, tree=SHALLOW)
    return path, result, len(calls)


@pytest.fixture(scope="module")
def shallow(shallow_run):
    return shallow_run[1]


@pytest.fixture(scope="module")
def plain(tmp_path_factory, scan):
    """The run without the tree, once for the tests that read it or compare with it (read only)."""
    return _run(tmp_path_factory.mktemp("plain"), scan)


def _run(tmp_path, scan, extra="", tree="{enabled: false}", ingest="{tile_size: 50.0}"):
    tmp_path.mkdir(parents=True, exist_ok=True)
    wf_path = tmp_path / "wf.yaml"
    wf_path.write_text(f"""\
input: {{files: [{scan}]}}
store: {tmp_path / 's.zarr'}
ingest: {ingest}
coarse: {{min_support: 300}}
tree: {tree}
cluster: {{scheduler: sync}}
{extra}""")
    run_workflow(load_workflow(wf_path), progress=False, say=lambda _: None)
    store = RunStore.open(tmp_path / "s.zarr")
    return store, {k: store.read_slice(f"labels/{k}") for k in LABEL_DTYPES}


def test_a_run_without_the_tree_says_why_classes_are_0(tmp_path, scan):
    wf_path = tmp_path / "wf.yaml"
    wf_path.write_text(f"input: {{files: [{scan}]}}\nstore: {tmp_path / 's.zarr'}\ntree: {{enabled: false}}\n"
                       "cluster: {scheduler: sync}\n")
    lines = run_workflow(load_workflow(wf_path), progress=False, say=lambda _: None).lines
    said = [line for line in lines if "class 0" in line]
    assert said == ["labels: the tree is off (tree.enabled: false): every point keeps class 0, with its coarse "
                    "segment and primitive (labels/segment, labels/primitive)"]


def test_labels_follow_the_input_order(scan, plain):
    store, lab = plain
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
    assert inside.any()
    assert (~inside).any()
    assert (lab["segment"][~inside] == 0).all()
    assert (lab["primitive"][~inside] == 0).all()
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


def test_large_groups_are_built_on_a_sample(tmp_path, scan, shallow):
    """An element group above tree.max_group_points builds its tree on a sample and every
    point takes its nearest sampled point's labels: all points labelled, node counts cover
    the whole group, and the classes mostly agree with the tree on every point."""
    import pyarrow.parquet as pq

    store, sampled = _run(tmp_path / "a", scan, tree="{enabled: true, max_depth: 1, max_group_points: 4000}")
    _, full = shallow  # every group of this small scan is below the default max_group_points
    recs = store.records("tree")
    big = [b for b, r in recs.items() if r.get("sampled")]  # its unit holds the sample
    assert big
    spread = store.records("tree.spread")  # the spread units hold the group's points
    for b in big:
        t = pq.read_table(tmp_path / "a" / "s.zarr" / "tree" / "tables" / f"{b}.parquet").to_pydict()
        roots = [i for i, p in enumerate(t["parent"]) if p == -1]
        assert len(roots) == 1  # one group
        n = recs[b]["csr"][1] - recs[b]["csr"][0]
        assert recs[b]["n_points"] == recs[b]["sampled"] < n
        assert sum(r["n_points"] for u, r in spread.items() if u.split(".")[0] == b) == n
        assert t["n_points"][roots[0]] == n
        assert sum(k for k, leaf in zip(t["n_points"], t["is_leaf"], strict=True) if leaf) == n
        leaf = store.read_slice(f"tree/batches/{b}/leaf")
        assert len(leaf) == n
        assert set(np.unique(leaf).tolist()) <= {i for i, x in enumerate(t["is_leaf"]) if x}
    assert (sampled["class"] == full["class"]).mean() > 0.8


@pytest.mark.parametrize("voxel", [None, 0.2])
def test_labels_in_small_parts_are_the_same(tmp_path, scan, plain, monkeypatch, voxel):
    """A tile's labels written PART_ROWS points at a time (the stage's memory bound) are
    the labels of one part per tile, with and without voxel-dropped points."""
    import hollowtree.pipeline.labels as labels

    ingest = "{tile_size: 50.0}" if voxel is None else f"{{tile_size: 50.0, voxel: {voxel}}}"
    _, whole = plain if voxel is None else _run(tmp_path / "whole", scan, ingest=ingest)
    monkeypatch.setattr(labels, "PART_ROWS", 2_000)
    small_store, small = _run(tmp_path / "small", scan, ingest=ingest)
    recs = small_store.records("labels_tiles")
    assert max(len(r["parts"]) for r in recs.values()) > 2  # several parts really written
    n_dropped = sum(small_store.array_length(f"tiles/{t}/voxel_dropped") for t in small_store.attrs["ingest"]["tiles"]
                    if small_store.has(f"tiles/{t}/voxel_dropped"))
    assert (n_dropped > 2_000) == (voxel is not None)
    for k in LABEL_DTYPES:
        np.testing.assert_array_equal(small[k], whole[k], err_msg=k)
    assert (small["segment"] > 0).mean() > 0.3
    if voxel is None:  # the export's figure finds every core point's class in its part
        from hollowtree.pipeline.export import _sample

        _, cls = _sample(small_store, n_max=10**9)
        np.testing.assert_array_equal(np.bincount(cls, minlength=9), np.bincount(small["class"], minlength=9))



def test_instances_merged_across_groups_reach_labels_and_nodes(tmp_path, scan, shallow, monkeypatch):
    """The tree stage's merge map (tree/merge.py) is what labels/instance and
    tree/nodes.parquet hold: a map that joins every instance into instance 1 leaves one
    instance wherever there was one; the classes are untouched."""
    import pyarrow.parquet as pq

    import hollowtree.tree.merge as tm
    from hollowtree.pipeline.tree_stage import MERGE_MAP

    plain_store, plain = shallow
    imap = plain_store.read_slice(MERGE_MAP)
    assert imap[0] == 0
    np.testing.assert_array_equal(imap, np.arange(len(imap)))  # this small scan: nothing to merge
    assert len(np.unique(plain["instance"])) > 3

    def merge_all(instance, class_id, group, bbox, n_instances, **kw):
        return np.minimum(np.arange(n_instances + 1), 1).astype(np.uint32)

    # Without the element check, which would judge the one merged instance anew.
    no_check = "{enabled: true, max_depth: 1, verify: false}"
    _, plain = _run(tmp_path / "no-check", scan, tree=no_check)
    monkeypatch.setattr(tm, "merge_instances", merge_all)
    store, merged = _run(tmp_path / "all", scan, tree=no_check)
    np.testing.assert_array_equal(merged["class"], plain["class"])
    np.testing.assert_array_equal(merged["instance"], np.minimum(plain["instance"], 1))
    nodes = pq.read_table(tmp_path / "all" / "s.zarr" / "tree" / "nodes.parquet").column("instance").to_numpy()
    assert set(np.unique(nodes).tolist()) <= {0, 1}


def test_classes_after_the_merge_reach_labels_and_nodes(tmp_path, scan, shallow, monkeypatch):
    """The tree stage's class map (tree.merge.merged_classes: a piece that joined an
    instance of another class takes its class) is what labels/class and the instance
    nodes of tree/nodes.parquet hold; points in no instance keep the tree's class."""
    import pyarrow.parquet as pq

    import hollowtree.tree.merge as tm
    from hollowtree.pipeline.tree_stage import MERGE_CLASS_MAP

    plain_store, plain = shallow
    assert plain_store.has(MERGE_CLASS_MAP)

    def all_other(instance, class_id, instance_map, **kw):
        out = np.full(len(instance_map), int(ClassId.OTHER), dtype=np.uint8)
        out[0] = 0
        return out

    monkeypatch.setattr(tm, "merged_classes", all_other)
    _, merged = _run(tmp_path / "other", scan, tree=SHALLOW)
    inside = plain["instance"] > 0
    assert inside.any()
    assert (~inside).any()
    assert (merged["class"][inside] == int(ClassId.OTHER)).all()
    np.testing.assert_array_equal(merged["class"][~inside], plain["class"][~inside])
    nodes = pq.read_table(tmp_path / "other" / "s.zarr" / "tree" / "nodes.parquet")
    inst = nodes.column("instance").to_numpy()
    assert (nodes.column("class_id").to_numpy()[inst > 0] == int(ClassId.OTHER)).all()


def test_arcade_cells_reach_labels(tmp_path, scan, shallow, monkeypatch):
    """The tree stage's arcade cells (tree/rows.py) are what the labels stage applies:
    inside a `take` cell the wall, other, pillar and dome points join its bay (class arch),
    every other point keeps its labels; the cells are kept in tree/rows/cells."""
    import hollowtree.tree.rows as tr
    from hollowtree.pipeline.tree_stage import ROWS

    plain_store, plain = shallow
    assert plain_store.has(ROWS)
    las = laspy.read(scan)
    off = np.asarray(plain_store.attrs["coords"]["offset"])
    xyz = np.column_stack([las.x, las.y, las.z]) - off
    wall = np.flatnonzero(plain["class"] == int(ClassId.WALL))
    h = 3.0005  # off the scan's 1 mm grid: no point on a cell face, where rounding could put it either side

    def cell_at(p):
        return tr.ArcadeCells(np.array([[p[0], p[1], 0.6, 0.8]]), np.array([[-h, h, -h, h, p[2] - h, p[2] + h]]),
                              np.array([10_000]), np.array([True]), np.array([False]))

    def moved(c):
        return int((tr.apply_cells(xyz, plain["class"], plain["instance"], c)[1] != plain["instance"]).sum())

    # The cell around the wall point (of 16 along the wall) whose cell takes the most points.
    cells = max((cell_at(xyz[w]) for w in wall[np.linspace(0, len(wall) - 1, 16).astype(int)]), key=moved)
    monkeypatch.setattr(tr, "arcade_cells", lambda samples, next_id, domes=None: (cells, {}))
    store, got = _run(tmp_path / "cells", scan, tree=SHALLOW)
    np.testing.assert_array_equal(tr.ArcadeCells.from_array(store.read_slice(ROWS)).instance, [10_000])
    want_cls, want_inst = tr.apply_cells(xyz, plain["class"], plain["instance"], cells)
    changed = want_inst != plain["instance"]
    assert changed.sum() > 50
    assert (want_cls[changed] == int(ClassId.ARCH)).all()
    np.testing.assert_array_equal(got["class"], want_cls)
    np.testing.assert_array_equal(got["instance"], want_inst)


def test_frame_joins_reach_labels(tmp_path, scan, shallow, monkeypatch):
    """A face that tree/frames.py joins to a passage is that instance in the labels, with
    class arch, wall faces included; the frames' cells follow the rows' in tree/rows/cells."""
    import hollowtree.tree.frames as tf
    import hollowtree.tree.rows as tr
    from hollowtree.pipeline.tree_stage import ROWS

    _, plain = shallow
    chosen: dict[str, int] = {}

    def frames(arches, walls, skip, next_id=None):
        chosen["wall"], chosen["into"] = sorted(walls)[0], sorted(walls)[1]
        far = np.array([[1e4, 1e4, 1.0, 0.0]])  # a cell far away: it changes no point
        cell = tr.ArcadeCells(far, np.array([[-1.0, 1.0, -1.0, 1.0, 0.0, 1.0]]),
                              np.array([chosen["into"]]), np.array([1], np.int8), np.array([False]))
        return cell, {chosen["wall"]: chosen["into"]}

    monkeypatch.setattr(tf, "frame_cells", frames)
    store, got = _run(tmp_path / "frames", scan, tree=SHALLOW)
    assert tr.ArcadeCells.from_array(store.read_slice(ROWS)).instance[-1] == chosen["into"]
    face = plain["instance"] == chosen["wall"]
    assert face.sum() > 50
    assert (plain["class"][face] == int(ClassId.WALL)).all()
    assert (got["instance"][face] == chosen["into"]).all()
    assert (got["class"][face] == int(ClassId.ARCH)).all()
    rest = ~face & (plain["instance"] != chosen["into"])
    np.testing.assert_array_equal(got["instance"][rest], plain["instance"][rest])


def test_workers_are_replaced_after_each_stage_that_ran_tasks(tmp_path, scan, shallow_run, monkeypatch):
    """``hollowtree run`` hands each stage fresh workers: after the ingest, the coarse
    stage and the tree when they ran tasks, never after a stage the store already
    records (a rerun with another tree parameter replaces them after the tree only)."""
    import shutil

    import hollowtree.pipeline.graph as graph

    folder, _, n_fresh = shallow_run
    assert n_fresh == 3  # the SHALLOW run from an empty store
    shutil.copytree(folder / "s.zarr", tmp_path / "s.zarr")  # the shared store stays as it is
    calls: list[int] = []
    monkeypatch.setattr(graph, "fresh_workers", lambda runner: calls.append(1))
    _run(tmp_path, scan, tree="{enabled: true, max_depth: 2}")
    assert len(calls) == 1
    calls.clear()
    _run(tmp_path, scan, tree="{enabled: false}")  # labels only: no stage before it ran tasks
    assert calls == []


def _kept_store(tmp_path, parts):
    store = RunStore.create(tmp_path / "k.zarr", attrs={})
    for j, index in enumerate(parts):
        index = np.sort(np.asarray(index, dtype=np.uint64))
        store.write_unit(f"labels/parts/3/{j}", {"index": index, **{
            k: (index * 7 % 251).astype(dt) for k, dt in LABEL_DTYPES.items()}})
    return store


def test_representatives_are_found_in_any_part_two_parts_held(tmp_path, monkeypatch):
    """The dropped points' lookup (labels._KeptParts) finds a representative in whichever
    part holds it, also behind the last part that answered, holds at most two parts, and
    names the tile when one is missing."""
    from hollowtree.errors import PipelineError
    from hollowtree.pipeline.labels import _KeptParts

    rng = np.random.default_rng(0)
    index = rng.permutation(10_000).astype(np.uint64)
    store = _kept_store(tmp_path, [index[a:a + 2_000] for a in range(0, 10_000, 2_000)] + [[]])
    kept = _KeptParts(store, 3, 6)
    loads = []
    original = _KeptParts._part

    def counted(self, j):
        loads.append(j not in self.held)
        out = original(self, j)
        assert len(self.held) <= 2
        return out

    monkeypatch.setattr(_KeptParts, "_part", counted)
    for reps in (index[4_100:4_600], index[8_500:9_000], index[:300], rng.choice(index, 3_000)):
        got = kept.labels_of(reps)
        for k, dt in LABEL_DTYPES.items():
            np.testing.assert_array_equal(got[k], (reps * 7 % 251).astype(dt), err_msg=k)
    # Consecutive representatives in one part: that part is read once and answers alone.
    loads.clear()
    kept.labels_of(index[6_100:6_200])
    kept.labels_of(index[6_300:6_400])
    assert sum(loads) <= 2
    with pytest.raises(PipelineError, match="tile 3 has dropped points without their representative"):
        kept.labels_of(np.array([10_000_001], np.uint64))


def test_labels_task_reads_each_kept_part_about_once(tmp_path, scan, monkeypatch):
    """With voxels, a tile's dropped points look their representatives up part by part in
    the order the ingest wrote them: part loads stay near one per kept part and dropped
    part, not their product (memory: two kept parts and one dropped part at a time). This
    holds while a part is no shorter than an ingest batch (labels.PART_ROWS >= ingest.FLUSH_ROWS)."""
    import hollowtree.pipeline.labels as labels

    loads: list[int] = []
    original = labels._KeptParts._part

    def counted(self, j):
        if j not in self.held:
            loads.append(j)
        return original(self, j)

    import hollowtree.tiling.ingest as ingest

    monkeypatch.setattr(labels, "PART_ROWS", 1_500)
    monkeypatch.setattr(ingest, "FLUSH_ROWS", 1_500)  # the ingest's batches, as in a large tile
    monkeypatch.setattr(labels._KeptParts, "_part", counted)
    store, _ = _run(tmp_path, scan, ingest="{tile_size: 50.0, voxel: 0.2}")
    n_kept = n_dropped = 0
    for t in store.attrs["ingest"]["tiles"]:
        n_kept += -(-store.array_length(f"tiles/{t}/index") // 1_500)
        n_dropped += -(-store.array_length(f"tiles/{t}/voxel_dropped") // 1_500)
    assert n_dropped > 4
    assert n_kept > 4
    assert len(loads) <= n_kept + n_dropped


def test_tree_device_auto_on_a_cpu_machine_gives_the_cpu_labels(tmp_path, scan, shallow, monkeypatch):
    """``tree.device: auto`` runs HollowNet on the CPU where torch sees no GPU, with the
    labels of ``cpu``; the device is not a parameter of the result (a rerun with another
    device redoes nothing), and ``cuda`` without a GPU is refused before anything runs."""
    import shutil

    import torch

    import hollowtree.pipeline.tree_stage as tree_stage
    from hollowtree.errors import ConfigError

    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    seen: list[str] = []
    get = tree_stage._device
    monkeypatch.setattr(tree_stage, "_device", lambda d: seen.append(get(d)) or seen[-1])
    _, want = shallow
    _, got = _run(tmp_path / "a", scan, tree=SHALLOW[:-1] + ", device: auto}")
    assert seen
    assert set(seen) == {"cpu"}
    for k in LABEL_DTYPES:
        np.testing.assert_array_equal(got[k], want[k], err_msg=k)
    seen.clear()
    _run(tmp_path / "a", scan, tree=SHALLOW[:-1] + ", device: cpu}")
    assert seen == []  # nothing redone
    shutil.rmtree(tmp_path / "b", ignore_errors=True)
    with pytest.raises(ConfigError, match="tree.device is cuda but torch sees no CUDA device"):
        _run(tmp_path / "b", scan, tree=SHALLOW[:-1] + ", device: cuda}")
    assert not (tmp_path / "b" / "s.zarr").exists()


def test_an_existing_client_runs_the_workflow_and_stays_open(tmp_path, scan, shallow):
    """``hollowtree.run(path, client=...)`` from a notebook: its Client (here of a
    LocalCluster of threads) runs the tasks instead of the workflow's cluster, with the same
    labels, and is still usable afterwards; the result opens as arrays."""
    from distributed import Client, LocalCluster

    import hollowtree

    wf_path = tmp_path / "wf.yaml"
    wf_path.write_text(f"input: {{files: [{scan}]}}\nstore: {tmp_path / 's.zarr'}\ningest: {{tile_size: 50.0}}\n"
                       f"coarse: {{min_support: 300}}\ntree: {SHALLOW}\ncluster: {{scheduler: sync}}\n")
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=False, dashboard_address=":0") as cluster, \
            Client(cluster) as client:
        result = hollowtree.run(wf_path, client=client)
        assert client.submit(sum, [1, 2]).result() == 3
        prefixes = set(client.run_on_scheduler(lambda dask_scheduler: list(dask_scheduler.task_prefixes)))
    assert {"map_chunk", "tree_batch", "labels_range"} <= prefixes  # its workers ran the stages
    _, want = shallow
    np.testing.assert_array_equal(result.class_id, want["class"])
    np.testing.assert_array_equal(result.instance, want["instance"])
    store = RunStore.open(tmp_path / "s.zarr")
    for k in LABEL_DTYPES:
        np.testing.assert_array_equal(store.read_slice(f"labels/{k}"), want[k], err_msg=k)


def test_open_reads_labels_points_and_tables(shallow_run, scan):
    """``hollowtree.open(store)``: labels in input order, the points' world coordinates,
    an Arrow table of both, the segment and node tables; a store without labels or no
    store at all is one clear error."""
    import hollowtree
    from hollowtree.errors import PipelineError

    folder, (_, want), _ = shallow_run
    res = hollowtree.open(folder / "s.zarr")
    assert len(res) == len(want["class"])
    assert "points" in repr(res)
    np.testing.assert_array_equal(res.segment, want["segment"])
    assert sum(res.counts().values()) == len(res)
    assert set(res.counts()) <= set(res.class_name)
    index, xyz = res.points()
    src = laspy.read(scan)
    np.testing.assert_array_equal(index, np.arange(len(src)))
    np.testing.assert_allclose(xyz, np.c_[src.x, src.y, src.z], atol=1e-6)
    table = res.to_arrow()
    assert table.num_rows == len(src)
    assert table.column_names[:4] == ["index", "x", "y", "z"]
    np.testing.assert_array_equal(table["instance"].to_numpy(), want["instance"])
    names = table["class_name"].to_pylist()
    assert names[:50] == list(res.class_name[:50])
    assert res.segments().num_rows > 0
    assert res.nodes().num_rows > 0
    with pytest.raises(PipelineError, match="does not exist|not a hollowtree store|no store"):
        hollowtree.open(folder / "nothing.zarr")


def test_export_keeps_the_users_data(tmp_path, scan):
    """The labelled LAZ keeps what the input held: scaled extra dimensions to the stored
    value, their descriptions, the user's own VLRs, the GPS time type and the input's
    classification (in ``input_classification``); the class codes are named."""
    import laspy
    from laspy.vlrs.known import ClassificationLookupVlr

    from hollowtree.pipeline.export import INPUT_CLASSIFICATION, LAS_CLASSIFICATION

    las = laspy.read(scan)
    las.header.global_encoding.gps_time_type = laspy.header.GpsTimeType.STANDARD
    las.add_extra_dim(laspy.ExtraBytesParams(name="reflectance", type=np.int16, scales=np.array([0.01]),
                                             offsets=np.array([0.0]), description="reflectance dB"))
    rng = np.random.default_rng(0)
    las.reflectance = np.round(rng.uniform(-20, 5, len(las.points)), 2)
    las.classification = rng.integers(0, 20, len(las.points)).astype(np.uint8)
    las.header.vlrs.append(laspy.VLR(user_id="SurveyOffice", record_id=7, description="station list",
                                     record_data=b"station 1; station 2"))
    src = tmp_path / "user.laz"
    las.write(src)
    out = tmp_path / "labelled.laz"
    _run(tmp_path / "r", src, extra=f"outputs: {{las: {out}}}\n")
    got = laspy.read(out)
    np.testing.assert_array_equal(np.asarray(got.reflectance), np.asarray(las.reflectance))  # -4.08 stays -4.08
    dim = next(d for d in got.point_format.extra_dimensions if d.name == "reflectance")
    assert dim.description == "reflectance dB"
    assert any(v.user_id == "SurveyOffice" and v.record_data == b"station 1; station 2" for v in got.header.vlrs)
    assert got.header.global_encoding.gps_time_type == laspy.header.GpsTimeType.STANDARD
    np.testing.assert_array_equal(np.asarray(got[INPUT_CLASSIFICATION]), np.asarray(las.classification))
    lookup = next(v for v in got.header.vlrs if isinstance(v, ClassificationLookupVlr))
    assert lookup.lookups[LAS_CLASSIFICATION[ClassId.DOME]] == "dome"
    assert lookup.lookups[2] == "ground"


def test_the_element_checks_decision_reaches_labels(tmp_path, scan):
    """Every element instance takes the class the element check (tree/verify.py) gives it:
    a check that believes every instance a pillar makes them pillars, one that believes
    none makes them other; points in no element instance keep their class. The check runs
    by default (``tree.verify`` unset)."""
    from hollowtree.classes import ELEMENT_CLASSES
    from hollowtree.tree.verify import SHAPE_FEATURES, VERIFY_FEATURES, ElementCheck, VerifyModel

    leaf = {"feature": np.array([-2]), "threshold": np.array([0.0]), "left": np.array([-1]),
            "right": np.array([-1]), "value": np.array([0.0])}
    yes, no = (VerifyModel(init=v, learning_rate=0.1, trees=(leaf,)) for v in (4.0, -4.0))
    assert len(VERIFY_FEATURES) == len(yes.feature_names)
    store, off = _run(tmp_path / "off", scan, tree="{enabled: true, max_depth: 1, verify: false}")
    elements = (off["instance"] > 0) & np.isin(off["class"], [int(c) for c in ELEMENT_CLASSES])
    assert elements.any()
    # every instance node carries its points' shape (the check's SHAPE_FEATURES)
    nodes = store.read_table("tree/nodes.parquet")
    node_inst = np.asarray(nodes.column("instance").to_numpy())
    shape = np.column_stack([np.asarray(nodes.column(c).to_numpy(), dtype=float) for c in SHAPE_FEATURES])
    assert (node_inst > 0).any()
    assert np.isfinite(shape[node_inst > 0]).all()
    assert np.isnan(shape[node_inst == 0]).all()
    for believed, want in (({4: no, 5: no, 6: no, 7: yes}, ClassId.PILLAR), ({4: no, 5: no, 6: no, 7: no},
                                                                              ClassId.OTHER)):
        path = tmp_path / f"check-{want.label}.json"
        ElementCheck(believed, threshold=0.5).save(path)
        on = "verify: true, " if want == ClassId.PILLAR else ""
        _, checked = _run(tmp_path / want.label, scan, tree=f"{{enabled: true, max_depth: 1, {on}verify_model: {path}}}")
        assert (checked["class"][elements] == int(want)).all()
        np.testing.assert_array_equal(checked["class"][~elements], off["class"][~elements])


def test_a_check_refitted_under_the_same_path_redoes_the_tree(tmp_path, scan):
    """A rerun after the element check's file changed in place (a refit written over it)
    is not 'nothing to do': the tree stage runs again and the labels follow the new check."""
    from hollowtree.classes import ELEMENT_CLASSES
    from hollowtree.tree.verify import ElementCheck, VerifyModel

    leaf = {"feature": np.array([-2]), "threshold": np.array([0.0]), "left": np.array([-1]),
            "right": np.array([-1]), "value": np.array([0.0])}
    yes, no = (VerifyModel(init=v, learning_rate=0.1, trees=(leaf,)) for v in (4.0, -4.0))
    path = tmp_path / "check.json"
    tree = f"{{enabled: true, max_depth: 1, verify_model: {path}}}"
    ElementCheck({4: no, 5: no, 6: no, 7: yes}, threshold=0.5).save(path)
    _, first = _run(tmp_path / "run", scan, tree=tree)
    checked = (first["instance"] > 0) & (first["class"] == int(ClassId.PILLAR))
    assert checked.any()
    ElementCheck({4: no, 5: no, 6: no, 7: no}, threshold=0.5).save(path)
    _, again = _run(tmp_path / "run", scan, tree=tree)
    assert (again["class"][checked] == int(ClassId.OTHER)).all()
    assert not ((again["instance"] > 0) & np.isin(again["class"], [int(c) for c in ELEMENT_CLASSES])).any()


def test_weights_or_split_model_rewritten_in_place_change_the_recorded_tree_parameters(tmp_path, scan):
    """HollowNet's weights and the split model rewritten under the same path (a refit with
    ``--out`` over the file) change the tree's recorded parameters, so a rerun redoes the
    tree and the labels; the split model is reread, not served from the process's cache."""
    import shutil

    from hollowtree.hollownet import DEFAULT_WEIGHTS
    from hollowtree.pipeline.run import _stage_params, changed_stages
    from hollowtree.tree.split import DEFAULT_SPLIT_PATH, load_split_model

    weights, split = tmp_path / "w.pt", tmp_path / "split.json"
    shutil.copy(DEFAULT_WEIGHTS, weights)
    shutil.copy(DEFAULT_SPLIT_PATH, split)
    wf_path = tmp_path / "wf.yaml"
    wf_path.write_text(f"input: {{files: [{scan}]}}\nstore: {tmp_path / 's.zarr'}\n"
                       f"tree: {{enabled: true, weights: {weights}, split_model: {split}}}\n")
    before = _stage_params(load_workflow(wf_path))
    assert changed_stages(before, _stage_params(load_workflow(wf_path))) == ([], [])
    first = load_split_model(split)
    model = json.loads(split.read_text())
    model["threshold"] = 0.25
    split.write_text(json.dumps(model))
    redo, diffs = changed_stages(before, _stage_params(load_workflow(wf_path)))
    assert redo == ["tree", "labels"]
    assert [d.split(":")[0] for d in diffs] == ["tree.split"]
    assert load_split_model(split).threshold == 0.25 != first.threshold
    before = _stage_params(load_workflow(wf_path))
    with weights.open("ab") as f:
        f.write(b"\0")
    redo, diffs = changed_stages(before, _stage_params(load_workflow(wf_path)))
    assert redo == ["tree", "labels"]
    assert [d.split(":")[0] for d in diffs] == ["tree.hollownet"]


def test_tile_slices_give_the_labels_of_whole_tiles_and_resume_per_slice(tmp_path, scan, monkeypatch):
    """A tile cut into row slices (labels.plan_slices, issue 44), each slice also labelling
    the voxel-dropped points whose representative is among its rows, gives the labels of
    one task per tile; a lost slice record redoes that slice alone, and records of another
    plan of slices are all redone."""
    import hollowtree.pipeline.labels as labels
    from hollowtree.pipeline.export import _sample
    from hollowtree.pipeline.graph import task_runner

    ingest = "{tile_size: 50.0, voxel: 0.2}"
    plan = labels.plan_slices
    monkeypatch.setattr(labels, "plan_slices", lambda sizes: plan(sizes, above=1e9))  # one slice a tile
    whole_store, whole = _run(tmp_path / "whole", scan, ingest=ingest)
    assert all(k.endswith(".0") for k in whole_store.records("labels_tiles"))
    monkeypatch.setattr(labels, "plan_slices", lambda sizes: [
        (t, s, a, b) for t, (rows, _) in sorted(sizes.items())
        for s, (a, b) in enumerate(zip([0, rows // 3, 2 * rows // 3], [rows // 3, 2 * rows // 3, rows], strict=True))])
    store, sliced = _run(tmp_path / "sliced", scan, ingest=ingest)
    recs = store.records("labels_tiles")
    assert len(recs) == 3 * len(store.attrs["ingest"]["tiles"])
    assert sum(r["n_points"] for r in recs.values()) == sum(r["n_points"] for r in whole_store.records("labels_tiles").values())
    for k in LABEL_DTYPES:
        np.testing.assert_array_equal(sliced[k], whole[k], err_msg=k)
    _, cls = _sample(store, n_max=10**9)
    np.testing.assert_array_equal(cls, _sample(whole_store, n_max=10**9)[1])

    url = str(tmp_path / "sliced" / "s.zarr")
    a = RunStore.open(url, mode="a")
    a.clear_records("labels")  # as if interrupted before the ranges, with one slice lost
    lost = sorted(recs)[1]
    a.delete(f"records/labels_tiles/{lost}")
    with task_runner("sync", progress=False) as run:
        report = labels.run_labels(url, use_tree=False, runner=run)
    assert (report.tiles_run, report.tiles_skipped) == (1, len(recs) - 1)
    for k in LABEL_DTYPES:
        np.testing.assert_array_equal(a.read_slice(f"labels/{k}"), whole[k], err_msg=k)
    monkeypatch.setattr(labels, "plan_slices", lambda sizes: plan(sizes, above=1e9))  # another plan
    with task_runner("sync", progress=False) as run:
        report = labels.run_labels(url, use_tree=False, runner=run)
    assert (report.tiles_run, report.tiles_skipped) == (len(whole_store.records("labels_tiles")), 0)
    assert sorted(a.records("labels_tiles")) == sorted(whole_store.records("labels_tiles"))
    assert not a.has(f"labels/parts/{sorted(a.attrs['ingest']['tiles'])[0]}/2")  # the old plan's parts are gone
    for k in LABEL_DTYPES:
        np.testing.assert_array_equal(a.read_slice(f"labels/{k}"), whole[k], err_msg=k)
