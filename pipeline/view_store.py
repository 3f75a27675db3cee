"""The store side of ``hollowtree view``: a labelled run store opened read-only, its nodes'
levels read by whole chunks (``view_lod``), the elements and the hierarchical tree.

Every read goes through :meth:`ViewStore._read`, which counts the chunks it touches
(``benchmarks/bench_view.py`` reports them).
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from typing import Any

import numpy as np

from hollowtree.classes import CLASS_NAMES, NUM_CLASSES
from hollowtree.errors import ConfigError, PipelineError
from hollowtree.pipeline.view_lod import (
    LEVELS,
    first_view,
    level_rows,
    pack,
    subtree_leaves,
    tree_path,
)
from hollowtree.tiling.store import CHUNK_POINTS, RunStore

__all__ = ["ViewStore", "SEQUENCES", "PARTS_CACHE_BYTES", "LEAF_BITS", "CLASS_RGB", "tile_parts"]

#: ``labels/segment = coarse segment << LEAF_BITS | tree leaf`` (``pipeline.labels.LEAF_BITS``;
#: not imported: pipeline.labels loads the whole pipeline and delays the server's start).
LEAF_BITS = 20
#: The class colours of ``pipeline.export.CLASS_COLOURS`` (the PNG views), RGB 0-255; the
#: tests check that they agree.
CLASS_RGB = ((191, 191, 191), (140, 115, 76), (217, 178, 128), (153, 51, 51), (26, 115, 217),
             (242, 140, 13), (38, 166, 64), (153, 64, 191), (89, 89, 89))
#: The labels stage's name (``pipeline.labels.STAGE``).
LABELS_STAGE = "labels"
#: Names of the tree table's ``sequence`` codes (docs/store.md, the tree stage).
SEQUENCES = {0: "root", 1: "S1", 2: "S2", 3: "S3", 5: "gaps", 6: "parts"}
#: Bytes of tile labels (``labels/parts``) kept between requests.
PARTS_CACHE_BYTES = 320 << 20
_LABEL_FIELDS = ("index", "class", "instance", "segment", "score")


def tile_parts(records: dict[str, dict[str, Any]], tile: int) -> list[str]:
    """The groups of a tile's label parts, in order, from the ``labels_tiles`` records of
    its row slices (``pipeline.labels``: ``labels/parts/<tile>/<slice>/<j>``), or of a store
    labelled before the slices (one record a tile, ``labels/parts/<tile>/<j>``)."""
    old = records.get(str(tile))
    if old is not None and "slice" not in old:
        return [f"labels/parts/{tile}/{j}" for j in range(len(old.get("parts", [])))]
    units = sorted((v for v in records.values() if "slice" in v and int(v["tile"]) == tile), key=lambda v: int(v["slice"]))
    return [f"labels/parts/{tile}/{v['slice']}/{j}" for v in units for j in range(len(v["parts"]))]


class ViewStore:
    """A labelled run store opened read-only for the viewer; counts the chunks it reads."""

    def __init__(self, url: str) -> None:
        self.url = str(url)
        self.store = RunStore.open(self.url)
        attrs = self.store.attrs
        lab = attrs.get("stages", {}).get(LABELS_STAGE)
        if not lab or lab.get("done") != lab.get("units"):  # pipeline.labels.require_labels
            raise PipelineError(f"store {self.url} has no complete labels; run `hollowtree run` first")
        self.scale = np.asarray(attrs["coords"]["scale"], dtype=np.float64)
        self.offset = np.asarray(attrs["coords"]["offset"], dtype=np.float64)
        self.fields = attrs.get("fields", {})
        self.chunk_reads = 0
        self.bytes_read = 0
        self._lock = threading.Lock()
        self._tile_locks: dict[int, threading.Lock] = {}
        self._parts: OrderedDict[int, dict[str, list[np.ndarray]]] = OrderedDict()
        self._parts_bytes = 0
        self._instances: np.ndarray | None = None
        self._tree: _Tree | None = None
        h = lab.get("params_hash")
        recs = self.store.records(LABELS_STAGE)
        counts = np.zeros(NUM_CLASSES, np.int64)
        for info in recs.values():
            if h is None or info.get("params_hash") == h:
                counts += np.asarray(info.get("class_counts", [0] * NUM_CLASSES), np.int64)[:NUM_CLASSES]
        self.counts = counts
        tile_recs = self.store.records("labels_tiles")
        self.tiles = [int(t) for t in attrs["ingest"]["tiles"]]
        self.part_groups = {t: tile_parts(tile_recs, t) for t in self.tiles}
        # each tile's rows from its ingest record (one listing; on S3 one request a tile less),
        # else from its array's metadata
        ing, ih = self.store.records("ingest"), attrs["ingest"].get("params_hash")
        self.rows = {t: int(r["n_points"]) if (r := ing.get(str(t), {})).get("params_hash") == ih
                     and "n_points" in r else self.store.array_length(f"tiles/{t}/index") for t in self.tiles}
        self.nodes = [{"tile": t, "chunk": c, "rows": min(CHUNK_POINTS, self.rows[t] - c * CHUNK_POINTS)}
                      for t in self.tiles for c in range(-(-self.rows[t] // CHUNK_POINTS))]
        mins = np.min([s["mins"] for s in attrs["sources"] if "mins" in s] or [[0, 0, 0]], axis=0)
        maxs = np.max([s["maxs"] for s in attrs["sources"] if "maxs" in s] or [[0, 0, 0]], axis=0)
        self.origin = np.round((np.asarray(mins) + np.asarray(maxs)) / 2, 0)
        self.bounds = [*(np.asarray(mins) - self.origin).tolist(), *(np.asarray(maxs) - self.origin).tolist()]
        self.grid = attrs["grid"]

    # ------------------------------------------------------------------ reads
    def _read(self, path: str, start: int = 0, stop: int | None = None) -> np.ndarray:
        a = self.store.read_slice(path, start, stop)
        stop = start + len(a)
        with self._lock:
            self.chunk_reads += (stop - 1) // CHUNK_POINTS - start // CHUNK_POINTS + 1 if stop > start else 0
            self.bytes_read += a.nbytes
        return a

    def meta(self) -> dict[str, Any]:
        """What the page needs first (no array is read)."""
        return {
            "store": self.url, "origin": self.origin.tolist(), "bounds": self.bounds,
            "n_input": int(self.counts.sum()), "levels": LEVELS, "chunk_points": CHUNK_POINTS,
            "nodes": self.nodes, "first_view": first_view(self.nodes),
            "tiles": {str(t): self._tile_box(t) for t in self.tiles},
            "classes": [{"id": c, "name": CLASS_NAMES[c], "count": int(self.counts[c]),
                         "colour": list(CLASS_RGB[c])} for c in range(NUM_CLASSES)],
            "has_rgb": "rgb" in self.fields, "has_intensity": "intensity" in self.fields,
            "leaf_bits": LEAF_BITS,
        }

    def _tile_box(self, t: int) -> list[float]:
        nx = int(self.grid["shape"][0])
        size, (ox, oy) = float(self.grid["tile_size"]), self.grid["origin"]
        ix, iy = t % nx, t // nx
        x0, y0 = ox + ix * size - self.origin[0], oy + iy * size - self.origin[1]
        return [x0, y0, self.bounds[2], x0 + size, y0 + size, self.bounds[5]]

    def _tile_parts(self, t: int) -> dict[str, list[np.ndarray]]:
        """The tile's label parts (each sorted by original index), through the cache."""
        with self._lock:
            lock = self._tile_locks.setdefault(t, threading.Lock())
        with lock:
            with self._lock:
                if t in self._parts:
                    self._parts.move_to_end(t)
                    return self._parts[t]
            parts: dict[str, list[np.ndarray]] = {k: [] for k in _LABEL_FIELDS}
            for group in self.part_groups[t]:
                for k in _LABEL_FIELDS:
                    parts[k].append(self._read(f"{group}/{k}"))
            size = sum(a.nbytes for v in parts.values() for a in v)
            with self._lock:
                self._parts[t] = parts
                self._parts_bytes += size
                while self._parts_bytes > PARTS_CACHE_BYTES and len(self._parts) > 1:
                    _, old = self._parts.popitem(last=False)
                    self._parts_bytes -= sum(a.nbytes for v in old.values() for a in v)
            return parts

    def node(self, tile: int, chunk: int, level: int, first: int | None = None) -> bytes:
        """Levels ``first..level`` (default: ``level`` alone) of node (``tile``, ``chunk``)
        as one binary message."""
        first = level if first is None else first
        if tile not in self.rows:
            raise ConfigError(f"no tile {tile} in this store")
        n = self.rows[tile]
        start = chunk * CHUNK_POINTS
        if chunk < 0 or start >= n or not 0 <= first <= level < LEVELS:
            raise ConfigError(f"no node ({tile}, {chunk}) at levels {first}..{level}")
        stop = min(start + CHUNK_POINTS, n)
        # one seed for every node: its rows are its own points (a compact piece of space), so
        # the same row order draws an unrelated sample in each, and is made once
        rows = level_rows(stop - start, level, seed=0, first=first)
        core = self._read(f"tiles/{tile}/core", start, stop)
        rows = rows[core[rows]]
        index = self._read(f"tiles/{tile}/index", start, stop)[rows]
        xyz = self._read(f"tiles/{tile}/xyz", start, stop)[rows]
        pos = (xyz * self.scale + (self.offset - self.origin)).astype(np.float32)
        out: dict[str, np.ndarray] = {"position": pos}
        lab = {k: np.zeros(len(rows), dt) for k, dt in
               (("class", np.uint8), ("instance", np.uint32), ("segment", np.uint64), ("score", np.float32))}
        parts = self._tile_parts(tile)
        for j, pidx in enumerate(parts["index"]):
            at = np.minimum(np.searchsorted(pidx, index), max(len(pidx) - 1, 0))
            hit = pidx[at] == index if len(pidx) else np.zeros(len(index), bool)
            for k in lab:
                lab[k][hit] = parts[k][j][at[hit]]
        out["class"] = lab["class"]
        out["instance"] = lab["instance"]
        out["segment"] = (lab["segment"] >> np.uint64(LEAF_BITS)).astype(np.uint32)
        out["leaf"] = (lab["segment"] & np.uint64((1 << LEAF_BITS) - 1)).astype(np.uint32)
        out["score"] = lab["score"]
        if "rgb" in self.fields:
            rgb = self._read(f"tiles/{tile}/rgb", start, stop)[rows]
            out["rgb"] = (rgb >> 8 if rgb.dtype.itemsize > 1 and rgb.max(initial=0) > 255 else rgb).astype(np.uint8)
        if "intensity" in self.fields:
            out["intensity"] = self._read(f"tiles/{tile}/intensity", start, stop)[rows].astype(np.uint16)
        return pack({"tile": tile, "chunk": chunk, "level": level, "first": first, "n": len(rows)}, out)

    # ------------------------------------------------------------------ elements and the tree
    def tree(self) -> _Tree:
        with self._lock:
            if self._tree is None:
                self._tree = _Tree(self.store)
            return self._tree

    def instance_counts(self) -> np.ndarray | None:
        """Points per instance over every input point (``labels/instance``, read once, a
        chunk at a time); None in a store without the array."""
        with self._lock:
            if self._instances is not None:
                return self._instances
        if not self.store.has("labels/instance"):
            return None
        n = self.store.array_length("labels/instance")
        counts = np.zeros(1, np.int64)
        for a in range(0, n, CHUNK_POINTS):
            c = np.bincount(self._read("labels/instance", a, min(a + CHUNK_POINTS, n)))
            if len(c) > len(counts):
                counts = np.pad(counts, (0, len(c) - len(counts)))
            counts[:len(c)] += c
        with self._lock:
            self._instances = counts
        return counts

    def _relative(self, box: np.ndarray) -> np.ndarray:
        """A node table's box (store-local metres, or world in a store that wrote world
        boxes: the frame that puts it inside the scan) in metres from ``origin``."""
        local = box + np.tile(self.offset - self.origin, 2)
        lo, hi = np.asarray(self.bounds[:3]), np.asarray(self.bounds[3:])
        centre = (local[:3] + local[3:]) / 2
        inside = bool(((centre >= lo - 1) & (centre <= hi + 1)).all())
        return local if inside else box - np.tile(self.origin, 2)

    def element(self, instance: int, segment: int, leaf: int) -> dict[str, Any]:
        """A point's element: its instance's point count and box, and its tree path."""
        tree = self.tree()
        out: dict[str, Any] = {"instance": instance, "segment": segment, "leaf": leaf}
        if instance > 0:
            counts = self.instance_counts()
            out["n_points"] = None if counts is None else int(counts[instance]) if instance < len(counts) else 0
            box = tree.instance_box(instance)
            out["bbox"] = None if box is None else self._relative(np.asarray(box)).round(3).tolist()
        key = tree.tree_of(segment)
        out["tree"] = key
        out["path"] = tree.path(key, leaf) if key is not None else []
        return out


