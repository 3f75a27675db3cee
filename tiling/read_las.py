"""LAS, LAZ and COPC: header facts, the CRS and its unit, records in blocks (``tiling/readers.py``)."""

from __future__ import annotations

import struct
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import laspy
import numpy as np

from hollowtree.errors import (
    ConfigError,
    CorruptInputError,
)
from hollowtree.tiling._points import (
    PointBlock,
    SourceInfo,
    _errors,
    _span,
    _vec,
    logger,
)

_LAS_ERRORS = (laspy.errors.LaspyException, RuntimeError)  # lazrs.LazrsError is a RuntimeError
_LAS_STANDARD_EXTRAS = ("classification", "point_source_id")


def _las_header_checks(p: Path, h: laspy.LasHeader) -> None:
    if not h.are_points_compressed:
        need = h.offset_to_point_data + h.point_count * h.point_format.size
        size = p.stat().st_size
        if size < need:
            raise CorruptInputError(f"{p}: truncated LAS: the header promises {h.point_count} points "
                                    f"({need} bytes) but the file has {size} bytes")


#: Inputs whose broken CRS VLR this process has warned about while reading: a run reads a
#: file's header more than once (probe, ingest) and says so once.
_WARNED_CRS: set[str] = set()


def las_crs(header: laspy.LasHeader, path: str | Path, *, writing: str | None = None) -> Any:
    """The CRS of a LAS header (a ``pyproj.CRS``), or None when it has none, or (with a
    warning naming ``path``) when its CRS VLR is empty or broken, as in a WKT VLR that
    holds ``''``: a scan without a readable CRS is still a scan. Reading, the warning is
    given once per file and process; ``writing`` (what gets no CRS) warns every time."""
    try:
        return header.parse_crs()
    except Exception as e:  # pyproj's CRSError, laspy's errors: a broken VLR is not a reason to stop  # noqa: BLE001
        if writing is not None:
            logger.warning("%s: CRS VLR could not be parsed (%s); %s has no CRS", path, e, writing)
        elif str(path) not in _WARNED_CRS:
            _WARNED_CRS.add(str(path))
            logger.warning("%s: CRS VLR could not be parsed (%s); taken as no CRS", path, e)
        return None


def crs_units(wkt: str | None, path: str | Path = "") -> tuple[tuple[float, float, float], str] | None:
    """Metres per coordinate unit along x, y and z, and the unit's name, from a CRS's WKT;
    None where there is no CRS, it cannot be read (a warning) or names no linear unit.
    z takes the vertical CRS's unit where the CRS is compound, else the horizontal one.

    Raises
    ------
    ConfigError
        If the horizontal CRS is geographic (coordinates in degrees): the method's
        parameters are lengths.

    Examples
    --------
    >>> crs_units('PROJCS["x",GEOGCS["g",DATUM["d",SPHEROID["s",6378137,298.257]],PRIMEM["G",0],'
    ...           'UNIT["degree",0.0174532925199433]],PROJECTION["Transverse_Mercator"],UNIT["foot",0.3048]]')
    ((0.3048, 0.3048, 0.3048), 'foot')
    >>> crs_units(None) is None
    True
    """
    if not wkt:
        return None
    try:
        import pyproj

        crs = pyproj.CRS.from_wkt(wkt)
    except Exception as e:  # pyproj's CRSError and friends: an unreadable CRS is no CRS  # noqa: BLE001
        logger.warning("%s: CRS could not be read (%s); coordinates taken as metres", path or "input", e)
        return None
    subs = crs.sub_crs_list if crs.is_compound else [crs]
    horizontal = next((c for c in subs if not c.is_vertical), None)
    vertical = next((c for c in subs if c.is_vertical), None)
    if horizontal is not None and horizontal.is_geographic:
        raise ConfigError(f"{path or 'input'}: coordinates in degrees ({horizontal.name}); reproject the scan "
                          "to a projected CRS in metres or feet first, or name its units with --units")

    def linear(c: Any) -> tuple[float, str] | None:
        axes = [a for a in (c.axis_info if c is not None else []) if a.unit_conversion_factor]
        if not axes or (axes[0].unit_name or "").lower() in ("degree", "radian", "grad"):
            return None
        return float(axes[0].unit_conversion_factor), str(axes[0].unit_name)

    h = linear(horizontal)
    if h is None:
        return None
    v = linear(vertical) or h
    return (h[0], h[0], v[0]), h[1]


