"""PLY, ascii and binary: header facts and records in blocks (``tiling/readers.py``)."""

from __future__ import annotations

import io
import itertools
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import plyfile

from hollowtree.errors import (
    CorruptInputError,
)
from hollowtree.tiling._points import (
    PointBlock,
    SourceInfo,
    _errors,
    _finite_keep,
    _native,
    _span,
)

# -- PLY ------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _PlyLayout:
    text: bool
    byte_order: str
    version: str
    count: int
    dtype: np.dtype
    mode: str  # "mmap" (binary, streamed), "ascii" (streamed by lines) or "whole"
    offset: int  # byte offset of the vertex data (mmap) or of the body (ascii)
    skip_lines: int  # ascii: lines of the elements before the vertex element
    has_lists: bool


def _ply_layout(p: Path) -> _PlyLayout:
    with _errors(p, "corrupt PLY header", plyfile.PlyParseError, UnicodeDecodeError), p.open("rb") as f:
        # plyfile's header parser (a static method since plyfile 0.4) gives element dtypes
        # without reading the body; PlyData.read would load or map every element.
        ply = plyfile.PlyData._parse_header(f)
        body = f.tell()
    names = [e.name for e in ply.elements]
    if "vertex" not in names:
        raise CorruptInputError(f"{p}: PLY file has no 'vertex' element, so it holds no points")
    vertex = ply["vertex"]
    missing = {"x", "y", "z"} - {q.name for q in vertex.properties}
    if missing:
        raise CorruptInputError(f"{p}: PLY vertex element lacks {sorted(missing)}")
    before = ply.elements[: names.index("vertex")]

    def lists(e: plyfile.PlyElement) -> bool:
        return any(isinstance(q, plyfile.PlyListProperty) for q in e.properties)

    has_lists = lists(vertex)
    dtype = vertex.dtype(ply.byte_order)
    version = "ascii" if ply.text else {"<": "binary_little_endian", ">": "binary_big_endian"}.get(
        ply.byte_order, "binary")
    if ply.text:
        mode, offset = ("whole" if has_lists else "ascii"), body
    else:
        offset = body + sum(e.count * e.dtype(ply.byte_order).itemsize for e in before)
        mode = "whole" if has_lists or any(lists(e) for e in before) else "mmap"
        size = p.stat().st_size
        if mode == "mmap" and offset + vertex.count * dtype.itemsize > size:
            raise CorruptInputError(f"{p}: truncated PLY: {vertex.count} vertices need "
                                    f"{offset + vertex.count * dtype.itemsize} bytes but the file has {size}")
    return _PlyLayout(text=ply.text, byte_order=ply.byte_order, version=version, count=vertex.count,
                      dtype=dtype, mode=mode, offset=offset,
                      skip_lines=sum(e.count for e in before), has_lists=has_lists)


def _ply_roles(dtype: np.dtype) -> tuple[str | None, tuple[str, ...] | None, tuple[str, ...]]:
    """Which vertex fields are intensity (integer), rgb (uint8/uint16) and extra."""
    kinds = {n: dtype[n] for n in dtype.names or ()}
    inten = next((n for n in kinds if n.lower() in ("intensity", "scalar_intensity")
                  and kinds[n].kind in "ui"), None)
    rgb = ("red", "green", "blue")
    rgb_ok = all(c in kinds and kinds[c].kind == "u" and kinds[c].itemsize <= 2 for c in rgb)
    taken = {"x", "y", "z", inten, *(rgb if rgb_ok else ())}
    extra = tuple(n for n in kinds if n not in taken)
    return inten, (rgb if rgb_ok else None), extra


def _probe_ply(p: Path) -> SourceInfo:
    lay = _ply_layout(p)
    inten, rgb, extra = _ply_roles(lay.dtype)
    return SourceInfo(
        path=str(p), format="ply", format_version=lay.version, size_bytes=p.stat().st_size,
        point_count=lay.count, scale=None, offset=None, crs_wkt=None,
        has_intensity=inten is not None, has_rgb=rgb is not None, has_returns=False,
        has_gps_time=False, extra_dims=extra, mins=None, maxs=None,
    )


def _ply_chunks(p: Path, lay: _PlyLayout, lo: int, hi: int, chunk: int) -> Iterator[tuple[int, np.ndarray]]:
    if lay.mode == "mmap":
        mm = np.memmap(p, dtype=lay.dtype, mode="r", offset=lay.offset, shape=(lay.count,))
        for a in range(lo, hi, chunk):
            yield a, np.array(mm[a : min(a + chunk, hi)])
        del mm
    elif lay.mode == "ascii":
        with p.open("rb") as raw:
            raw.seek(lay.offset)
            text = io.TextIOWrapper(raw, encoding="ascii")
            skip = lay.skip_lines + lo
            if sum(1 for _ in itertools.islice(text, skip)) < skip:
                raise CorruptInputError(f"{p}: truncated PLY: the file ends before vertex {lo}")
            for a in range(lo, hi, chunk):
                rows = list(itertools.islice(text, min(chunk, hi - a)))
                if len(rows) < min(chunk, hi - a):
                    raise CorruptInputError(f"{p}: truncated PLY: {lay.count} vertices promised, "
                                            f"the file ends after {a + len(rows)}")
                yield a, np.loadtxt(rows, dtype=lay.dtype, ndmin=1, comments=None)
    else:
        data = plyfile.PlyData.read(str(p))["vertex"].data
        for a in range(lo, hi, chunk):
            yield a, data[a : min(a + chunk, hi)]


def _ply_blocks(p: Path, chunk: int, start: int, stop: int | None) -> Iterator[PointBlock]:
    lay = _ply_layout(p)
    inten, rgb, extra = _ply_roles(lay.dtype)
    lo, hi = _span(start, stop, lay.count)
    with _errors(p, "truncated or corrupt PLY data", plyfile.PlyParseError, UnicodeDecodeError):
        for first, arr in _ply_chunks(p, lay, lo, hi, chunk):
            xyz = np.stack([arr["x"], arr["y"], arr["z"]], axis=1).astype(np.float64)
            keep, index, dropped = _finite_keep(xyz, first)
            kept = {n: _native(arr[n][keep]) for n in arr.dtype.names or ()}
            yield PointBlock(
                xyz=xyz[keep], index=index, n_dropped=dropped,
                intensity=None if inten is None else np.clip(kept[inten], 0, 65535).astype(np.uint16),
                rgb=None if rgb is None else np.stack(
                    [kept[c].astype(np.uint16) * (257 if kept[c].dtype.itemsize == 1 else 1) for c in rgb],
                    axis=1).astype(np.uint16),
                extra={e: kept[e] for e in extra},
            )
