"""Run store I/O of the ingest: compressed fragments read by row range, and the tile
writer that encodes Zarr chunks itself (read back through Zarr)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from hollowtree.tiling.store import CHUNK_POINTS, FRAGMENT_BLOCK_ROWS, RunStore, StoreError


@pytest.fixture
def store(tmp_path) -> RunStore:
    return RunStore.create(tmp_path / "s.zarr", attrs={})


def _rows(n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    dt = np.dtype([("xyz", "<i4", (3,)), ("index", "<u8"), ("core", "?"), ("rgb", "<u2", (3,))])
    rows = np.zeros(n, dt)
    rows["xyz"] = rng.integers(-1000, 1000, (n, 3))
    rows["index"] = rng.permutation(n)
    rows["core"] = rng.random(n) < 0.8
    rows["rgb"] = rng.integers(0, 65535, (n, 3))
    return rows


def test_fragment_row_ranges_across_blocks(store):
    n = 2 * FRAGMENT_BLOCK_ROWS + 123
    rows = _rows(n)
    groups = np.array([[5, 0], [9, 70_000], [np.iinfo(np.int64).max, n]], dtype=np.int64)
    store.write_fragment("m0000000_t0000001", rows, groups)
    assert np.array_equal(store.read_fragment_groups("m0000000_t0000001"), groups)
    cuts = [(0, n), (0, 1), (FRAGMENT_BLOCK_ROWS - 3, FRAGMENT_BLOCK_ROWS + 5),
            (FRAGMENT_BLOCK_ROWS, 2 * FRAGMENT_BLOCK_ROWS), (n - 7, n), (100, 100), (n - 2, n + 50)]
    for a, b in cuts:
        assert np.array_equal(store.read_fragment_rows("m0000000_t0000001", a, b), rows[a:b])
    out = np.empty(10, rows.dtype)
    assert store.read_fragment_rows("m0000000_t0000001", 50, 60, out=out) is out
    assert np.array_equal(out, rows[50:60])
    with pytest.raises(StoreError):
        store.read_fragment_rows("m0000000_t0000001", 50, 61, out=out)
    store.write_fragment("empty", rows[:0], groups[-1:])
    assert len(store.read_fragment_rows("empty", 0, 10)) == 0
    store.delete_fragments(["m0000000_t0000001"])
    store.delete_fragments()
    assert not [p for p in (Path(store.url) / "fragments").iterdir() if p.name != "zarr.json"]


@pytest.mark.parametrize("n_rows", [0, 1, CHUNK_POINTS, 4 * CHUNK_POINTS + 17, 9 * CHUNK_POINTS - 1])
@pytest.mark.parametrize("known", [True, False])
def test_unit_writer_round_trip(store, n_rows, known):
    rng = np.random.default_rng(n_rows)
    data = {"xyz": rng.integers(-5, 5, (n_rows, 3)).astype(np.int32),
            "index": np.arange(n_rows, dtype=np.uint64), "core": rng.random(n_rows) < 0.5,
            "zero": np.zeros(n_rows, np.uint8), "t": rng.random(n_rows)}
    w = store.unit_writer("tiles/0", n_rows=n_rows if known else None)
    at = 0
    for step in (1, 300_000, 1_000_000, 10**9):  # uneven pieces
        w.append({k: v[at:at + step] for k, v in data.items()})
        at += step
        if at >= n_rows:
            break
    w.close({k: v[:0] for k, v in data.items()})
    back = store.read_unit("tiles/0")
    assert back.keys() == data.keys()
    for k, v in data.items():
        assert back[k].dtype == v.dtype, k
        assert np.array_equal(back[k], v), k


def test_unit_writer_refuses_more_rows_than_announced(store):
    w = store.unit_writer("tiles/0", n_rows=5)
    w.append({"a": np.zeros(6, np.int32)})  # held back (under one chunk): checked when written
    with pytest.raises(StoreError, match="more than the 5 rows announced"):
        w.close({})


def test_unit_writer_takes_strided_field_views(store):
    rows = _rows(3 * CHUNK_POINTS + 5, seed=3)
    w = store.unit_writer("tiles/1", n_rows=len(rows))
    for a in range(0, len(rows), 700_000):
        piece = rows[a:a + 700_000]
        w.append({name: piece[name] for name in rows.dtype.names})  # strided views
    w.close({})
    back = store.read_unit("tiles/1")
    for name in rows.dtype.names:
        assert np.array_equal(back[name], rows[name]), name


def test_arrays_are_made_with_few_store_requests(tmp_path):
    """A unit's arrays are made with one metadata object each, not Zarr's probe and
    rewrite of every level above them (each a request on an object store): writing 8
    small arrays into a new group four levels down calls the store 8 times for metadata,
    8 for chunks and a few for the group, where Zarr's create_array made 125 calls.
    Rewriting the unit replaces its arrays (none left of the old ones)."""
    import zarr
    from zarr.storage import LocalStore, LoggingStore

    logged = LoggingStore(LocalStore(tmp_path / "s.zarr"), log_level="DEBUG")
    root = zarr.open_group(store=logged, mode="a")
    root.attrs["schema_version"] = 1
    store = RunStore(root, str(tmp_path / "s.zarr"))
    arrays = {k: np.arange(1000, dtype=np.uint16) * (i + 1) for i, k in enumerate("abcdefgh")}
    logged.counter.clear()
    store.write_unit("labels/parts/3/0", arrays)
    calls = sum(logged.counter.values())
    assert calls <= 32, dict(logged.counter)
    assert logged.counter["set"] == 17  # 8 metadata, 8 chunks, the new group's own
    store.write_unit("labels/parts/3/0", {"b": np.arange(5, dtype=np.int64)})
    assert store.unit_arrays("labels/parts/3/0") == ["b"]
    np.testing.assert_array_equal(store.read_unit("labels/parts/3/0")["b"], np.arange(5))
    writer = store.unit_writer("tiles/5")  # grown with each flush
    writer.append({"xyz": np.ones((3 * CHUNK_POINTS // 2, 3), np.int32)})
    writer.close({"rgb": np.zeros((0, 3), np.uint16)})
    got = store.read_unit("tiles/5")
    assert got["xyz"].shape == (3 * CHUNK_POINTS // 2, 3)
    assert (got["xyz"] == 1).all()
    assert got["rgb"].shape == (0, 3)
    assert got["rgb"].dtype == np.uint16
    assert zarr.open_group(tmp_path / "s.zarr", mode="r")["tiles/5/xyz"].metadata.codecs[1].cname.value == "lz4"


def test_an_array_written_whole_is_one_chunk_of_its_rows_up_to_a_full_chunk(store):
    """A chunk is encoded whole, fill included: a 1 000-row array in a 262 144-row chunk
    would compress a quarter million rows of fill at every write."""
    import zarr

    store.write_unit("g", {"short": np.arange(1000, dtype=np.int32), "xyz": np.ones((10, 3), np.float32),
                           "long": np.zeros(CHUNK_POINTS + 5, np.uint8), "empty": np.zeros(0, np.int64)})
    root = zarr.open_group(store.url, mode="r")
    assert root["g/short"].chunks == (1000,)
    assert root["g/xyz"].chunks == (10, 3)
    assert root["g/long"].chunks == (CHUNK_POINTS,)
    assert root["g/empty"].chunks == (1,)
    got = store.read_unit("g")
    np.testing.assert_array_equal(got["short"], np.arange(1000))
    assert got["long"].shape == (CHUNK_POINTS + 5,)
    assert got["empty"].shape == (0,)
    np.testing.assert_array_equal(store.read_slice("g/short", 990, 1000), np.arange(990, 1000))


def test_a_reset_keeps_the_run_lock_and_says_nothing_of_it(store):
    import warnings

    store.write_unit("tiles/0", {"xyz": np.ones((4, 3), np.int32)})
    lock = Path(store.url) / "run.lock"
    lock.write_text("{}")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        store.reset({"ingest": {}})
    assert lock.read_text() == "{}"
    assert not store.has("tiles/0")
    assert store.has("records")


def test_a_record_says_where_and_how_long_its_unit_ran(store):
    """Each record holds the seconds since its handle was opened or last recorded, the
    process's CPU seconds, the worker (host:pid) and when it finished; ``info`` wins."""
    import time

    t0 = time.time()
    c0 = time.process_time()
    while time.process_time() - c0 < 0.05:  # 50 ms of CPU (and so at least 50 ms of wall time)
        pass
    store.record("tree", "0", {"params_hash": "h"})
    store.record("tree", "1", {"params_hash": "h", "worker": "mine"})
    r0, r1 = store.records("tree")["0"], store.records("tree")["1"]
    assert r0["wall_s"] >= 0.05
    assert r0["cpu_s"] >= 0.04
    assert r1["wall_s"] < r0["wall_s"]  # the clock restarts at each record
    assert r0["worker"].endswith(f":{os.getpid()}")
    assert r1["worker"] == "mine"
    assert t0 <= r0["finished"] <= time.time() + 1


