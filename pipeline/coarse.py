"""The coarse stage: per-tile normals, Efficient RANSAC and DBSCAN, then stitching.

Orchestration only: the numerical work is in ``primitives/`` (pure kernels); this module
reads a tile from the run store, calls the kernels, writes the tile's results and its
completion record (a Dask task per tile, through the ``runner`` of ``pipeline/graph.py``),
and after all tiles joins the tiles' segments across their shared buffer points.

Store layout written here (``docs/store.md``)::

    coarse/normals/<tile>/<unit>/<part>          a big unit's normals, in parts (deleted with the unit's results)
    coarse/tiles/<tile>/primitive   uint8 (n,)   0 none, 1 plane, 2 sphere, 3 cylinder, 4 cone, 5 torus
    coarse/tiles/<tile>/segment     int32 (n,)   tile-local segment, 0 = unsegmented
    coarse/tiles/<tile>/global      uint64 (n,)  global segment of core rows (0 elsewhere)
    coarse/tables/<tile>.parquet                 the tile's segments
    coarse/segments.parquet                      the global segments
    coarse/csr/indices, coarse/csr/offsets       original indices grouped by global segment
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Iterator
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import pyarrow as pa

from hollowtree.errors import ConfigError, PipelineError
from hollowtree.pipeline.coarse_stitch import READ_ROWS, STITCH_STAGES, EdgeRows, stitch
from hollowtree.pipeline.graph import Task, in_child, run_graph
from hollowtree.pipeline.timing import UNIT_BALANCE, balance, unit_priority
from hollowtree.primitives.dbscan import spacing_quantile, window_distances
from hollowtree.primitives.group import (
    OUTLINE_DIRECTIONS,
    outline_add,
    segment_contacts_chunked,
)
from hollowtree.primitives.normals import estimate_normals
from hollowtree.primitives.score import load_kernels
from hollowtree.primitives.segment import (
    PRIMITIVE_CODES,
    CoarseParams,
    block_inputs,
    join_blocks,
    segment_block,
    segment_tile,
)
from hollowtree.tiling.stage import Stage, params_hash
from hollowtree.tiling.store import CHUNK_POINTS, RunStore

__all__ = ["CoarseParams", "PRIMITIVE_CODES", "balanced_block_points", "coarse_tile", "run_coarse", "CoarseReport"]

logger = logging.getLogger(__name__)

STAGE = "coarse"
#: Records of the block tasks of tiles above ``block_points`` (unit ``"<tile>.<block>"``).
BLOCK_STAGE = "coarse.blocks"
#: Records of the tiles cut into blocks (:func:`plan_blocks`; unit ``"<tile>"``).
PLAN_STAGE = "coarse.plan"
#: Records of the normals tasks (:func:`coarse_normals`; unit ``"<tile>.<block>.<part>"``,
#: block ``w`` for a tile segmented whole).
NORMAL_STAGE = "coarse.normals"
#: Normals tasks per ``block_points`` points of a unit (a block, or a tile segmented
#: whole): a unit's normals are up to about half of its time, and in parts of their own they
#: no longer sit on the longest chain of tasks (plan, block, join). A unit of at most
#: ``block_points / NORMAL_PARTS`` points computes its normals itself.
NORMAL_PARTS = 2


def normal_parts(points: int, cap: int) -> int:
    """Normals tasks of a unit of ``points`` points when blocks hold at most ``cap`` (1:
    the unit computes them itself).

    >>> normal_parts(2_000_000, 2_000_000), normal_parts(2_100_000, 2_000_000), normal_parts(900_000, 2_000_000)
    (2, 3, 1)
    >>> normal_parts(5_000_000, 0)  # no blocks
    1
    """
    return max(1, math.ceil(NORMAL_PARTS * points / cap)) if cap > 0 else 1


def _unit_name(tile: int, b: int) -> str:
    return f"{tile}.{b if b >= 0 else 'w'}"


def _margin(store: RunStore, cfg: dict[str, Any], params: CoarseParams) -> float:
    return (min(float(store.attrs["grid"]["buffer"]), 2.0 * float(cfg["eps"]))
            if params.block_margin is None else float(params.block_margin))


def _block_results_path(tile: int, b: int) -> tuple[str, str]:
    return f"coarse/blocks/{tile}/{b}", f"coarse/block_fits/{tile}/{b}.parquet"


def plan_blocks(url: str, tile: int, cfg: dict[str, Any]) -> list[int]:
    """Dask task: cut a tile above ``block_points`` into blocks, once. Writes each block's
    input (``coarse/block_input/<tile>/<b>``: the tile rows of its context, which of them
    it owns and their stored coordinates), then its record; returns the points of each
    block's context. A block task then reads only its own context, not the whole tile."""
    store = RunStore.open(url, mode="a")
    params = CoarseParams.from_dict(cfg["params"])
    raw = store.read_unit(f"tiles/{tile}", ["xyz"])["xyz"]
    scale = np.asarray(store.attrs["coords"]["scale"], dtype=np.float64)
    # Split on the stored integers with their scale (the blocks of the tile's metres,
    # _unit_xyz, to the bit) and write each block's input as it is made: the task
    # holds the stored coordinates (12 bytes a row) and about 17 bytes a row more during
    # the split, not a float copy of the tile (the 7.9 M rows of the 100 M-point
    # benchmark's densest tile cost about 40 bytes a row with a float copy).
    n_blocks, inputs = block_inputs(raw, params.block_points, _margin(store, cfg, params), scale[:2])
    contexts = []
    for b, (rows, mine) in enumerate(inputs):
        store.write_unit(f"coarse/block_input/{tile}/{b}", {"rows": rows, "mine": mine, "xyz": raw[rows]})
        contexts.append(len(rows))
    store.record(PLAN_STAGE, str(tile), {"params_hash": cfg["params_hash"], "n_blocks": n_blocks,
                                         "n_context": sum(contexts), "contexts": contexts})
    return contexts


