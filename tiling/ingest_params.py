"""The ingest's parameters, declared once (``hollowtree.params``): :class:`IngestParams`,
run by ``tiling/ingest.py``. A light module (no NumPy, no readers): the workflow's
``ingest`` section and the command line's flags are derived from these fields.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

from hollowtree.errors import ConfigError
from hollowtree.params import Params, param

__all__ = ["IngestParams", "UNIT_METRES"]

#: Metres per unit of the linear units a user may name (``ingest.units``, ``--units``).
UNIT_METRES = {"m": 1.0, "metre": 1.0, "meter": 1.0, "cm": 0.01, "mm": 0.001,
               "ft": 0.3048, "foot": 0.3048, "us-ft": 1200 / 3937, "us_survey_foot": 1200 / 3937}


@dataclass(frozen=True, kw_only=True)
class IngestParams(Params, owner="ingest"):
    """Parameters of an ingest; every one is recorded in the store.

    Parameters
    ----------
    tile_size : float or None
        Side of a tile's core, metres. None (the default, ``--tile-size auto``) picks the
        side from the inputs' extent and point count so that an average tile holds about
        ``tile_points`` points (a multiple of 5 m, at least 5 m; with ``voxel``, counting at
        most the points the voxel grid can keep, :func:`auto_tile_size`).
    tile_points : int
        Target points per tile for the automatic tile size (default 2 000 000).
    tile_origin : (x, y) or None
        A point the tile edges pass through (the inputs' coordinates, like ``bbox``): tiles
        that line up across runs or with a survey's own tiling (PDAL ``filters.splitter``'s
        ``origin_x``/``origin_y``). None (the default) centres the fewest tiles on the scan.
    buffer : float
        Width of the ring of neighbours' points copied into each tile, metres (default 2).
    voxel : float or None
        Keep one point per voxel of this size (metres); None keeps every point.
    bbox : (xmin, ymin, xmax, ymax) or None
        Ingest only the tiles whose core intersects this box (world coordinates).
    tiles : tuple of int or None
        Ingest only these tile ids.
    chunk_size : int
        Records per map unit (sets the map phase's memory: about 150 bytes per record).
    units : float, str or None
        Metres per coordinate unit of the inputs, or a unit's name
        (:data:`UNIT_METRES`: ``m``, ``ft``, ``us-ft``, ...). None (the
        default) takes the linear unit of the inputs' CRS (metres where they have none).
        The store holds metres: every length parameter (here and in later stages) is in
        metres whatever the input's unit; the exported scan keeps the input's own
        coordinates. ``bbox`` is in the inputs' coordinates.
    """

    tile_size: float | None = param(None, gt=0, doc="tile core side, metres; null = about tile_points points per tile")
    tile_points: int = param(2_000_000, ge=1, doc="target points per tile for the automatic tile size")
    tile_origin: tuple[float, float] | None = param(
        None, check=lambda o: None if len(o) == 2 else "must be [x, y]",
        doc="[x, y] the tile edges pass through (inputs' coordinates); null = the fewest tiles centred on the scan")
    buffer: float = param(2.0, ge=0, doc="buffer width, metres")
    voxel: float | None = param(None, gt=0, doc="keep one point per voxel of this size, metres; null = all")
    bbox: tuple[float, float, float, float] | None = param(
        None, check=lambda b: None if b[0] < b[2] and b[1] < b[3] else "must have xmin < xmax and ymin < ymax",
        doc="only tiles meeting [xmin, ymin, xmax, ymax]")
    tiles: tuple[int, ...] | None = param(None, ge=0, doc="only these tile ids")
    chunk_size: int = param(1_000_000, ge=1, doc="records per map task")
    units: float | str | None = param(
        None, gt=0, check=lambda u: None if not isinstance(u, str) or u.lower() in UNIT_METRES else
        f"must be metres per coordinate unit or a unit this knows ({', '.join(sorted(UNIT_METRES))})",
        doc="metres per coordinate unit of the inputs (0.3048) or a unit's name (m, ft, us-ft); null = the linear "
            "unit of their CRS, metres where they have none")

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.tile_size is not None and not self.buffer < self.tile_size:
            raise ConfigError(f"The 'buffer' parameter of ingest must be less than tile_size={self.tile_size}. "
                              f"Got {self.buffer!r} instead.")
        if self.tiles is not None:
            object.__setattr__(self, "tiles", tuple(sorted(set(self.tiles))))
        if isinstance(self.units, str):
            object.__setattr__(self, "units", UNIT_METRES[self.units.lower()])

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["bbox"] = list(self.bbox) if self.bbox is not None else None
        d["tiles"] = list(self.tiles) if self.tiles is not None else None
        if self.units is None:  # as stores made before the key recorded it
            del d["units"]
        if self.tile_origin is None:  # likewise
            del d["tile_origin"]
        else:
            d["tile_origin"] = list(self.tile_origin)
        return d

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> IngestParams:
        """Inverse of :meth:`to_dict`."""
        return cls(**data)
