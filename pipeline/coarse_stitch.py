"""The coarse stage's stitch: tile-local segments joined into global ones across tile
borders, then into element groups for the tree (``pipeline/coarse.py`` runs it once,
after every tile is recorded). It writes ``coarse/segments.parquet``, the per-point
global segment of every tile and the segments' CSR of original indices.

Three waves of tasks around a small reduction in the driver (issue 44: no serial middle):

- **pairs** (a task per tile): the tile's buffer rows matched to the core rows of its 8
  neighbours (the same original index), as counts per pair of tile-local segments;
- the driver joins the pairs (union-find over the tables' segments, not points), makes the
  element groups and the global ids, and counts each segment's points from the tables;
- **parts** (a task per tile): its rows' global ids and CSR positions
  (``coarse/tiles/<tile>/{global, csr_pos}``) and its CSR rows in CSR order
  (``coarse/csr_parts/<tile>``);
- **csr** (a task per run of whole CSR chunks): those rows gathered from the tiles' parts.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np
import pyarrow as pa

from hollowtree.errors import PipelineError
from hollowtree.primitives.group import (
    STRIP_FACTOR,
    join_stacked,
    large_segments,
    set_in_walls,
)
from hollowtree.primitives.segment import (
    CoarseParams,
    same_primitive,
)
from hollowtree.primitives.stitch import UnionFind
from hollowtree.tiling.grid import TileGrid
from hollowtree.tiling.ingest_plan import part_counts
from hollowtree.tiling.store import CHUNK_POINTS, RunStore

__all__ = ["CSR_ROWS", "READ_ROWS", "STITCH_STAGES", "EdgeRows", "stitch"]

PAIRS_STAGE = "coarse.pairs"
PARTS_STAGE = "coarse.csr_parts"
CSR_STAGE = "coarse.csr"
STITCH_STAGES = (PAIRS_STAGE, PARTS_STAGE, CSR_STAGE)
#: CSR rows a csr task gathers and writes (whole chunks, about 80 MB of index and xyz).
CSR_ROWS = 16 * CHUNK_POINTS
#: A tile above UNIT_SPLIT times the median tile's rows (buffer rows for the pairs) is
#: stitched in parts of about the median (issue 44's balanced units).
UNIT_SPLIT = 2.0
#: Tile rows read at a time by a tile's table and contacts (``pipeline.coarse``) and by the
#: stitch: their memory follows this, not the densest tile. A multiple of the store's
#: chunk, so the stitch writes whole chunks.
READ_ROWS = 4 * CHUNK_POINTS


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
    outline: dict[int, np.ndarray] | None = {}  # None: a table made before outlines
    for i, r in enumerate(roots.tolist()):
        row = info[keys[i]]
        if row["n_points"] > big_n.get(r, -1):
            big_n[r], kind[r] = row["n_points"], row["kind"]
            plane[r] = row["params"] if row["kind"] == "plane" else "[]"
        b = box.setdefault(r, [np.inf, np.inf, np.inf, -np.inf, -np.inf, -np.inf])
        b[0], b[1], b[2] = min(b[0], row["xmin"]), min(b[1], row["ymin"]), min(b[2], row["zmin"])
        b[3], b[4], b[5] = max(b[3], row["xmax"]), max(b[4], row["ymax"]), max(b[5], row["zmax"])
        if outline is not None and row.get("outline") is None:
            outline = None
        elif outline is not None:
            o = np.asarray(row["outline"], dtype=np.float64)
            k = len(o) // 2
            if r in outline:
                o = np.r_[np.minimum(outline[r][:k], o[:k]), np.maximum(outline[r][k:], o[k:])]
            outline[r] = o
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
            c = store.read_table(rel)
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
                                params.group_set_in, outline=outline)
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


def _pieces(store: RunStore, t: int, names: Sequence[str], rows: tuple[int, int] | None = None
            ) -> Iterator[dict[str, np.ndarray]]:
    """Tile ``t``'s rows (all, or ``rows = (first, end)``) ``READ_ROWS`` at a time:
    ``names`` of tiles/<t> and its segment."""
    first, n = rows if rows is not None else (0, store.array_length(f"coarse/tiles/{t}/segment"))
    for start in range(first, n, READ_ROWS):
        stop = min(start + READ_ROWS, n)
        d = {k: store.read_slice(f"tiles/{t}/{k}", start, stop) for k in names}
        d["segment"] = store.read_slice(f"coarse/tiles/{t}/segment", start, stop).astype(np.int64)
        d["start"] = np.int64(start)
        yield d


class EdgeRows:
    """What the stitch needs of a tile, gathered piece by piece: its segmented buffer rows
    and the segmented core rows near its edge (the only ones a neighbour's buffer can
    hold: within the buffer, and a little more, since rows were routed before their
    coordinates were stored), each as original index and tile-local segment. The coarse
    task fills it as it summarises its tile and writes it to ``coarse/edges/<tile>``."""

    NAMES = ("buffer_index", "buffer_segment", "core_index", "core_segment")
    #: and per piece of rows added: its rows, and its core rows per tile-local segment (the
    #: stitch cuts a dense tile's CSR work at these pieces; pieces x segments, flattened)
    PIECES = ("piece_rows", "piece_core")

    def __init__(self, store: RunStore, tile: int) -> None:
        grid = TileGrid.from_dict(store.attrs["grid"])
        self.scale = np.asarray(store.attrs["coords"]["scale"], dtype=np.float64)
        self.offset = np.asarray(store.attrs["coords"]["offset"], dtype=np.float64)
        self.bounds = grid.core_bounds(tile)
        self.reach = float(grid.buffer) + 10.0 * float(self.scale[:2].max())
        self.parts: dict[str, list[np.ndarray]] = {k: [] for k in self.NAMES}
        self.piece_rows: list[int] = []
        self.piece_core: list[np.ndarray] = []

    def add(self, raw: np.ndarray, core: np.ndarray, index: np.ndarray, seg: np.ndarray) -> None:
        """One piece of the tile's rows: stored xyz, core flag, original index, segment."""
        x0, y0, x1, y1 = self.bounds
        xy = raw[:, :2].astype(np.float64) * self.scale[:2] + self.offset[:2]
        edge = ((xy[:, 0] < x0 + self.reach) | (xy[:, 0] > x1 - self.reach)
                | (xy[:, 1] < y0 + self.reach) | (xy[:, 1] > y1 - self.reach))
        core = core.astype(bool)
        self.piece_rows.append(len(seg))
        self.piece_core.append(np.bincount(seg[core].astype(np.int64)))
        for m, name in ((~core & (seg > 0), "buffer"), (core & (seg > 0) & edge, "core")):
            self.parts[f"{name}_index"].append(index[m].astype(np.int64))
            self.parts[f"{name}_segment"].append(seg[m].astype(np.int64))

    def arrays(self) -> dict[str, np.ndarray]:
        """The four arrays, each kind of rows sorted by original index (matched by a
        binary search of sorted keys), and the pieces' rows and counts."""
        out = {k: _joined(v) for k, v in self.parts.items()}
        for kind in ("buffer", "core"):
            order = np.argsort(out[f"{kind}_index"])
            out[f"{kind}_index"], out[f"{kind}_segment"] = out[f"{kind}_index"][order], out[f"{kind}_segment"][order]
        width = max([1, *(len(c) for c in self.piece_core)])
        out["piece_rows"] = np.asarray(self.piece_rows, dtype=np.int64)
        core = np.zeros((len(self.piece_core), width), dtype=np.int64)
        for i, c in enumerate(self.piece_core):
            core[i, :len(c)] = c
        # flat: a store chunk holds CHUNK_POINTS rows, each of a 2-D array's full width
        out["piece_core"] = core.reshape(-1)
        return out


