"""The coarse stage: per-tile normals, Efficient RANSAC and DBSCAN, then stitching.

Orchestration only: the numerical work is in ``primitives/`` (pure kernels); this module
reads a tile from the run store, calls the kernels, writes the tile's results and its
completion record (a Dask task per tile, through the ``runner`` of ``pipeline/graph.py``),
and after all tiles joins the tiles' segments across their shared buffer points.

Store layout written here (``docs/store.md``)::

    coarse/tiles/<tile>/primitive   uint8 (n,)   0 none, 1 plane, 2 sphere, 3 cylinder, 4 cone, 5 torus
    coarse/tiles/<tile>/segment     int32 (n,)   tile-local segment, 0 = unsegmented
    coarse/tiles/<tile>/global      uint64 (n,)  global segment of core rows (0 elsewhere)
    coarse/tables/<tile>.parquet                 the tile's segments
    coarse/segments.parquet                      the global segments
    coarse/csr/indices, coarse/csr/offsets       original indices grouped by global segment
"""

from __future__ import annotations

import logging
import os
import tempfile
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from hollowtree.errors import ConfigError, PipelineError
from hollowtree.pipeline.graph import in_child
from hollowtree.primitives.dbscan import window_spacing
from hollowtree.primitives.group import (
    STRIP_FACTOR,
    join_stacked,
    large_segments,
    segment_contacts_chunked,
    set_in_walls,
)
from hollowtree.primitives.ransac import RansacParams
from hollowtree.primitives.score import load_kernels
from hollowtree.primitives.segment import (
    PRIMITIVE_CODES,
    CoarseParams,
    block_inputs,
    join_blocks,
    same_primitive,
    segment_block,
    segment_tile,
)
from hollowtree.primitives.stitch import UnionFind
from hollowtree.tiling.grid import TileGrid
from hollowtree.tiling.stage import Stage, params_hash
from hollowtree.tiling.store import CHUNK_POINTS, RunStore

__all__ = ["CoarseParams", "PRIMITIVE_CODES", "coarse_tile", "run_coarse", "CoarseReport"]

logger = logging.getLogger(__name__)

STAGE = "coarse"
#: Records of the block tasks of tiles above ``block_points`` (unit ``"<tile>.<block>"``).
BLOCK_STAGE = "coarse.blocks"
#: Records of the tiles cut into blocks (:func:`plan_blocks`; unit ``"<tile>"``).
PLAN_STAGE = "coarse.plan"


def _tile_points(store: RunStore, tile: int, scale: np.ndarray) -> dict[str, np.ndarray]:
    d = store.read_unit(f"tiles/{tile}", ["xyz", "core", "index"])
    # Store-local metres: consistent across tiles, so primitive parameters compare.
    d["local"] = d["xyz"].astype(np.float64) * scale
    return d




def _margin(store: RunStore, cfg: dict[str, Any], params: CoarseParams) -> float:
    return (min(float(store.attrs["grid"]["buffer"]), 2.0 * float(cfg["eps"]))
            if params.block_margin is None else float(params.block_margin))


def _block_results_path(tile: int, b: int) -> tuple[str, str]:
    return f"coarse/blocks/{tile}/{b}", f"coarse/block_fits/{tile}/{b}.parquet"


def plan_blocks(url: str, tile: int, cfg: dict[str, Any]) -> int:
    """Dask task: cut a tile above ``block_points`` into blocks, once. Writes each block's
    input (``coarse/block_input/<tile>/<b>``: the tile rows of its context, which of them
    it owns and their stored coordinates), then its record; returns the number of blocks.
    A block task then reads only its own context, not the whole tile."""
    store = RunStore.open(url, mode="a")
    params = CoarseParams.from_dict(cfg["params"])
    raw = store.read_unit(f"tiles/{tile}", ["xyz"])["xyz"]
    scale = np.asarray(store.attrs["coords"]["scale"], dtype=np.float64)
    # Split on the stored integers with their scale (the blocks of the tile's metres,
    # _tile_points, to the bit) and write each block's input as it is made: the task
    # holds the stored coordinates (12 bytes a row) and about 17 bytes a row more during
    # the split, not a float copy of the tile (the 7.9 M rows of the 100 M-point
    # benchmark's densest tile cost about 40 bytes a row with a float copy).
    n_blocks, inputs = block_inputs(raw, params.block_points, _margin(store, cfg, params), scale[:2])
    n_context = 0
    for b, (rows, mine) in enumerate(inputs):
        store.write_unit(f"coarse/block_input/{tile}/{b}", {"rows": rows, "mine": mine, "xyz": raw[rows]})
        n_context += len(rows)
    store.record(PLAN_STAGE, str(tile), {"params_hash": cfg["params_hash"], "n_blocks": n_blocks,
                                         "n_context": n_context})
    return n_blocks