def _probe_las(p: Path) -> SourceInfo:
    with _errors(p, "corrupt LAS/LAZ header", *_LAS_ERRORS), laspy.open(p) as r:
        h = r.header
        _las_header_checks(p, h)
        parsed = las_crs(h, p)
        crs = None if parsed is None else parsed.to_wkt()
        names = set(h.point_format.dimension_names)
        return SourceInfo(
            path=str(p), format="laz" if h.are_points_compressed else "las",
            format_version=f"{h.version} pf{h.point_format.id}", size_bytes=p.stat().st_size,
            point_count=int(h.point_count), scale=_vec(h.scales), offset=_vec(h.offsets),
            crs_wkt=crs, has_intensity="intensity" in names, has_rgb="red" in names,
            has_returns="return_number" in names, has_gps_time="gps_time" in names,
            extra_dims=(*_LAS_STANDARD_EXTRAS, *h.point_format.extra_dimension_names),
            mins=_vec(h.mins), maxs=_vec(h.maxs),
        )


def _variable_chunks(h: laspy.LasHeader) -> bool:
    """True for LAZ with variable-size chunks (COPC), where lazrs' seek lands wrongly."""
    if not h.are_points_compressed:
        return False
    vlr = h.vlrs[h.vlrs.index("LasZipVlr")]
    return bool(struct.unpack_from("<I", vlr.record_data, 12)[0] == 0xFFFFFFFF)


def _las_blocks(p: Path, chunk: int, start: int, stop: int | None) -> Iterator[PointBlock]:
    with _errors(p, "corrupt LAS/LAZ header", *_LAS_ERRORS):
        r = laspy.open(p)
    with r, _errors(p, "truncated or corrupt LAS/LAZ data", *_LAS_ERRORS):
        h = r.header
        _las_header_checks(p, h)
        n = int(h.point_count)
        lo, hi = _span(start, stop, n)
        names = set(h.point_format.dimension_names)
        extras = (*_LAS_STANDARD_EXTRAS, *h.point_format.extra_dimension_names)
        if 0 < lo < hi and _variable_chunks(h):
            # lazrs 0.8 seeks to the wrong records in variable-chunk LAZ (checked on
            # PDAL's lone-star.copc.laz), so decompress and discard up to ``lo`` instead.
            for skipped in range(0, lo, chunk):
                r.read_points(min(chunk, lo - skipped))
        elif 0 < lo < hi:
            r.seek(lo)
        pos = lo
        while pos < hi:
            k = min(chunk, hi - pos)
            rec = r.read_points(k)
            if len(rec) != k:
                raise CorruptInputError(f"{p}: truncated LAS/LAZ: the header promises {n} points "
                                        f"but the data ends after {pos + len(rec)}")
            # Scaled coordinates computed straight into their columns, as laspy computes
            # them (X * scale + offset); plain fields are views of the block's records
            # (no copies: blocks are read-only to their consumers).
            xyz = np.empty((k, 3))
            raw = rec.array
            for axis, name in enumerate("XYZ"):
                np.multiply(raw[name], h.scales[axis], out=xyz[:, axis])
                np.add(xyz[:, axis], h.offsets[axis], out=xyz[:, axis])
            yield PointBlock(
                xyz=xyz, index=np.arange(pos, pos + k, dtype=np.uint64),
                intensity=np.asarray(rec.intensity, dtype=np.uint16),
                rgb=(np.stack([rec.red, rec.green, rec.blue], axis=1).astype(np.uint16, copy=False)
                     if "red" in names else None),
                return_number=np.asarray(rec.return_number, dtype=np.uint8),
                number_of_returns=np.asarray(rec.number_of_returns, dtype=np.uint8),
                gps_time=np.asarray(rec.gps_time, dtype=np.float64) if "gps_time" in names else None,
                extra={e: np.asarray(rec[e]) for e in extras},
            )
            pos += k
