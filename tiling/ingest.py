"""Ingest: stream point files of any size into the tiles of a run store.

Two phases of independent units, each unit a Dask task scheduled by ``pipeline/graph.py``
(this module never imports Dask; the driver :func:`ingest` takes a ``runner``):

- **map** (one unit per ``chunk_size`` records of one input file): read the records,
  convert coordinates to the store's integer grid, route every point to its core tile and
  to the tiles whose buffer holds it, and write one fragment per tile touched;
- **reduce** (one unit per tile): gather the tile's fragments, sort the points in Morton
  order, optionally keep one representative per voxel, write the tile's arrays. A tile
  above twice the median tile's rows (a scan's density peaks around its stations) is
  reduced in parts instead, runs of its batches written to ``ingest/parts/<tile>/<k>``
  beside the other tiles' units, then copied into the tile's arrays by chunk-aligned
  **copy** units: the same rows in the same order as one unit would write.

Each unit writes its completion record after its data. Rerunning the same ingest skips
recorded units; a different parameter on an existing store is refused. Peak memory is
set by ``chunk_size`` (map) and the largest tile (reduce), never by the scan.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from hollowtree.errors import CorruptInputError
from hollowtree.tiling.grid import TileGrid
from hollowtree.tiling.ingest_plan import (
    IngestParams,
    IngestPlan,
    MapUnit,
    auto_tile_size,
    part_counts,
    plan_ingest,
)
from hollowtree.tiling.kernels import morton_index_order, quantise, route_groups, split_rows
from hollowtree.tiling.readers import (
    PointBlock,
    read_blocks,
)
from hollowtree.tiling.stage import Stage
from hollowtree.tiling.store import CHUNK_POINTS, RunStore, StoreError, check_writable

__all__ = [
    "IngestParams",
    "IngestPlan",
    "MapUnit",
    "plan_ingest",
    "map_chunk",
    "reduce_tile",
    "ingest",
    "IngestReport",
    "Runner",
    "auto_tile_size",
]

STAGE = "ingest"
MAP_STAGE = "ingest.map"
PARTS_STAGE = "ingest.parts"
COPY_STAGE = "ingest.copies"
#: A tile above SPLIT_ABOVE times the median tile's rows is reduced in parts of about the
#: median (at most one per batch), so no reduce unit is far above the median (issue 44).
SPLIT_ABOVE = 2.0
#: Fragments are sorted by SUBCELLS x SUBCELLS x-y sub-cells of their tile; the reduce phase
#: gathers runs of sub-cells up to FLUSH_ROWS rows, so its memory follows that budget (or
#: the densest sub-cell), not the tile: TLS density peaks sharply around each station.
SUBCELLS = 32
#: Rows the reduce phase gathers, sorts and appends at a time (about 60 MB).
FLUSH_ROWS = 1_000_000
_END = np.iinfo(np.int64).max  # sentinel key closing a fragment's group table
#: Layout of the map phase's fragments; map records of another layout are redone.
FRAGMENT_FORMAT = 3

#: ``runner(fn, args_list, desc) -> results`` runs ``fn(*args)`` for every entry (as Dask
#: tasks or in process) and returns the results in order.
Runner = Callable[[Callable[..., Any], Sequence[tuple[Any, ...]], str], list[Any]]



def _row_dtype(fields: dict[str, list[Any]], voxel: bool) -> np.dtype:
    """One fragment row: a point's store fields, plus its core tile where voxels need it."""
    spec: list[Any] = [("xyz", "<i4", (3,)), ("index", "<u8"), ("core", "?")]
    if voxel:
        spec.append(("core_tile", "<i8"))
    for name, (dt, shape) in fields.items():
        spec.append((name, dt, tuple(shape)) if shape else (name, dt))
    return np.dtype(spec)


def subcell_width(tile_size: float, voxel: float | None) -> float:
    """Side of the reduce phase's sub-cells: tile / SUBCELLS, a whole number of voxels.

    Examples
    --------
    >>> subcell_width(20.0, None), subcell_width(20.0, 0.3)
    (0.625, 0.9)
    """
    width = tile_size / SUBCELLS
    if voxel:
        width = voxel * math.ceil(round(width / voxel, 9))
    return round(width, 9)