def _unit_xyz(store: RunStore, tile: int, b: int) -> np.ndarray:
    """The points a unit segments (store-local metres): block ``b``'s context, or (``b``
    < 0) the whole tile; the same conversion everywhere (the stored integers times the scale), so the
    normals tasks and the unit see the same points to the bit."""
    scale = np.asarray(store.attrs["coords"]["scale"], dtype=np.float64)
    group = f"coarse/block_input/{tile}/{b}" if b >= 0 else f"tiles/{tile}"
    return store.read_unit(group, ["xyz"])["xyz"].astype(np.float64) * scale


def coarse_normals(url: str, tile: int, b: int, part: int, n_parts: int, cfg: dict[str, Any]) -> dict[str, Any]:
    """Dask task: the normals of part ``part`` of ``n_parts`` of a unit's points (block
    ``b`` of a tile, or the whole tile for ``b`` < 0; ``estimate_normals(part=...)``: the
    whole unit's k-d tree, so exactly the normals the unit would compute); writes the rows
    that have one and their normals (``coarse/normals/<tile>/<unit>/<part>``), then its
    record."""
    store = RunStore.open(url, mode="a")
    params = CoarseParams.from_dict(cfg["params"])
    xyz = _unit_xyz(store, tile, b)
    n = len(xyz)
    nr = estimate_normals(xyz, k=params.k, part=(part, n_parts))
    rows = np.flatnonzero(nr.valid)
    store.write_unit(f"coarse/normals/{tile}/{_unit_name(tile, b)}/{part}",
                     {"rows": rows, "normals": nr.normals[rows]})
    info = {"params_hash": cfg["params_hash"], "n_points": n * (part + 1) // n_parts - n * part // n_parts,
            "n_context": n}
    store.record(NORMAL_STAGE, f"{_unit_name(tile, b)}.{part}", info)
    return info


