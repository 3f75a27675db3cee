"""Ingest into the run store: round trip, resume after SIGKILL, refusals, bad input."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
import warnings
from pathlib import Path

import laspy
import numpy as np
import pytest

from hollowtree.pipeline.cli import main
from hollowtree.pipeline.graph import task_runner
from hollowtree.scenes.synth import synth
from hollowtree.tiling.grid import TileGrid
from hollowtree.tiling.ingest import IngestParams, ingest
from hollowtree.tiling.store import RunStore, StoreError


@pytest.fixture(scope="module")
def scan_file(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("ingest") / "minaret.laz"
    synth("minaret", out, n_points=60_000, seed=5)
    return out


def _ingest(inputs, store, **kw):
    params = IngestParams(**{"tile_size": 10.0, "buffer": 1.0, "chunk_size": 20_000, **kw})
    with task_runner("sync", progress=False) as run:
        return ingest([str(p) for p in inputs], str(store), params, runner=run)


def _tiles(store_path) -> dict[int, dict[str, np.ndarray]]:
    store = RunStore.open(store_path)
    recs = store.records("ingest")
    return {int(t): store.read_unit(f"tiles/{t}") for t in recs}


def _assert_same_tiles(path_a, path_b) -> None:
    a, b = _tiles(path_a), _tiles(path_b)
    assert a.keys() == b.keys()
    for t in a:
        assert a[t].keys() == b[t].keys()
        for name in a[t]:
            assert np.array_equal(a[t][name], b[t][name]), (t, name)


def test_round_trip(scan_file, tmp_path):
    report = _ingest([scan_file], tmp_path / "s")
    las = laspy.read(scan_file)
    n = len(las.points)
    store = RunStore.open(tmp_path / "s")
    attrs = store.attrs
    grid = TileGrid.from_dict(attrs["grid"])
    scale, offset = np.array(attrs["coords"]["scale"]), np.array(attrs["coords"]["offset"])
    tiles = _tiles(tmp_path / "s")
    assert len(tiles) == grid.n_tiles == report.n_tiles

    core_idx = np.concatenate([t["index"][t["core"]] for t in tiles.values()])
    assert np.array_equal(np.sort(core_idx), np.arange(n, dtype=np.uint64))  # a permutation

    world = np.stack([las.x, las.y, las.z], axis=1)
    pt, tl, is_core = grid.route(world)
    for tid, t in tiles.items():
        xyz = t["xyz"] * scale + offset
        idx = t["index"].astype(np.int64)
        # coordinates within half a scale step of the source, attributes carried along
        assert np.abs(xyz - world[idx]).max() <= 0.5 * las.header.scales.max() + 1e-9
        assert np.array_equal(t["extra.gt_instance"], np.asarray(las.gt_instance)[idx])
        assert np.array_equal(t["intensity"], np.asarray(las.intensity)[idx])
        # the buffer holds exactly the neighbours' points within the buffer width
        expected_buffer = np.sort(pt[(tl == tid) & ~is_core])
        assert np.array_equal(np.sort(idx[~t["core"]]), expected_buffer)
        assert np.array_equal(np.sort(idx[t["core"]]), np.sort(pt[(tl == tid) & is_core]))
        # Morton order within the tile
        if len(xyz) > 100:
            step = np.linalg.norm(np.diff(xyz, axis=0), axis=1).mean()
            shuffled = xyz[np.random.default_rng(0).permutation(len(xyz))]
            assert step < 0.4 * np.linalg.norm(np.diff(shuffled, axis=0), axis=1).mean()


def test_rerun_skips_everything(scan_file, tmp_path):
    _ingest([scan_file], tmp_path / "s")
    again = _ingest([scan_file], tmp_path / "s")
    assert again.tiles_run == 0
    assert again.maps_run == 0
    assert again.tiles_skipped == again.n_tiles


def test_a_store_keeps_the_grid_it_was_made_with(monkeypatch, scan_file, tmp_path):
    """A store laid out by another version's grid rule resumes with its own grid."""
    first = _ingest([scan_file], tmp_path / "s")
    grid = RunStore.open(tmp_path / "s").attrs["grid"]
    covering = TileGrid.covering.__func__

    def shifted(cls, *args, **kw):
        g = covering(cls, *args, **kw)
        return TileGrid(origin=(g.origin[0] - 3.0, g.origin[1]), tile_size=g.tile_size, buffer=g.buffer,
                        shape=(g.shape[0] + 1, g.shape[1]))

    monkeypatch.setattr(TileGrid, "covering", classmethod(shifted))
    again = _ingest([scan_file], tmp_path / "s")
    assert RunStore.open(tmp_path / "s").attrs["grid"] == grid
    assert (again.tiles_run, again.maps_run, again.n_tiles) == (0, 0, first.n_tiles)
    other = _ingest([scan_file], tmp_path / "t")  # a new store takes this version's grid
    assert RunStore.open(tmp_path / "t").attrs["grid"] != grid
    assert other.n_tiles == first.n_tiles + TileGrid.from_dict(grid).shape[1]


