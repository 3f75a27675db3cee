"""Streaming point readers: LAS/LAZ, PLY, E57 and (optionally) PDAL pipelines.

The readers (this module, the per-format ``read_las``, ``read_ply``, ``read_e57`` and
``read_pdal``, and their shared ``_points``) are the only modules of ``tiling/`` that
import laspy, plyfile, pye57 or pdal. It turns a file into
header facts (:func:`probe` -> :class:`SourceInfo`) and into blocks of NumPy arrays
(:func:`read_blocks` -> :class:`PointBlock`), so nothing downstream ever sees a
``LasData``. Memory is bounded by ``chunk_size`` records, not by the file.

Conventions
-----------
* **Index.** ``PointBlock.index`` is each point's 0-based record number in its file, in
  file order. E57 files number their scans' records one after another (scan 0 first).
  ``start``/``stop`` of :func:`read_blocks` select records ``[start, stop)`` the way a
  slice does, so ``read_blocks(p, start=a, stop=b)`` equals the full read sliced to the
  records with ``a <= index < b``.
* **Dropped points.** LAS coordinates are integers and are always finite. PLY, E57 and
  PDAL records whose x, y or z is NaN or infinite, and E57 records flagged by
  ``cartesianInvalidState``/``sphericalInvalidState != 0``, are dropped: they get no row,
  their index is skipped (so indices keep naming file records), and each block counts
  them in ``n_dropped``. A block may be empty when every record in its range was dropped.
* **Units.** ``rgb`` is 16-bit; 8-bit sources (PLY ``uchar``, E57 colours up to 255) are
  scaled by 257 so that 255 becomes 65535. E57 intensity is rescaled from the scan's
  ``intensityLimits`` to 0..65535. PLY intensity of integer type is clipped to uint16;
  float PLY intensity has no known range and is kept unscaled in ``extra["intensity"]``.
* **Extras.** LAS extra-bytes dimensions (e.g. ``gt_class``, ``gt_instance``) plus the
  standard ``classification`` and ``point_source_id``; every other PLY vertex property
  (``nx``, ``gt_class``, ...); ``scan_index`` for E57; other PDAL dimensions.

Errors are one line and name the file: :class:`~hollowtree.errors.InputFileError` (missing),
:class:`~hollowtree.errors.UnsupportedInputError` (unknown suffix, optional reader not
installed) and :class:`~hollowtree.errors.CorruptInputError` (empty, truncated, corrupt).
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np

from hollowtree.errors import ConfigError
from hollowtree.tiling._points import SUFFIXES, PointBlock, SourceInfo, _check_path
from hollowtree.tiling.ingest_params import UNIT_METRES
from hollowtree.tiling.read_e57 import _e57_blocks, _probe_e57
from hollowtree.tiling.read_las import _las_blocks, _probe_las, crs_units, las_crs
from hollowtree.tiling.read_pdal import _pdal_blocks, _probe_pdal
from hollowtree.tiling.read_ply import _ply_blocks, _probe_ply

__all__ = ["SourceInfo", "PointBlock", "UNIT_METRES", "crs_units", "las_crs", "probe", "read_blocks", "SUFFIXES"]


# -- entry points ---------------------------------------------------------------------------


def probe(path: str | Path) -> SourceInfo:
    """Read a point file's header (never its points) into a :class:`SourceInfo`.

    Raises
    ------
    InputFileError
        If the file is missing or not a regular file.
    UnsupportedInputError
        If the suffix is unknown or the optional reader (pye57, pdal) is not installed.
    CorruptInputError
        If the file is empty, truncated (where the header shows it) or corrupt.
    """
    p, kind = _check_path(path)
    return {"las": _probe_las, "ply": _probe_ply, "e57": _probe_e57, "pdal": _probe_pdal}[kind](p)


def read_blocks(
    path: str | Path, *, chunk_size: int = 1_000_000, start: int = 0, stop: int | None = None
) -> Iterator[PointBlock]:
    """Stream records ``[start, stop)`` of a point file as :class:`PointBlock` s.

    Parameters
    ----------
    path : str or Path
        ``.las``, ``.laz`` (COPC too), ``.ply`` (ascii or binary), ``.e57``, or a PDAL
        pipeline ``.json`` (optional: only where ``import pdal`` works).
    chunk_size : int, default 1_000_000
        Records per block (a block may be shorter, never longer).
    start, stop : int
        Record range, clipped to the file like a slice; ``stop=None`` reads to the end.
        LAS, LAZ and binary PLY seek straight to ``start``; ascii PLY, E57 and LAZ with
        variable-size chunks (COPC; lazrs 0.8 seeks wrongly there) read past the records
        before it.

    Yields
    ------
    PointBlock
        In file order; see the module notes on indices and dropped records.

    Raises
    ------
    InputFileError, UnsupportedInputError, CorruptInputError
        As in :func:`probe`. A missing file, unknown suffix or empty file raises at the
        call; a bad header at the first ``next()``; truncated or corrupt data while
        reading, after the blocks before the damage were yielded.
    ConfigError
        If ``chunk_size``, ``start`` or ``stop`` is invalid.

    Notes
    -----
    Memory: one chunk of raw records plus its output arrays (about 60 bytes per point for
    LAS point format 7 with two extra dims). A PLY whose vertex element has list
    properties, or follows a binary element with list properties, is read whole.
    """
    def is_int(v: object) -> bool:
        return isinstance(v, (int, np.integer)) and not isinstance(v, bool)

    # parameter rules, as data: name -> (value, minimum)
    for name, (v, least) in {"chunk_size": (chunk_size, 1), "start": (start, 0),
                             "stop": (start if stop is None else stop, start)}.items():
        if not is_int(v) or v < least:
            raise ConfigError(f"The '{name}' parameter of read_blocks must be an int >= {least!r}"
                              f"{' or None' if name == 'stop' else ''}; got {v!r}.")
    p, kind = _check_path(path)
    reader = {"las": _las_blocks, "ply": _ply_blocks, "e57": _e57_blocks, "pdal": _pdal_blocks}[kind]
    return reader(p, int(chunk_size), int(start), None if stop is None else int(stop))