def coarse_block(url: str, tile: int, b: int, cfg: dict[str, Any]) -> dict[str, Any]:
    """Dask task: segment block ``b`` of a tile above ``block_points`` from its input
    (:func:`plan_blocks`); write what the tile's join needs (``coarse/blocks/<tile>/<b>``,
    ``coarse/block_fits/<tile>/<b>.parquet``), then its record."""
    store = RunStore.open(url, mode="a")
    params = CoarseParams.from_dict(cfg["params"])
    scale = np.asarray(store.attrs["coords"]["scale"])
    d = store.read_unit(f"coarse/block_input/{tile}/{b}")
    # The same conversion as the tile's (_tile_points): the same metres, the same answer.
    r = segment_block(d["xyz"].astype(np.float64) * scale, d["rows"], d["mine"], b, params, cfg["eps"], tile)
    arrays, table = _block_results_path(tile, b)
    store.write_unit(arrays, {"own_rows": r["own_rows"].astype(np.int64), "own_seg": r["own_seg"].astype(np.int32),
                              "other_rows": r["other_rows"].astype(np.int64),
                              "other_seg": r["other_seg"].astype(np.int32)})
    _write_table(store, table, pa.table({"kind": [f["kind"] for f in r["fits"]],
                                         "params": [f["params"] for f in r["fits"]],
                                         "rms": [float(f["rms"]) for f in r["fits"]]},
                                        schema=_FIT_SCHEMA))
    info = {"params_hash": cfg["params_hash"], "n_own": int(len(r["own_rows"])), "n_context": int(len(d["rows"])),
            "n_fits": len(r["fits"]), "n_invalid": r["n_invalid"]}
    store.record(BLOCK_STAGE, f"{tile}.{b}", info)
    return info


def _coarse_unit(url: str, tile: int, b: int, cfg: dict[str, Any]) -> dict[str, Any]:
    """Dask task of the stage's first round: block ``b`` of a tile, or (``b`` < 0) a whole tile."""
    return coarse_tile(url, tile, cfg) if b < 0 else coarse_block(url, tile, b, cfg)


def _block_results(store: RunStore, tile: int, n_blocks: int) -> Iterator[dict[str, Any]]:
    """The results of a tile's block tasks, one block at a time (for :func:`join_blocks`)."""
    recs = store.records(BLOCK_STAGE)
    for b in range(n_blocks):
        arrays, table = _block_results_path(tile, b)
        r: dict[str, Any] = dict(store.read_unit(arrays))
        t = _read_table(store, table).to_pydict()
        r["fits"] = [{"kind": k, "params": p, "rms": float(x)}
                     for k, p, x in zip(t["kind"], t["params"], t["rms"], strict=True)]
        r["n_invalid"] = int(recs[f"{tile}.{b}"]["n_invalid"])
        yield r


#: Edge rows (16 bytes each) the stitch keeps of the tiles it matched last (least recently
#: used dropped first): tiles are visited row by row, so a window of about three rows of
#: tiles is reused; a bound, not a grow-with-the-scan cache.
STITCH_CACHE_ROWS = 8_000_000
#: Tile rows read at a time by a tile's table and contacts (:func:`_tile_summary`) and by
#: the stitch (:func:`_stitch`): their memory follows this, not the densest tile. A
#: multiple of the store's chunk, so the stitch writes whole chunks.
READ_ROWS = 4 * CHUNK_POINTS


def _tile_summary(store: RunStore, tile: int, segment: np.ndarray, n_segments: int, scale: np.ndarray,
                  offset: np.ndarray, params: CoarseParams
                  ) -> tuple[dict[str, np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray] | None]:
    """Per segment ``1..n_segments`` of a tile: points, core points, lowest core index and
    world bounding box; and the contacts between its segments (``group_gap > 0``).

    The tile's points are read ``READ_ROWS`` rows at a time, so memory follows that
    and the segments, not the tile (a dense tile near a station holds millions of points).
    The bounding box is taken on the stored integers and converted once: the conversion
    is monotonic, so it equals the box of the converted points.
    """
    m = n_segments + 1
    n_pts = np.zeros(m, dtype=np.int64)
    n_core = np.zeros(m, dtype=np.int64)
    min_index = np.full(m, np.iinfo(np.int64).max, dtype=np.int64)
    lo = np.full((m, 3), np.iinfo(np.int64).max, dtype=np.int64)
    hi = np.full((m, 3), np.iinfo(np.int64).min, dtype=np.int64)
    n = len(segment)

    def chunks() -> Iterator[tuple[np.ndarray, np.ndarray]]:
        for start in range(0, n, READ_ROWS):
            stop = min(start + READ_ROWS, n)
            seg = segment[start:stop].astype(np.int64)
            raw = store.read_slice(f"tiles/{tile}/xyz", start, stop)
            core = store.read_slice(f"tiles/{tile}/core", start, stop).astype(bool)
            index = store.read_slice(f"tiles/{tile}/index", start, stop).astype(np.int64)
            n_pts[:] += np.bincount(seg, minlength=m)
            n_core[:] += np.bincount(seg[core], minlength=m)
            np.minimum.at(min_index, seg[core], index[core])
            for j in range(3):
                col = raw[:, j].astype(np.int64)
                np.minimum.at(lo[:, j], seg, col)
                np.maximum.at(hi[:, j], seg, col)
            # The same metres as the segmentation's (_tile_points), so the same contacts.
            yield raw.astype(np.float64) * scale, seg

    contacts = None
    if params.group_gap > 0:
        contacts = segment_contacts_chunked(chunks(), params.group_gap, min_contacts=params.group_min_contacts)
    else:
        for _ in chunks():
            pass
    sid = np.flatnonzero(n_pts[1:] > 0) + 1
    world_lo = lo[sid].astype(np.float64) * scale + offset
    world_hi = hi[sid].astype(np.float64) * scale + offset
    table = {"segment": sid, "n_points": n_pts[sid], "n_core": n_core[sid],
             "min_index": np.where(n_core[sid] > 0, min_index[sid], -1),
             "xmin": world_lo[:, 0], "ymin": world_lo[:, 1], "zmin": world_lo[:, 2],
             "xmax": world_hi[:, 0], "ymax": world_hi[:, 1], "zmax": world_hi[:, 2]}
    return table, contacts


