"""Level of detail for ``hollowtree view``: pure NumPy, no I/O.

A *node* of the viewer is one chunk of a tile's arrays (``tiles/<tile>/xyz`` rows
``[c * CHUNK_POINTS, (c + 1) * CHUNK_POINTS)``). A tile is sorted in 3-D Morton order, so a
node is a compact piece of space, read whole by one chunk read per array. Its rows are
put in a seeded random order (:func:`level_rows`) and cut into :data:`LEVELS` levels: level
``k`` holds the rows up to the fraction ``2 ** (k - LEVELS + 1)`` of the node, so level 0
is a uniform 1/64 sample of the node's piece of space and each level doubles it. The
viewer asks for a node's levels one after another and only gets the rows it lacks.

The first view (:func:`first_view`) is a bounded plan: at most :data:`FIRST_TILES` tiles
(the largest) and :data:`FIRST_POINTS` points, whatever the store's size, so the number of
chunks it reads does not grow with the point count; the rest streams in afterwards.
"""

from __future__ import annotations

import functools
import json
import struct
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

__all__ = ["LEVELS", "FIRST_TILES", "FIRST_POINTS", "level_fraction", "level_rows", "level_size",
           "first_view", "pack", "unpack", "tree_path", "subtree_leaves"]

#: Levels of a node: level k holds the fraction 2 ** (k - LEVELS + 1) of its rows.
LEVELS = 7
#: The first view reads at most this many tiles ...
FIRST_TILES = 6
#: ... and sends at most this many points.
FIRST_POINTS = 400_000


def level_fraction(level: int) -> float:
    """The fraction of a node's rows held by levels ``0..level`` together."""
    return float(2.0 ** (min(level, LEVELS - 1) - LEVELS + 1))


def _cut(n: int, level: int) -> int:
    return n if level >= LEVELS - 1 else int(np.ceil(n * level_fraction(level)))


def level_size(n: int, level: int) -> int:
    """Rows of a node of ``n`` rows that level ``level`` adds to the levels below it."""
    if level < 0 or level >= LEVELS:
        return 0
    return _cut(n, level) - (_cut(n, level - 1) if level else 0)


def level_rows(n: int, level: int, seed: int, first: int | None = None) -> np.ndarray:
    """The rows (sorted) of a node of ``n`` rows that levels ``first..level`` add (``first``
    defaults to ``level``): a seeded random sample, disjoint from every other level's; all
    levels together are every row."""
    first = level if first is None else first
    if not 0 <= first <= level < LEVELS:
        raise ValueError(f"levels must be 0 <= first <= level < {LEVELS}, not {first}..{level}")
    perm = _permutation(n, seed)
    lo = _cut(n, first - 1) if first else 0
    return np.sort(perm[lo:_cut(n, level)])


@functools.lru_cache(maxsize=8)
def _permutation(n: int, seed: int) -> np.ndarray:
    """A seeded permutation of ``range(n)``, made once (nodes are mostly ``CHUNK_POINTS``
    rows, so one permutation serves every full node of a store that uses one seed)."""
    perm = np.random.default_rng(seed).permutation(n)
    perm.setflags(write=False)
    return perm


def first_view(nodes: Sequence[Mapping[str, int]], *, max_tiles: int = FIRST_TILES,
               max_points: int = FIRST_POINTS) -> list[dict[str, int]]:
    """The nodes of the first view and the level to fetch each at.

    ``nodes``: ``{"tile", "chunk", "rows"}`` of every node. The first view takes the
    ``max_tiles`` tiles with most rows (the building, where a scan is densest) and the
    highest level at which their nodes hold at most ``max_points`` rows (level 0 at least):
    bounded whatever the store holds. Returned ordered by tile, then chunk.
    """
    per_tile: dict[int, int] = {}
    for nd in nodes:
        per_tile[nd["tile"]] = per_tile.get(nd["tile"], 0) + int(nd["rows"])
    chosen = set(sorted(per_tile, key=lambda t: (-per_tile[t], t))[:max_tiles])
    picked = [nd for nd in nodes if nd["tile"] in chosen]
    level = 0
    for k in range(LEVELS - 1, -1, -1):
        if sum(_cut(int(nd["rows"]), k) for nd in picked) <= max_points:
            level = k
            break
    # at level 0 the plan may still exceed max_points on huge tiles: drop nodes evenly
    while len(picked) > 1 and sum(_cut(int(nd["rows"]), level) for nd in picked) > max_points:
        picked = picked[::2]
    return [{"tile": int(nd["tile"]), "chunk": int(nd["chunk"]), "level": level}
            for nd in sorted(picked, key=lambda d: (d["tile"], d["chunk"]))]


def pack(header: Mapping[str, Any], arrays: Mapping[str, np.ndarray]) -> bytes:
    """One binary message: a little-endian uint32 header length, the JSON header (with
    ``fields``: name, dtype, shape, byte offset into the body) padded to 4 bytes, then the
    arrays, each starting on a 4-byte boundary (JavaScript typed arrays view them in place)."""
    fields, blobs, off = [], [], 0
    for name, a in arrays.items():
        a = np.ascontiguousarray(a)
        if a.dtype.byteorder == ">":
            a = a.astype(a.dtype.newbyteorder("<"))
        raw = a.tobytes()
        fields.append({"name": name, "dtype": a.dtype.str.lstrip("<|="), "shape": list(a.shape), "offset": off})
        pad = (-len(raw)) % 4
        blobs.append(raw + b"\0" * pad)
        off += len(raw) + pad
    head = json.dumps({**header, "fields": fields}, separators=(",", ":")).encode()
    head += b" " * ((-len(head)) % 4)
    return struct.pack("<I", len(head)) + head + b"".join(blobs)


def unpack(message: bytes) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """The inverse of :func:`pack` (for tests and benchmarks)."""
    (n,) = struct.unpack_from("<I", message)
    header = json.loads(message[4:4 + n])
    body = memoryview(message)[4 + n:]
    arrays = {}
    for f in header["fields"]:
        dt = np.dtype("<" + f["dtype"]) if f["dtype"][-1] != "1" else np.dtype(f["dtype"])
        count = int(np.prod(f["shape"])) if f["shape"] else 1
        arrays[f["name"]] = np.frombuffer(body, dt, count, f["offset"]).reshape(f["shape"])
    return header, arrays


def tree_path(parent: Mapping[int, int], node: int) -> list[int]:
    """Node ids from the root down to ``node`` (``parent`` maps a node to its parent; a
    root's parent is negative or absent)."""
    path, seen = [node], {node}
    while True:
        p = parent.get(path[-1], -1)
        if p is None or p < 0 or p in seen:
            break
        path.append(p)
        seen.add(p)
    return path[::-1]


def subtree_leaves(children: Mapping[int, Sequence[int]], node: int) -> list[int]:
    """Every node id of the subtree under ``node`` (itself included)."""
    out, stack = [], [node]
    while stack:
        n = stack.pop()
        out.append(n)
        stack.extend(children.get(n, ()))
    return sorted(out)
