"""The labels stage: per input point, in the input's own order, what the run found.

Two phases of Dask tasks, each unit recorded after its data like every other stage:

1. ``labels: tiles`` (one task per tile, or per row slice of a tile far above the median:
   :func:`plan_slices`, so that units are balanced by points, issue 44): the slice's core
   rows get their coarse primitive
   and global segment (coarse stage) and their tree leaf, class, instance and score (tree
   stage, found through the row's CSR position); points dropped by voxel downsampling take
   their representative's labels (the representative is a core row of the same tile; a
   slice takes the dropped points whose representative is among its rows), looked up in
   the core rows' parts, two parts held at a time. The points are written as parts of at
   most ``PART_ROWS`` points, each sorted by original index
   (``labels/parts/<tile>/<slice>/<j>``: first the core rows', then the dropped points'), so
   the task's memory does not grow with the tile; the record (``<tile>.<slice>``) keeps its
   rows and, for every part and output range, which rows of the part fall in it.
2. ``labels: ranges`` (one task per range of ``RANGE_ROWS`` input points, whole chunks):
   the parts' rows of the range are gathered and written to ``labels/<name>`` at their
   original index. Ranges never share a chunk, so tasks never race.

Arrays written (``docs/store.md``), each of length = the number of input points::

    labels/class      uint8    the class vocabulary (hollowtree/classes.py); 0 = not labelled
    labels/instance   uint32   element instance (or planar instance: one per planar class and element group), unique in the store; 0 = none
    labels/segment    uint64   tree leaf: global coarse segment << 20 | leaf node id; 0 = none
    labels/score      float32  the classifier's score of the point's class
    labels/primitive  uint8    coarse primitive (pipeline/coarse.py PRIMITIVE_CODES); 0 = none

Points outside the ingested tiles (a run limited by ``bbox`` or ``tiles``) and points in
no coarse segment keep 0 everywhere.

A sparse scan (points more than ``MAX_SPACING`` apart: an airborne scan) takes its ground
from the terrain filter (``primitives/terrain.py``, SMRF) run on each whole tile: those
points are class ground, instance 0, whatever the tree said.
"""

from __future__ import annotations

import time
from collections import OrderedDict
from dataclasses import dataclass
from typing import Any

import numpy as np

from hollowtree.classes import NUM_CLASSES, ClassId
from hollowtree.errors import PipelineError
from hollowtree.pipeline.coarse import MAX_SPACING
from hollowtree.pipeline.graph import in_child
from hollowtree.pipeline.tree_stage import MERGE_CLASS_MAP, MERGE_MAP, ROWS
from hollowtree.pipeline.view_store import tile_parts
from hollowtree.primitives.terrain import smrf_ground
from hollowtree.tiling.grid import TileGrid
from hollowtree.tiling.ingest_plan import part_counts
from hollowtree.tiling.stage import Stage, params_hash
from hollowtree.tiling.store import CHUNK_POINTS, RunStore
from hollowtree.tree.rows import ArcadeCells, apply_cells, cell_corners

__all__ = ["LABEL_DTYPES", "RANGE_ROWS", "PART_ROWS", "LEAF_BITS", "run_labels", "labels_tile", "labels_range",
           "part_rows", "plan_slices", "tile_parts", "LabelsReport"]

TILE_STAGE = "labels_tiles"
STAGE = "labels"
RANGE_ROWS = 4 * CHUNK_POINTS
#: Points of a tile labelled (and written as one part) at a time: the tile task's memory
#: follows this, not the tile's size nor the points its voxels dropped. At least the
#: ingest's batch (``tiling.ingest.FLUSH_ROWS``), so that a run of dropped points finds its
#: representatives in one or two parts (:class:`_KeptParts`).
PART_ROWS = 2_000_000
#: Fewest rows of a tile slice (:func:`plan_slices`): a unit costs tens of milliseconds
#: whatever its size (store reads and writes), so cutting a small dense tile among sparse
#: ones (a small scan, or one building in a wide sparse survey) would cost more than it
#: balances (the median tile of a small scan may hold a few dozen rows).
MIN_SLICE_ROWS = CHUNK_POINTS // 4
#: ``segment = global coarse segment << LEAF_BITS | tree leaf node id``.
LEAF_BITS = 20
LABEL_DTYPES: dict[str, Any] = {
    "class": np.uint8, "instance": np.uint32, "segment": np.uint64, "score": np.float32, "primitive": np.uint8,
}


