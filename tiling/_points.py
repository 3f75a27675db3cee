"""What every point reader shares: :class:`SourceInfo`, :class:`PointBlock`, the suffix
table and the helpers that turn a library's failure into one line naming the file
(``tiling/readers.py`` has the conventions)."""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from hollowtree.errors import (
    ConfigError,
    CorruptInputError,
    InputFileError,
    PipelineError,
    UnsupportedInputError,
)

logger = logging.getLogger("hollowtree.tiling.readers")

SUFFIXES: dict[str, str] = {".las": "las", ".laz": "las", ".ply": "ply", ".e57": "e57", ".json": "pdal"}
_MAGIC = {"las": b"LASF", "ply": b"ply", "e57": b"ASTM-E57"}
_F64 = npt.NDArray[np.float64]
_Vec3 = tuple[float, float, float]


@dataclass(frozen=True, kw_only=True)
class SourceInfo:
    """What a file's header says, read without touching the points.

    ``scale``/``offset`` are ``None`` for formats that store floats (PLY, E57); ``mins``/
    ``maxs`` are ``None`` where the header holds no trustworthy bounds (PLY has none;
    E57 writers disagree on the frame of ``cartesianBounds``). ``point_count`` counts
    records, including any that :func:`read_blocks` will drop.

    Examples
    --------
    >>> info = SourceInfo(path="a.ply", format="ply", format_version="ascii", size_bytes=10,
    ...                   point_count=3, scale=None, offset=None, crs_wkt=None,
    ...                   has_intensity=False, has_rgb=True, has_returns=False,
    ...                   has_gps_time=False, extra_dims=("nx",), mins=None, maxs=None)
    >>> SourceInfo.from_dict(info.to_dict()) == info
    True
    """

    path: str
    format: str
    format_version: str
    size_bytes: int
    point_count: int
    scale: _Vec3 | None
    offset: _Vec3 | None
    crs_wkt: str | None
    has_intensity: bool
    has_rgb: bool
    has_returns: bool
    has_gps_time: bool
    extra_dims: tuple[str, ...]
    mins: _Vec3 | None
    maxs: _Vec3 | None

    def to_dict(self) -> dict[str, Any]:
        """Return a JSON-ready dict; :meth:`from_dict` inverts it."""
        return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> SourceInfo:
        """Build from :meth:`to_dict` output; unknown or missing keys are errors."""
        names = [f.name for f in fields(cls)]
        unknown, missing = sorted(set(data) - set(names)), [k for k in names if k not in data]
        if unknown or missing:
            raise ConfigError(f"SourceInfo.from_dict: unknown keys {unknown}, missing keys {missing}.")
        values: dict[str, Any] = {k: tuple(v) if isinstance(v, list) else v for k, v in data.items()}
        return cls(**values)


@dataclass(frozen=True, kw_only=True, eq=False)
class PointBlock:
    """A block of consecutive records of one file, as plain arrays.

    Attributes
    ----------
    xyz : ndarray of shape (n_points, 3), float64
        World coordinates (LAS: laspy's scaled values; E57: with each scan's pose applied).
    index : ndarray of shape (n_points,), uint64
        Record number in the file (0-based, file order; gaps where records were dropped).
    intensity : ndarray of shape (n_points,), uint16, or None
    rgb : ndarray of shape (n_points, 3), uint16, or None
    return_number, number_of_returns : ndarray of shape (n_points,), uint8, or None
    gps_time : ndarray of shape (n_points,), float64, or None
    extra : dict of str to ndarray of shape (n_points, ...)
        Other per-point fields, e.g. ``gt_class`` and ``gt_instance`` of synthetic scans.
    n_dropped : int
        Records in this block's range that were dropped (non-finite or invalid).
    """

    xyz: _F64
    index: npt.NDArray[np.uint64]
    intensity: npt.NDArray[np.uint16] | None = None
    rgb: npt.NDArray[np.uint16] | None = None
    return_number: npt.NDArray[np.uint8] | None = None
    number_of_returns: npt.NDArray[np.uint8] | None = None
    gps_time: _F64 | None = None
    extra: dict[str, np.ndarray] = field(default_factory=dict)
    n_dropped: int = 0

    def __post_init__(self) -> None:
        n = len(self.index)
        if self.xyz.shape != (n, 3) or self.xyz.dtype != np.float64 or self.index.dtype != np.uint64:
            raise ConfigError(f"PointBlock: xyz must be float64 ({n}, 3) and index uint64; "
                              f"got {self.xyz.dtype} {self.xyz.shape} and {self.index.dtype}.")
        arrays = {k: getattr(self, k) for k in ("intensity", "rgb", "return_number",
                                                "number_of_returns", "gps_time")} | self.extra
        bad = [k for k, a in arrays.items() if a is not None and len(a) != n]
        if bad:
            raise ConfigError(f"PointBlock: fields {bad} do not have {n} rows like xyz.")

    def __len__(self) -> int:
        return len(self.index)

    @classmethod
    def concat(cls, blocks: Iterable[PointBlock]) -> PointBlock:
        """Join blocks of one file (same fields) into one block, e.g. to read a small file."""
        bs = list(blocks)
        if not bs:
            return cls(xyz=np.empty((0, 3)), index=np.empty(0, np.uint64))

        def cat(get: Any) -> Any:
            parts = [get(b) for b in bs]
            return None if parts[0] is None else np.concatenate(parts)

        opt = {k: cat(lambda b, k=k: getattr(b, k)) for k in (
            "intensity", "rgb", "return_number", "number_of_returns", "gps_time")}
        extra = {k: np.concatenate([b.extra[k] for b in bs]) for k in bs[0].extra}
        return cls(xyz=cat(lambda b: b.xyz), index=cat(lambda b: b.index), extra=extra,
                   n_dropped=sum(b.n_dropped for b in bs), **opt)




