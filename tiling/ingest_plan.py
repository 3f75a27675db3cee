"""What an ingest will do, before it reads a point: its parameters (:class:`IngestParams`,
declared in ``tiling/ingest_params.py``), the tile grid, the store's coordinates and the
map units (:func:`plan_ingest` -> :class:`IngestPlan`). ``tiling/ingest.py`` runs the plan."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hollowtree.columns import column_max, column_min
from hollowtree.errors import ConfigError, CorruptInputError
from hollowtree.tiling.grid import TileGrid
from hollowtree.tiling.ingest_params import IngestParams
from hollowtree.tiling.readers import (
    SourceInfo,
    crs_units,
    probe,
    read_blocks,
)
from hollowtree.tiling.stage import params_hash

__all__ = ["IngestParams", "IngestPlan", "MapUnit", "SURFACE_PER_FOOTPRINT", "auto_tile_size", "part_counts",
           "plan_ingest"]

#: Coordinate resolution for inputs that store floats (PLY, E57): 0.1 mm.
FLOAT_SOURCE_SCALE = 0.0001
_INT32_MAX = 2**31 - 1


@dataclass(frozen=True, kw_only=True)
class MapUnit:
    """One map task: records ``[start, stop)`` of source ``source``."""

    map_id: int
    source: int
    path: str
    base: int  # global index of the source's first record
    start: int
    stop: int


@dataclass(frozen=True, kw_only=True)
class IngestPlan:
    """Everything the tasks need, fixed before any of them runs."""

    sources: tuple[SourceInfo, ...]
    grid: TileGrid
    scale: tuple[float, float, float]
    offset: tuple[float, float, float]
    tiles: tuple[int, ...]
    fields: dict[str, list[Any]]  # name -> [dtype str, trailing shape]
    params: IngestParams
    units: tuple[MapUnit, ...] = field(repr=False)
    params_hash: str = ""
    #: metres per input coordinate unit along x, y, z, and where that came from
    metres_per_unit: tuple[float, float, float] = (1.0, 1.0, 1.0)
    unit_name: str = "metre (no CRS)"

    def attrs(self) -> dict[str, Any]:
        """The root attributes that describe this ingest."""
        return {
            "sources": [s.to_dict() for s in self.sources],
            "grid": self.grid.to_dict(),
            "coords": {"dtype": "int32", "scale": list(self.scale), "offset": list(self.offset),
                       # only where they are not metres: the identity of a store made before
                       **({"metres_per_unit": list(self.metres_per_unit), "unit": self.unit_name}
                          if self.metres_per_unit != (1.0, 1.0, 1.0) else {})},
            "fields": self.fields,
            "ingest": {"params": self.params.to_dict(), "params_hash": self.params_hash,
                       "tiles": list(self.tiles)},
        }


#: For the automatic tile size with a voxel: a scan keeps at most about this many times its
#: x-y footprint's area in surfaces (ground, walls, roofs) of one point per voxel face. It
#: bounds the points a voxel grid keeps, so a very dense scan does not get tiles far
#: smaller than its kept points need; it sets only the tile size, never a label.
SURFACE_PER_FOOTPRINT = 2.0


def auto_tile_size(width: float, depth: float, n_points: int, *, tile_points: int, buffer: float,
                   voxel: float | None = None) -> float:
    """Tile side (metres) for which an average tile holds about ``tile_points`` points.

    A multiple of 5 m, at least 5 m and more than twice the buffer. With ``voxel`` the
    points counted are at most those the voxel grid can keep
    (``SURFACE_PER_FOOTPRINT * area / voxel**2``).

    Examples
    --------
    >>> auto_tile_size(140.0, 100.0, 10_000_000, tile_points=2_000_000, buffer=2.0)
    55.0
    >>> auto_tile_size(140.0, 100.0, 100_000_000, tile_points=2_000_000, buffer=2.0)
    20.0
    >>> auto_tile_size(140.0, 100.0, 1_000_000_000, tile_points=2_000_000, buffer=2.0)
    10.0
    >>> auto_tile_size(140.0, 100.0, 1_000_000_000, tile_points=2_000_000, buffer=2.0, voxel=0.02)
    20.0
    """
    area = max(width, 1.0) * max(depth, 1.0)
    if voxel:
        n_points = min(n_points, int(SURFACE_PER_FOOTPRINT * area / voxel**2))
    side = math.sqrt(area * tile_points / max(n_points, 1))
    side = max(5.0, 5.0 * math.ceil(side / 5.0))
    while side <= 2 * buffer:
        side += 5.0
    return side


def part_counts(points: dict[int, int], *, above: float = 2.0, cap: dict[int, int] | None = None) -> dict[int, int]:
    """How many parts each unit of a wave is cut into (issue 44's balance): a unit above
    ``above`` times the median unit's points (units without points left out of the median)
    into ``ceil(points / median)``, at most ``cap[unit]`` (and at least 1); the others 1.
    The ingest's dense tiles and the labels' tiles are cut this way.

    >>> part_counts({0: 10, 1: 10, 2: 40, 3: 0}), part_counts({0: 10, 1: 10, 2: 40}, cap={2: 3})
    ({0: 1, 1: 1, 2: 4, 3: 1}, {0: 1, 1: 1, 2: 3})
    """
    pts = sorted(p for p in points.values() if p > 0)
    n = len(pts)
    med = (pts[n // 2] if n % 2 else (pts[n // 2 - 1] + pts[n // 2]) / 2) if pts else 0
    out = {}
    for t, p in points.items():
        k = -(-int(p) // int(med)) if med and p > above * med else 1
        out[t] = max(1, min(k, cap[t])) if cap is not None and t in cap else k
    return out


def _source_bounds(info: SourceInfo, chunk_size: int) -> tuple[np.ndarray, np.ndarray]:
    if info.mins is not None and info.maxs is not None:
        return np.asarray(info.mins, float), np.asarray(info.maxs, float)
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for block in read_blocks(info.path, chunk_size=chunk_size):
        if len(block.xyz):
            lo = np.minimum(lo, column_min(block.xyz))
            hi = np.maximum(hi, column_max(block.xyz))
    return lo, hi


def _fields(sources: Sequence[SourceInfo]) -> dict[str, list[Any]]:
    """Per-point fields of the store: those any source has, with their dtypes."""
    out: dict[str, list[Any]] = {}
    if any(s.has_intensity for s in sources):
        out["intensity"] = ["uint16", []]
    if any(s.has_rgb for s in sources):
        out["rgb"] = ["uint16", [3]]
    if any(s.has_returns for s in sources):
        out["return_number"] = ["uint8", []]
        out["number_of_returns"] = ["uint8", []]
    if any(s.has_gps_time for s in sources):
        out["gps_time"] = ["float64", []]
    for s in sources:
        if not s.extra_dims:
            continue
        block = next(iter(read_blocks(s.path, chunk_size=1, stop=1)), None)
        if block is None:
            continue
        for name, values in block.extra.items():
            key = f"extra.{name}"
            if key not in out:
                out[key] = [np.asarray(values).dtype.str, list(np.asarray(values).shape[1:])]
    return out


def _metres_per_unit(sources: Sequence[SourceInfo], params: IngestParams) -> tuple[np.ndarray, str]:
    """Metres per input coordinate unit (x, y, z) and its description: ``params.units``,
    else the inputs' CRS (their CRSs are one, checked before), else metres."""
    if params.units is not None:
        return np.full(3, float(params.units)), f"{params.units:g} m per unit (ingest.units)"
    wkt = next((s.crs_wkt for s in sources if s.crs_wkt), None)
    found = crs_units(wkt, next((s.path for s in sources if s.crs_wkt), ""))
    if found is None:
        return np.ones(3), "metre (no CRS)" if wkt is None else "metre (the CRS names no linear unit)"
    f, name = found
    return np.asarray(f, float), f"{name} ({f[0]:g} m, from the CRS)"


def plan_ingest(inputs: Sequence[str | Path], params: IngestParams, *, grid: TileGrid | None = None) -> IngestPlan:
    """Probe the inputs and fix the grid, the coordinate grid and the map units.

    ``grid``: this tile grid instead of the one the bounds and parameters give (a store's
    own, to resume it with the grid it was made with).

    Raises
    ------
    ConfigError, InputFileError, CorruptInputError, UnsupportedInputError
        On a bad input or parameter; nothing has been written then.
    """
    if not inputs:
        raise ConfigError("ingest needs at least one input file")
    sources = tuple(probe(p) for p in inputs)
    crs = {s.crs_wkt for s in sources if s.crs_wkt}
    if len(crs) > 1:
        named = ", ".join(Path(s.path).name for s in sources if s.crs_wkt)
        raise ConfigError(f"inputs {named} have different coordinate reference systems; reproject them to one first")
    for s in sources:
        if s.point_count == 0:
            raise CorruptInputError(f"{s.path}: holds no points")
    f, unit_name = _metres_per_unit(sources, params)
    bounds = [_source_bounds(s, params.chunk_size) for s in sources]
    lo = np.min([b[0] for b in bounds], axis=0) * f
    hi = np.max([b[1] for b in bounds], axis=0) * f
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
        raise CorruptInputError(f"{sources[0].path}: no finite coordinates in the inputs")
    if grid is None:
        tile_size = params.tile_size
        if tile_size is None:
            tile_size = auto_tile_size(
                float(hi[0] - lo[0]), float(hi[1] - lo[1]), sum(s.point_count for s in sources),
                tile_points=params.tile_points, buffer=params.buffer, voxel=params.voxel,
            )
        align = None if params.tile_origin is None else (params.tile_origin[0] * f[0], params.tile_origin[1] * f[1])
        grid = TileGrid.covering(lo[0], lo[1], hi[0], hi[1], tile_size=tile_size, buffer=params.buffer, align=align)

    las = [s for s in sources if s.scale is not None]
    scale = np.full(3, FLOAT_SOURCE_SCALE)
    if las:  # the inputs' own integer grid, in metres
        scale = np.min([np.asarray(s.scale, float) for s in las], axis=0) * f
        if any(s.scale is None for s in sources):
            scale = np.minimum(scale, FLOAT_SOURCE_SCALE)
    if las and las[0].offset is not None:
        offset = np.asarray(las[0].offset, float) * f
    else:
        offset = np.floor(lo)
    span = np.maximum(np.abs(hi - offset), np.abs(lo - offset)) / scale
    if np.any(span > _INT32_MAX):
        raise ConfigError(
            f"the inputs span {hi - lo} m: too large for int32 coordinates at scale {scale.tolist()}"
        )

    all_tiles = np.arange(grid.n_tiles)
    if params.tiles is not None:
        if max(params.tiles) >= grid.n_tiles:
            raise ConfigError(
                f"tile {max(params.tiles)} does not exist: the grid has {grid.n_tiles} tiles (0-{grid.n_tiles - 1})"
            )
        all_tiles = np.asarray(params.tiles)
    if params.bbox is not None:
        xmin, ymin, xmax, ymax = (v * f[i % 2] for i, v in enumerate(params.bbox))
        keep = []
        for t in all_tiles:
            x0, y0, x1, y1 = grid.core_bounds(int(t))
            if x0 < xmax and xmin < x1 and y0 < ymax and ymin < y1:
                keep.append(int(t))
        if not keep:
            raise ConfigError(f"bbox {list(params.bbox)} meets no tile of the inputs' extent {lo[:2].tolist()}-{hi[:2].tolist()}")
        all_tiles = np.asarray(keep)

    units = []
    base = 0
    for i, s in enumerate(sources):
        for start in range(0, s.point_count, params.chunk_size):
            units.append(MapUnit(map_id=len(units), source=i, path=s.path, base=base, start=start,
                                 stop=min(start + params.chunk_size, s.point_count)))
        base += s.point_count
    plan = IngestPlan(
        sources=sources, grid=grid, scale=tuple(scale.tolist()), offset=tuple(offset.tolist()),
        tiles=tuple(int(t) for t in all_tiles), fields=_fields(sources), params=params,
        units=tuple(units), metres_per_unit=tuple(float(v) for v in f), unit_name=unit_name,
    )
    identity = {k: v for k, v in plan.attrs().items() if k != "ingest"}
    identity["params"] = params.to_dict()
    identity["sources"] = [
        {"path": str(Path(s.path).resolve()), "size": s.size_bytes, "points": s.point_count} for s in sources
    ]
    return IngestPlan(**{**plan.__dict__, "params_hash": params_hash(identity)})