class _Tree:
    """The tree's node table and the coarse segments' element groups, indexed for lookups."""

    def __init__(self, store: RunStore) -> None:
        self.ok = store.has_file("tree/nodes.parquet")
        self.rows: dict[tuple[int, int], int] = {}
        self.parent: dict[int, dict[int, int]] = {}
        self.children: dict[int, dict[int, list[int]]] = {}
        self.group_first: dict[int, int] = {}
        self.group_members: dict[int, list[int]] = {}
        self.cols: dict[str, np.ndarray] = {}
        if store.has_file("coarse/segments.parquet"):
            seg = store.read_table("coarse/segments.parquet")
            ids = seg.column("segment").to_numpy().astype(np.int64)
            groups = seg.column("group").to_numpy().astype(np.int64) if "group" in seg.column_names else ids
            first: dict[int, int] = {}
            for s, g in zip(ids.tolist(), groups.tolist(), strict=True):
                first[g] = min(first.get(g, s), s)
            for s, g in zip(ids.tolist(), groups.tolist(), strict=True):
                self.group_first[s] = first[g]
                self.group_members.setdefault(first[g], []).append(s)
        if not self.ok:
            return
        t = store.read_table("tree/nodes.parquet")
        self.cols = {c: t.column(c).to_numpy(zero_copy_only=False) for c in t.column_names}
        seg, nid, par = (self.cols[c].astype(np.int64) for c in ("segment", "node_id", "parent"))
        for i, (s, n, p) in enumerate(zip(seg.tolist(), nid.tolist(), par.tolist(), strict=True)):
            self.rows[(s, n)] = i
            self.parent.setdefault(s, {})[n] = p
            if p >= 0 and p != n:
                self.children.setdefault(s, {}).setdefault(p, []).append(n)

    def tree_of(self, segment: int) -> int | None:
        if segment <= 0:
            return None
        return self.group_first.get(segment, segment)

    def node(self, key: int, n: int) -> dict[str, Any] | None:
        i = self.rows.get((key, n))
        if i is None:
            return None
        c = self.cols

        def num(name: str) -> float | None:
            v = float(c[name][i]) if name in c else float("nan")
            return None if not np.isfinite(v) else round(v, 4)

        seq = int(c["sequence"][i]) if "sequence" in c else -1
        cls = int(c["class_id"][i]) if "class_id" in c else 0
        return {"tree": key, "node": n, "depth": int(c["depth"][i]) if "depth" in c else None,
                "sequence": SEQUENCES.get(seq, str(seq)), "class": CLASS_NAMES[cls] if 0 <= cls < NUM_CLASSES else str(cls),
                "score": num("score"), "xi": num("xi"), "energy": [num(f"e{k}") for k in range(1, 6)],
                "n_points": int(c["n_points"][i]) if "n_points" in c else None,
                "instance": int(c["instance"][i]) if "instance" in c else None,
                "is_leaf": bool(c["is_leaf"][i]) if "is_leaf" in c else not self.children.get(key, {}).get(n),
                "n_children": len(self.children.get(key, {}).get(n, []))}

    def path(self, key: int, leaf: int) -> list[dict[str, Any]]:
        if key not in self.parent:
            return []
        return [d for n in tree_path(self.parent[key], leaf) if (d := self.node(key, n)) is not None]

    def roots(self, limit: int) -> tuple[list[dict[str, Any]], int]:
        found = [(k, n) for k, par in self.parent.items() for n, p in par.items() if p < 0 or p == n]
        nodes = [d for k, n in found if (d := self.node(k, n)) is not None]
        nodes.sort(key=lambda d: (-(d["n_points"] or 0), d["tree"], d["node"]))
        return nodes[:limit], len(nodes)

    def kids(self, key: int, n: int) -> list[dict[str, Any]]:
        return [d for c in sorted(self.children.get(key, {}).get(n, [])) if (d := self.node(key, c)) is not None]

    def subtree(self, key: int, n: int) -> dict[str, Any]:
        return {"tree": key, "node": n, "segments": sorted(self.group_members.get(key, [key])),
                "nodes": subtree_leaves(self.children.get(key, {}), n)}

    def instance_box(self, instance: int) -> list[float] | None:
        c = self.cols
        if not self.ok or "instance" not in c:
            return None
        sel = c["instance"].astype(np.int64) == instance
        if "is_leaf" in c and (sel & c["is_leaf"].astype(bool)).any():
            sel &= c["is_leaf"].astype(bool)
        if not sel.any():
            return None
        lo = [float(c[k][sel].min()) for k in ("xmin", "ymin", "zmin")]
        hi = [float(c[k][sel].max()) for k in ("xmax", "ymax", "zmax")]
        return lo + hi