def _tree_values(store: RunStore, pos: np.ndarray, tree: dict[str, Any]) -> dict[str, np.ndarray]:
    """Tree leaf, class, global instance and score at CSR positions ``pos`` (>= 0)."""
    n = len(pos)
    out = {"leaf": np.zeros(n, np.uint64), "class": np.zeros(n, np.uint8),
           "instance": np.zeros(n, np.uint32), "score": np.zeros(n, np.float32)}
    batches = np.asarray(tree.get("batches", []), dtype=np.int64).reshape(-1, 2)
    if not n or not len(batches):
        return out
    offsets = np.asarray(tree["instance_offsets"], dtype=np.int64)
    # Instances merged across element groups (tree.merge); a store without the map has none.
    imap = store.read_slice(MERGE_MAP).astype(np.int64) if store.has(MERGE_MAP) else None
    # Their classes after the merge (a piece that joined an instance of another class); 0 = as is.
    cmap = store.read_slice(MERGE_CLASS_MAP) if store.has(MERGE_CLASS_MAP) else None
    b_of = np.searchsorted(batches[:, 0], pos, side="right") - 1
    for b in np.unique(b_of).tolist():
        sel = np.flatnonzero(b_of == b)
        start, stop = batches[b]
        local = pos[sel] - start
        if (local >= stop - start).any():
            raise PipelineError(f"store {store.url}: tree batch {b} does not cover CSR rows it should")
        # Only the rows this tile touches: a batch of one large group (a ground plane) can
        # hold tens of millions of rows, and every tile it crosses reads from it.
        lo, hi = int(local.min()), int(local.max()) + 1
        arrays = {k: store.read_slice(f"tree/batches/{b}/{k}", lo, hi) for k in ("leaf", "class", "instance", "score")}
        local = local - lo
        out["leaf"][sel] = arrays["leaf"][local]
        inst = arrays["instance"][local].astype(np.int64)
        inst = np.where(inst > 0, inst + offsets[b], 0)
        merged = cmap[inst] if cmap is not None else np.zeros(len(inst), np.uint8)
        out["class"][sel] = np.where(merged > 0, merged, arrays["class"][local])
        out["instance"][sel] = (imap[inst] if imap is not None else inst).astype(np.uint32)
        out["score"][sel] = arrays["score"][local]
    return out


def _arcade_cells(store: RunStore, tile: int) -> ArcadeCells:
    """The arcade cells (``tree/rows/cells``) that reach tile ``tile``'s buffered box; none
    in a store made before them."""
    if not store.has(ROWS):
        return ArcadeCells.empty()
    cells = ArcadeCells.from_array(store.read_slice(ROWS))
    if not len(cells):
        return cells
    grid = TileGrid.from_dict(store.attrs["grid"])
    off = np.asarray(store.attrs["coords"]["offset"], dtype=np.float64)
    x0, y0, x1, y1 = grid.buffered_bounds(tile)
    box = cells.box[:, :4].copy()
    box[cells.trim, :2] += (-1e3, 1e3)  # a cut bay's points beyond its cell can lie anywhere along the line
    x, y = cell_corners(cells.frame, box)
    x, y = x + off[0], y + off[1]
    keep = (x.max(axis=1) >= x0) & (x.min(axis=1) <= x1) & (y.max(axis=1) >= y0) & (y.min(axis=1) <= y1)
    return ArcadeCells(cells.frame[keep], cells.box[keep], cells.instance[keep], cells.take[keep], cells.trim[keep])