def fragment_key(map_id: int, tile: int) -> str:
    return f"m{map_id:07d}_t{tile:07d}"


def map_chunk(url: str, unit: MapUnit, plan_attrs: dict[str, Any]) -> dict[str, int]:
    """Map task: route records of ``unit`` to tiles; write fragments, then the record.

    Every fragment holds one tile's rows sorted by x-y sub-cell (then by record), with a
    table of its sub-cells' first rows. Routing and that order come from one compiled
    kernel (tiling/kernels.py). Returns ``{tile: number of points}`` for the tiles this
    unit wrote.
    """
    store = RunStore.open(url, mode="a")
    grid = TileGrid.from_dict(plan_attrs["grid"])
    scale = np.asarray(plan_attrs["coords"]["scale"])
    offset = np.asarray(plan_attrs["coords"]["offset"])
    fields = plan_attrs["fields"]
    voxel = plan_attrs["ingest"]["params"].get("voxel")
    wanted = np.zeros(grid.n_tiles, dtype=bool)
    wanted[plan_attrs["ingest"]["tiles"]] = True
    width = subcell_width(grid.tile_size, voxel)
    dtype = _row_dtype(fields, bool(voxel))
    blocks = list(read_blocks(unit.path, chunk_size=unit.stop - unit.start, start=unit.start, stop=unit.stop))
    n_dropped = sum(b.n_dropped for b in blocks)
    block = blocks[0] if len(blocks) == 1 else PointBlock.concat(blocks)
    f = np.asarray(plan_attrs["coords"].get("metres_per_unit", (1.0, 1.0, 1.0)), dtype=np.float64)
    if np.any(f != 1.0):  # the store holds metres
        block = dataclasses.replace(block, xyz=block.xyz * f)
    counts: dict[str, int] = {}
    if len(block):
        ex, ey = grid.edges()
        core, point, is_core, g_tile, g_key, g_start = route_groups(
            block.xyz[:, 0], block.xyz[:, 1], ex, ey, tile_size=grid.tile_size, buffer=grid.buffer,
            sub_offset=(float(offset[0]), float(offset[1])), sub_width=width, wanted=wanted,
        )
        if np.any(core < 0):  # each point must have one core tile
            raise CorruptInputError(
                f"{unit.path}: points outside the bounds its header gives (records {unit.start}-{unit.stop})"
            )
        # rows in record order (sequential field copies), then whole rows in pair order:
        # measured faster than gathering every field at the pairs' scattered rows
        src = np.empty(len(block), dtype=dtype)
        src["xyz"] = quantise(block.xyz, offset, scale)
        src["index"] = block.index + np.uint64(unit.base)
        if voxel:
            src["core_tile"] = core
        for name in fields:
            values = block.extra.get(name[6:]) if name.startswith("extra.") else getattr(block, name)
            src[name] = 0 if values is None else values
        rows = src.take(point)
        del src
        rows["core"] = is_core
        firsts = np.flatnonzero(np.r_[True, g_tile[1:] != g_tile[:-1]]) if len(g_tile) else np.zeros(0, np.int64)
        for i, f in enumerate(firsts.tolist()):
            last = int(firsts[i + 1]) if i + 1 < len(firsts) else len(g_tile)
            a = int(g_start[f])
            b = int(g_start[last]) if last < len(g_tile) else len(point)
            groups = np.stack([np.r_[g_key[f:last], _END], np.r_[g_start[f:last] - a, b - a]], axis=1)
            t = int(g_tile[f])
            store.write_fragment(fragment_key(unit.map_id, t), rows[a:b], groups)
            counts[str(t)] = b - a
    store.record(MAP_STAGE, str(unit.map_id), {
        "params_hash": plan_attrs["ingest"]["params_hash"], "tiles": counts, "n_dropped": n_dropped,
        "fragment": FRAGMENT_FORMAT,
    })
    return counts