def coarse_tile(url: str, tile: int, cfg: dict[str, Any], n_blocks: int = 0) -> dict[str, int]:
    """Dask task: segment one tile (or, with ``n_blocks``, join the results of its block
    tasks, :func:`coarse_block`); write its arrays and table, then its record.

    A join holds a few bytes per point of the tile and one block's results at a time
    (:func:`join_blocks`, :func:`_tile_summary`), never the tile's coordinates: a tile
    above ``block_points`` costs its join no more memory than a block task."""
    store = RunStore.open(url, mode="a")
    params = CoarseParams.from_dict(cfg["params"])
    scale = np.asarray(store.attrs["coords"]["scale"])
    offset = np.asarray(store.attrs["coords"]["offset"])
    n = store.array_length(f"tiles/{tile}/index")
    from_tasks = bool(n_blocks)
    if from_tasks:
        segment, fits, n_invalid = join_blocks(n, _block_results(store, tile, n_blocks), params)
    else:
        xyz = _tile_points(store, tile, scale)["local"]
        segment, fits, n_invalid, n_blocks = segment_tile(xyz, params, cfg["eps"], tile, _margin(store, cfg, params))
        del xyz
    segment = segment.astype(np.int32, copy=False)
    kinds = np.array([0] + [PRIMITIVE_CODES.get(f["kind"], 0) for f in fits], dtype=np.uint8)  # free: 0
    store.write_unit(f"coarse/tiles/{tile}", {"primitive": kinds[segment], "segment": segment})
    # One row per local segment: its primitive, point counts, lowest core index, bbox.
    summary, contacts = _tile_summary(store, tile, segment, len(fits), scale, offset, params)
    sid = summary["segment"]
    rows: dict[str, Any] = {
        "tile": np.full(len(sid), tile, dtype=np.int64), "segment": sid,
        "kind": [fits[i - 1]["kind"] for i in sid.tolist()], "params": [fits[i - 1]["params"] for i in sid.tolist()],
        "rms": [float(fits[i - 1]["rms"]) for i in sid.tolist()],
        **{k: summary[k] for k in ("n_points", "n_core", "min_index", "xmin", "ymin", "zmin", "xmax", "ymax", "zmax")},
    }
    _write_table(store, f"coarse/tables/{tile}.parquet", pa.table(rows, schema=_TABLE_SCHEMA))
    n_contacts = 0
    if contacts is not None:
        ca, cb, cn = contacts
        _write_table(store, f"coarse/contacts/{tile}.parquet", pa.table({"a": ca, "b": cb, "n": cn}))
        n_contacts = len(ca)
    info = {
        "params_hash": cfg["params_hash"],
        "n_points": n,
        "n_segments": int(len(sid)),
        "n_unsegmented": int((segment == 0).sum()),
        "n_no_normal": n_invalid,
        "n_blocks": n_blocks,
        "n_contacts": n_contacts,
    }
    store.record(STAGE, str(tile), info)
    if from_tasks:  # the blocks' inputs and results are in the tile's arrays now
        for group in ("blocks", "block_input", "block_of"):  # block_of: stores of before 2026-11-26
            store.delete(f"coarse/{group}/{tile}")
        fs, root = _fs(store)
        if fs.exists(f"{root}/coarse/block_fits/{tile}"):
            fs.rm(f"{root}/coarse/block_fits/{tile}", recursive=True)
    return info


_FIT_SCHEMA = pa.schema([("kind", pa.string()), ("params", pa.string()), ("rms", pa.float64())])

_TABLE_SCHEMA = pa.schema([
    ("tile", pa.int64()), ("segment", pa.int64()), ("kind", pa.string()), ("params", pa.string()),
    ("rms", pa.float64()), ("n_points", pa.int64()), ("n_core", pa.int64()), ("min_index", pa.int64()),
    ("xmin", pa.float64()), ("ymin", pa.float64()), ("zmin", pa.float64()),
    ("xmax", pa.float64()), ("ymax", pa.float64()), ("zmax", pa.float64()),
])


def _fs(store: RunStore) -> tuple[Any, str]:
    import fsspec

    fs, root = fsspec.core.url_to_fs(store.url)
    return fs, root.rstrip("/")


def _write_table(store: RunStore, rel: str, table: pa.Table) -> None:
    fs, root = _fs(store)
    path = f"{root}/{rel}"
    fs.makedirs(path.rsplit("/", 1)[0], exist_ok=True)
    with fs.open(path, "wb") as f:
        pq.write_table(table, f)


def _read_table(store: RunStore, rel: str) -> pa.Table:
    fs, root = _fs(store)
    with fs.open(f"{root}/{rel}", "rb") as f:
        return pq.read_table(f)




@dataclass(frozen=True, kw_only=True)
class CoarseReport:
    store: str
    n_tiles: int
    tiles_run: int
    tiles_skipped: int
    n_tile_segments: int
    n_segments: int
    n_unsegmented: int
    n_no_normal: int
    seconds: float
    eps: float = float("nan")
    stitch_seconds: float = 0.0

    def summary(self) -> str:
        return (
            f"{self.store}: {self.n_segments:,} global segments from {self.n_tile_segments:,} "
            f"tile segments in {self.n_tiles} tiles ({self.tiles_run} run, {self.tiles_skipped} "
            f"skipped); {self.n_unsegmented:,} point copies unsegmented, {self.n_no_normal:,} "
            f"without a normal; DBSCAN eps {self.eps:.3f} m; {self.seconds:.1f} s (stitch "
            f"{self.stitch_seconds:.1f} s)"
        )