def _core_labels(store: RunStore, tile: int, start: int, stop: int, cfg: dict[str, Any],
                 ground: np.ndarray | None = None) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Original index and labels of the core points among tile rows ``[start, stop)``;
    ``ground``: the tile's rows that the terrain filter calls ground (sparse scans)."""
    pts = {k: store.read_slice(f"tiles/{tile}/{k}", start, stop) for k in ("index", "core")}
    coarse = {k: store.read_slice(f"coarse/tiles/{tile}/{k}", start, stop) for k in ("primitive", "global", "csr_pos")}
    core = np.flatnonzero(pts["core"])
    glob = coarse["global"][core].astype(np.uint64)
    pos = coarse["csr_pos"][core]
    values = {"primitive": coarse["primitive"][core], "class": np.zeros(len(core), np.uint8),
              "instance": np.zeros(len(core), np.uint32), "score": np.zeros(len(core), np.float32)}
    leaf = np.zeros(len(core), np.uint64)
    has = pos >= 0
    if cfg["tree"] and has.any():
        tv = _tree_values(store, pos[has], cfg["tree"])
        cells = _arcade_cells(store, tile)
        if len(cells):
            # Arcade rows (tree/rows.py): bays take their piers, gaps get their bays, end bays lose their end wall.
            xyz = store.read_slice(f"tiles/{tile}/xyz", start, stop)[core[has]].astype(np.float64)
            xyz *= np.asarray(store.attrs["coords"]["scale"], dtype=np.float64)
            tv["class"], tv["instance"] = apply_cells(xyz, tv["class"], tv["instance"], cells)
        leaf[has] = tv["leaf"]
        for k in ("class", "instance", "score"):
            values[k][has] = tv[k]
    if ground is not None:  # a sparse scan: its ground is the terrain filter's
        on = ground[start:stop][core]
        values["class"][on] = ClassId.GROUND
        values["instance"][on] = 0
    values["segment"] = np.where(glob > 0, (glob << np.uint64(LEAF_BITS)) | leaf, 0).astype(np.uint64)
    return pts["index"][core], {k: v.astype(LABEL_DTYPES[k]) for k, v in values.items()}


def _write_part(store: RunStore, group: str, index: np.ndarray, values: dict[str, np.ndarray],
                n_points: int) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """Write part ``group`` sorted by original index; return it and its record entry
    (its length and, per output range it touches, its rows there). ``values`` are sorted
    in place of the caller's (one array at a time: the part is held once, not twice)."""
    order = np.argsort(index)
    part = {"index": index[order]}
    del index
    for k in LABEL_DTYPES:
        part[k] = values.pop(k)[order]
    del order
    store.write_unit(group, part)
    bounds = np.arange(0, n_points + RANGE_ROWS, RANGE_ROWS)
    cuts = np.searchsorted(part["index"], bounds.astype(np.uint64))
    ranges = {str(r): [int(cuts[r]), int(cuts[r + 1])] for r in range(len(bounds) - 1) if cuts[r + 1] > cuts[r]}
    return part, {"n": int(len(part["index"])), "ranges": ranges}


class _KeptParts:
    """The labels of a tile's kept core points, looked up by original index in the tile's
    first parts (each sorted by index): at most two parts are held at a time.

    The ingest writes a tile batch by batch, each batch's kept rows and its dropped points
    (``voxel_dropped``, with their representatives among that batch's rows) together, so
    consecutive dropped points find their representatives in consecutive parts: a search
    starts one part before the last part that answered and goes on from there, wrapping
    round to the first part (any order is correct; this one reads each part about once).
    """

    def __init__(self, store: RunStore, tile: int, n_parts: int, prefix: str | None = None) -> None:
        self.store, self.tile, self.n_parts = store, tile, n_parts
        self.prefix = prefix or f"labels/parts/{tile}"
        self.held: OrderedDict[int, dict[str, np.ndarray]] = OrderedDict()
        self.last = 0

    def _part(self, j: int) -> dict[str, np.ndarray]:
        if j in self.held:
            self.held.move_to_end(j)
        else:
            while len(self.held) >= 2:
                self.held.popitem(last=False)
            group = f"{self.prefix}/{j}"
            self.held[j] = {k: self.store.read_slice(f"{group}/{k}") for k in ("index", *LABEL_DTYPES)}
        return self.held[j]

    def labels_of(self, rep: np.ndarray) -> dict[str, np.ndarray]:
        """Labels of the kept points with original index ``rep`` (every one must be there)."""
        out = {k: np.zeros(len(rep), dtype=dt) for k, dt in LABEL_DTYPES.items()}
        need = np.ones(len(rep), dtype=bool)
        first = max(self.last - 1, 0)
        for j in [*range(first, self.n_parts), *range(first)]:
            if not need.any():
                break
            part = self._part(j)
            if not len(part["index"]):
                continue
            sel = np.flatnonzero(need)
            q = rep[sel]
            at = np.minimum(np.searchsorted(part["index"], q), len(part["index"]) - 1)
            hit = part["index"][at] == q
            if hit.any():
                sel, at = sel[hit], at[hit]
                for k in LABEL_DTYPES:
                    out[k][sel] = part[k][at]
                need[sel] = False
                self.last = j
        if need.any():
            raise PipelineError(f"store {self.store.url}: tile {self.tile} has dropped points without their "
                                "representative")
        return out


