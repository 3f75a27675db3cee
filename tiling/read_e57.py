"""E57 (pye57, optional): header facts and records in blocks, scan after scan (``tiling/readers.py``)."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hollowtree.errors import (
    CorruptInputError,
)
from hollowtree.tiling._points import (
    _F64,
    PointBlock,
    SourceInfo,
    _errors,
    _finite_keep,
    _optional,
    _scale_u16,
    _span,
)


@dataclass(frozen=True)
class _Scan:
    header: Any
    count: int
    coords: tuple[str, str, str]
    invalid: str | None
    intensity: tuple[float, float] | None  # limits, or (nan, nan) when the scan has none
    rgb_top: float | None
    pose: tuple[_F64, _F64] | None


def _e57_scans(e: Any, p: Path) -> list[_Scan]:
    from pye57 import libe57

    scans = []
    for i in range(e.scan_count):
        h = e.get_header(i)
        f = set(h.point_fields)
        cart = ("cartesianX", "cartesianY", "cartesianZ")
        sph = ("sphericalRange", "sphericalAzimuth", "sphericalElevation")
        coords = cart if set(cart) <= f else sph if set(sph) <= f else None
        if coords is None:
            raise CorruptInputError(f"{p}: E57 scan {i} has neither cartesian nor spherical coordinates")
        invalid = ("cartesianInvalidState" if coords is cart else "sphericalInvalidState")
        limits = None
        if "intensity" in f:
            try:
                limits = (float(h.intensityMinimum), float(h.intensityMaximum))
            except libe57.E57Exception:
                limits = (float("nan"), float("nan"))
        top = None
        if {"colorRed", "colorGreen", "colorBlue"} <= f:
            try:
                top = float(h["colorLimits"]["colorRedMaximum"].value()) or 255.0
            except libe57.E57Exception:
                top = 255.0
        pose = (h.rotation_matrix, np.asarray(h.translation, np.float64)) if h.has_pose() else None
        scans.append(_Scan(h, int(h.point_count), coords, invalid if invalid in f else None,
                           limits, top, pose))
    return scans


@contextlib.contextmanager
def _open_e57(p: Path) -> Iterator[tuple[Any, list[_Scan]]]:
    pye57 = _optional("pye57", p, "E57")
    from pye57 import libe57

    with _errors(p, "corrupt E57 file", libe57.E57Exception, RuntimeError):
        e = pye57.E57(str(p))
        try:
            yield e, _e57_scans(e, p)
        finally:
            e.close()


def _probe_e57(p: Path) -> SourceInfo:
    with _open_e57(p) as (e, scans):
        root = e.root
        crs = root["coordinateMetadata"].value() if root.isDefined("coordinateMetadata") else ""
        version = f"{root['versionMajor'].value()}.{root['versionMinor'].value()}"
        return SourceInfo(
            path=str(p), format="e57", format_version=version, size_bytes=p.stat().st_size,
            point_count=sum(s.count for s in scans), scale=None, offset=None, crs_wkt=crs or None,
            has_intensity=any(s.intensity for s in scans), has_rgb=any(s.rgb_top for s in scans),
            has_returns=False, has_gps_time=False, extra_dims=("scan_index",), mins=None, maxs=None,
        )


def _e57_blocks(p: Path, chunk: int, start: int, stop: int | None) -> Iterator[PointBlock]:
    with _open_e57(p) as (e, scans):
        any_int, any_rgb = any(s.intensity for s in scans), any(s.rgb_top for s in scans)
        lo, hi = _span(start, stop, sum(s.count for s in scans))
        g0 = 0
        for i, s in enumerate(scans):
            a, b = max(lo - g0, 0), min(hi - g0, s.count)
            if a < b:
                yield from _e57_scan_blocks(e, p, s, i, g0, a, b, chunk, any_int, any_rgb)
            g0 += s.count


def _e57_scan_blocks(e: Any, p: Path, s: _Scan, i: int, g0: int, a: int, b: int, chunk: int,
                     any_int: bool, any_rgb: bool) -> Iterator[PointBlock]:
    names = [*s.coords, *([s.invalid] if s.invalid else []), *(["intensity"] if s.intensity else []),
             *(["colorRed", "colorGreen", "colorBlue"] if s.rgb_top else [])]
    buf, bufs = e.make_buffers(names, min(chunk, b))
    reader = s.header.points.reader(bufs)
    try:
        pos = 0  # records of this scan consumed so far; libE57 cannot seek, so read past a
        while pos < b:
            got = int(reader.read())
            if got == 0:
                raise CorruptInputError(f"{p}: truncated E57: scan {i} promises {s.count} points "
                                        f"but ends after {pos}")
            u, v = max(a - pos, 0), min(b - pos, got)
            if u < v:
                yield _e57_block({n: buf[n][u:v] for n in names}, s, i, g0 + pos + u, any_int, any_rgb)
            pos += got
    finally:
        reader.close()


def _e57_block(d: dict[str, np.ndarray], s: _Scan, i: int, first: int,
               any_int: bool, any_rgb: bool) -> PointBlock:
    from pye57.utils import convert_spherical_to_cartesian

    xyz = np.stack([d[c] for c in s.coords], axis=1).astype(np.float64)
    if s.coords[0] == "sphericalRange":
        xyz = convert_spherical_to_cartesian(xyz)
    if s.pose is not None:  # the same expression as pye57's E57.to_global
        rot, t = s.pose
        xyz = (np.dot(rot, xyz.T) + t.reshape(3, 1)).T
    valid = None if s.invalid is None else d[s.invalid] == 0
    keep, index, dropped = _finite_keep(xyz, first, valid)
    n = int(keep.sum())
    intensity = rgb = None
    if s.intensity is not None:
        lo_, hi_ = s.intensity
        raw = d["intensity"][keep].astype(np.float64)
        scaled = (raw - lo_) * (65535.0 / (hi_ - lo_)) if hi_ > lo_ else raw
        intensity = np.clip(np.rint(scaled), 0, 65535).astype(np.uint16)
    elif any_int:
        intensity = np.zeros(n, np.uint16)
    if s.rgb_top is not None:
        rgb = np.stack([_scale_u16(d[c][keep], s.rgb_top) for c in ("colorRed", "colorGreen", "colorBlue")], 1)
    elif any_rgb:
        rgb = np.zeros((n, 3), np.uint16)
    return PointBlock(xyz=np.ascontiguousarray(xyz[keep]), index=index, intensity=intensity, rgb=rgb,
                      extra={"scan_index": np.full(n, i, np.uint32)}, n_dropped=dropped)