def _unit_normals(store: RunStore, tile: int, b: int, n: int, n_parts: int
                  ) -> tuple[np.ndarray, np.ndarray] | None:
    """A unit's normals and which points have one, from its normals tasks
    (:func:`coarse_normals`); None where it computes them itself (``n_parts`` < 2)."""
    if n_parts < 2:
        return None
    normals = np.zeros((n, 3))
    valid = np.zeros(n, dtype=bool)
    for part in range(n_parts):
        d = store.read_unit(f"coarse/normals/{tile}/{_unit_name(tile, b)}/{part}")
        normals[d["rows"]] = d["normals"]
        valid[d["rows"]] = True
    return normals, valid


def coarse_block(url: str, tile: int, b: int, cfg: dict[str, Any], n_parts: int = 1) -> dict[str, Any]:
    """Dask task: segment block ``b`` of a tile above ``block_points`` from its input
    (:func:`plan_blocks`) and, with ``n_parts`` > 1, its normals tasks' results; write what
    the tile's join needs (``coarse/blocks/<tile>/<b>``, ``coarse/block_fits/<tile>/<b>.parquet``),
    then its record."""
    store = RunStore.open(url, mode="a")
    params = CoarseParams.from_dict(cfg["params"])
    d = store.read_unit(f"coarse/block_input/{tile}/{b}", ["rows", "mine"])
    xyz = _unit_xyz(store, tile, b)  # the same conversion as the tile's: the same metres, the same answer
    r = segment_block(xyz, d["rows"], d["mine"], b, params, cfg["eps"], tile,
                      normals=_unit_normals(store, tile, b, len(xyz), n_parts))
    arrays, table = _block_results_path(tile, b)
    store.write_unit(arrays, {"own_rows": r["own_rows"].astype(np.int64), "own_seg": r["own_seg"].astype(np.int32),
                              "other_rows": r["other_rows"].astype(np.int64),
                              "other_seg": r["other_seg"].astype(np.int32)})
    store.write_table(table, pa.table({"kind": [f["kind"] for f in r["fits"]],
                                         "params": [f["params"] for f in r["fits"]],
                                         "rms": [float(f["rms"]) for f in r["fits"]]},
                                        schema=_FIT_SCHEMA))
    info = {"params_hash": cfg["params_hash"], "n_own": int(len(r["own_rows"])), "n_context": int(len(d["rows"])),
            "n_fits": len(r["fits"]), "n_invalid": r["n_invalid"]}
    store.record(BLOCK_STAGE, f"{tile}.{b}", info)
    return info


def _coarse_unit(url: str, tile: int, b: int, cfg: dict[str, Any], n_parts: int = 1) -> dict[str, Any]:
    """Dask task of the stage's first round: block ``b`` of a tile, or (``b`` < 0) a whole
    tile; ``n_parts`` normals tasks ran before it (1: none)."""
    return coarse_tile(url, tile, cfg, n_parts=n_parts) if b < 0 else coarse_block(url, tile, b, cfg, n_parts)


def _block_results(store: RunStore, tile: int, n_blocks: int) -> Iterator[dict[str, Any]]:
    """The results of a tile's block tasks, one block at a time (for :func:`join_blocks`)."""
    recs = store.records(BLOCK_STAGE)
    for b in range(n_blocks):
        arrays, table = _block_results_path(tile, b)
        r: dict[str, Any] = dict(store.read_unit(arrays))
        t = store.read_table(table).to_pydict()
        r["fits"] = [{"kind": k, "params": p, "rms": float(x)}
                     for k, p, x in zip(t["kind"], t["params"], t["rms"], strict=True)]
        r["n_invalid"] = int(recs[f"{tile}.{b}"]["n_invalid"])
        yield r




