"""The coarse stage's stitch: tile-local segments joined into global ones across tile
borders, then into element groups for the tree (``pipeline/coarse.py`` runs it once,
after every tile is recorded). It writes ``coarse/segments.parquet``, the per-point
global segment of every tile and the segments' CSR of original indices."""

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
from hollowtree.tiling.store import CHUNK_POINTS, RunStore

__all__ = ["READ_ROWS", "STITCH_CACHE_ROWS", "stitch"]

#: Edge rows (16 bytes each) the stitch keeps of the tiles it matched last (least recently
#: used dropped first): tiles are visited row by row, so a window of about three rows of
#: tiles is reused; a bound, not a grow-with-the-scan cache.
STITCH_CACHE_ROWS = 8_000_000
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


def stitch(store: RunStore, tiles: Sequence[int], params: CoarseParams) -> tuple[int, int]:
    """Join tile segments over shared buffer points; write global ids, table and CSR."""
    grid = TileGrid.from_dict(store.attrs["grid"])
    tables = [store.read_table(f"coarse/tables/{t}.parquet").to_pylist() for t in tiles]
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
    store.write_table("coarse/segments.parquet", pa.table(out))
    return n_segments, len(keys)