def _edges(store: RunStore, tile: int, rows: str) -> dict[str, np.ndarray]:
    """A tile's ``rows`` (``buffer`` or ``core``) of its :class:`EdgeRows`, as its coarse
    task wrote them (or, in a store whose coarse tasks did not, taken from the tile)."""
    if store.has(f"coarse/edges/{tile}"):
        return store.read_unit(f"coarse/edges/{tile}", [f"{rows}_index", f"{rows}_segment"])
    rows = EdgeRows(store, tile)
    for d in _pieces(store, tile, ("xyz", "core", "index")):
        rows.add(d["xyz"], d["core"], d["index"], d["segment"])
    return rows.arrays()


def stitch_pairs(url: str, tile: int, neighbours: Sequence[int], h: str,
                 part: tuple[int, int, int] | None = None) -> np.ndarray:
    """Pairs task: ``(k, 5)`` int64 rows ``(tile, segment, neighbour, its segment, shared
    points)``: the tile's segmented buffer rows (all, or ``part = (k, first, end)`` of
    them) found among the segmented edge core rows of ``neighbours`` (every buffer row is
    a copy of one of their core rows)."""
    store = RunStore.open(url, mode="a")
    if part is None:
        own = _edges(store, tile, "buffer")
        b_idx, b_seg = own["buffer_index"], own["buffer_segment"]
    else:
        b_idx, b_seg = (store.read_slice(f"coarse/edges/{tile}/buffer_{k}", part[1], part[2])
                        for k in ("index", "segment"))
    out = [np.zeros((0, 5), dtype=np.int64)]
    for n in neighbours if len(b_idx) else ():
        other = _edges(store, n, "core")
        c_idx, c_seg = other["core_index"], other["core_segment"]
        if not len(c_idx):
            continue
        pos = np.minimum(np.searchsorted(c_idx, b_idx), len(c_idx) - 1)
        hit = c_idx[pos] == b_idx
        if not hit.any():
            continue
        sa, sb = b_seg[hit], c_seg[pos[hit]]
        width = int(sb.max()) + 1
        code = sa * width + sb
        if (int(sa.max()) + 1) * width <= 4 * len(code) + 1_000_000:  # few local segments: a bincount
            cnt = np.bincount(code)
            pair = np.flatnonzero(cnt)
            cnt = cnt[pair]
        else:
            pair, cnt = np.unique(code, return_counts=True)
        out.append(np.column_stack([np.full(len(pair), tile), pair // width, np.full(len(pair), n), pair % width,
                                    cnt]))
    store.record(PAIRS_STAGE, str(tile) if part is None else f"{tile}.{part[0]}",
                 {"params_hash": h, "n_points": int(len(b_idx))})
    return np.concatenate(out).astype(np.int64)