def _tile_summary(store: RunStore, tile: int, segment: np.ndarray, n_segments: int, scale: np.ndarray,
                  offset: np.ndarray, params: CoarseParams
                  ) -> tuple[dict[str, np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray] | None]:
    """Per segment ``1..n_segments`` of a tile: points, core points, lowest core index and
    world bounding box and outline in plan (``primitives.group.outline_add``, store-local);
    and the contacts between its segments (``group_gap > 0``). Writes
    the tile's edge rows for the stitch (``coarse/edges/<tile>``, ``EdgeRows``).

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
    out_lo = np.full((m, OUTLINE_DIRECTIONS), np.inf)
    out_hi = np.full((m, OUTLINE_DIRECTIONS), -np.inf)
    n = len(segment)
    edges = EdgeRows(store, tile)

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
            edges.add(raw, core, index, seg)
            for j in range(3):
                col = raw[:, j].astype(np.int64)
                np.minimum.at(lo[:, j], seg, col)
                np.maximum.at(hi[:, j], seg, col)
            # The same metres as the segmentation's (_unit_xyz), so the same contacts.
            xyz = raw.astype(np.float64) * scale
            outline_add(out_lo, out_hi, xyz, seg)
            yield xyz, seg

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
             "xmax": world_hi[:, 0], "ymax": world_hi[:, 1], "zmax": world_hi[:, 2],
             "outline": np.hstack([out_lo[sid], out_hi[sid]]).tolist()}  # store-local metres
    store.write_unit(f"coarse/edges/{tile}", edges.arrays())  # for the stitch
    return table, contacts


def coarse_tile(url: str, tile: int, cfg: dict[str, Any], n_blocks: int = 0, n_parts: int = 1) -> dict[str, int]:
    """Dask task: segment one tile (with ``n_parts`` > 1, from its normals tasks' results),
    or, with ``n_blocks``, join the results of its block tasks (:func:`coarse_block`);
    write its arrays and table, then its record.

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
        xyz = _unit_xyz(store, tile, -1)
        segment, fits, n_invalid, n_blocks = segment_tile(xyz, params, cfg["eps"], tile, _margin(store, cfg, params),
                                                          normals=_unit_normals(store, tile, -1, len(xyz), n_parts))
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
        **{k: summary[k] for k in ("n_points", "n_core", "min_index", "xmin", "ymin", "zmin", "xmax", "ymax", "zmax",
                                   "outline")},
    }
    store.write_table(f"coarse/tables/{tile}.parquet", pa.table(rows, schema=_TABLE_SCHEMA))
    n_contacts = 0
    if contacts is not None:
        ca, cb, cn = contacts
        store.write_table(f"coarse/contacts/{tile}.parquet", pa.table({"a": ca, "b": cb, "n": cn}))
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
    # The blocks' inputs and results and the units' normals are in the tile's arrays now.
    for group in ("blocks", "block_input", "block_of", "normals"):  # block_of: older stores
        store.delete(f"coarse/{group}/{tile}")
    if from_tasks:
        store.delete_files(f"coarse/block_fits/{tile}")
    return info


_FIT_SCHEMA = pa.schema([("kind", pa.string()), ("params", pa.string()), ("rms", pa.float64())])

_TABLE_SCHEMA = pa.schema([
    ("tile", pa.int64()), ("segment", pa.int64()), ("kind", pa.string()), ("params", pa.string()),
    ("rms", pa.float64()), ("n_points", pa.int64()), ("n_core", pa.int64()), ("min_index", pa.int64()),
    ("xmin", pa.float64()), ("ymin", pa.float64()), ("zmin", pa.float64()),
    ("xmax", pa.float64()), ("ymax", pa.float64()), ("zmax", pa.float64()),
    ("outline", pa.list_(pa.float64())),
])


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
# CONTEXT_FACTOR x block_points is cut again (block_inputs); coarse-v7: a small free
# cluster that spans free_min_cells cells is a segment; coarse-v8: set in a wall by the
# segment's outline (primitives.group.OUTLINE_DIRECTIONS), not its bounding box.
COARSE_ALGORITHM = "coarse-v8"
SPACING_WINDOWS = 1024
WINDOW_ROWS = 1024


#: Tasks the spacing's windows are measured in (:func:`scan_spacing`): consecutive runs of
#: the windows in tile and row order, of equal counts, so no task stands out.
SPACING_UNITS = 16
#: Records of the spacing's tasks (unit ``"<k>"``): their timing, for the predictor.
SPACING_STAGE = "coarse.spacing"