def _voxel_representatives(
    xyz: npt.NDArray[np.int32], index: npt.NDArray[np.uint64], core_tile: npt.NDArray[np.int64],
    *, scale: npt.NDArray[np.float64], voxel: float,
) -> tuple[npt.NDArray[np.bool_], npt.NDArray[np.int64]]:
    """Keep-mask (one point per voxel and core tile: the lowest index) and, for every
    point, the row of its representative.

    The rows are ordered by voxel, core tile and index. Where ``index`` is increasing (the
    reduce's batches are sorted by it) and the voxel and tile numbers fit in 63 bits
    together, that order is a stable sort of one packed integer key: the lexicographic
    sort's order to the row, in 0.58 of its time on a 10 M-point scan's batches (4x faster
    on random points; docs/decisions/speed-and-memory.md, "The voxel sort as one packed key").
    """
    key = np.floor(xyz * (scale / voxel)).astype(np.int64)
    cols = (key[:, 0], key[:, 1], key[:, 2], core_tile)
    packed = _packed_key(cols) if len(index) > 1 and bool(np.all(index[1:] > index[:-1])) else None
    if packed is None:
        order = np.lexsort((index, *cols[::-1]))
        k, c = key[order], core_tile[order]
        first = np.r_[True, np.any(k[1:] != k[:-1], axis=1) | (c[1:] != c[:-1])]
    else:
        order = np.argsort(packed, kind="stable")  # ties stay in index order
        p = packed[order]
        first = np.r_[True, p[1:] != p[:-1]]
    group_first = order[np.flatnonzero(first)]
    rep = np.empty(len(index), dtype=np.int64)
    rep[order] = group_first[np.cumsum(first) - 1]
    keep = np.zeros(len(index), dtype=bool)
    keep[group_first] = True
    return keep, rep


def _packed_key(cols: Sequence[npt.NDArray[np.int64]]) -> npt.NDArray[np.int64] | None:
    """One int64 per row that orders the rows as ``cols`` do lexicographically (first
    column first), or None where their ranges need more than 63 bits together."""
    lows = [int(c.min()) for c in cols]
    bits = [max(1, (int(c.max()) - lo).bit_length()) for c, lo in zip(cols, lows, strict=True)]
    if sum(bits) > 63:
        return None
    packed = np.zeros(len(cols[0]), dtype=np.int64)
    for c, lo, b in zip(cols, lows, bits, strict=True):
        packed <<= b
        packed |= c - lo
    return packed


def tile_batches(tables: dict[str, npt.NDArray[np.int64]]) -> tuple[list[tuple[int, int]], int]:
    """The reduce's batches of a tile, ``(first sub-cell, last sub-cell)`` each, from its
    fragments' sub-cell tables: runs of consecutive sub-cells of at least FLUSH_ROWS rows
    (the last run shorter); and the tile's rows."""
    totals: dict[int, int] = {}
    for groups in tables.values():
        for sub, n in zip(groups[:-1, 0].tolist(), np.diff(groups[:, 1]).tolist(), strict=True):
            totals[sub] = totals.get(sub, 0) + n
    batches: list[tuple[int, int]] = []
    first, acc = None, 0
    for sub in sorted(totals):
        first = sub if first is None else first
        acc += totals[sub]
        if acc >= FLUSH_ROWS:
            batches.append((first, sub))
            first, acc = None, 0
    if first is not None:
        batches.append((first, max(totals)))
    return batches, sum(totals.values())