def stitch_part(url: str, tile: int, k: int, span: tuple[int, int], lookup: np.ndarray, cursor: np.ndarray,
                h: str) -> int:
    """Parts task: the global id (``lookup[local segment]`` of a core row, else 0) and
    CSR position of every row in ``span = (first, end)`` of the tile (whole chunks: the
    driver made its arrays); and their CSR rows (original index, store xyz) in CSR order,
    at ``coarse/csr_parts/<tile>/<k>``. ``cursor``: ``(g, first position, first part
    row)`` for each global segment the rows hold; a segment's rows of one part are
    consecutive in both, in row order. Returns the CSR rows written.

    The part is filled through a disk-backed scratch file (positioned writes, not a memory
    map, whose pages would count in the task's resident memory): the task holds
    ``READ_ROWS`` rows at a time, not the tile.
    """
    store = RunStore.open(url, mode="a")
    first = np.zeros(int(lookup.max(initial=0)) + 1, dtype=np.int64)
    part_at = np.zeros(len(first), dtype=np.int64)
    first[cursor[:, 0]], part_at[cursor[:, 0]] = cursor[:, 1], cursor[:, 2]
    n_of = np.zeros(len(first), dtype=np.int64)
    written = 0
    with tempfile.TemporaryFile() as scratch_i, tempfile.TemporaryFile() as scratch_x:
        fd_i, fd_x = scratch_i.fileno(), scratch_x.fileno()
        for d in _pieces(store, tile, ("core", "index", "xyz"), span):
            seg = d["segment"]
            top = int(seg.max(initial=0))
            lut = lookup if top < len(lookup) else np.r_[lookup, np.zeros(top + 1 - len(lookup), np.int64)]
            glob = np.where(d["core"].astype(bool), lut[seg], 0)
            pos = np.full(len(glob), -1, dtype=np.int64)
            rows = np.flatnonzero(glob > 0)
            if len(rows):
                g = glob[rows]
                order = np.argsort(g, kind="stable")
                rows, g = rows[order], g[order]
                starts = np.flatnonzero(np.r_[True, g[1:] != g[:-1]])
                rank = np.arange(len(g)) - np.repeat(starts, np.diff(np.r_[starts, len(g)])) + n_of[g]
                pos[rows] = first[g] + rank
                at = part_at[g] + rank
                n_of[g[starts]] += np.diff(np.r_[starts, len(g)])
                # runs of consecutive part rows: one positioned write each
                brk = np.flatnonzero(np.r_[True, np.diff(at) != 1, True])
                idx, xyz = d["index"][rows].astype(np.uint64), d["xyz"][rows].astype(np.int32)
                for a, b in zip(brk[:-1].tolist(), brk[1:].tolist(), strict=True):
                    _pwrite_all(fd_i, np.ascontiguousarray(idx[a:b]), int(at[a]) * 8)
                    _pwrite_all(fd_x, np.ascontiguousarray(xyz[a:b]), int(at[a]) * 12)
                written += len(rows)
            store.write_slice(f"coarse/tiles/{tile}/global", int(d["start"]), glob.astype(np.uint64))
            store.write_slice(f"coarse/tiles/{tile}/csr_pos", int(d["start"]), pos)
        writer = store.unit_writer(f"coarse/csr_parts/{tile}/{k}", n_rows=written)
        for a in range(0, written, READ_ROWS):
            m = min(READ_ROWS, written - a)
            writer.append({"indices": _pread_all(fd_i, m * 8, a * 8).view(np.uint64),
                           "xyz": _pread_all(fd_x, m * 12, a * 12).view(np.int32).reshape(m, 3)})
        writer.close({"indices": np.zeros(0, np.uint64), "xyz": np.zeros((0, 3), np.int32)})
    store.record(PARTS_STAGE, f"{tile}.{k}", {"params_hash": h, "n_points": span[1] - span[0]})
    return written