def _spacing_windows(sizes: dict[int, int], seed: int) -> list[tuple[int, int]]:
    """The windows of :func:`scan_spacing`: ``(tile, first row)``, in tile and row order."""
    tiles = sorted(t for t, n in sizes.items() if n > 0)
    counts = np.array([sizes[t] for t in tiles], dtype=np.int64)
    cum = np.r_[0, np.cumsum(counts)]
    rng = np.random.default_rng(np.random.SeedSequence([seed, 8]))
    picks = rng.integers(0, int(cum[-1]), size=SPACING_WINDOWS)
    starts = set()
    for p in picks.tolist():
        i = int(np.searchsorted(cum, p, side="right")) - 1
        n, r = int(counts[i]), p - int(cum[i])
        starts.add((tiles[i], max(0, min(r - WINDOW_ROWS // 2, n - WINDOW_ROWS))))
    return sorted(starts)


def window_distances_task(url: str, k: int, windows: list[tuple[int, int]], sizes: dict[int, int]) -> np.ndarray:
    """Dask task: the 8-NN distances of the core rows of ``windows`` (``(tile, first
    row)`` each, :func:`_spacing_windows`), reading each chunk of a tile's arrays once;
    records its timing as unit ``k`` of ``SPACING_STAGE``."""
    store = RunStore.open(url, mode="a")
    scale = np.asarray(store.attrs["coords"]["scale"])

    def read() -> Any:
        cached: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = {}
        for t, a in windows:
            b = min(sizes[t], a + WINDOW_ROWS)
            parts = []
            for c in range(a // CHUNK_POINTS, (b - 1) // CHUNK_POINTS + 1):
                if (t, c) not in cached:
                    if len(cached) >= 2:
                        cached.clear()
                    lo, hi = c * CHUNK_POINTS, min(sizes[t], (c + 1) * CHUNK_POINTS)
                    cached[(t, c)] = (store.read_slice(f"tiles/{t}/xyz", lo, hi),
                                      store.read_slice(f"tiles/{t}/core", lo, hi))
                x, m = cached[(t, c)]
                lo = c * CHUNK_POINTS
                parts.append((x[max(a, lo) - lo:b - lo], m[max(a, lo) - lo:b - lo]))
            yield (np.concatenate([x for x, _ in parts]).astype(np.float64) * scale,
                   np.concatenate([m for _, m in parts]))

    d = window_distances(read(), k=8)
    store.record(SPACING_STAGE, str(k), {"n_points": len(windows) * WINDOW_ROWS, "n_windows": len(windows)})
    return d


def scan_spacing(store: RunStore, sizes: dict[int, int], *, seed: int = 0, runner: Any = None) -> float | None:
    """The scan's point spacing for the automatic eps: the ``EPS_QUANTILE`` of the 8-NN
    distance over ``SPACING_WINDOWS`` windows of ``WINDOW_ROWS`` consecutive tile rows,
    whose starts are drawn uniformly over all the scan's kept points (``sizes``: points
    per tile), so a tile is measured in proportion to its points. Tile rows are
    Morton-sorted, so a window is a compact piece of surface and a point's neighbours are
    its true neighbours. Reads only the windows (a few MB), never a whole tile; the
    windows are measured in ``SPACING_UNITS`` tasks of ``runner`` (in this process
    without one) and their distances pooled: the same value as one pass over them all.
    None when the scan has no spacing to measure: fewer than 9 points, no window with 9
    points, or nothing but exact duplicates (the caller then falls back to a fixed eps).
    """
    if sum(n for n in sizes.values() if n > 0) <= 8:
        return None
    windows = _spacing_windows(sizes, seed)
    n_units = min(SPACING_UNITS, len(windows))
    units = [(store.url, k, windows[k * len(windows) // n_units:(k + 1) * len(windows) // n_units], sizes)
             for k in range(n_units)]
    if runner is None:
        found = [window_distances_task(*u) for u in units]
    else:
        found = runner(window_distances_task, units, "coarse: spacing")
    try:
        return spacing_quantile(found, k=8, quantile=EPS_QUANTILE)
    except ConfigError:  # no distinct neighbours anywhere in the windows
        return None


def _first_round(sizes: list[int], cap: int) -> list[float]:
    """The points of the first round's units when tiles above ``cap`` are cut into blocks:
    median cuts (``primitives.blocks.split_blocks``) make ``2**k`` blocks of about
    ``n / 2**k`` points of a tile of ``n``, ``k = ceil(log2(n / cap))``."""
    out: list[float] = []
    for n in sizes:
        k = math.ceil(math.log2(n / cap)) if n > cap else 0
        out += [n / 2**k] * 2**k
    return out


def balanced_block_points(sizes: list[int], block_points: int, *, limit: float = UNIT_BALANCE) -> int:
    """The block size of a run (issue 44): ``block_points``, or less where tiles near it
    would stand beside units far smaller, so that the stage's first round (a unit per tile
    at or below the block size, one per block above it) holds no unit above about
    ``limit`` times the median unit's points.

    From the tiles' points (``sizes``; tiles without points are no work and left out),
    the largest size from ``block_points`` down in steps of a tenth, to ``block_points / 8``,
    whose predicted units (:func:`_first_round`) are within ``0.8 * limit``; the one with
    the smallest ratio where none is. A scan whose tiles are alike keeps ``block_points``.

    >>> balanced_block_points([47_559, 51_595, 118_922, 783_473], 2_200_000)
    366894
    >>> balanced_block_points([900_000, 1_000_000, 1_100_000, 0], 2_200_000)
    2200000
    """
    pts = [int(n) for n in sizes if n > 0]
    if not block_points or not pts:
        return block_points
    best: tuple[float, int] | None = None
    cap = int(block_points)
    while cap >= max(block_points // 8, 1):
        ratio = balance(_first_round(pts, cap)) or 1.0
        if ratio <= 0.8 * limit:
            return cap
        if best is None or ratio < best[0]:
            best = (ratio, cap)
        cap = int(cap * 0.9)
    return best[1] if best else block_points


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
        spacing = scan_spacing(store, sizes, seed=params.seed, runner=runner)
        if spacing is not None and spacing > MAX_SPACING:
            logger.warning("%s: the scan's points are %.2f m apart (8-NN spacing, 25 %% quantile): hollowtree is "
                           "made for terrestrial scans of buildings, a few cm apart, and will label a scan this "
                           "sparse poorly (an airborne scan? coordinates in another unit? see ingest.units)",
                           url, spacing)
        auto_eps = EPS_FACTOR * spacing if spacing is not None else FALLBACK_EPS
        eps = auto_eps if eps is None else eps
        if cluster_epsilon is None:
            cluster_epsilon = max(0.15, 2.0 * auto_eps / 3.0)
    # Blocks sized by the tiles' points, like eps by the scan's spacing: a derived parameter.
    cap = balanced_block_points([int(done_ingest[str(t)].get("n_points", 0)) for t in tiles], params.block_points)
    params = replace(params, cluster_epsilon=float(cluster_epsilon), eps=float(eps), block_points=cap)
    cfg = {"params": params.to_dict(), "eps": float(eps), "algorithm": COARSE_ALGORITHM}
    h = params_hash([cfg, attrs["ingest"]["params_hash"]])
    cfg["params_hash"] = h
    stage = Stage(store, STAGE, h, unit_stages=(BLOCK_STAGE, PLAN_STAGE, NORMAL_STAGE, *STITCH_STAGES))
    previous = stage.last
    stage.clear_if_changed()  # other parameters: every tile is redone
    done = set(stage.done())
    todo = [t for t in tiles if str(t) not in done]
    # Tiles above block_points are cut into blocks, each a task of its own, so that a
    # task's memory follows block_points rather than the densest tile; a join task then
    # makes the tile from its blocks. One graph of tasks (run_graph): a big tile's blocks
    # start when its plan ends and its join when its blocks do, beside the other tiles'
    # tasks, never waiting for a whole wave (pipeline.timing.PIPELINED). Each task runs
    # in a child process of its worker (in_child): a worker's heap would keep what its
    # earlier tasks left, and a later task peak 80-140 MB above the first. Per tile:
    # [plan] -> normals parts -> units (its blocks, or the whole tile) -> [join].
    size = {t: int(done_ingest[str(t)].get("n_points", 0)) for t in todo}
    big = [t for t in todo if params.block_points and size[t] > params.block_points]
    contexts: dict[int, list[int]] = {}  # a cut tile's blocks' context points
    for k, v in stage.done(PLAN_STAGE).items():
        if int(k) in size:
            contexts[int(k)] = [int(c) for c in v["contexts"]] if "contexts" in v else [
                store.array_length(f"coarse/block_input/{k}/{b}/rows") for b in range(int(v["n_blocks"]))]
    blocks_done = set(stage.done(BLOCK_STAGE))
    normals_done = set(stage.done(NORMAL_STAGE))
    # Units of many points compute their normals in tasks of their own first (NORMAL_PARTS),
    # where tasks run side by side; one task at a time (in process, one worker) that would
    # only repeat the k-d trees.
    split = not getattr(runner, "serial", False)
    plan_fn, unit_fn, join_fn = in_child(plan_blocks), in_child(_coarse_unit, load_kernels), in_child(coarse_tile)
    normals_fn = in_child(coarse_normals)
    left: dict[int, int] = {}  # tasks of a tile's current step not ended yet

    def parts(t: int, b: int) -> int:
        return normal_parts(contexts[t][b] if b >= 0 else size[t], params.block_points) if split else 1

    def units(t: int) -> list[int]:  # a tile's units not recorded: its blocks, or the tile (-1)
        return [b for b in range(len(contexts[t])) if f"{t}.{b}" not in blocks_done] if t in contexts else [-1]

    def normals(t: int) -> list[Task]:
        """A tile's normals tasks not recorded, or (none) its next step."""
        tasks = [Task(normals_fn, (url, t, b, i, parts(t, b), cfg), unit_priority(STAGE, "normals", size[t]),
                      ("normals", t), "coarse: normals")
                 for b in units(t) for i in range(parts(t, b) if parts(t, b) > 1 else 0)
                 if f"{_unit_name(t, b)}.{i}" not in normals_done]
        left[t] = len(tasks)
        return tasks or segment(t)

    def segment(t: int) -> list[Task]:
        """A tile's units not recorded (they go by their tile's points: the tile ends only
        when its last block does, pipeline.timing.unit_priority), or (none) its join."""
        todo_u = units(t)
        left[t] = len(todo_u)
        return [Task(unit_fn, (url, t, b, cfg, parts(t, b)), unit_priority(STAGE, "tiles", size[t]),
                     ("unit", t, b), "coarse: tiles") for b in todo_u] or [
            Task(join_fn, (url, t, cfg, len(contexts[t])), unit_priority(STAGE, "joins", size[t]), ("join", t),
                 "coarse: joins")]

    def then(tag: tuple[Any, ...], result: Any) -> list[Task]:
        kind, t = tag[0], tag[1]
        if kind == "plan":
            contexts[t] = [int(c) for c in result]
            return normals(t)
        if kind in ("normals", "unit"):
            left[t] -= 1
            if left[t]:
                return []
            if kind == "normals":
                return segment(t)
            if t in contexts:  # a cut tile's blocks are all recorded: its join
                blocks_done.update(f"{t}.{b}" for b in range(len(contexts[t])))
                return segment(t)
        return []

    first = [Task(plan_fn, (url, t, cfg), unit_priority(STAGE, "plan", size[t]), ("plan", t), "coarse: blocks")
             for t in big if t not in contexts]
    for t in todo:
        if t not in big or t in contexts:
            first += normals(t)
    run_graph(runner, first, then, "coarse: tiles")
    t_stitch = time.perf_counter()
    if not todo and previous.get("params_hash") == h and "n_tile_segments" in previous:
        n_segments, n_keys = int(previous["n_segments"]), int(previous["n_tile_segments"])  # stitched before
    else:
        n_segments, n_keys = stitch(store, tiles, params, runner=runner, h=h)
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