def _pwrite_all(fd: int, values: np.ndarray, at: int) -> None:
    """Write ``values``' bytes at byte offset ``at`` of file ``fd``, all of them."""
    view = memoryview(values).cast("B")
    while len(view):
        n = os.pwrite(fd, view, at)
        view, at = view[n:], at + n


def _pread_all(fd: int, size: int, at: int) -> np.ndarray:
    """``size`` bytes from byte offset ``at`` of file ``fd``, as a uint8 array."""
    out = np.empty(size, dtype=np.uint8)
    view, done = memoryview(out), 0
    while done < size:
        chunk = os.pread(fd, size - done, at + done)
        if not chunk:
            raise PipelineError(f"scratch file ended after {done} of {size} bytes")
        view[done:done + len(chunk)] = chunk
        done += len(chunk)
    return out


def _element_groups(store: RunStore, tiles: Sequence[int], keys: list[tuple[int, int]],
                    key_rows: dict[int, list[tuple[int, int]]], info: dict[tuple[int, int], dict[str, Any]],
                    roots: np.ndarray, params: CoarseParams) -> np.ndarray:
    """Group root (a key row) of every key row: stitched segments joined over the tiles'
    contacts (``coarse/contacts/<tile>.parquet``) unless one of the two is a large plane
    or set in a large wall; a segment set in a wall joins it (``CoarseParams.group_set_in``)."""
    n = len(keys)
    # Per stitched segment (root): the primitive of its largest member and its bounding box.
    big_n: dict[int, int] = {}
    kind: dict[int, str] = {}
    plane: dict[int, Any] = {}
    box: dict[int, list[float]] = {}
    for i, r in enumerate(roots.tolist()):
        row = info[keys[i]]
        if row["n_points"] > big_n.get(r, -1):
            big_n[r], kind[r] = row["n_points"], row["kind"]
            plane[r] = row["params"] if row["kind"] == "plane" else "[]"
        b = box.setdefault(r, [np.inf, np.inf, np.inf, -np.inf, -np.inf, -np.inf])
        b[0], b[1], b[2] = min(b[0], row["xmin"]), min(b[1], row["ymin"]), min(b[2], row["zmin"])
        b[3], b[4], b[5] = max(b[3], row["xmax"]), max(b[4], row["ymax"]), max(b[5], row["zmax"])
    large = np.zeros(n, dtype=bool)
    rs = sorted(box)
    if rs:
        large[rs] = large_segments([kind[r] for r in rs], [box[r] for r in rs], params.group_max_plane,
                                   strip_factor=STRIP_FACTOR)
    uf = UnionFind(n)
    uf.union_pairs(np.arange(n, dtype=np.int64), roots.astype(np.int64))
    pairs_a: list[np.ndarray] = []
    pairs_b: list[np.ndarray] = []
    pairs_n: list[np.ndarray] = []
    for t in tiles:
        rel = f"coarse/contacts/{t}.parquet"
        try:
            c = _read_table(store, rel)
        except FileNotFoundError:
            raise PipelineError(f"store {store.url}: tile {t} has no {rel}; rerun `hollowtree coarse`") from None
        a = np.asarray(c.column("a").to_numpy(), dtype=np.int64)
        b = np.asarray(c.column("b").to_numpy(), dtype=np.int64)
        if not len(a):
            continue
        rows = key_rows.get(t, [])
        lut = np.full(max([int(max(a.max(), b.max()))] + [s_ for s_, _ in rows]) + 1, -1, dtype=np.int64)
        for s_, i in rows:
            lut[s_] = i
        ka, kb = lut[a], lut[b]
        ok = (ka >= 0) & (kb >= 0)
        pairs_a.append(roots[ka[ok]])
        pairs_b.append(roots[kb[ok]])
        pairs_n.append(np.asarray(c.column("n").to_numpy(), dtype=np.int64)[ok])
    if not pairs_a:
        return uf.find(np.arange(n))
    ra, rb, cnt = np.concatenate(pairs_a), np.concatenate(pairs_b), np.concatenate(pairs_n)
    wall_of: dict[int, int] = {}
    if params.group_set_in > 0:
        wall_of = set_in_walls(ra, rb, cnt, large, plane, box, np.asarray(store.attrs["coords"]["offset"], np.float64),
                                params.group_set_in)
    set_in = np.zeros(n, dtype=bool)
    set_in[list(wall_of)] = True
    join = ~large[ra] & ~large[rb] & ~set_in[ra] & ~set_in[rb]
    if join.any():
        uf.union_pairs(ra[join], rb[join])
    if wall_of:
        uf.union_pairs(np.asarray(list(wall_of), dtype=np.int64), np.asarray(list(wall_of.values()), dtype=np.int64))
    if params.group_stack > 0:
        join_stacked(uf, large, box, params.group_stack)
    return uf.find(np.arange(n))





def _joined(parts: list[np.ndarray]) -> np.ndarray:
    """``np.concatenate`` of int64 parts, empty for a tile without rows (no parts)."""
    return np.concatenate(parts) if parts else np.zeros(0, dtype=np.int64)


