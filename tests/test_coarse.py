"""The coarse stage on the run store: tile-size invariance, stitching, CSR, resume."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import laspy
import numpy as np
import pyarrow.parquet as pq
import pytest
from sklearn.metrics import adjusted_rand_score

from hollowtree.errors import ConfigError
from hollowtree.pipeline.cli import main
from hollowtree.pipeline.coarse import FALLBACK_EPS, CoarseParams, run_coarse
from hollowtree.pipeline.graph import task_runner
from hollowtree.pipeline.tree_stage import group_starts
from hollowtree.primitives.dbscan import window_spacing
from hollowtree.scenes.synth import synth
from hollowtree.tiling.ingest import IngestParams, ingest
from hollowtree.tiling.store import CHUNK_POINTS, RunStore

PARAMS = CoarseParams(eps=0.3)


@pytest.fixture(scope="module")
def scan(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("coarse") / "minaret.laz"
    synth("minaret", out, n_points=60_000, seed=2)
    return out


def _segment(scan_path: Path, store: Path, tile_size: float, params: CoarseParams = PARAMS) -> np.ndarray:
    """Global segment id per original point (core copies), after ingest + coarse."""
    with task_runner("sync", progress=False) as run:
        ingest([str(scan_path)], str(store), IngestParams(tile_size=tile_size, buffer=2.0), runner=run)
        run_coarse(str(store), params, runner=run)
    return _labels(scan_path, store)


def _labels(scan_path: Path, store: Path) -> np.ndarray:
    s = RunStore.open(store)
    n = laspy.read(scan_path).header.point_count
    labels = np.full(n, -1, dtype=np.int64)
    for t in s.records("ingest"):
        d = s.read_unit(f"tiles/{t}", ["index", "core"])
        g = s.read_unit(f"coarse/tiles/{t}", ["global"])["global"]
        labels[d["index"][d["core"]].astype(np.int64)] = g[d["core"]].astype(np.int64)
    assert (labels >= 0).all()  # every point got exactly its core copy's label
    return labels


@pytest.fixture(scope="module")
def untiled_run(scan, tmp_path_factory) -> tuple[np.ndarray, Path]:
    """Segment per point and store of the whole scan in one tile (PARAMS); shared, read only."""
    store = tmp_path_factory.mktemp("untiled") / "s"
    return _segment(scan, store, 500.0), store


@pytest.fixture(scope="module")
def untiled(untiled_run) -> np.ndarray:
    return untiled_run[0]


@pytest.mark.parametrize("tile_size", [10.0, 20.0, 50.0])
def test_tile_size_does_not_change_the_answer(scan, untiled_run, request, tmp_path, tile_size):
    """Neither the segments nor their element groups move with the tile size."""
    untiled, untiled_store = untiled_run
    if tile_size == 20.0:
        tiled, store = request.getfixturevalue("tiled20")
    else:
        tiled, store = _segment(scan, tmp_path / "s", tile_size), tmp_path / "s"
    assert adjusted_rand_score(untiled, tiled) >= 0.95
    # no ground-truth element is split at a tile border
    _assert_elements_kept(scan, tiled, untiled)
    assert adjusted_rand_score(_groups(untiled_store, untiled)[0], _groups(store, tiled)[0]) >= 0.95


def _assert_elements_kept(scan: Path, labels: np.ndarray, reference: np.ndarray) -> None:
    """Each ground-truth element's dominant segment covers as much of it as in ``reference``."""
    gt = np.asarray(laspy.read(scan).gt_instance)
    for inst in np.unique(gt):
        sel = gt == inst
        if sel.sum() < 500:
            continue
        share = np.bincount(labels[sel]).max() / sel.sum()
        reference_share = np.bincount(reference[sel]).max() / sel.sum()
        assert share >= reference_share - 0.05, inst


BLOCKED = CoarseParams(eps=0.3, block_points=8_000)


@pytest.fixture(scope="module")
def blocked8k(scan, tmp_path_factory) -> tuple[np.ndarray, Path]:
    """Segment per point and store of the whole scan in one tile cut into blocks of 8 000
    points (BLOCKED); shared, read only."""
    store = tmp_path_factory.mktemp("blocked") / "s"
    return _segment(scan, store, 500.0, BLOCKED), store