def test_tile_origin_puts_the_tile_edges_through_it(scan_file, tmp_path):
    """``ingest.tile_origin``: the edges pass through the point given, every point is in a
    core once, and the store records the key (a store without it keeps its old hash)."""
    plain = _ingest([scan_file], tmp_path / "c")
    at = (3.25, -1.5)
    moved = _ingest([scan_file], tmp_path / "s", tile_origin=at)
    grid = TileGrid.from_dict(RunStore.open(tmp_path / "s").attrs["grid"])
    assert [round((grid.origin[i] - at[i]) / 10.0, 9) % 1 for i in (0, 1)] == [0.0, 0.0]
    assert grid.origin != TileGrid.from_dict(RunStore.open(tmp_path / "c").attrs["grid"]).origin
    cores = sum(int(t["core"].sum()) for t in _tiles(tmp_path / "s").values())
    assert cores == moved.n_core_points == plain.n_core_points == plain.n_points_in
    assert RunStore.open(tmp_path / "s").attrs["ingest"]["params"]["tile_origin"] == list(at)
    assert "tile_origin" not in RunStore.open(tmp_path / "c").attrs["ingest"]["params"]


def test_other_parameters_are_refused(scan_file, tmp_path, capsys):
    _ingest([scan_file], tmp_path / "s")
    code = main(["ingest", str(scan_file), "--store", str(tmp_path / "s"), "--tile-size", "20",
                 "--buffer", "1", "--scheduler", "sync", "--no-progress"])
    err = capsys.readouterr().err
    assert code == 2
    assert "tile_size" in err
    assert "10" in err
    assert "20" in err


def test_replace_ingests_anew_with_the_other_parameters(scan_file, tmp_path):
    """``replace`` (``hollowtree run`` after a changed ingest parameter) empties the store
    and ingests anew: the same tiles as a new store of those parameters."""
    _ingest([scan_file], tmp_path / "s")
    params = IngestParams(tile_size=20.0, buffer=1.0, chunk_size=20_000)
    with task_runner("sync", progress=False) as run:
        ingest([str(scan_file)], str(tmp_path / "s"), params, replace=True, runner=run)
    _ingest([scan_file], tmp_path / "fresh", tile_size=20.0)
    _assert_same_tiles(tmp_path / "s", tmp_path / "fresh")


def test_unknown_schema_version_is_refused(scan_file, tmp_path):
    _ingest([scan_file], tmp_path / "s")
    RunStore.open(tmp_path / "s", mode="a").update_attrs({"schema_version": 99})
    with pytest.raises(StoreError, match="schema_version 99"):
        RunStore.open(tmp_path / "s")


def test_two_files_one_store(tmp_path):
    a, b = tmp_path / "a.laz", tmp_path / "b.laz"
    synth("pillar", a, n_points=8_000, seed=1)
    synth("pillar", b, n_points=8_000, seed=2)
    n = laspy.read(a).header.point_count + laspy.read(b).header.point_count
    _ingest([a, b], tmp_path / "s")
    core = np.concatenate([t["index"][t["core"]] for t in _tiles(tmp_path / "s").values()])
    assert np.array_equal(np.sort(core), np.arange(n, dtype=np.uint64))


def test_voxel_downsampling_maps_every_dropped_point(scan_file, tmp_path):
    _ingest([scan_file], tmp_path / "s", voxel=0.25)
    store = RunStore.open(tmp_path / "s")
    scale = np.array(store.attrs["coords"]["scale"])
    n = laspy.read(scan_file).header.point_count
    kept, dropped = [], []
    for t in _tiles(tmp_path / "s").values():
        kept.append(t["index"][t["core"]])
        dropped.append(t["voxel_dropped"])
        rep = t["voxel_representative"]
        assert np.isin(rep, t["index"][t["core"]]).all()
        # one core point per voxel
        key = np.floor(t["xyz"][t["core"]] * scale / 0.25).astype(np.int64)
        assert len(np.unique(key, axis=0)) == len(key)
    kept, dropped = np.concatenate(kept), np.concatenate(dropped)
    assert len(kept) + len(dropped) == n
    assert np.array_equal(np.sort(np.concatenate([kept, dropped])), np.arange(n, dtype=np.uint64))
    assert len(kept) < 0.8 * n