def stitch_csr(url: str, unit: int, first: int, end: int, blocks: np.ndarray, parts: dict[int, str],
               h: str) -> int:
    """CSR task: CSR rows ``[first, end)`` (``first`` on a chunk boundary) from the tiles'
    parts. ``blocks``: ``(part, CSR position, part row, rows)`` of every run of a part's
    rows in the range (a part's runs are consecutive part rows: one read per part);
    ``parts``: each part's group path."""
    store = RunStore.open(url, mode="a")
    indices = np.zeros(end - first, dtype=np.uint64)
    xyz = np.zeros((end - first, 3), dtype=np.int32)
    for t in np.unique(blocks[:, 0]).tolist():
        bt = blocks[blocks[:, 0] == t]
        lo, hi = int(bt[:, 2].min()), int((bt[:, 2] + bt[:, 3]).max())
        part_i = store.read_slice(f"{parts[t]}/indices", lo, hi)
        part_x = store.read_slice(f"{parts[t]}/xyz", lo, hi)
        for _, p, r, n in bt.tolist():
            indices[p - first:p - first + n] = part_i[r - lo:r - lo + n]
            xyz[p - first:p - first + n] = part_x[r - lo:r - lo + n]
    store.write_slice("coarse/csr/indices", first, indices)
    store.write_slice("coarse/csr/xyz", first, xyz)
    store.record(CSR_STAGE, str(unit), {"params_hash": h, "n_points": end - first})
    return end - first