@pytest.mark.parametrize("block_points", [8_000, 20_000])
def test_blocks_inside_a_tile_do_not_change_the_answer(scan, untiled, request, tmp_path, block_points):
    """A tile above ``block_points`` is segmented block by block and joined like tiles."""
    if block_points == BLOCKED.block_points:
        blocked, store = request.getfixturevalue("blocked8k")
    else:
        store = tmp_path / "s"
        blocked = _segment(scan, store, 500.0, CoarseParams(eps=0.3, block_points=block_points))
    recs = RunStore.open(store).records("coarse")
    assert all(r["n_blocks"] >= -(-r["n_points"] // block_points) for r in recs.values())
    assert max(r["n_blocks"] for r in recs.values()) >= 2  # tiles were split
    assert adjusted_rand_score(untiled, blocked) >= 0.95
    _assert_elements_kept(scan, blocked, untiled)


def test_block_split_holds_no_copy_of_the_coordinates():
    """The split of a dense tile into blocks (primitives.blocks.split_blocks) takes its
    columns as views, one coordinate at a time, and int32 indices: about 17 bytes per
    point besides its input (57 when it copied both columns and both coordinates of every
    rectangle, 32-45 with int64 indices), so a plan task of the 100 M-point benchmark's
    7.9 M-row tile costs less than a block task."""
    import tracemalloc

    from hollowtree.primitives.blocks import split_blocks

    xy = np.random.default_rng(0).random((400_000, 2)) * [30.0, 20.0]
    for a in (xy, (xy * 1e6).astype(np.int32)):
        tracemalloc.start()
        try:
            block_of, rects = split_blocks(a, 100_000)
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        assert len(rects) == 4
        assert np.bincount(block_of).max() <= 100_000
        assert peak / len(xy) < 20


def test_blocks_of_stored_integers_are_those_of_their_metres():
    """plan_blocks splits a tile's stored integers with their scale: the blocks and the
    rectangles are those of the metres (integers times scale, in float64) to the bit,
    with ties on the median and a scale of its own per axis."""
    from hollowtree.primitives.blocks import split_blocks

    rng = np.random.default_rng(1)
    for scale in ([0.001, 0.001], [0.00025, 0.0005], [0.01, 0.003]):
        raw = rng.integers(-3_000, 40_000, size=(60_000, 3)).astype(np.int32)
        raw[:20_000, 0] = 7_000  # a column of equal x: the median falls on a tie
        raw[20_000:26_000, 1] = raw[20_000, 1]
        s = np.asarray(scale + [0.001])
        metres = raw.astype(np.float64) * s
        for cap in (5_000, 17_000):
            b_int, r_int = split_blocks(raw, cap, scale)
            b_m, r_m = split_blocks(metres[:, :2], cap)
            np.testing.assert_array_equal(b_int, b_m)
            np.testing.assert_array_equal(r_int, r_m)
    with pytest.raises(ConfigError, match="scale"):
        split_blocks(raw, 10, [0.0, 1.0])


def test_a_block_with_a_dense_context_is_cut_again():
    """A block whose context (own points and those within the margin) holds more than
    CONTEXT_FACTOR * block_points is split again while it owns more than a quarter of
    block_points; blocks with a small context are split_blocks' own, numbers included."""
    from hollowtree.primitives.blocks import block_context, split_blocks
    from hollowtree.primitives.segment import CONTEXT_FACTOR, block_inputs

    xy = np.random.default_rng(3).random((20_000, 2)) * 10.0
    cap = 10_000
    block_of, rects = split_blocks(xy, cap)
    n, inputs = block_inputs(xy, cap, 0.05)  # a thin margin: split_blocks' blocks
    assert n == len(rects)
    for b, (rows, mine) in enumerate(inputs):
        np.testing.assert_array_equal(rows, block_context(xy, rects[b], 0.05))
        np.testing.assert_array_equal(rows[mine], np.flatnonzero(block_of == b))
    n, inputs = block_inputs(xy, cap, 2.0)  # contexts of about 1.4 blocks: cut again
    assert n > len(rects)
    owner = np.full(len(xy), -1)
    for b, (rows, mine) in enumerate(inputs):
        assert (owner[rows[mine]] == -1).all()
        owner[rows[mine]] = b
        assert len(rows) <= CONTEXT_FACTOR * cap or 4 * mine.sum() <= cap
    assert (owner >= 0).all()


def test_block_points_is_validated():
    with pytest.raises(ConfigError, match="block_points"):
        CoarseParams(block_points=-1)


@pytest.fixture(scope="module")
def tiled20(scan, tmp_path_factory) -> tuple[np.ndarray, Path]:
    store = tmp_path_factory.mktemp("tiled20") / "s"
    return _segment(scan, store, 20.0), store


def test_tables_and_csr(tiled20):
    labels, store = tiled20
    s = RunStore.open(store)
    csr = s.read_unit("coarse/csr")
    indices, offsets = csr["indices"].astype(np.int64), csr["offsets"]
    table = pq.read_table(store / "coarse" / "segments.parquet")
    g_max = labels.max()
    assert len(offsets) == g_max + 1 == table.num_rows + 1
    for g in range(1, g_max + 1):
        members = indices[offsets[g - 1]:offsets[g]]
        assert (labels[members] == g).all()
        assert len(members) == (labels == g).sum() == table.column("n_points")[g - 1].as_py()
    assert set(table.column("kind").to_pylist()) <= {"plane", "sphere", "cylinder", "cone", "torus", "free"}


def test_rerun_is_resumed(tiled20, capsys):
    assert main(["coarse", str(tiled20[1]), "--eps", "0.3", "--scheduler", "sync",
                 "--no-progress"]) == 0
    assert "0 run" in capsys.readouterr().out


def _true_spacing_quantile(store: Path, q: float) -> float:
    """The q-quantile of the 8-NN spacing of every core point, neighbours from its whole tile."""
    from scipy.spatial import cKDTree

    s = RunStore.open(store)
    scale = np.asarray(s.attrs["coords"]["scale"])
    found = []
    for t in s.records("ingest"):
        d = s.read_unit(f"tiles/{t}", ["xyz", "core"])
        xyz = d["xyz"].astype(np.float64) * scale
        found.append(cKDTree(xyz).query(xyz[d["core"]], k=9)[0][:, 8])
    return float(np.quantile(np.concatenate(found), q))


def test_automatic_eps_follows_the_scan_spacing_not_the_tiles(scan, tiled20, tmp_path):
    """The automatic eps is EPS_FACTOR x the 25 % spacing quantile measured on windows of
    the scan; it matches the spacing of all points and does not move with the tile size."""
    from hollowtree.pipeline.coarse import (
        EPS_FACTOR,
        EPS_QUANTILE,
        SPACING_STAGE,
        SPACING_UNITS,
        scan_spacing,
    )

    store = tiled20[1]
    s = RunStore.open(store)
    sizes = {int(t): int(r["n_points"]) for t, r in s.records("ingest").items()}
    assert len(sizes) > 1
    measured = scan_spacing(s, sizes, seed=0)
    assert measured == pytest.approx(_true_spacing_quantile(store, EPS_QUANTILE), rel=0.1)
    with task_runner(None, workers=2, progress=False, processes=False) as run:  # windows as Dask tasks: same value
        assert scan_spacing(s, sizes, seed=0, runner=run) == measured
    recs = RunStore.open(store).records(SPACING_STAGE)
    assert len(recs) == SPACING_UNITS
    assert all("wall_s" in r for r in recs.values())
    one = tmp_path / "one"
    with task_runner("sync", progress=False) as run:
        ingest([str(scan)], str(one), IngestParams(tile_size=500.0, buffer=2.0), runner=run)
        run_coarse(str(one), CoarseParams(), runner=run)
    stage = RunStore.open(one).attrs["stages"]["coarse"]
    assert stage["eps"] == pytest.approx(EPS_FACTOR * stage["spacing"])
    assert stage["params"]["cluster_epsilon"] == pytest.approx(max(0.15, 2.0 * stage["eps"] / 3.0))
    assert stage["spacing"] == pytest.approx(measured, rel=0.1)


def _tiny_las(path: Path, pts: np.ndarray) -> Path:
    header = laspy.LasHeader(point_format=6, version="1.4")
    header.scales, header.offsets = [0.001] * 3, [500000.0, 3500000.0, 0.0]
    las = laspy.LasData(header)
    las.x, las.y, las.z = pts.T
    las.write(path)
    return path


def test_duplicate_points_fall_back_to_a_fixed_eps(tmp_path):
    """Exact duplicates have no spacing to measure: the stage runs with FALLBACK_EPS."""
    scan = _tiny_las(tmp_path / "dup.las", np.zeros((40, 3)) + [500000.0, 3500000.0, 200.0])
    with task_runner("sync", progress=False) as run:
        ingest([str(scan)], str(tmp_path / "s"), IngestParams(tile_size=10.0), runner=run)
        rep = run_coarse(str(tmp_path / "s"), CoarseParams(), runner=run)
    assert rep.eps == FALLBACK_EPS
    assert RunStore.open(str(tmp_path / "s")).attrs["stages"]["coarse"]["spacing"] is None


def test_spacing_ignores_exact_duplicates():
    rng = np.random.default_rng(0)
    pts = rng.uniform(0, 1, (500, 3))
    once = window_spacing([(pts, np.ones(500, bool))], k=8, quantile=0.25)
    many = np.r_[pts, np.repeat(pts[:50], 9, axis=0)]  # 50 points with 9 copies each
    again = window_spacing([(many, np.ones(len(many), bool))], k=8, quantile=0.25)
    assert again > 0
    assert again == pytest.approx(once, rel=0.5)


def test_tiny_tile_does_not_crash(tmp_path):
    pts = np.zeros((50, 3)) + [500000.0, 3500000.0, 200.0]
    pts[:, 0] += np.linspace(0, 1, 50)  # collinear
    scan = _tiny_las(tmp_path / "line.las", pts)
    with task_runner("sync", progress=False) as run:
        ingest([str(scan)], str(tmp_path / "s"), IngestParams(tile_size=10.0), runner=run)
        rep = run_coarse(str(tmp_path / "s"), PARAMS, runner=run)
    assert rep.n_segments == 0
    assert rep.n_unsegmented == 50


def test_store_without_ingest_is_refused(tmp_path, capsys):
    assert main(["coarse", str(tmp_path / "nothing"), "--scheduler", "sync"]) == 2
    assert "does not exist" in capsys.readouterr().err


def _groups(store, labels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Element group per point and the group column (by segment) of the global table."""
    table = pq.read_table(store / "coarse" / "segments.parquet")
    seg = np.asarray(table.column("segment").to_numpy())
    grp = np.asarray(table.column("group").to_numpy())[np.argsort(seg)]
    return np.r_[0, grp][labels], grp


def test_groups_are_runs_of_segments(scan, untiled_run, tmp_path):
    """Element groups (ids 1..K) are runs of consecutive global segments, and grouping
    leaves the segments themselves unchanged. (test_tile_size_does_not_change_the_answer
    checks that the groups do not move with the tiles.)"""
    untiled, store = untiled_run
    _, col = _groups(store, untiled)
    # ids 1..K, each group one run of consecutive global segments, in order
    assert col[0] == 1
    assert set(np.diff(col).tolist()) <= {0, 1}
    assert 1 < col.max() < len(col)  # some segments were grouped, not all into one
    starts = group_starts(RunStore.open(store))
    assert starts.tolist() == np.r_[np.flatnonzero(np.r_[True, col[1:] != col[:-1]]), len(col)].tolist()
    # a group is a union of segments: the segments themselves are unchanged by grouping
    plain = _segment(scan, tmp_path / "p", 500.0, CoarseParams(eps=0.3, group_gap=0.0))
    assert adjusted_rand_score(plain, untiled) == 1.0
    _, col0 = _groups(tmp_path / "p", plain)
    assert col0.tolist() == list(range(1, len(col0) + 1))  # grouping off: one group per segment


def test_large_planes_are_never_grouped(untiled_run):
    labels, store = untiled_run
    table = pq.read_table(store / "coarse" / "segments.parquet").to_pydict()
    grp = np.asarray(table["group"])
    sizes = np.bincount(grp)
    wide = [i for i, k in enumerate(table["kind"]) if k == "plane"
            and np.hypot(table["xmax"][i] - table["xmin"][i], table["ymax"][i] - table["ymin"][i])
            > PARAMS.group_max_plane]
    assert wide  # the minaret scene's ground is one
    assert all(sizes[grp[i]] == 1 for i in wide)
    assert (labels > 0).any()


def _group_table(store: Path) -> dict:
    t = pq.read_table(store / "coarse" / "segments.parquet").to_pydict()
    t["wide"] = [k == "plane" and np.hypot(x1 - x0, y1 - y0) > CoarseParams().group_max_plane
                 for k, x0, x1, y0, y1 in zip(t["kind"], t["xmin"], t["xmax"], t["ymin"], t["ymax"], strict=True)]
    t["wall"] = [w and abs(json.loads(p)[2]) < 0.3 for w, p in zip(t["wide"], t["params"], strict=True)]
    return t


def _largest_group_share(scan_path: Path, store: Path, labels: np.ndarray, gt_class: int) -> float:
    """Share of the ground truth's points of one class in their most common group."""
    las = laspy.read(scan_path)
    t = pq.read_table(store / "coarse" / "segments.parquet").to_pydict()
    grp = np.zeros(max(t["segment"]) + 1, dtype=np.int64)
    grp[t["segment"]] = t["group"]
    m = (np.asarray(las["gt_class"]) == gt_class) & (labels > 0)
    return float(np.bincount(grp[labels[m]]).max() / (np.asarray(las["gt_class"]) == gt_class).sum())


@pytest.fixture(scope="module")
def arcade(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("arcade") / "arcade.laz"
    synth("arcade", out, n_points=80_000, seed=2)
    return out


def test_segments_set_in_a_wall_join_it(arcade, tmp_path):
    """An arch's jambs and intrados join the arcade's face (group_set_in), and nothing joins
    two wide planes or the ground."""
    off = _segment(arcade, tmp_path / "off", 500.0, CoarseParams(eps=0.3, group_set_in=0.0, group_stack=0.0))
    on = _segment(arcade, tmp_path / "on", 500.0, CoarseParams(eps=0.3))
    t_off, t_on = _group_table(tmp_path / "off"), _group_table(tmp_path / "on")
    assert any(t_on["wall"])
    assert not all(t_on["wide"])
    sizes = np.bincount(np.asarray(t_off["group"]))
    assert all(sizes[g] == 1 for g, w in zip(t_off["group"], t_off["wide"], strict=True) if w)
    g_on = np.asarray(t_on["group"])
    wide = np.asarray(t_on["wide"])
    assert np.bincount(g_on[wide]).max() == 1  # never two wide planes in one group
    joined = {g for g, w in zip(g_on, t_on["wall"], strict=True) if w}
    assert any(k != "plane" for g, k in zip(g_on, t_on["kind"], strict=True) if g in joined)
    for g, w, wl in zip(g_on, wide, t_on["wall"], strict=True):
        if w and not wl:  # the ground: alone
            assert (g_on == g).sum() == 1
    # the arches' points now share a group with their face
    share_off = _largest_group_share(arcade, tmp_path / "off", off, 4)
    share_on = _largest_group_share(arcade, tmp_path / "on", on, 4)
    assert share_on > share_off + 0.2


def test_stacked_stages_are_one_group(scan, untiled_run, tmp_path):
    """A minaret's stages, whose joints its balconies hide, become one group (group_stack)."""
    off = _segment(scan, tmp_path / "off", 500.0, CoarseParams(eps=0.3, group_stack=0.0))
    on, on_store = untiled_run
    share_off = _largest_group_share(scan, tmp_path / "off", off, 6)
    share_on = _largest_group_share(scan, on_store, on, 6)
    assert share_on > share_off + 0.1
    assert len(set(_group_table(on_store)["group"])) < len(set(_group_table(tmp_path / "off")["group"]))
    assert adjusted_rand_score(off, on) == 1.0  # the segments themselves are unchanged


def test_sparse_pass_segments_a_far_thin_surface():
    """A wall scanned 10x sparser than the ground that sets eps is segmented only by the
    sparse pass (``sparse_factor``); the dense ground is segmented either way."""
    from hollowtree.primitives.segment import segment_points

    rng = np.random.default_rng(1)
    ground = np.c_[rng.uniform(0, 20, (160_000, 2)), rng.normal(0, 0.002, 160_000)]  # 0.05 m
    n_far = 1_600
    wall = np.c_[rng.uniform(40, 60, n_far), np.full(n_far, 30.0) + rng.normal(0, 0.01, n_far),
                 rng.uniform(0, 20, n_far)]  # 20 x 20 m, 0.5 m spacing
    xyz = np.r_[ground, wall]
    eps = 0.15  # 3 x the ground's spacing, as the stage's default would set it
    far = np.arange(len(ground), len(xyz))
    one, _, _ = segment_points(xyz, CoarseParams(sparse_factor=0.0), eps, np.random.default_rng(0))
    two, fits, _ = segment_points(xyz, CoarseParams(sparse_factor=4.0), eps, np.random.default_rng(0))
    assert (one[far] > 0).mean() < 0.1
    assert (two[far] > 0).mean() > 0.8
    main_far = np.bincount(two[far][two[far] > 0]).argmax()
    assert fits[main_far - 1]["kind"] == "plane"
    assert (two[: len(ground)] > 0).mean() > 0.9


def test_a_small_sparse_element_is_a_segment_and_a_dense_shred_is_not():
    """Free clusters under ``free_min_points`` points: a sparsely scanned column (120
    points over 4 m) spans many cells and is a segment; a shred of the same count packed in
    a hand's width stays unsegmented, as both do with ``free_min_cells`` 0."""
    from hollowtree.primitives.segment import segment_points

    rng = np.random.default_rng(3)
    ground = np.c_[rng.uniform(-5, 5, (40_000, 2)), rng.normal(0, 0.002, 40_000)]
    t, z = rng.uniform(0, 2 * np.pi, 120), rng.uniform(0.1, 4.0, 120)
    column = np.c_[0.2 * np.cos(t), 0.2 * np.sin(t), z]
    shred = np.c_[3.0, 3.0, 1.0] + rng.normal(0, 0.04, (120, 3))
    xyz = np.r_[ground, column, shred]
    col, shr = np.arange(40_000, 40_120), np.arange(40_120, 40_240)
    seg, fits, _ = segment_points(xyz, CoarseParams(sparse_factor=0.0), 0.6, np.random.default_rng(0))
    assert (seg[col] > 0).mean() > 0.9
    assert fits[np.bincount(seg[col]).argmax() - 1]["kind"] == "free"
    assert (seg[shr] == 0).all()
    off, _, _ = segment_points(xyz, CoarseParams(sparse_factor=0.0, free_min_cells=0), 0.6, np.random.default_rng(0))
    assert (off[col] == 0).all()
    assert (off[shr] == 0).all()


def test_sparse_part_of_a_plane_joins_its_dense_part():
    """Ground scanned densely near the station and sparsely beyond is one segment: the
    sparse pass's plane is joined to the first pass's where they touch and agree."""
    from hollowtree.primitives.segment import segment_points

    rng = np.random.default_rng(2)
    near = np.c_[rng.uniform(0, 20, (160_000, 2)), rng.normal(0, 0.002, 160_000)]  # 0.05 m
    far = np.c_[rng.uniform(20, 60, 12_800), rng.uniform(0, 20, 12_800), rng.normal(0, 0.01, 12_800)]  # 0.25 m
    xyz = np.r_[near, far]
    seg, fits, _ = segment_points(xyz, CoarseParams(sparse_factor=2.0), 0.15, np.random.default_rng(0))
    main_near = np.bincount(seg[: len(near)][seg[: len(near)] > 0]).argmax()
    assert (seg[len(near):] == main_near).mean() > 0.8
    assert fits[main_near - 1]["kind"] == "plane"


def test_block_tasks_equal_the_in_process_blocks(blocked8k):
    """run_coarse runs the blocks of a dense tile as tasks of their own and joins them in a
    second round: the tile's segments equal those of the in-process loop, point by point,
    and the blocks' inputs and intermediate results are gone once the tile is recorded."""
    from hollowtree.pipeline.coarse import BLOCK_STAGE, PLAN_STAGE, _margin, _unit_xyz
    from hollowtree.primitives.segment import segment_tile

    s = RunStore.open(blocked8k[1])
    stage = s.attrs["stages"]["coarse"]
    params = CoarseParams.from_dict(stage["params"])
    cfg = {"eps": stage["eps"]}
    recs = s.records("coarse")
    blocked = [int(t) for t, r in recs.items() if r["n_blocks"] > 1]
    assert blocked
    assert len(s.records(BLOCK_STAGE)) == sum(recs[str(t)]["n_blocks"] for t in blocked)
    assert {int(t): r["n_blocks"] for t, r in s.records(PLAN_STAGE).items()} == {t: recs[str(t)]["n_blocks"]
                                                                                for t in blocked}
    for t in blocked:
        xyz = _unit_xyz(s, t, -1)
        seg, _, _, n_blocks = segment_tile(xyz, params, cfg["eps"], t, _margin(s, cfg, params))
        assert n_blocks == recs[str(t)]["n_blocks"]
        assert np.array_equal(s.read_unit(f"coarse/tiles/{t}", ["segment"])["segment"], seg)
        for group in ("blocks", "block_input", "block_of", "normals"):
            assert not s.has(f"coarse/{group}/{t}")


def test_tile_tables_and_contacts_read_a_piece_at_a_time(scan, tmp_path, monkeypatch):
    """A tile's table and contacts are taken READ_ROWS rows at a time (so a dense tile's
    join holds no coordinates): they equal those of the whole tile's points at once."""
    import hollowtree.pipeline.coarse as coarse
    from hollowtree.primitives.group import segment_contacts

    monkeypatch.setattr(coarse, "READ_ROWS", 997)
    store_path = tmp_path / "s"
    params = CoarseParams(eps=0.3, block_points=8_000)
    _segment(scan, store_path, 500.0, params)
    s = RunStore.open(store_path)
    scale, offset = (np.asarray(s.attrs["coords"][k]) for k in ("scale", "offset"))
    gap = CoarseParams.from_dict(s.attrs["stages"]["coarse"]["params"]).group_gap
    for t in s.records("coarse"):
        d = s.read_unit(f"tiles/{t}", ["xyz", "core", "index"])
        local = d["xyz"].astype(np.float64) * scale
        seg = s.read_unit(f"coarse/tiles/{t}", ["segment"])["segment"].astype(np.int64)
        assert len(seg) > 997
        table = pq.read_table(store_path / "coarse" / "tables" / f"{t}.parquet").to_pydict()
        sids = np.unique(seg[seg > 0])
        assert table["segment"] == sids.tolist()
        for i, sid in enumerate(sids.tolist()):
            rows = seg == sid
            world = local[rows] + offset
            core = d["core"][rows].astype(bool)
            assert table["n_points"][i] == rows.sum()
            assert table["n_core"][i] == core.sum()
            assert table["min_index"][i] == (int(d["index"][rows][core].min()) if core.any() else -1)
            assert [table[k][i] for k in ("xmin", "ymin", "zmin")] == world.min(axis=0).tolist()
            assert [table[k][i] for k in ("xmax", "ymax", "zmax")] == world.max(axis=0).tolist()
        got = pq.read_table(store_path / "coarse" / "contacts" / f"{t}.parquet").to_pydict()
        a, b, n = segment_contacts(local, seg, gap, min_contacts=params.group_min_contacts)
        assert (got["a"], got["b"], got["n"]) == (a.tolist(), b.tolist(), n.tolist())


def test_stitch_reads_a_piece_at_a_time(tiled20, tmp_path, monkeypatch):
    """The stitch reads tiles READ_ROWS rows at a time and matches buffer rows only to core
    rows near a tile's edge: the global ids, CSR and table equal those of whole tiles."""
    import hollowtree.pipeline.coarse_stitch as coarse_stitch

    store_path = tmp_path / "s"
    shutil.copytree(tiled20[1], store_path)  # the shared store stays as it is
    s = RunStore.open(store_path, mode="a")
    tiles = [int(t) for t in s.attrs["ingest"]["tiles"]]
    assert len(tiles) > 2

    def outputs() -> dict[str, object]:
        out: dict[str, object] = {k: s.read_unit("coarse/csr")[k] for k in ("offsets", "indices", "xyz")}
        for t in tiles:
            out.update({f"{t}/{k}": v for k, v in s.read_unit(f"coarse/tiles/{t}", ["global", "csr_pos"]).items()})
        out["table"] = pq.read_table(store_path / "coarse" / "segments.parquet").to_pydict()
        return out

    params = CoarseParams.from_dict(s.attrs["stages"]["coarse"]["params"])
    whole = outputs()
    assert len(whole["indices"]) > 997  # type: ignore[arg-type]
    monkeypatch.setattr(coarse_stitch, "READ_ROWS", 997)
    monkeypatch.setattr(coarse_stitch, "CSR_ROWS", 2 * CHUNK_POINTS)  # several csr tasks
    with task_runner("sync", progress=False) as run:
        coarse_stitch.stitch(s, tiles, params, runner=run)
    pieces = outputs()
    assert pieces.keys() == whole.keys()
    for k, v in whole.items():
        if k == "table":
            assert pieces[k].keys() == v.keys()  # type: ignore[union-attr]
            for c in v:  # type: ignore[union-attr]
                np.testing.assert_array_equal(pieces[k][c], v[c])  # type: ignore[index]  # NaN == NaN here
        else:
            assert np.array_equal(pieces[k], v), k


def test_dense_tiles_are_stitched_in_parts(scan, tmp_path, monkeypatch):
    """A tile above twice the median is stitched in parts (its buffer rows matched in
    slices, its CSR rows written per run of the pieces its coarse task counted), with
    the global ids, CSR and table of the stitch in whole tiles."""
    import hollowtree.pipeline.coarse as coarse
    import hollowtree.pipeline.coarse_stitch as coarse_stitch

    monkeypatch.setattr(coarse, "READ_ROWS", 2_048)
    monkeypatch.setattr(coarse_stitch, "READ_ROWS", 2_048)
    monkeypatch.setattr(coarse_stitch, "CHUNK_POINTS", 1_024)
    monkeypatch.setattr(coarse_stitch, "CSR_ROWS", 4_096)
    out = {}
    for split in (float("inf"), 2.0):
        monkeypatch.setattr(coarse_stitch, "UNIT_SPLIT", split)
        store = tmp_path / f"s{split}"
        _segment(scan, store, 10.0)
        s = RunStore.open(store)
        tiles = [int(t) for t in s.attrs["ingest"]["tiles"]]
        out[split] = {"csr": s.read_unit("coarse/csr"), "table": pq.read_table(store / "coarse" / "segments.parquet"),
                      **{t: s.read_unit(f"coarse/tiles/{t}", ["global", "csr_pos"]) for t in tiles},
                      "parts": set(s.records("coarse.csr_parts")), "pairs": set(s.records("coarse.pairs"))}
    whole, parts = out[float("inf")], out[2.0]
    assert any(u.endswith(".1") for u in parts["parts"]), parts["parts"]  # some tile in row parts
    assert any(u.endswith(".1") for u in parts["pairs"]), parts["pairs"]  # and its buffer in slices
    assert not any(u.endswith(".1") for u in whole["parts"] | whole["pairs"])
    for c in whole["table"].column_names:  # NaN == NaN here
        np.testing.assert_array_equal(whole["table"].column(c).to_numpy(), parts["table"].column(c).to_numpy())
    for k in whole:
        if isinstance(k, int) or k == "csr":
            for name, v in whole[k].items():
                assert np.array_equal(v, parts[k][name]), (k, name)


def test_interrupted_block_tasks_resume(scan, blocked8k, tmp_path):
    """A run stopped after some block tasks resumes: planned tiles are not cut again,
    recorded blocks and normals are not run again, and the answer is that of an
    uninterrupted run. This runner runs tasks side by side (not ``serial``): blocks take
    their normals from normals tasks, and give the answer of the one-process run
    (``blocked8k``), which computes them in the block."""
    from hollowtree.pipeline.coarse import NORMAL_STAGE, coarse_normals, plan_blocks

    params = BLOCKED
    whole = blocked8k[0]

    def is_block(args, desc):
        return desc == "coarse: tiles" and args[2] >= 0

    class Stop(Exception):
        pass

    calls: list[tuple] = []

    def runner(stop_after):
        def run_units(fn, args_list, desc):
            out = []
            with task_runner("sync", progress=False) as run:
                for args in args_list:
                    if is_block(args, desc) and sum(is_block(a, d) for _, a, d in calls) == stop_after:
                        raise Stop
                    calls.append((fn, args, desc))
                    out.extend(run(fn, [args], desc))
            return out
        return run_units

    store = tmp_path / "b"
    with task_runner("sync", progress=False) as run:
        ingest([str(scan)], str(store), IngestParams(tile_size=500.0, buffer=2.0), runner=run)
    with pytest.raises(Stop):
        run_coarse(str(store), params, runner=runner(3))
    assert any(getattr(fn, "fn", fn) is plan_blocks for fn, _, _ in calls)  # in_child(plan_blocks)
    normals_first = [a for fn, a, _ in calls if getattr(fn, "fn", fn) is coarse_normals]
    calls.clear()
    run_coarse(str(store), params, runner=runner(-1))
    s = RunStore.open(store)
    n_blocks = sum(r["n_blocks"] for r in s.records("coarse").values() if r["n_blocks"] > 1)
    assert not any(getattr(fn, "fn", fn) is plan_blocks for fn, _, _ in calls)
    assert sum(is_block(a, d) for _, a, d in calls) == n_blocks - 3
    assert np.array_equal(_labels(scan, store), whole)
    normals_again = [a for fn, a, _ in calls if getattr(fn, "fn", fn) is coarse_normals]
    assert normals_first
    assert len(normals_first) + len(normals_again) == len(s.records(NORMAL_STAGE))
    assert not any(s.has(f"coarse/normals/{t}") for t in s.records("coarse"))


def test_normals_tasks_give_the_answer_of_one_process(scan, tmp_path):
    """Where tasks run side by side (a runner that is not ``serial``), a unit of more than
    ``block_points / NORMAL_PARTS`` points (a block, or a tile segmented whole) takes its
    normals from normals tasks, each a part of the unit's points in its k-d tree's order
    with the whole unit's tree: the segments equal those of the one-process run, which
    computes the normals in the unit, point by point."""
    from hollowtree.pipeline.coarse import NORMAL_STAGE, coarse_normals

    params = CoarseParams(eps=0.3, block_points=12_000)  # at 20 m: tiles of 6.7-11 k whole, 14-20 k cut
    with task_runner("sync", progress=False) as run:
        ingest([str(scan)], str(tmp_path / "a"), IngestParams(tile_size=20.0, buffer=2.0), runner=run)
    shutil.copytree(tmp_path / "a", tmp_path / "b")
    ran: list[tuple] = []

    def side_by_side(fn, args_list, desc):
        ran.extend((fn, args) for args in args_list)
        with task_runner("sync", progress=False) as run:
            return run(fn, args_list, desc)

    with task_runner("sync", progress=False) as run:
        run_coarse(str(tmp_path / "a"), params, runner=run)
    run_coarse(str(tmp_path / "b"), params, runner=side_by_side)
    assert np.array_equal(_labels(scan, tmp_path / "a"), _labels(scan, tmp_path / "b"))
    parts = RunStore.open(tmp_path / "b").records(NORMAL_STAGE)
    units = {k.rsplit(".", 1)[0] for k in parts}
    assert any(u.endswith(".w") for u in units)  # whole tiles
    assert any(not u.endswith(".w") for u in units)  # blocks
    assert sum(getattr(fn, "fn", fn) is coarse_normals for fn, _ in ran) == len(parts)
    assert RunStore.open(tmp_path / "a").records(NORMAL_STAGE) == {}  # serial: in the unit


def test_segment_points_holds_no_copy_of_the_points():
    """A tile's points and normals go to Efficient RANSAC as they are (a point without a
    normal has a zero one, which RANSAC leaves out) and the curvature is dropped first:
    traced peak under 330 bytes per point on 200 k points, against 339 when the points
    with a normal were copied for the search (383 before primitives.ransac's own cut;
    275 now)."""
    import tracemalloc

    from hollowtree.primitives.segment import segment_points

    rng = np.random.default_rng(0)
    n = 200_000
    a = rng.random((n, 2)) * 10
    k = rng.integers(0, 3, n)
    zero = np.zeros(n)
    xyz = np.where((k == 0)[:, None], np.c_[a, zero], np.where((k == 1)[:, None], np.c_[a[:, 0], zero, a[:, 1]],
                                                                np.c_[zero, a[:, 0], a[:, 1]]))
    xyz += rng.normal(0, 0.003, xyz.shape)
    tracemalloc.start()
    try:
        segment, fits, _ = segment_points(xyz, CoarseParams(sparse_factor=0), 0.1, np.random.default_rng(0))
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert [f["kind"] for f in fits] == ["plane"] * 3
    assert adjusted_rand_score(k, segment) > 0.95
    assert peak / n < 330, f"{peak / n:.0f} bytes per point"


def test_steps_compose_into_an_export(tiled20, tmp_path, capsys):
    """ingest -> coarse -> labels -> export: the labels step writes what export needs
    (from the coarse segments when the tree never ran, saying so); on a store without
    a coarse stage it is one line, exit 2."""
    import shutil

    import laspy

    store = tmp_path / "s"
    shutil.copytree(tiled20[1], store)
    assert main(["export", str(store), "--las", str(tmp_path / "before.laz"), "--no-progress"]) == 2
    capsys.readouterr()
    assert main(["labels", str(store), "--scheduler", "sync", "--no-progress"]) == 0
    out = capsys.readouterr()
    assert "no complete tree stage" in out.err
    assert "labels:" in out.out
    assert main(["export", str(store), "--las", str(tmp_path / "out.laz"), "--no-progress"]) == 0
    las = laspy.read(tmp_path / "out.laz")
    assert len(las.points) == sum(int(s["point_count"]) for s in RunStore.open(store).attrs["sources"])
    assert (np.asarray(las["segment_id"]) > 0).any()
    capsys.readouterr()
    s = RunStore.open(store, mode="a")
    s.clear_records("coarse")
    s.update_attrs({"stages": {k: v for k, v in s.attrs["stages"].items() if k != "coarse"}})
    assert main(["labels", str(store), "--scheduler", "sync", "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert "no complete coarse stage" in err[0]