def _check_path(path: str | Path) -> tuple[Path, str]:
    p = Path(path)
    if not p.exists():
        raise InputFileError(f"{p}: no such file")
    if not p.is_file():
        raise InputFileError(f"{p}: not a regular file")
    kind = SUFFIXES.get(p.suffix.lower())
    if kind is None:
        raise UnsupportedInputError(f"{p}: unknown point cloud suffix {p.suffix!r}; expected one of "
                                    f"{', '.join(SUFFIXES)} (.json = PDAL pipeline)")
    if p.stat().st_size == 0:
        raise CorruptInputError(f"{p}: empty file (0 bytes)")
    if kind in _MAGIC:
        try:
            with p.open("rb") as f:
                head = f.read(len(_MAGIC[kind]))
        except OSError as e:
            raise InputFileError(f"{p}: cannot be read ({e.strerror})") from e
        if head != _MAGIC[kind]:
            raise CorruptInputError(f"{p}: not a {kind.upper()} point cloud (starts with {head!r}, "
                                    f"expected {_MAGIC[kind]!r})")
    return p, kind


@contextlib.contextmanager
def _errors(p: Path, what: str, *types: type[BaseException]) -> Iterator[None]:
    """Turn a library's exception into a one-line CorruptInputError naming the file."""
    catch: tuple[type[BaseException], ...] = (*types, ValueError, OSError, EOFError)
    try:
        yield
    except PipelineError:
        raise
    except catch as e:
        msg = " ".join(str(e).split())[:200] or type(e).__name__
        raise CorruptInputError(f"{p}: {what} ({msg})") from e


def _span(start: int, stop: int | None, n: int) -> tuple[int, int]:
    hi = n if stop is None else min(stop, n)
    return min(start, hi), hi


def _scale_u16(a: np.ndarray, top: float) -> npt.NDArray[np.uint16]:
    out: npt.NDArray[np.uint16] = np.clip(np.rint(np.asarray(a, np.float64) * (65535.0 / top)),
                                          0, 65535).astype(np.uint16)
    return out


def _finite_keep(xyz: _F64, first: int, valid: npt.NDArray[np.bool_] | None = None
                 ) -> tuple[npt.NDArray[np.bool_], npt.NDArray[np.uint64], int]:
    keep: npt.NDArray[np.bool_] = np.asarray(np.isfinite(xyz).all(axis=1), dtype=bool)
    if valid is not None:
        keep &= valid
    index = (first + np.flatnonzero(keep)).astype(np.uint64)
    return keep, index, int(len(keep) - keep.sum())


# -- LAS / LAZ ------------------------------------------------------------------------------


def _vec(a: Any) -> _Vec3:
    return float(a[0]), float(a[1]), float(a[2])


def _native(a: np.ndarray) -> np.ndarray:
    return a.astype(a.dtype.newbyteorder("="), copy=False)


# -- E57 ------------------------------------------------------------------------------------


def _optional(module: str, p: Path, what: str) -> Any:
    try:
        return __import__(module)
    except ImportError as e:
        raise UnsupportedInputError(f"{p}: reading {what} needs the optional package {module!r}, "
                                    f"which is not installed ({e})") from e