def _row_parts(store: RunStore, t: int, n_rows: int, k: int, key_rows: dict[int, list[tuple[int, int]]],
               info: dict[tuple[int, int], dict[str, Any]]) -> list[tuple[int, int, np.ndarray]]:
    """Tile ``t``'s rows cut into ``k`` parts at the pieces its coarse task counted (whole
    chunks): ``(first row, end row, core rows per tile-local segment)`` each; one part
    with the table's counts where the tile has no such counts."""
    if k > 1 and store.has(f"coarse/edges/{t}/piece_rows"):
        rows = store.read_slice(f"coarse/edges/{t}/piece_rows")
        core = store.read_slice(f"coarse/edges/{t}/piece_core").reshape(len(rows), -1)
        ends = np.cumsum(rows)
        if len(rows) and ends[-1] == n_rows and not np.any(ends[:-1] % CHUNK_POINTS):
            k = min(k, len(rows))
            cuts = [i * len(rows) // k for i in range(k + 1)]
            starts = np.r_[0, ends]
            return [(int(starts[a]), int(starts[b]), core[a:b].sum(axis=0)) for a, b in zip(cuts[:-1], cuts[1:], strict=True)]
    local = np.zeros(max([1, *(s_ + 1 for s_, _ in key_rows.get(t, []))]), dtype=np.int64)
    for s_, _ in key_rows.get(t, []):
        local[s_] = info[(t, s_)]["n_core"]
    return [(0, n_rows, local)]


def _pair_counts(store: RunStore, tiles: Sequence[int], n_keys: int, key_lut: dict[int, np.ndarray],
                 runner: Any, h: str) -> dict[tuple[int, int], int]:
    """The pairs wave: shared buffer points per pair of table rows (``key_lut``: per tile,
    local segment -> row), a dense tile's buffer matched in slices of about the median's."""
    grid = TileGrid.from_dict(store.attrs["grid"])
    present = set(tiles)
    jobs = []
    for t in tiles:
        ix, iy = grid.tile_index(t)
        near = [grid.tile_id(jx, jy) for jy in (iy - 1, iy, iy + 1) for jx in (ix - 1, ix, ix + 1)
                if (jx, jy) != (ix, iy) and 0 <= jx < grid.shape[0] and 0 <= jy < grid.shape[1]]
        jobs.append((store.url, t, [n for n in near if n in present], h))
    # a tile of many buffer rows (a dense one) is matched in parts of about the median's
    n_buffer = {t: (store.array_length(f"coarse/edges/{t}/buffer_index") if store.has(f"coarse/edges/{t}") else 0)
                for t in tiles}
    k_buffer = part_counts(n_buffer, above=UNIT_SPLIT, cap={t: max(1, n) for t, n in n_buffer.items()})
    jobs = [job if k_buffer[job[1]] == 1 else
            (*job, (k, k * n_buffer[job[1]] // k_buffer[job[1]], (k + 1) * n_buffer[job[1]] // k_buffer[job[1]]))
            for job in jobs for k in range(k_buffer[job[1]])]
    found = runner(stitch_pairs, jobs, "coarse: stitch pairs")
    pairs = np.concatenate([np.zeros((0, 5), np.int64), *found])

    def key_of(tile_col: np.ndarray, seg_col: np.ndarray) -> np.ndarray:
        kid = np.full(len(seg_col), -1, dtype=np.int64)
        for tt in np.unique(tile_col).tolist():
            m = tile_col == tt
            lut = key_lut.get(tt, np.full(1, -1, dtype=np.int64))
            sg = seg_col[m]
            kid[m] = np.where(sg < len(lut), lut[np.minimum(sg, len(lut) - 1)], -1)
        if (kid < 0).any():
            bad = int(tile_col[np.flatnonzero(kid < 0)[0]])
            raise PipelineError(f"store {store.url}: tile {bad} labels points with a segment its table lacks; "
                                "rerun `hollowtree coarse`")
        return kid

    pair_counts: dict[tuple[int, int], int] = {}
    if len(pairs):
        ka, kb = key_of(pairs[:, 0], pairs[:, 1]), key_of(pairs[:, 2], pairs[:, 3])
        lo, hi = np.minimum(ka, kb), np.maximum(ka, kb)
        code, inv = np.unique(lo * n_keys + hi, return_inverse=True)
        cnt = np.bincount(inv, weights=pairs[:, 4]).astype(np.int64)
        pair_counts = {(int(c_ // n_keys), int(c_ % n_keys)): int(n_)
                       for c_, n_ in zip(code.tolist(), cnt.tolist(), strict=True)}
    return pair_counts


def _write_csr(store: RunStore, tiles: Sequence[int], keys: list[tuple[int, int]],
               key_rows: dict[int, list[tuple[int, int]]],
               key_lut: dict[int, np.ndarray], info: dict[tuple[int, int], dict[str, Any]], key_global: np.ndarray,
               n_segments: int, runner: Any, h: str) -> np.ndarray:
    """The parts and csr waves: every tile row's global id and CSR position, and the CSR;
    returns each global segment's core points."""
    # Each global segment's core points per part of a tile, from what its coarse task
    # counted (or the tables); a part's rows of one segment are consecutive in the CSR,
    # tiles in order, a tile's parts in order, rows in row order.
    key_core = np.array([info[k]["n_core"] for k in keys], dtype=np.int64)
    counts = np.bincount(key_global, weights=key_core, minlength=n_segments + 1).astype(np.int64)
    offsets = np.r_[0, np.cumsum(counts[1:])].astype(np.int64)
    total = int(offsets[-1])
    n_rows = {t: store.array_length(f"coarse/tiles/{t}/segment") for t in tiles}
    k_rows = part_counts(n_rows, above=UNIT_SPLIT, cap={t: max(1, -(-n // READ_ROWS)) for t, n in n_rows.items()})
    run = offsets[:-1].copy()
    jobs, blocks, paths = [], [], {}
    for t in tiles:
        lookup = np.zeros(len(key_lut.get(t, [0])), dtype=np.int64)
        for s_, i in key_rows.get(t, []):
            lookup[s_] = key_global[i]
        store.create_array(f"coarse/tiles/{t}/global", shape=(n_rows[t],), dtype=np.uint64)
        store.create_array(f"coarse/tiles/{t}/csr_pos", shape=(n_rows[t],), dtype=np.int64)
        for k, (first_row, end_row, local) in enumerate(_row_parts(store, t, n_rows[t], k_rows[t], key_rows, info)):
            ids = np.arange(len(local))
            gl = np.where(ids < len(lookup), lookup[np.minimum(ids, len(lookup) - 1)], 0)
            per_g = np.bincount(gl, weights=local, minlength=n_segments + 1).astype(np.int64)
            g = np.flatnonzero(per_g[1:]) + 1
            n = per_g[g]
            first = run[g - 1].copy()
            run[g - 1] += n
            paths[len(paths)] = f"coarse/csr_parts/{t}/{k}"
            jobs.append((store.url, t, k, (first_row, end_row), lookup, np.stack([g, first, np.cumsum(n) - n], axis=1), h))
            blocks.append(np.stack([np.full(len(g), len(paths) - 1), first, np.cumsum(n) - n, n], axis=1))
    runner(stitch_part, jobs, "coarse: stitch parts")
    store.write_unit("coarse/csr", {"offsets": offsets})
    store.create_array("coarse/csr/indices", shape=(total,), dtype=np.uint64)
    store.create_array("coarse/csr/xyz", shape=(total, 3), dtype=np.int32)
    allb = np.concatenate([np.zeros((0, 4), np.int64), *blocks]).astype(np.int64)
    units = []
    for j, lo in enumerate(range(0, total, CSR_ROWS)):
        hi = min(lo + CSR_ROWS, total)
        bl = allb[(allb[:, 1] < hi) & (allb[:, 1] + allb[:, 3] > lo)].copy()
        start, end = np.maximum(bl[:, 1], lo), np.minimum(bl[:, 1] + bl[:, 3], hi)
        bl[:, 2] += start - bl[:, 1]
        bl[:, 1], bl[:, 3] = start, end - start
        units.append((store.url, j, lo, hi, bl, {int(i): paths[int(i)] for i in np.unique(bl[:, 0])}, h))
    runner(stitch_csr, units, "coarse: csr")
    store.delete("coarse/csr_parts")
    store.delete("coarse/edges")
    return counts


def stitch(store: RunStore, tiles: Sequence[int], params: CoarseParams, *, runner: Any, h: str = "") -> tuple[int, int]:
    """Join tile segments over shared buffer points; write global ids, table and CSR.

    ``runner(fn, args_list, desc)`` runs the tasks (``pipeline.graph``); ``h`` is the
    stage's hash, in the tasks' records."""
    tables = [store.read_table(f"coarse/tables/{t}.parquet").to_pylist() for t in tiles]
    keys = [(r["tile"], r["segment"]) for tab in tables for r in tab]
    info = {k: r for k, r in zip(keys, (r for tab in tables for r in tab), strict=True)}
    # Per tile, local segment id -> row of ``keys`` (a lookup array, not a dict per point).
    key_rows: dict[int, list[tuple[int, int]]] = {}
    for i, (tt, s_) in enumerate(keys):
        key_rows.setdefault(tt, []).append((s_, i))
    key_lut: dict[int, np.ndarray] = {}
    for tt, rows in key_rows.items():
        key_lut[tt] = np.full(max(s_ for s_, _ in rows) + 1, -1, dtype=np.int64)
        for s_, i in rows:
            key_lut[tt][s_] = i
    uf = UnionFind(len(keys))
    pair_counts = _pair_counts(store, tiles, len(keys), key_lut, runner, h)
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

    counts = _write_csr(store, tiles, keys, key_rows, key_lut, info, key_global, n_segments, runner, h)
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
    store.write_table("coarse/segments.parquet", pa.table(out))
    return n_segments, len(keys)