def plan_slices(sizes: dict[int, tuple[int, int]], *, above: float = 2.0,
                min_rows: int | None = None) -> list[tuple[int, int, int, int]]:
    """The units of the tile phase, ``(tile, slice, first row, end row)``, from each
    tile's ``(rows, points)`` (points: its core rows and voxel-dropped points, the work).

    A tile above ``above`` times the median tile's points (tiles without points left out
    of the median) is cut into ``ceil(points / median)`` slices of equal rows; the others
    are one slice, so the largest unit stays near ``UNIT_BALANCE`` times the median unit.
    No slice has fewer than ``min_rows`` rows (default ``MIN_SLICE_ROWS``).

    >>> plan_slices({0: (10, 10), 1: (12, 10), 2: (50, 40), 3: (0, 0)}, min_rows=1)
    [(0, 0, 0, 10), (1, 0, 0, 12), (2, 0, 0, 12), (2, 1, 12, 25), (2, 2, 25, 37), (2, 3, 37, 50), (3, 0, 0, 0)]
    >>> plan_slices({0: (10, 10), 1: (12, 10), 2: (50, 40)}, min_rows=20)
    [(0, 0, 0, 10), (1, 0, 0, 12), (2, 0, 0, 25), (2, 1, 25, 50)]
    >>> plan_slices({0: (10, 10), 1: (12, 10), 2: (50, 40)})  # small tiles stay whole
    [(0, 0, 0, 10), (1, 0, 0, 12), (2, 0, 0, 50)]
    """
    least = MIN_SLICE_ROWS if min_rows is None else min_rows
    counts = part_counts({t: p for t, (_, p) in sizes.items()}, above=above,
                         cap={t: max(1, r // least) for t, (r, _) in sizes.items()})
    out = []
    for t in sorted(sizes):
        rows, k = sizes[t][0], counts[t]
        cuts = [i * rows // k for i in range(k + 1)]
        out += [(t, s, cuts[s], cuts[s + 1]) for s in range(k)]
    return out


def labels_tile(url: str, tile: int, cfg: dict[str, Any], piece: tuple[int, int, int] | None = None) -> dict[str, Any]:
    """Dask task: the labels of one tile's core points (and of their dropped neighbours),
    or of slice ``piece = (slice, first row, end row)`` of them (:func:`plan_slices`).

    Written as parts of at most ``PART_ROWS`` points (``labels/parts/<tile>/<slice>/<j>``),
    so the task's memory follows that, not the tile: first the slice's core rows,
    ``PART_ROWS`` rows at a time; then, with voxels, the dropped points whose representative
    is among those rows, ``PART_ROWS`` of the tile's at a time, each taking its
    representative's labels from the first parts (:class:`_KeptParts`).
    """
    store = RunStore.open(url, mode="a")
    n_rows = store.array_length(f"tiles/{tile}/index")
    s, first, end = piece if piece is not None else (0, 0, n_rows)
    prefix = f"labels/parts/{tile}/{s}"
    if store.has(prefix):  # an interrupted attempt
        store.delete(prefix)
    whole = first == 0 and end >= n_rows
    n_dropped = store.array_length(f"tiles/{tile}/voxel_dropped") if store.has(f"tiles/{tile}/voxel_dropped") else 0
    ground = None
    if cfg.get("terrain"):  # the whole tile, buffer included: the filter's windows reach past the core
        scale = np.asarray(store.attrs["coords"]["scale"], dtype=np.float64)
        ground = smrf_ground(store.read_slice(f"tiles/{tile}/xyz").astype(np.float64) * scale)
    parts = []
    own = []  # the slice's kept points (original index), where the tile has other slices
    for start in range(first, max(end, first + 1), PART_ROWS):
        index, values = _core_labels(store, tile, start, min(start + PART_ROWS, end), cfg, ground)
        part, info = _write_part(store, f"{prefix}/{len(parts)}", index, values, cfg["n_points"])
        if not whole and n_dropped:
            own.append(part["index"])
        del part
        parts.append(info)
    mine = np.sort(np.concatenate(own)) if own else np.zeros(0, np.uint64)
    del own
    kept = _KeptParts(store, tile, len(parts), prefix)
    for start in range(0, n_dropped, PART_ROWS):
        stop = min(start + PART_ROWS, n_dropped)
        rep = store.read_slice(f"tiles/{tile}/voxel_representative", start, stop)
        sel = None
        if not whole:  # the dropped points whose representative is this slice's
            if not len(mine):
                break
            at = np.minimum(np.searchsorted(mine, rep), len(mine) - 1)
            sel = np.flatnonzero(mine[at] == rep)
            if not len(sel):
                continue
            rep = rep[sel]
        values = kept.labels_of(rep)
        del rep
        dropped = store.read_slice(f"tiles/{tile}/voxel_dropped", start, stop)
        if sel is not None:
            dropped = dropped[sel]
        _, info = _write_part(store, f"{prefix}/{len(parts)}", dropped, values, cfg["n_points"])
        parts.append(info)
    info = {"params_hash": cfg["params_hash"], "tile": tile, "slice": s, "rows": [first, end],
            "n_points": int(sum(p["n"] for p in parts)), "parts": parts}
    store.record(TILE_STAGE, f"{tile}.{s}", info)
    return info


def part_rows(info: dict[str, Any]) -> list[tuple[str, int, int, int]]:
    """``(part group, range, first row, end row)`` of every output range a unit's parts touch."""
    return [(f"labels/parts/{info['tile']}/{info['slice']}/{j}", int(r), a, b)
            for j, part in enumerate(info["parts"]) for r, (a, b) in part["ranges"].items()]


def labels_range(url: str, r: int, parts: list[tuple[str, int, int]], cfg: dict[str, Any]) -> int:
    """Dask task: write input points ``[r * RANGE_ROWS, ...)`` of every label array from
    ``parts`` (``(part group, first row, end row)``)."""
    store = RunStore.open(url, mode="a")
    start = r * RANGE_ROWS
    stop = min(start + RANGE_ROWS, cfg["n_points"])
    out = {k: np.zeros(stop - start, dtype=dt) for k, dt in LABEL_DTYPES.items()}
    n = 0
    for group, a, b in parts:
        index = store.read_slice(f"{group}/index", a, b).astype(np.int64) - start
        for k in LABEL_DTYPES:
            out[k][index] = store.read_slice(f"{group}/{k}", a, b)
        n += b - a
    for k, values in out.items():
        store.write_slice(f"labels/{k}", start, values)
    counts = np.bincount(out["class"], minlength=NUM_CLASSES)
    store.record(STAGE, str(r), {"params_hash": cfg["params_hash"], "n_labelled": n,
                                 "class_counts": counts.tolist()})
    return n


@dataclass(frozen=True, kw_only=True)
class LabelsReport:
    store: str
    n_points: int
    n_labelled: int
    tiles_run: int
    tiles_skipped: int
    ranges_run: int
    ranges_skipped: int
    seconds: float

    def summary(self) -> str:
        return (f"labels: {self.n_labelled:,} of {self.n_points:,} input points labelled; tile slices "
                f"{self.tiles_run} run, {self.tiles_skipped} skipped; ranges {self.ranges_run} run, "
                f"{self.ranges_skipped} skipped; {self.seconds:.1f} s")


def require_labels(store: RunStore) -> None:
    """Raise a one-line ``PipelineError`` unless ``store``'s labels stage is complete."""
    lab = store.attrs.get("stages", {}).get(STAGE)
    if not lab or lab.get("done") != lab.get("units"):
        raise PipelineError(f"store {store.url} has no complete labels; run `hollowtree run` first")


def labels_hash(attrs: dict[str, Any], *, use_tree: bool) -> str:
    """The labels' parameters hash: that of the stage they are read from."""
    stages = attrs.get("stages", {})
    upstream = stages.get("tree" if use_tree else "coarse", {}).get("params_hash")
    if upstream is None:
        raise PipelineError(f"the {'tree' if use_tree else 'coarse'} stage has not run on this store")
    return params_hash(["labels-v4", upstream, use_tree, terrain(attrs)])


def terrain(attrs: dict[str, Any]) -> bool:
    """Whether the scan's ground comes from the terrain filter (``primitives/terrain.py``):
    its points are more than ``MAX_SPACING`` apart, as the coarse stage measured."""
    spacing = attrs.get("stages", {}).get("coarse", {}).get("spacing")
    return spacing is not None and float(spacing) > MAX_SPACING


def _tile_sizes(store: RunStore, tiles: list[int]) -> dict[int, tuple[int, int]]:
    """Each tile's rows and points to label (core rows and voxel-dropped points)."""
    recs, h = store.records("ingest"), store.attrs["ingest"].get("params_hash")
    out = {}
    for t in tiles:
        rows = store.array_length(f"tiles/{t}/index")
        rec = recs.get(str(t), {})
        core = int(rec["n_core"]) if rec.get("params_hash") == h and "n_core" in rec else rows
        dropped = store.array_length(f"tiles/{t}/voxel_dropped") if store.has(f"tiles/{t}/voxel_dropped") else 0
        out[t] = (rows, core + dropped)
    return out


def run_labels(url: str, *, use_tree: bool, runner: Any) -> LabelsReport:
    """Write the per-point label arrays of the store (resumable per tile slice and range)."""
    t0 = time.perf_counter()
    store = RunStore.open(url, mode="a")
    attrs = store.attrs
    h = labels_hash(attrs, use_tree=use_tree)
    n_points = int(sum(int(s["point_count"]) for s in attrs["sources"]))
    tiles = [int(t) for t in attrs["ingest"]["tiles"]]
    stages = attrs.get("stages", {})
    stage = Stage(store, STAGE, h, unit_stages=(TILE_STAGE,))
    stage.clear_if_changed()
    cfg = {"params_hash": h, "n_points": n_points, "tree": stages.get("tree") if use_tree else None,
           "terrain": terrain(attrs)}
    sizes = _tile_sizes(store, tiles)
    # A sparse scan's tiles stay whole: each slice would run the terrain filter on the whole tile.
    plan = [(t, 0, 0, r) for t, (r, _) in sorted(sizes.items())] if cfg["terrain"] else plan_slices(sizes)
    units = {f"{t}.{s}": (t, s, a, b) for t, s, a, b in plan}
    recs_t = store.records(TILE_STAGE)
    if any(k not in units or v.get("rows") != list(units[k][2:]) for k, v in recs_t.items()):
        # records of another plan of slices (or of the tiles before them): all redone
        store.clear_records(TILE_STAGE)
        store.clear_records(STAGE)
    done_t = stage.done(TILE_STAGE)
    if not done_t:  # nothing kept: no part of an earlier layout or plan is left behind
        store.delete("labels/parts")
    todo_t = [k for k in units if k not in done_t]
    done_r = set(stage.done())
    if not done_r:  # first time with these parameters: fresh, zero-filled arrays
        for k, dt in LABEL_DTYPES.items():
            store.create_array(f"labels/{k}", shape=(n_points,), dtype=dt)
    # Each task in a child process of its worker (in_child): what one task leaves in a
    # worker's heap does not raise the next one's peak.
    results = runner(in_child(labels_tile), [(url, units[k][0], cfg, units[k][1:]) for k in todo_t], "labels: tiles")
    for k, info in zip(todo_t, results, strict=True):
        done_t[k] = info
    parts: dict[int, list[tuple[str, int, int]]] = {}
    for k in units:
        for group, r, a, b in part_rows(done_t[k]):
            parts.setdefault(r, []).append((group, a, b))
    n_ranges = -(-n_points // RANGE_ROWS)
    todo_r = [r for r in range(n_ranges) if str(r) not in done_r]
    runner(in_child(labels_range), [(url, r, parts.get(r, []), cfg) for r in todo_r], "labels: ranges")
    n_labelled = sum(int(done_t[k]["n_points"]) for k in units)
    stage.finish(n_ranges, tree=use_tree, n_labelled=n_labelled)
    return LabelsReport(store=url, n_points=n_points, n_labelled=n_labelled, tiles_run=len(todo_t),
                        tiles_skipped=len(units) - len(todo_t), ranges_run=len(todo_r),
                        ranges_skipped=n_ranges - len(todo_r), seconds=time.perf_counter() - t0)