def _stitch(store: RunStore, tiles: Sequence[int], params: CoarseParams) -> tuple[int, int]:
    """Join tile segments over shared buffer points; write global ids, table and CSR."""
    grid = TileGrid.from_dict(store.attrs["grid"])
    tables = [_read_table(store, f"coarse/tables/{t}.parquet").to_pylist() for t in tiles]
    keys = [(r["tile"], r["segment"]) for tab in tables for r in tab]
    info = {k: r for k, r in zip(keys, (r for tab in tables for r in tab), strict=True)}
    # Per tile, local segment id -> row of ``keys`` (a lookup array, not a dict per point).
    key_rows: dict[int, list[tuple[int, int]]] = {}
    for i, (tt, s_) in enumerate(keys):
        key_rows.setdefault(tt, []).append((s_, i))
    uf = UnionFind(len(keys))
    # Every buffer row of a tile is a copy of a core row of one of its 8 neighbours (the
    # same original index). Match them tile pair by tile pair, so that the driver holds
    # one tile's buffer rows and one neighbour's core rows at a time, never the scan.
    present = set(tiles)
    cache: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    scale = np.asarray(store.attrs["coords"]["scale"], dtype=np.float64)
    offset = np.asarray(store.attrs["coords"]["offset"], dtype=np.float64)
    # A core row can be another tile's buffer row only within the buffer of its tile's
    # edge (a little more: the rows were routed before their coordinates were stored).
    reach = float(grid.buffer) + 10.0 * float(scale[:2].max())

    def keys_of(t: int, seg: np.ndarray) -> np.ndarray:
        rows = key_rows.get(t, [])
        lut = np.full(max([int(seg.max(initial=0))] + [s_ for s_, _ in rows]) + 1, -1, dtype=np.int64)
        for s_, i in rows:
            lut[s_] = i
        kid = lut[seg]
        if (kid < 0).any():
            raise PipelineError(f"store {store.url}: tile {t} labels points with a segment its table lacks; "
                                "rerun `hollowtree coarse`")
        return kid

    def pieces(t: int, names: Sequence[str]) -> Iterator[dict[str, np.ndarray]]:
        """Tile ``t``'s rows ``READ_ROWS`` at a time: ``names`` of tiles/<t> and its segment."""
        n = store.array_length(f"coarse/tiles/{t}/segment")
        for start in range(0, n, READ_ROWS):
            stop = min(start + READ_ROWS, n)
            d = {k: store.read_slice(f"tiles/{t}/{k}", start, stop) for k in names}
            d["segment"] = store.read_slice(f"coarse/tiles/{t}/segment", start, stop)
            d["start"] = np.int64(start)
            yield d

    def core_rows(t: int) -> tuple[np.ndarray, np.ndarray]:
        """Original index (sorted) and key row of the segmented core rows of tile ``t``
        near its edge (the only ones a neighbour's buffer can hold)."""
        if t in cache:
            cache[t] = cache.pop(t)  # most recently used last
        else:
            x0, y0, x1, y1 = grid.core_bounds(t)
            idx_parts, key_parts = [], []
            for d in pieces(t, ("core", "index", "xyz")):
                xy = d["xyz"][:, :2].astype(np.float64) * scale[:2] + offset[:2]
                edge = ((xy[:, 0] < x0 + reach) | (xy[:, 0] > x1 - reach)
                        | (xy[:, 1] < y0 + reach) | (xy[:, 1] > y1 - reach))
                m = d["core"].astype(bool) & (d["segment"] > 0) & edge
                idx_parts.append(d["index"][m].astype(np.int64))
                key_parts.append(keys_of(t, d["segment"][m]))
            idx, key = _joined(idx_parts), _joined(key_parts)
            order = np.argsort(idx)
            cache[t] = idx[order], key[order]
            while len(cache) > 1 and sum(len(v[0]) for v in cache.values()) > STITCH_CACHE_ROWS:
                cache.pop(next(iter(cache)))  # least recently used
        return cache[t]

    pair_counts: dict[tuple[int, int], int] = {}
    for t in tiles:
        b_parts, k_parts = [], []
        for d in pieces(t, ("core", "index")):
            m = ~d["core"].astype(bool) & (d["segment"] > 0)
            b_parts.append(d["index"][m].astype(np.int64))
            k_parts.append(keys_of(t, d["segment"][m]))
        b_idx, b_key = _joined(b_parts), _joined(k_parts)
        if not len(b_idx):
            continue
        ix, iy = grid.tile_index(t)
        for jy in (iy - 1, iy, iy + 1):
            for jx in (ix - 1, ix, ix + 1):
                if (jx, jy) == (ix, iy) or not (0 <= jx < grid.shape[0] and 0 <= jy < grid.shape[1]):
                    continue
                n = grid.tile_id(jx, jy)
                if n not in present:
                    continue
                c_idx, c_key = core_rows(n)
                if not len(c_idx):
                    continue
                pos = np.minimum(np.searchsorted(c_idx, b_idx), len(c_idx) - 1)
                hit = c_idx[pos] == b_idx
                if not hit.any():
                    continue
                ka, kb = b_key[hit], c_key[pos[hit]]
                lo, hi = np.minimum(ka, kb), np.maximum(ka, kb)
                code = lo * len(keys) + hi
                u, cnt = np.unique(code[lo != hi], return_counts=True)
                for c_, n_ in zip(u.tolist(), cnt.tolist(), strict=True):
                    k2 = (c_ // len(keys), c_ % len(keys))
                    pair_counts[k2] = pair_counts.get(k2, 0) + n_
    cache.clear()
    sel = [(i, j) for (i, j), n in sorted(pair_counts.items())
           if n >= 3 and same_primitive(info[keys[i]], info[keys[j]], params)]
    if sel:
        arr = np.asarray(sel, dtype=np.int64)
        uf.union_pairs(arr[:, 0], arr[:, 1])
    roots = uf.find(np.arange(len(keys))) if keys else np.zeros(0, np.int64)
    # Global ids 1..G in order of each global segment's lowest core index.
    n_core = np.array([info[k]["n_core"] for k in keys], dtype=np.int64)
    min_index = np.array([info[k]["min_index"] if info[k]["n_core"] else np.iinfo(np.int64).max
                          for k in keys], dtype=np.int64)
    root_min: dict[int, int] = {}
    root_core: dict[int, int] = {}
    for r, m, c in zip(roots.tolist(), min_index.tolist(), n_core.tolist(), strict=True):
        root_min[r] = min(root_min.get(r, m), m)
        root_core[r] = root_core.get(r, 0) + c
    # Element groups: the members of one group get consecutive global ids, so that a
    # group is one run of the CSR (the tree stage's unit). Without grouping every
    # segment is its own group and the order is that of each segment's lowest index.
    group_root = (_element_groups(store, tiles, keys, key_rows, info, roots, params)
                  if params.group_gap > 0 and keys else roots)
    group_min: dict[int, int] = {}
    for r, m in root_min.items():
        if root_core[r] > 0:
            gr = int(group_root[r])
            group_min[gr] = min(group_min.get(gr, m), m)
    live = sorted((group_min[int(group_root[r])], m, r) for r, m in root_min.items() if root_core[r] > 0)
    gid_of_root = {r: g + 1 for g, (_, _, r) in enumerate(live)}
    key_global = np.array([gid_of_root.get(r, 0) for r in roots.tolist()], dtype=np.int64)
    n_segments = len(live)
    group_of_segment = np.zeros(n_segments + 1, dtype=np.int64)
    if live:
        gm = np.array([gmin for gmin, _, _ in live], dtype=np.int64)
        group_of_segment[1:] = np.cumsum(np.r_[True, gm[1:] != gm[:-1]])

    # Per tile: the global id of every core row; counts per global segment for the CSR.
    by_tile: dict[int, list[tuple[int, int]]] = {}
    for (tt, s_), g in zip(keys, key_global.tolist(), strict=True):
        by_tile.setdefault(tt, []).append((s_, g))
    local_to_global: dict[int, np.ndarray] = {}
    for tt, members_tt in by_tile.items():
        lookup = np.zeros(max(s_ for s_, _ in members_tt) + 1, dtype=np.int64)
        for s_, g in members_tt:
            lookup[s_] = g
        local_to_global[tt] = lookup

    def tile_global(t: int, d: dict[str, np.ndarray]) -> np.ndarray:
        seg = d["segment"].astype(np.int64)
        lookup = local_to_global.get(t, np.zeros(1, dtype=np.int64))
        top = int(seg.max(initial=0))
        if top >= len(lookup):  # a segment without a table row: no global id
            lookup = np.r_[lookup, np.zeros(top + 1 - len(lookup), dtype=np.int64)]
        return np.where(d["core"].astype(bool), lookup[seg], 0)

    counts = np.zeros(n_segments + 1, dtype=np.int64)
    for t in tiles:
        for d in pieces(t, ("core",)):
            counts += np.bincount(tile_global(t, d), minlength=n_segments + 1)
    # The CSR (original index and store xyz of every core point, grouped by global
    # segment) is filled through disk-backed scratch arrays, so the driver never holds
    # the scan in memory. Each tile also keeps the CSR position of its core rows. Rows
    # are taken READ_ROWS at a time, in order: within a global segment a tile's rows get
    # consecutive positions in row order, as a stable sort of the whole tile would give.
    offsets = np.r_[0, np.cumsum(counts[1:])].astype(np.int64)
    total = int(offsets[-1])
    with tempfile.TemporaryFile() as scratch_i, tempfile.TemporaryFile() as scratch_x:
        # Positioned writes, not a memory map: mapped pages would count in the driver's
        # resident memory and grow with the scan.
        fd_i, fd_x = scratch_i.fileno(), scratch_x.fileno()
        cursor = offsets[:-1].copy()
        for t in tiles:
            n_rows = store.array_length(f"coarse/tiles/{t}/segment")
            store.create_array(f"coarse/tiles/{t}/global", shape=(n_rows,), dtype=np.uint64)
            store.create_array(f"coarse/tiles/{t}/csr_pos", shape=(n_rows,), dtype=np.int64)
            for d in pieces(t, ("core", "index", "xyz")):
                glob = tile_global(t, d)
                pos = np.full(len(glob), -1, dtype=np.int64)
                rows = np.flatnonzero(glob > 0)
                if len(rows):
                    g = glob[rows]
                    order = np.argsort(g, kind="stable")
                    rows, g = rows[order], g[order]
                    starts = np.flatnonzero(np.r_[True, g[1:] != g[:-1]])
                    ends = np.r_[starts[1:], len(g)]
                    for a, b in zip(starts.tolist(), ends.tolist(), strict=True):
                        gg = int(g[a]) - 1
                        span = np.arange(cursor[gg], cursor[gg] + (b - a))
                        pos[rows[a:b]] = span
                        _pwrite_all(fd_i, np.ascontiguousarray(d["index"][rows[a:b]], dtype=np.uint64),
                                    int(span[0]) * 8)
                        _pwrite_all(fd_x, np.ascontiguousarray(d["xyz"][rows[a:b]], dtype=np.int32),
                                    int(span[0]) * 12)
                        cursor[gg] += b - a
                store.write_slice(f"coarse/tiles/{t}/global", int(d["start"]), glob.astype(np.uint64))
                store.write_slice(f"coarse/tiles/{t}/csr_pos", int(d["start"]), pos)
        store.write_unit("coarse/csr", {"offsets": offsets})
        store.create_array("coarse/csr/indices", shape=(total,), dtype=np.uint64)
        store.create_array("coarse/csr/xyz", shape=(total, 3), dtype=np.int32)
        step = 4 * CHUNK_POINTS  # whole chunks, a few tens of MB at a time
        for a in range(0, total, step):
            m = min(step, total - a)
            store.write_slice("coarse/csr/indices", a, _pread_all(fd_i, m * 8, a * 8).view(np.uint64))
            store.write_slice("coarse/csr/xyz", a, _pread_all(fd_x, m * 12, a * 12).view(np.int32).reshape(m, 3))
    # The global table: one row per global segment (the primitive of its largest member).
    members: dict[int, list[dict[str, Any]]] = {}
    for k, g in zip(keys, key_global.tolist(), strict=True):
        if g:
            members.setdefault(g, []).append(info[k])
    out: dict[str, list[Any]] = {c: [] for c in (
        "segment", "group", "kind", "params", "rms", "n_points", "n_tiles",
        "xmin", "ymin", "zmin", "xmax", "ymax", "zmax")}
    for g in range(1, n_segments + 1):
        ms = members[g]
        big = max(ms, key=lambda r: r["n_points"])
        out["segment"].append(g)
        out["group"].append(int(group_of_segment[g]))
        out["kind"].append(big["kind"])
        out["params"].append(big["params"])
        out["rms"].append(big["rms"])
        out["n_points"].append(int(counts[g]))
        out["n_tiles"].append(len({m["tile"] for m in ms}))
        for c in ("xmin", "ymin", "zmin"):
            out[c].append(min(m[c] for m in ms))
        for c in ("xmax", "ymax", "zmax"):
            out[c].append(max(m[c] for m in ms))
    _write_table(store, "coarse/segments.parquet", pa.table(out))
    return n_segments, len(keys)


# The automatic DBSCAN eps (docs/method.md, "The DBSCAN eps"): EPS_FACTOR x the
# EPS_QUANTILE of the 8-NN spacing, measured on SPACING_WINDOWS windows of WINDOW_ROWS
# consecutive (Morton-sorted, so compact) rows drawn over the whole scan.
EPS_QUANTILE = 0.25
EPS_FACTOR = 9.0
#: A scan whose spacing (as measured for the eps) is above this many metres gets a warning:
#: columns and mouldings 0.3-1 m across need points a few cm apart to be cut out.
MAX_SPACING = 0.5
#: The eps of a scan with no spacing to measure (a handful of points, exact duplicates), m.
FALLBACK_EPS = 0.3
# The version of the stage's code where it changes a result (recorded with a run's
# workflow, so a rerun after such a change redoes the stage). coarse-v2: the eps rule above;
# coarse-v3: segments set in a wall join it, stacked groups join (group_set_in, group_stack);
# coarse-v4: a free segment wider than STRIP_FACTOR x group_max_plane is large;
# coarse-v6 (v5 named a trial that was dropped): a block whose context holds more than
# CONTEXT_FACTOR x block_points is cut again (block_inputs).
COARSE_ALGORITHM = "coarse-v6"
SPACING_WINDOWS = 1024
WINDOW_ROWS = 1024


def scan_spacing(store: RunStore, sizes: dict[int, int], *, seed: int = 0) -> float | None:
    """The scan's point spacing for the automatic eps: the ``EPS_QUANTILE`` of the 8-NN
    distance over ``SPACING_WINDOWS`` windows of ``WINDOW_ROWS`` consecutive tile rows,
    whose starts are drawn uniformly over all the scan's kept points (``sizes``: points
    per tile), so a tile is measured in proportion to its points. Tile rows are
    Morton-sorted, so a window is a compact piece of surface and a point's neighbours are
    its true neighbours. Reads only the windows (a few MB), never a whole tile. None when
    the scan has no spacing to measure: fewer than 9 points, no window with 9 points, or
    nothing but exact duplicates (the caller then falls back to a fixed eps).
    """
    tiles = sorted(t for t, n in sizes.items() if n > 0)
    if sum(sizes[t] for t in tiles) <= 8:
        return None
    counts = np.array([sizes[t] for t in tiles], dtype=np.int64)
    cum = np.r_[0, np.cumsum(counts)]
    rng = np.random.default_rng(np.random.SeedSequence([seed, 8]))
    picks = rng.integers(0, int(cum[-1]), size=SPACING_WINDOWS)
    starts = set()
    for p in picks.tolist():
        i = int(np.searchsorted(cum, p, side="right")) - 1
        n, r = int(counts[i]), p - int(cum[i])
        starts.add((tiles[i], max(0, min(r - WINDOW_ROWS // 2, n - WINDOW_ROWS))))
    scale = np.asarray(store.attrs["coords"]["scale"])

    def windows() -> Any:
        # Windows in row order; each chunk of the tile's arrays is read (decoded) once.
        cached: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = {}
        for t, a in sorted(starts):
            b = min(sizes[t], a + WINDOW_ROWS)
            parts = []
            for c in range(a // CHUNK_POINTS, (b - 1) // CHUNK_POINTS + 1):
                if (t, c) not in cached:
                    if len(cached) >= 2:
                        cached.clear()
                    lo, hi = c * CHUNK_POINTS, min(sizes[t], (c + 1) * CHUNK_POINTS)
                    cached[(t, c)] = (store.read_slice(f"tiles/{t}/xyz", lo, hi),
                                      store.read_slice(f"tiles/{t}/core", lo, hi))
                x, k = cached[(t, c)]
                lo = c * CHUNK_POINTS
                parts.append((x[max(a, lo) - lo:b - lo], k[max(a, lo) - lo:b - lo]))
            xyz = np.concatenate([x for x, _ in parts]).astype(np.float64) * scale
            yield xyz, np.concatenate([k for _, k in parts])

    try:
        return window_spacing(windows(), k=8, quantile=EPS_QUANTILE)
    except ConfigError:  # no distinct neighbours anywhere in the windows
        return None


def run_coarse(url: str, params: CoarseParams, *, runner: Any) -> CoarseReport:
    """Run the coarse stage on an ingested store (resumable per tile), then stitch."""
    t0 = time.perf_counter()
    store = RunStore.open(url, mode="a")
    attrs = store.attrs
    tiles = [int(t) for t in attrs.get("ingest", {}).get("tiles", [])]
    done_ingest = store.records("ingest")
    missing = [t for t in tiles if str(t) not in done_ingest]
    if not tiles or missing:
        raise PipelineError(
            f"store {url}: ingest is not complete ({len(missing)} of {len(tiles)} tiles missing); "
            "rerun `hollowtree ingest` first"
        )
    eps, cluster_epsilon = params.eps, params.cluster_epsilon
    spacing = None
    if eps is None or cluster_epsilon is None:
        sizes = {t: int(done_ingest[str(t)].get("n_points", 0)) for t in tiles}
        spacing = scan_spacing(store, sizes, seed=params.seed)
        if spacing is not None and spacing > MAX_SPACING:
            logger.warning("%s: the scan's points are %.2f m apart (8-NN spacing, 25 %% quantile): hollowtree is "
                           "made for terrestrial scans of buildings, a few cm apart, and will label a scan this "
                           "sparse poorly (an airborne scan? coordinates in another unit? see ingest.units)",
                           url, spacing)
        auto_eps = EPS_FACTOR * spacing if spacing is not None else FALLBACK_EPS
        eps = auto_eps if eps is None else eps
        if cluster_epsilon is None:
            cluster_epsilon = max(0.15, 2.0 * auto_eps / 3.0)
    ransac = RansacParams.from_dict({**params.ransac.to_dict(), "cluster_epsilon": float(cluster_epsilon)})
    params = CoarseParams.from_dict({**params.to_dict(), "ransac": ransac.to_dict(),
                                     "cluster_epsilon": float(cluster_epsilon), "eps": float(eps)})
    cfg = {"params": params.to_dict(), "eps": float(eps), "algorithm": COARSE_ALGORITHM}
    h = params_hash([cfg, attrs["ingest"]["params_hash"]])
    cfg["params_hash"] = h
    stage = Stage(store, STAGE, h, unit_stages=(BLOCK_STAGE, PLAN_STAGE))
    previous = stage.last
    stage.clear_if_changed()  # other parameters: every tile is redone
    done = set(stage.done())
    todo = [t for t in tiles if str(t) not in done]
    # Tiles above block_points are cut into blocks, each a task of its own, so that a
    # task's memory follows block_points rather than the densest tile; a second round
    # joins each such tile's blocks. Largest units first (the longest tasks start first).
    size = {t: int(done_ingest[str(t)].get("n_points", 0)) for t in todo}
    big = [t for t in todo if params.block_points and size[t] > params.block_points]
    planned = {k: int(v["n_blocks"]) for k, v in stage.done(PLAN_STAGE).items()}
    n_blocks = {t: planned[str(t)] for t in big if str(t) in planned}
    unplanned = sorted((t for t in big if t not in n_blocks), key=lambda t: -size[t])
    # Each task in a child process of its worker (in_child): a worker's heap would keep
    # what its earlier tasks left, and a later task peak 80-140 MB above the first.
    n_blocks.update(zip(unplanned, runner(in_child(plan_blocks), [(url, t, cfg) for t in unplanned],
                                          "coarse: blocks"), strict=True))
    blocks_done = set(stage.done(BLOCK_STAGE))
    units = [(size[t], t, -1) for t in todo if t not in n_blocks]
    units += [(size[t] / n_blocks[t], t, b) for t in big for b in range(n_blocks[t]) if f"{t}.{b}" not in blocks_done]
    units.sort(key=lambda u: -u[0])
    runner(in_child(_coarse_unit, load_kernels), [(url, t, b, cfg) for _, t, b in units], "coarse: tiles")
    if big:
        runner(in_child(coarse_tile), [(url, t, cfg, n_blocks[t]) for t in big], "coarse: joins")
    t_stitch = time.perf_counter()
    if not todo and previous.get("params_hash") == h and "n_tile_segments" in previous:
        n_segments, n_keys = int(previous["n_segments"]), int(previous["n_tile_segments"])  # stitched before
    else:
        n_segments, n_keys = _stitch(store, tiles, params)
    t_stitch = time.perf_counter() - t_stitch
    recs = store.records(STAGE)
    stage.finish(len(tiles), eps=float(eps), spacing=spacing, params=params.to_dict(), n_segments=n_segments,
                 n_tile_segments=n_keys)
    return CoarseReport(
        store=url, n_tiles=len(tiles), tiles_run=len(todo), tiles_skipped=len(tiles) - len(todo),
        n_tile_segments=n_keys, n_segments=n_segments,
        n_unsegmented=sum(int(recs[str(t)]["n_unsegmented"]) for t in tiles),
        n_no_normal=sum(int(recs[str(t)]["n_no_normal"]) for t in tiles),
        seconds=time.perf_counter() - t0, eps=float(eps), stitch_seconds=t_stitch,
    )
