"""PDAL pipelines (``.json``; only where ``import pdal`` works): header facts and records in blocks (``tiling/readers.py``)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from hollowtree.tiling._points import (
    PointBlock,
    SourceInfo,
    _errors,
    _finite_keep,
    _optional,
    _vec,
)

# -- PDAL (optional) ------------------------------------------------------------------------
# libpdal has no Debian bookworm or PyPI build that our machines can install, so this thin
# adapter is untested here; its test skips unless ``import pdal`` works.

_PDAL_DIMS = {"X", "Y", "Z", "Intensity", "Red", "Green", "Blue", "ReturnNumber",
              "NumberOfReturns", "GpsTime"}


def _probe_pdal(p: Path) -> SourceInfo:
    pdal = _optional("pdal", p, "a PDAL pipeline")
    with _errors(p, "PDAL pipeline failed", RuntimeError, KeyError):
        info = next(iter(pdal.Pipeline(p.read_text()).quickinfo.values()))
        dims = [d.strip() for d in str(info.get("dimensions", "")).split(",") if d.strip()]
        bounds = info.get("bounds", {})
        return SourceInfo(
            path=str(p), format="pdal", format_version=str(pdal.__version__), size_bytes=p.stat().st_size,
            point_count=int(info["num_points"]), scale=None, offset=None,
            crs_wkt=(info.get("srs") or {}).get("wkt") or None, has_intensity="Intensity" in dims,
            has_rgb="Red" in dims, has_returns="ReturnNumber" in dims, has_gps_time="GpsTime" in dims,
            extra_dims=tuple(d for d in dims if d not in _PDAL_DIMS),
            mins=_vec([bounds[k] for k in ("minx", "miny", "minz")]) if bounds else None,
            maxs=_vec([bounds[k] for k in ("maxx", "maxy", "maxz")]) if bounds else None,
        )


def _pdal_blocks(p: Path, chunk: int, start: int, stop: int | None) -> Iterator[PointBlock]:
    pdal = _optional("pdal", p, "a PDAL pipeline")
    hi = stop if stop is not None else np.iinfo(np.int64).max
    with _errors(p, "PDAL pipeline failed", RuntimeError):
        pipeline = pdal.Pipeline(p.read_text())
        pos = 0
        for arr in pipeline.iterator(chunk_size=chunk):  # streams where the stages allow
            a, b = max(start - pos, 0), min(hi - pos, len(arr))
            if a < b:
                yield _pdal_block(arr[a:b], pos + a)
            pos += len(arr)
            if pos >= hi:
                break


def _pdal_block(arr: np.ndarray, first: int) -> PointBlock:
    names = set(arr.dtype.names or ())
    xyz = np.stack([arr["X"], arr["Y"], arr["Z"]], axis=1).astype(np.float64)
    keep, index, dropped = _finite_keep(xyz, first)
    arr = arr[keep]

    def get(name: str, dtype: Any) -> Any:
        return np.asarray(arr[name], dtype) if name in names else None

    return PointBlock(
        xyz=xyz[keep], index=index, n_dropped=dropped, intensity=get("Intensity", np.uint16),
        rgb=np.stack([arr[c] for c in ("Red", "Green", "Blue")], 1).astype(np.uint16) if "Red" in names else None,
        return_number=get("ReturnNumber", np.uint8), number_of_returns=get("NumberOfReturns", np.uint8),
        gps_time=get("GpsTime", np.float64),
        extra={n: np.array(arr[n]) for n in names - _PDAL_DIMS},
    )