@pytest.mark.parametrize("spread", [50_000, 2**30])
@pytest.mark.parametrize("sorted_index", [True, False])
def test_voxel_representatives_match_the_lexicographic_sort(spread, sorted_index):
    """The packed-key sort (index increasing, ranges within 63 bits) and the lexicographic
    fallback give the same keep-mask and representatives as a plain lexsort."""
    from hollowtree.tiling.ingest import _voxel_representatives

    rng = np.random.default_rng(spread)
    n = 20_000
    xyz = rng.integers(-spread, spread, (n, 3)).astype(np.int64)
    xyz[: n // 2] %= 100  # many points per voxel (and, with 2**30, ranges beyond 63 bits)
    index = rng.choice(10**9, n, replace=False).astype(np.uint64)
    if sorted_index:
        index.sort()
    core_tile = rng.integers(0, 4, n).astype(np.int64)
    scale, voxel = np.array([0.001, 0.001, 0.002]), 0.02
    keep, rep = _voxel_representatives(xyz, index, core_tile, scale=scale, voxel=voxel)
    key = np.floor(xyz * (scale / voxel)).astype(np.int64)
    order = np.lexsort((index, core_tile, key[:, 2], key[:, 1], key[:, 0]))
    k, c = key[order], core_tile[order]
    first = np.r_[True, np.any(k[1:] != k[:-1], axis=1) | (c[1:] != c[:-1])]
    want = np.empty(n, dtype=np.int64)
    want[order] = order[np.flatnonzero(first)][np.cumsum(first) - 1]
    np.testing.assert_array_equal(rep, want)
    np.testing.assert_array_equal(keep, np.isin(np.arange(n), want))
    assert 0 < keep.sum() < n
    # the representative is the lowest index of its voxel and tile
    low = np.full(n, np.iinfo(np.uint64).max, dtype=np.uint64)
    np.minimum.at(low, want, index)
    np.testing.assert_array_equal(low[want], index[want])


def test_bbox_subset(scan_file, tmp_path):
    las = laspy.read(scan_file)
    x, y = float(np.median(las.x)), float(np.median(las.y))
    rep = _ingest([scan_file], tmp_path / "s", bbox=(x - 1, y - 1, x + 1, y + 1))
    assert 1 <= rep.n_tiles <= 4
    assert len(_tiles(tmp_path / "s")) == rep.n_tiles


def test_bbox_with_chunks_that_miss_the_box(scan_file, tmp_path):
    """Map units whose records all fall outside the chosen tiles write nothing, no crash."""
    las = laspy.read(scan_file)
    x, y = float(las.x.min()), float(las.y.min())
    rep = _ingest([scan_file], tmp_path / "s", bbox=(x, y, x + 0.5, y + 0.5), chunk_size=500)
    assert rep.n_tiles == 1
    (t,) = _tiles(tmp_path / "s").values()
    assert t["core"].sum() == rep.n_core_points > 0


def _run_cli(scan_file, store, *extra):
    return [sys.executable, "-m", "hollowtree", "ingest", str(scan_file), "--store", str(store),
            "--tile-size", "8", "--buffer", "0.5", "--chunk-size", "5000", "--scheduler", "sync",
            "--no-progress", *extra]


def test_killed_ingest_resumes_to_the_same_store(scan_file, tmp_path):
    ref, killed = tmp_path / "ref", tmp_path / "killed"
    subprocess.run(_run_cli(scan_file, ref), check=True, capture_output=True)
    proc = subprocess.Popen(_run_cli(scan_file, killed), stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    records = killed / "records" / "ingest"
    deadline = time.time() + 120
    while time.time() < deadline and proc.poll() is None:
        if records.is_dir() and len(list(records.iterdir())) >= 3:
            os.kill(proc.pid, signal.SIGKILL)
            break
        time.sleep(0.01)
    proc.wait()
    assert proc.returncode == -signal.SIGKILL, "the ingest finished before it could be killed"
    partial = RunStore.open(killed).records("ingest")
    total = RunStore.open(ref).records("ingest")
    assert 0 < len(partial) < len(total)
    out = subprocess.run(_run_cli(scan_file, killed), check=True, capture_output=True, text=True)
    assert f"skipped {len(partial)}" in out.stdout
    _assert_same_tiles(ref, killed)
    assert not list((killed / "fragments").glob("*.npz"))


@pytest.mark.cluster
def test_one_and_two_workers_give_the_same_store(scan_file, tmp_path):
    params = IngestParams(tile_size=10.0, buffer=1.0, chunk_size=20_000)
    with task_runner("sync", progress=False) as run:
        ingest([str(scan_file)], str(tmp_path / "one"), params, runner=run)
    with task_runner(None, workers=2, progress=False) as run:
        ingest([str(scan_file)], str(tmp_path / "two"), params, runner=run)
    _assert_same_tiles(tmp_path / "one", tmp_path / "two")


def _fails(capsys, argv, needle):
    code = main(argv)
    err = capsys.readouterr().err
    assert code == 2, err
    assert needle in err
    assert len(err.strip().splitlines()) == 1, err
    return err


def test_truncated_laz_is_refused_and_nothing_recorded(scan_file, tmp_path, capsys):
    bad = tmp_path / "cut.laz"
    bad.write_bytes(scan_file.read_bytes()[: scan_file.stat().st_size // 2])
    _fails(capsys, ["ingest", str(bad), "--store", str(tmp_path / "s"), "--scheduler", "sync",
                    "--tile-size", "10", "--no-progress"], "cut.laz")
    if (tmp_path / "s").exists():
        assert RunStore.open(tmp_path / "s").records("ingest") == {}


@pytest.mark.parametrize(
    ("args", "needle"),
    [(["--tile-size", "0"], "tile_size"), (["--tile-size", "-5"], "tile_size"),
     (["--buffer", "-1"], "buffer"), (["--tile-size", "10", "--buffer", "80"], "buffer"), (["--voxel", "0"], "voxel"),
     (["--units", "furlong"], "units"), (["--units", "-0.3"], "units")],
)
def test_bad_parameters(scan_file, tmp_path, capsys, args, needle):
    _fails(capsys, ["ingest", str(scan_file), "--store", str(tmp_path / "s"), "--scheduler", "sync",
                    "--no-progress", *args], needle)
    assert not (tmp_path / "s").exists()


def test_unwritable_store(scan_file, tmp_path, capsys):
    blocker = tmp_path / "file.txt"
    blocker.write_text("x")
    _fails(capsys, ["ingest", str(scan_file), "--store", str(blocker / "s"), "--scheduler", "sync",
                    "--no-progress"], "does not exist")


def test_missing_input(tmp_path, capsys):
    _fails(capsys, ["ingest", str(tmp_path / "nope.laz"), "--store", str(tmp_path / "s"),
                    "--scheduler", "sync", "--no-progress"], "nope.laz")
    assert not (tmp_path / "s").exists()


def test_different_crs_is_refused(tmp_path, capsys):
    a, b = tmp_path / "a.laz", tmp_path / "b.laz"
    synth("pillar", a, n_points=5_000, crs="EPSG:32643")
    synth("pillar", b, n_points=5_000, crs="EPSG:32642")
    _fails(capsys, ["ingest", str(a), str(b), "--store", str(tmp_path / "s"), "--scheduler", "sync",
                    "--no-progress"], "coordinate reference systems")
    assert not (tmp_path / "s").exists()


def test_fsspec_url_store(scan_file):
    url = "memory://hollowtree-test-store"
    report = _ingest([scan_file], url)
    store = RunStore.open(url)
    assert len(store.records("ingest")) == report.n_tiles
    n = laspy.read(scan_file).header.point_count
    assert report.n_core_points == n


def test_ply_with_nan_is_dropped_and_counted(tmp_path):
    plyfile = pytest.importorskip("plyfile")
    rng = np.random.default_rng(0)
    pts = rng.uniform(0, 20, (5000, 3))
    pts[::100] = np.nan
    v = np.zeros(len(pts), dtype=[("x", "f8"), ("y", "f8"), ("z", "f8")])
    v["x"], v["y"], v["z"] = pts.T
    path = tmp_path / "p.ply"
    plyfile.PlyData([plyfile.PlyElement.describe(v, "vertex")]).write(str(path))
    report = _ingest([path], tmp_path / "s")
    assert report.n_dropped == 50
    assert report.n_core_points == 4950
    core = np.concatenate([t["index"][t["core"]] for t in _tiles(tmp_path / "s").values()])
    assert not np.isin(np.arange(0, 5000, 100), core).any()
    # float sources are kept at 0.1 mm
    store = RunStore.open(tmp_path / "s")
    scale, offset = np.array(store.attrs["coords"]["scale"]), np.array(store.attrs["coords"]["offset"])
    for t in _tiles(tmp_path / "s").values():
        xyz = t["xyz"] * scale + offset
        assert np.abs(xyz - pts[t["index"].astype(np.int64)]).max() <= 0.00005 + 1e-9


@pytest.mark.cluster
def test_scheduler_address(scan_file, tmp_path):
    from distributed import LocalCluster

    params = IngestParams(tile_size=10.0, buffer=1.0, chunk_size=20_000)
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                      dashboard_address=":0") as cluster:
        with task_runner(cluster.scheduler_address, progress=False) as run:
            report = ingest([str(scan_file)], str(tmp_path / "s"), params, runner=run)
    assert report.n_core_points == laspy.read(scan_file).header.point_count


def test_unreachable_scheduler(scan_file, tmp_path, capsys):
    code = main(["ingest", str(scan_file), "--store", str(tmp_path / "s"), "--scheduler",
                 "tcp://127.0.0.1:9", "--no-progress"])
    err = capsys.readouterr().err
    assert code == 2, err
    assert "scheduler" in err


@pytest.mark.cluster
def test_cli_default_thread_cluster_gives_the_same_store(scan_file, tmp_path):
    """`hollowtree ingest` without --scheduler runs its tasks on worker threads in its own
    process (and tunes that process); the store equals an in-process sync run's."""
    common = [str(scan_file), "--tile-size", "10", "--buffer", "1", "--chunk-size", "20000", "--no-progress"]
    sync = subprocess.run([sys.executable, "-m", "hollowtree", "ingest", "--store", str(tmp_path / "sync"),
                           "--scheduler", "sync", *common], capture_output=True, text=True)
    assert sync.returncode == 0, sync.stderr
    threads = subprocess.run([sys.executable, "-m", "hollowtree", "ingest", "--store", str(tmp_path / "thr"),
                              *common], capture_output=True, text=True)
    assert threads.returncode == 0, threads.stderr
    a, b = _tiles(tmp_path / "sync"), _tiles(tmp_path / "thr")
    assert a.keys() == b.keys()
    for t in a:
        for name in a[t]:
            assert np.array_equal(a[t][name], b[t][name]), (t, name)


def _copy_in(src: Path, out: Path, metres_per_unit: float, crs: str | None) -> None:
    """``src`` with its coordinates in another unit (and that CRS recorded)."""
    import pyproj

    las = laspy.read(src)
    x, y, z = (np.asarray(las.x) / metres_per_unit, np.asarray(las.y) / metres_per_unit,
               np.asarray(las.z) / metres_per_unit)
    with warnings.catch_warnings():  # the old coordinates overflow the new offsets' int32 until replaced
        warnings.simplefilter("ignore", RuntimeWarning)
        las.change_scaling(offsets=np.asarray(las.header.offsets) / metres_per_unit)
    las.x, las.y, las.z = x, y, z
    if crs:
        las.header.add_crs(pyproj.CRS(crs))
    las.write(out)


def test_a_scan_in_feet_is_ingested_in_metres(scan_file, tmp_path):
    """The CRS's linear unit (US survey feet here) converts the coordinates: the store
    holds the metres of the same scan ingested in metres, tiled alike; ``units`` names it
    without a CRS, and overrides one."""
    ft = 1200 / 3937
    _copy_in(scan_file, tmp_path / "ft.las", ft, "EPSG:2227")  # NAD83 / California zone 3 (ftUS)
    _copy_in(scan_file, tmp_path / "bare.las", ft, None)
    _ingest([scan_file], tmp_path / "m")
    _ingest([tmp_path / "ft.las"], tmp_path / "f")
    _ingest([tmp_path / "bare.las"], tmp_path / "b", units="us-ft")
    # no CRS, no units: taken as metres (tiles of as many feet, not ten times the tiles)
    _ingest([tmp_path / "bare.las"], tmp_path / "raw", tile_size=10.0 / ft)

    def metres(name: str) -> tuple[np.ndarray, dict]:
        st = RunStore.open(tmp_path / name)
        c = st.attrs["coords"]
        tiles = list(_tiles(tmp_path / name).values())
        pts = np.concatenate([t["xyz"][t["core"]] * np.asarray(c["scale"]) + np.asarray(c["offset"]) for t in tiles])
        idx = np.concatenate([t["index"][t["core"]] for t in tiles])
        return pts[np.argsort(idx)], st.attrs

    ref, ref_attrs = metres("m")
    for name in ("f", "b"):
        got, attrs = metres(name)
        assert np.abs(got - ref).max() < 2e-3
        assert attrs["grid"]["tile_size"] == ref_attrs["grid"]["tile_size"]
        assert attrs["coords"]["metres_per_unit"] == pytest.approx([ft] * 3)
    assert "US survey foot" in RunStore.open(tmp_path / "f").attrs["coords"]["unit"]
    raw, _ = metres("raw")
    assert np.ptp(raw[:, 2]) == pytest.approx(np.ptp(ref[:, 2]) / ft, rel=1e-3)


def test_a_scan_in_degrees_is_one_line(scan_file, tmp_path, capsys):
    _copy_in(scan_file, tmp_path / "deg.las", 1.0, "EPSG:4326")
    _fails(capsys, ["ingest", str(tmp_path / "deg.las"), "--store", str(tmp_path / "s"), "--scheduler", "sync",
                    "--no-progress"], "coordinates in degrees")
    assert not (tmp_path / "s").exists()


def test_dense_tiles_are_reduced_in_parts_into_the_same_store(monkeypatch, scan_file, tmp_path):
    """A tile above twice the median is reduced in parts of about a batch, then copied
    into the tile in chunk-aligned units; an interrupted copy resumes; the tiles are the
    ones a single unit per tile writes."""
    from hollowtree.pipeline.timing import waves
    from hollowtree.tiling import ingest as ing
    from hollowtree.tiling import store as st

    monkeypatch.setattr(ing, "FLUSH_ROWS", 1_500)
    monkeypatch.setattr(ing, "CHUNK_POINTS", 1_024)
    monkeypatch.setattr(st, "CHUNK_POINTS", 1_024)
    params = IngestParams(tile_size=5.0, buffer=1.0, chunk_size=20_000, voxel=0.02)
    whole, parts = tmp_path / "whole", tmp_path / "parts"
    monkeypatch.setattr(ing, "SPLIT_ABOVE", float("inf"))
    seen = []
    with task_runner("sync", progress=False) as run:
        ingest([str(scan_file)], str(whole), params, runner=run)

        def dies_in_copy(fn, args, desc):  # half the copy units finish, then the run dies
            if desc == "ingest: copy":
                run(fn, args[: len(args) // 2], desc)
                raise KeyboardInterrupt
            return run(fn, args, desc)

        def counting(fn, args, desc):
            seen.append((desc, len(args)))
            return run(fn, args, desc)

        monkeypatch.setattr(ing, "SPLIT_ABOVE", 2.0)
        with pytest.raises(KeyboardInterrupt):
            ingest([str(scan_file)], str(parts), params, runner=dies_in_copy)
        n_copied = len(RunStore.open(parts).records("ingest.copies"))
        assert n_copied > 0
        ingest([str(scan_file)], str(parts), params, runner=counting)
    assert ("ingest: tiles", 0) in seen  # every part was kept
    store = RunStore.open(parts)
    recs = store.records("ingest")
    split = {t: r["parts"] for t, r in recs.items() if "parts" in r}
    assert max(split.values(), default=0) >= 3, split  # the test makes dense tiles
    assert all("wall_s" not in recs[t] for t in split)  # timed by their units
    copies = store.records("ingest.copies")
    assert len(copies) > len(split)
    assert ("ingest: copy", len(copies) - n_copied) in seen
    _assert_same_tiles(whole, parts)
    assert not store.has("ingest/parts")
    # a part is about one batch: the dense tiles' units are cut to the batch size
    tiles = next(w for w in waves({k: store.records(k) for k in ("ingest", "ingest.parts")}) if w.name == "tiles")
    whole_tiles = [int(r["n_points"]) for r in RunStore.open(whole).records("ingest").values()]
    assert max(tiles.points) <= 2 * 1_500 < max(whole_tiles) / 2, (tiles.points, whole_tiles)