def reduce_tile(url: str, tile: int, keys: Sequence[str], plan_attrs: dict[str, Any],
                part: tuple[int, int] | None = None) -> int:
    """Reduce task: gather a tile's fragments, Morton-sort, downsample, write, record.

    ``part = (k, parts)``: only the k-th of ``parts`` runs of the tile's batches, written
    to ``ingest/parts/<tile>/<k>`` and recorded as a part; :func:`copy_rows` then makes
    the tile. Returns the number of points written.
    """
    store = RunStore.open(url, mode="a")
    fields = plan_attrs["fields"]
    scale = np.asarray(plan_attrs["coords"]["scale"])
    grid = TileGrid.from_dict(plan_attrs["grid"])
    params = plan_attrs["ingest"]["params"]
    voxel = params.get("voxel")
    dtype = _row_dtype(fields, bool(voxel))
    # Each fragment is sorted by sub-cell. Consecutive sub-cells are gathered into batches
    # of about FLUSH_ROWS rows (one read per fragment and batch), so memory follows the
    # batch (or the densest single sub-cell), never the tile.
    tables = {k: store.read_fragment_groups(k) for k in keys}  # (key, first row) + sentinel
    batches, total = tile_batches(tables)
    if part is not None:  # the part's run of batches, its rows to its own group
        k, n_parts = part
        batches = [b for i, b in enumerate(batches) if i * n_parts // len(batches) == k]
        total = None
    x0, y0, _, _ = grid.buffered_bounds(tile)
    offset = np.asarray(plan_attrs["coords"]["offset"])
    cell = max(1.0, round(0.01 / float(scale.min())))  # 1 cm Morton cells
    names = ["xyz", "index", "core", *fields]
    # Without voxels the tile's length is known: its arrays are made once at full size.
    group = f"tiles/{tile}" if part is None else f"ingest/parts/{tile}/{part[0]}"
    writer = store.unit_writer(group, n_rows=None if voxel else total)
    n_points = n_core = 0
    # One batch is encoded and written (Blosc and file writes release the GIL) while the
    # next is read and sorted: a dense tile's reduce then uses two cores, not one.
    with ThreadPoolExecutor(max_workers=1, thread_name_prefix="tile-writer") as pool:
        pending: Future[None] | None = None
        for lo, hi in batches:
            rows_out, extra = _reduce_batch(store, tables, lo, hi, dtype=dtype, names=names, voxel=voxel,
                                            scale=scale, offset=offset, corner=(x0, y0), cell=cell)
            if pending is not None:
                pending.result()
            pending = pool.submit(writer.append, {**rows_out, **extra})
            n_points += len(rows_out["index"])
            n_core += int(np.count_nonzero(rows_out["core"]))
        if pending is not None:
            pending.result()
    empty = np.zeros(0, dtype=dtype)
    writer.close({**{n: empty[n] for n in names},
                  **({"voxel_dropped": np.zeros(0, np.uint64), "voxel_representative": np.zeros(0, np.uint64)}
                     if voxel else {})})
    info = {"params_hash": plan_attrs["ingest"]["params_hash"], "n_points": n_points, "n_core": n_core}
    if part is not None:  # the fragments stay until the tile is whole
        n_vox = store.array_length(f"{group}/voxel_dropped") if voxel else 0
        store.record(PARTS_STAGE, f"{tile}.{part[0]}", {**info, "parts": part[1], "n_voxel": n_vox})
        return n_points
    store.record(STAGE, str(tile), info)
    store.delete_fragments(keys)
    return n_points


def copy_rows(url: str, tile: int, unit: int, spans: Sequence[tuple[Sequence[str], int, int, Sequence[int]]],
              info: dict[str, Any]) -> int:
    """Copy task: rows ``[first, end)`` of the arrays ``names`` of a tile reduced in parts,
    for every ``(names, first, end, part lengths)`` of ``spans``, from the parts into the
    tile's arrays (made at full length by the driver; ``first`` on a chunk boundary, so
    no two copy units share a chunk). Returns the rows copied.
    """
    store = RunStore.open(url, mode="a")
    n = 0
    for names, first, end, lengths in spans:
        starts = np.r_[0, np.cumsum(lengths)]
        for name in names:
            pieces = []
            for k in range(len(lengths)):
                a, b = max(first, int(starts[k])), min(end, int(starts[k + 1]))
                if a < b:
                    pieces.append(store.read_slice(f"ingest/parts/{tile}/{k}/{name}", a - int(starts[k]), b - int(starts[k])))
            if pieces:
                store.write_slice(f"tiles/{tile}/{name}", first, np.concatenate(pieces))
        n += end - first
    store.record(COPY_STAGE, f"{tile}.{unit}", {**info, "n_points": n})
    return n


def _reduce_batch(
    store: RunStore, tables: dict[str, npt.NDArray[np.int64]], lo: int, hi: int, *, dtype: np.dtype,
    names: list[str], voxel: float | None, scale: npt.NDArray[np.float64], offset: npt.NDArray[np.float64],
    corner: tuple[float, float], cell: float,
) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """The rows of sub-cells ``lo..hi`` of every fragment of a tile, Morton-sorted (and
    voxel-downsampled), as columns; plus the voxel tables."""
    x0, y0 = corner
    spans = []
    for k, groups in tables.items():
        a = int(np.searchsorted(groups[:, 0], lo, side="left"))
        b = int(np.searchsorted(groups[:, 0], hi, side="right"))
        if a < b:  # the sentinel keeps b < len(groups)
            spans.append((k, int(groups[a, 1]), int(groups[b, 1])))
    rows = np.empty(sum(b - a for _, a, b in spans), dtype=dtype)
    at = 0
    for k, a, b in spans:
        store.read_fragment_rows(k, a, b, out=rows[at:at + b - a])
        at += b - a
    index = np.ascontiguousarray(rows["index"])
    extra: dict[str, np.ndarray] = {}
    if voxel:
        perm = np.argsort(index)  # unique within a tile: any sort is stable
        xyz_i, idx_i = np.take(rows["xyz"], perm, axis=0), np.take(index, perm)
        keep, rep = _voxel_representatives(
            xyz_i, idx_i, np.take(rows["core_tile"], perm), scale=scale, voxel=voxel
        )
        dropped = np.take(rows["core"], perm) & ~keep
        extra["voxel_dropped"] = idx_i[dropped]
        extra["voxel_representative"] = idx_i[rep[dropped]]
        perm = perm[keep]
        xyz, index = np.take(rows["xyz"], perm, axis=0), np.take(index, perm)
    else:
        perm = np.arange(len(rows))
        xyz = np.ascontiguousarray(rows["xyz"])
    origin = np.array([(x0 - offset[0]) / scale[0], (y0 - offset[1]) / scale[1],
                       float(xyz[:, 2].min()) if len(xyz) else 0.0])
    # Morton order, equal codes by original index: independent of fragment order
    perm = perm[morton_index_order(xyz, index, origin=origin, cell=cell)]
    return split_rows(rows, names, perm), extra


def _ceil(a: int, b: int) -> int:
    return -(-a // b)


def _join_parts(store: RunStore, tiles: Sequence[int], n_parts: dict[int, int], keys: dict[int, list[str]],
                h: str, runner: Runner) -> None:
    """Make the tiles reduced in parts: their arrays at full length, then copy units of
    about the median part's rows (whole chunks), then each tile's record (its units hold
    the timing) with its parts and fragments removed."""
    if not tiles:
        return
    stage = Stage(store, STAGE, h)
    recs = stage.done(PARTS_STAGE)
    parts = {t: [recs[f"{t}.{k}"] for k in range(n_parts[t])] for t in tiles}
    sizes = [int(r["n_points"]) for t in tiles for r in parts[t] if int(r["n_points"]) > 0]
    step = max(1, round(float(np.median(sizes)) / CHUNK_POINTS)) * CHUNK_POINTS if sizes else CHUNK_POINTS
    copied = stage.done(COPY_STAGE)
    units = []
    for t in tiles:
        plan = [n_parts[t], step]
        done = {u for u, v in copied.items() if v.get("tile") == t and v.get("plan") == plan}
        base = f"ingest/parts/{t}/0"
        names = store.unit_arrays(base)
        families = [[n for n in names if not n.startswith("voxel_")], [n for n in names if n.startswith("voxel_")]]
        lengths = [[int(r["n_points"]) for r in parts[t]], [int(r.get("n_voxel", 0)) for r in parts[t]]]
        n_units = max(1, _ceil(sum(lengths[0]), step))
        if not done:  # else the recorded copy units' chunks are kept
            for fam, lens in zip(families, lengths, strict=True):
                for n in fam:
                    empty = store.read_slice(f"{base}/{n}", 0, 0)
                    store.create_array(f"tiles/{t}/{n}", shape=(sum(lens), *empty.shape[1:]), dtype=empty.dtype,
                                       chunks=CHUNK_POINTS)
        for j in range(n_units):
            spans = []
            for fam, lens in zip(families, lengths, strict=True):
                width = _ceil(_ceil(sum(lens), n_units), CHUNK_POINTS) * CHUNK_POINTS  # whole chunks per unit
                first, end = j * width, min((j + 1) * width, sum(lens))
                if fam and first < end:
                    spans.append((fam, first, end, lens))
            if f"{t}.{j}" not in done:
                units.append((store.url, t, j, spans, {"params_hash": h, "tile": t, "plan": plan}))
    runner(copy_rows, units, "ingest: copy")
    for t in tiles:
        store.record(STAGE, str(t), {"params_hash": h, "n_points": sum(int(r["n_points"]) for r in parts[t]),
                                     "n_core": sum(int(r["n_core"]) for r in parts[t]), "parts": n_parts[t]},
                     timed=False)
        store.delete_fragments(keys[t])
        store.delete(f"ingest/parts/{t}")
    store.delete("ingest/parts")


@dataclass(frozen=True, kw_only=True)
class IngestReport:
    """What an ingest did."""

    store: str
    n_tiles: int
    n_points_in: int
    n_core_points: int
    n_buffer_points: int
    n_dropped: int
    maps_run: int
    maps_skipped: int
    tiles_run: int
    tiles_skipped: int
    seconds: float

    def summary(self) -> str:
        return (
            f"{self.store}: {self.n_tiles} tiles, {self.n_core_points:,} core + "
            f"{self.n_buffer_points:,} buffer points from {self.n_points_in:,} input points "
            f"in {self.seconds:.1f} s; {self.n_dropped:,} records with non-finite coordinates "
            f"dropped (map units run {self.maps_run}, skipped "
            f"{self.maps_skipped}; tiles run {self.tiles_run}, skipped {self.tiles_skipped})"
        )


def _differences(old: dict[str, Any], new: dict[str, Any], prefix: str = "") -> list[str]:
    out = []
    for k in sorted(set(old) | set(new)):
        a, b = old.get(k), new.get(k)
        if isinstance(a, dict) and isinstance(b, dict):
            out += _differences(a, b, f"{prefix}{k}.")
        elif a != b:
            out.append(f"{prefix}{k}: store has {a!r}, this run asks for {b!r}")
    return out


def open_for_ingest(url: str, plan: IngestPlan, *, replace: bool = False) -> RunStore:
    """Create the store, or reopen it to resume the same ingest; refuse another one
    (or, with ``replace``, empty the store and start this one)."""
    attrs = plan.attrs()
    if RunStore.exists(url):
        store = RunStore.open(url, mode="a")
        old = store.attrs.get("ingest", {})
        if old.get("params_hash") != plan.params_hash and replace:
            store.reset(attrs)
            return store
        if old.get("params_hash") != plan.params_hash:
            diffs = _differences(old.get("params", {}), plan.params.to_dict())
            old_src = [(s.get("path"), s.get("size_bytes")) for s in store.attrs.get("sources", [])]
            new_src = [(s.path, s.size_bytes) for s in plan.sources]
            if old_src != new_src:
                diffs.append(f"inputs: store has {[p for p, _ in old_src]}, this run asks for {[p for p, _ in new_src]}")
            what = "; ".join(diffs) if diffs else "the inputs changed"
            raise StoreError(f"store {url} holds another ingest ({what}); use a new store")
        return store
    check_writable(url)
    return RunStore.create(url, attrs=attrs)


def ingest(
    inputs: Sequence[str | Path],
    url: str | Path,
    params: IngestParams,
    *,
    runner: Runner,
    replace: bool = False,
) -> IngestReport:
    """Ingest ``inputs`` into the run store at ``url``, resuming a previous run there.

    Parameters
    ----------
    inputs : sequence of paths
        LAS/LAZ/PLY/E57 files of one registered site, in order (the original index of a
        point is its position in their concatenation).
    url : str or Path
        Local path or fsspec URL of the store.
    params : IngestParams
    runner : callable
        ``runner(fn, args_list, desc)``; see :data:`Runner`.
    replace : bool
        When the store holds an ingest with other parameters or inputs: empty it and
        ingest anew (``hollowtree run`` after a changed parameter) instead of refusing.
    """
    t0 = time.perf_counter()
    url = str(url)
    plan = plan_ingest(inputs, params)
    if not replace and RunStore.exists(url):
        kept = RunStore.open(url).attrs.get("grid")
        if kept and kept != plan.grid.to_dict():  # laid out by another version: resume with its grid
            again = plan_ingest(inputs, params, grid=TileGrid.from_dict(kept))
            if again.params_hash == RunStore.open(url).attrs.get("ingest", {}).get("params_hash"):
                plan = again
    store = open_for_ingest(url, plan, replace=replace)
    attrs = store.attrs
    h = plan.params_hash
    stage = Stage(store, STAGE, h)  # another ingest was refused or replaced by open_for_ingest

    done_maps = stage.done(MAP_STAGE, where=lambda v: v.get("fragment") == FRAGMENT_FORMAT)
    done_tiles = set(stage.done())
    todo_units = [u for u in plan.units if str(u.map_id) not in done_maps]
    # Map units are needed only while some tile is not recorded yet.
    if len(done_tiles) == len(plan.tiles):
        todo_units = []
    results = runner(map_chunk, [(url, u, attrs) for u in todo_units], "ingest: map")
    tiles_of: dict[int, dict[str, int]] = {int(k): v["tiles"] for k, v in done_maps.items()}
    for u, counts in zip(todo_units, results, strict=True):
        tiles_of[u.map_id] = counts
    keys: dict[int, list[str]] = {t: [] for t in plan.tiles}
    for map_id in sorted(tiles_of):
        for t in tiles_of[map_id]:
            if int(t) in keys:
                keys[int(t)].append(fragment_key(map_id, int(t)))
    # Largest tiles first: a scan's density peaks around its stations, so one tile may
    # hold half the points; started last it would run alone while the workers idle.
    rows_of = {t: 0 for t in plan.tiles}
    for counts in tiles_of.values():
        for t, n in counts.items():
            if int(t) in rows_of:
                rows_of[int(t)] += int(n)
    todo_tiles = [t for t in plan.tiles if str(t) not in done_tiles]
    n_parts = part_counts(rows_of, above=SPLIT_ABOVE, cap={t: max(1, _ceil(n, FLUSH_ROWS)) for t, n in rows_of.items()})
    done_parts = stage.done(PARTS_STAGE)
    units = [(url, t, keys[t], attrs) if n_parts[t] == 1 else (url, t, keys[t], attrs, (k, n_parts[t]))
             for t in todo_tiles for k in range(n_parts[t])
             if n_parts[t] == 1 or done_parts.get(f"{t}.{k}", {}).get("parts") != n_parts[t]]
    units.sort(key=lambda u: (-rows_of[u[1]] / n_parts[u[1]], u[1]))
    runner(reduce_tile, units, "ingest: tiles")
    _join_parts(store, [t for t in todo_tiles if n_parts[t] > 1], n_parts, keys, h, runner)
    store.delete_fragments()

    maps = store.records(MAP_STAGE)
    n_dropped = sum(int(v.get("n_dropped", 0)) for v in maps.values() if v.get("params_hash") == h)
    recs = store.records(STAGE)
    n_core = sum(int(recs[str(t)]["n_core"]) for t in plan.tiles)
    n_all = sum(int(recs[str(t)]["n_points"]) for t in plan.tiles)
    stage.finish(len(plan.tiles))
    return IngestReport(
        store=url, n_tiles=len(plan.tiles), n_points_in=sum(s.point_count for s in plan.sources),
        n_core_points=n_core, n_buffer_points=n_all - n_core, n_dropped=n_dropped,
        maps_run=len(todo_units), maps_skipped=len(plan.units) - len(todo_units),
        tiles_run=len(todo_tiles), tiles_skipped=len(plan.tiles) - len(todo_tiles),
        seconds=time.perf_counter() - t0,
    )