def test_records_skip_a_unit_killed_before_its_record(store, tmp_path, recwarn):
    """A record is one object written after its unit's data: a writer killed before it
    leaves a unit folder without its zarr.json (and a local store's temporary file),
    which counts as not done, without a warning; the other records read whole."""
    store.record("coarse", "3", {"params_hash": "abc", "n_points": 5})
    store.record("coarse", "4", {"params_hash": "abc", "n_points": 7})
    base = tmp_path / "s.zarr" / "records" / "coarse"
    (base / "5").mkdir()  # killed before its zarr.json
    (base / "zarr.0123abcd.partial").write_bytes(b"{")  # killed mid-write
    got = store.records("coarse")
    assert {u: {k: r[k] for k in ("params_hash", "n_points")} for u, r in got.items()} == {
        "3": {"params_hash": "abc", "n_points": 5}, "4": {"params_hash": "abc", "n_points": 7}}
    assert store.records("tree") == {}
    assert not [w for w in recwarn if "not recognized" in str(w.message)]


def test_a_units_arrays_carry_zarrs_own_metadata_for_their_shape_and_dtype(store):
    """``write_unit`` builds each array's metadata from one in-memory template per dtype and
    rank: what it writes must be what Zarr's own ``create_array`` writes for that shape."""
    import zarr
    from zarr.storage import MemoryStore

    from hollowtree.tiling.store import _COMPRESSOR

    arrays = {"f": np.linspace(0, 1, 30).reshape(10, 3), "b": np.array([True, False, True]),
              "u": np.arange(7, dtype=np.uint16), "e": np.zeros((0, 2), np.float32)}
    store.write_unit("tiles/9", arrays)
    root = zarr.open_group(store.url, mode="r")
    for name, values in arrays.items():
        own = zarr.create_array(store=MemoryStore(), shape=values.shape, dtype=values.dtype,
                                chunks=(max(1, len(values)),) + values.shape[1:], compressors=_COMPRESSOR,
                                fill_value=0)
        assert root[f"tiles/9/{name}"].metadata.to_dict() == own.metadata.to_dict(), name
    got = store.read_unit("tiles/9", ["u", "f"])
    assert list(got) == ["u", "f"]
    np.testing.assert_array_equal(got["f"], arrays["f"])
    np.testing.assert_array_equal(store.read_unit("tiles/9")["b"], arrays["b"])
    assert store.read_unit("tiles/9")["e"].shape == (0, 2)
