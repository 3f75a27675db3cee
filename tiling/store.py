"""The run store: one Zarr v3 group per run, the only module that imports zarr.

Layout (``docs/store.md`` is the reference)::

    <store>/zarr.json              root attrs: schema_version, sources, grid, coords, ingest
    <store>/tiles/<tile>/          one group per tile: xyz, index, core, ... (whole chunks)
    <store>/fragments/<key>.frag   map-phase output (compressed row blocks), deleted once its tile is recorded
    <store>/records/<stage>/<unit> completion records: one group per finished unit

Completion records are written by the task that made the unit, after its data, as one
small object each (never a shared object that several writers rewrite), so a crash or a
SIGKILL can leave a unit unrecorded but never a record without its data. Readers trust
only recorded units.
"""

from __future__ import annotations

import asyncio
import dataclasses
import functools
import json
import logging
import os
import socket
import time
import warnings
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import zarr
from numcodecs import Blosc
from zarr.codecs import BloscCodec, BytesCodec
from zarr.core.array import AsyncArray
from zarr.core.buffer import default_buffer_prototype
from zarr.core.chunk_grids import RegularChunkGrid
from zarr.core.metadata import ArrayV3Metadata
from zarr.core.sync import sync
from zarr.storage import MemoryStore, StorePath

from hollowtree.errors import ConfigError, InputFileError, PipelineError

__all__ = ["SCHEMA_VERSION", "CHUNK_POINTS", "RunStore", "StoreError", "check_writable"]

logger = logging.getLogger(__name__)

#: Version of the layout; a store of another version is refused.
SCHEMA_VERSION = 1
#: Points per chunk along the first axis (about 3 MB of int32 xyz, 2 MB of uint64 index).
CHUNK_POINTS = 262_144
_COMPRESSOR = BloscCodec(cname="lz4", clevel=5, shuffle="shuffle")


#: Rows per independently compressed block of a map-phase fragment.
FRAGMENT_BLOCK_ROWS = 65_536
FRAGMENT_MAGIC = b"HTFRAG1\n"


def _fragment_codec(itemsize: int) -> Blosc:
    """Blosc-lz4 over whole rows (``typesize`` = row size: the shuffle groups each byte
    of every field together)."""
    return Blosc(cname="lz4", clevel=5, shuffle=Blosc.SHUFFLE, typesize=itemsize)


class StoreError(PipelineError, ValueError):
    """The run store is missing, of another schema version, or cannot be written."""


def _new_array(group: zarr.Group, name: str, *, shape: tuple[int, ...], dtype: Any,
               chunks: tuple[int, ...]) -> zarr.Array:
    """Array ``name`` of ``group``, new: where the caller has made sure no node is (a
    fresh or emptied group), its ``zarr.json`` is written as one object.

    Zarr's own ``create_array`` probes every level above the array and rewrites each
    missing parent (two to four requests a level, plus a listing for ``overwrite``):
    about 24 requests for an array of ``labels/parts/<tile>/<part>`` on an object store,
    its chunk included (``benchmarks/bench_store.py``), against this one object and the
    chunk. The metadata is Zarr's own for these settings (an array made in memory).
    """
    template = _template(shape=shape, dtype=dtype, chunks=chunks)
    return zarr.Array(sync(_put_array(group.store_path / name, template)))


def _template(*, shape: tuple[int, ...], dtype: Any, chunks: tuple[int, ...]) -> tuple[ArrayV3Metadata, Any]:
    """The metadata (and array config) of an array with the store's settings: Zarr's own,
    from an array made in memory once per dtype and rank, at this shape and chunking."""
    base, config = _base_template(np.dtype(dtype).str, len(shape))
    meta = dataclasses.replace(base, shape=tuple(shape), chunk_grid=RegularChunkGrid(chunk_shape=tuple(chunks)))
    return meta, config


@functools.lru_cache(maxsize=64)
def _base_template(dtype: str, ndim: int) -> tuple[ArrayV3Metadata, Any]:
    arr = zarr.create_array(store=MemoryStore(), shape=(1,) * ndim, dtype=np.dtype(dtype), chunks=(1,) * ndim,
                            compressors=_COMPRESSOR, fill_value=0)
    assert isinstance(arr.metadata, ArrayV3Metadata)
    return arr.metadata, arr._async_array.config


async def _put_array(store_path: StorePath, template: tuple[ArrayV3Metadata, Any]) -> AsyncArray[Any]:
    """Write ``template``'s metadata at ``store_path``; the array there."""
    meta, config = template
    docs = meta.to_buffer_dict(default_buffer_prototype())
    await asyncio.gather(*((store_path / key).set(value) for key, value in docs.items()))
    return AsyncArray(meta, store_path, config=config)


def _is_url(url: str) -> bool:
    return "://" in url and not url.startswith("file://")


class RunStore:
    """A run store opened for reading and writing.

    Use :meth:`create` for a new store (or to reopen one for resuming) and :meth:`open`
    for an existing one.
    """

    def __init__(self, root: zarr.Group, url: str) -> None:
        self._root = root
        self.url = url
        self._restart_clock()

    def _restart_clock(self) -> None:
        # the unit clock: a task opens its own handle, so this is the start of its unit
        self._clock = (time.perf_counter(), time.process_time(), os.getpid())

    # ------------------------------------------------------------------ opening
    @classmethod
    def open(cls, url: str | Path, *, mode: str = "r") -> RunStore:
        """Open an existing store; refuse a missing one or an unknown schema version."""
        url = str(url)
        if not _is_url(url) and not (Path(url) / "zarr.json").is_file():
            raise InputFileError(f"store {url} does not exist (no zarr.json there)")
        try:
            root = zarr.open_group(store=url, mode=mode)
        except Exception as exc:  # zarr raises many types for a damaged store
            raise StoreError(f"store {url} cannot be opened: {exc}") from None
        version = root.attrs.get("schema_version")
        if version != SCHEMA_VERSION:
            raise StoreError(
                f"store {url} has schema_version {version!r}; this hollowtree reads "
                f"version {SCHEMA_VERSION} only"
            )
        return cls(root, url)

    @classmethod
    def create(cls, url: str | Path, *, attrs: Mapping[str, Any]) -> RunStore:
        """Create a new store with root ``attrs`` (plus ``schema_version``)."""
        url = str(url)
        if not _is_url(url):
            parent = Path(url).resolve().parent
            if not parent.is_dir():
                raise StoreError(f"store {url}: folder {parent} does not exist")
            if Path(url).exists() and any(p.name != "run.lock" for p in Path(url).iterdir()):
                raise StoreError(f"store {url} exists and is not a hollowtree store")
        try:
            # "a", not "w": "w" would also delete the run lock that `hollowtree run` put there
            root = zarr.open_group(store=url, mode="a")
            root.attrs.update({"schema_version": SCHEMA_VERSION, **attrs})
            for name in ("tiles", "fragments", "records"):
                root.require_group(name)
        except PermissionError as exc:
            raise StoreError(f"store {url} cannot be written: {exc.strerror}") from None
        except OSError as exc:
            raise StoreError(f"store {url} cannot be written: {exc}") from None
        return cls(root, url)

    def reset(self, attrs: Mapping[str, Any]) -> None:
        """Delete every group of the store and start over with root ``attrs``.

        For a run whose ingest parameters changed: everything in the store was made
        from the old ones. Files beside the Zarr hierarchy (the run lock) stay.
        """
        with warnings.catch_warnings():  # Zarr names every file beside the hierarchy
            warnings.filterwarnings("ignore", message="Object at .* is not recognized", category=UserWarning)
            names = list(self._root.group_keys()) + list(self._root.array_keys())
        for name in names:
            del self._root[name]
        fs, base = self._fs()
        if fs.exists(base):  # fragment files beside the hierarchy; before the group is made again
            fs.rm(base, recursive=True)
        self._root.attrs.put({"schema_version": SCHEMA_VERSION, **attrs})
        for name in ("tiles", "fragments", "records"):
            self._root.require_group(name)

    @staticmethod
    def exists(url: str | Path) -> bool:
        """Whether a store (any version) is at ``url``."""
        url = str(url)
        if _is_url(url):
            try:
                zarr.open_group(store=url, mode="r")
            except Exception:
                return False
            return True
        return (Path(url) / "zarr.json").is_file()

    # ------------------------------------------------------------------ attributes
    @property
    def attrs(self) -> dict[str, Any]:
        """Root attributes (a copy)."""
        return dict(self._root.attrs)

    def update_attrs(self, values: Mapping[str, Any]) -> None:
        """Update root attributes (driver only: never from a task)."""
        self._root.attrs.update(dict(values))

    # ------------------------------------------------------------------ tiles
    def _require_group(self, path: str) -> zarr.Group:
        """``require_group`` that tolerates a concurrent writer: two Dask workers may
        create the same parent group (``records/<stage>``, ``tree/batches``) at the same
        moment, and the loser's ``require_group`` raises; it then finds the group there."""
        for attempt in range(5):
            try:
                return self._root.require_group(path)
            except Exception:
                if attempt == 4:
                    raise
                time.sleep(0.05 * (attempt + 1))
        raise AssertionError("unreachable")

    def write_unit(self, group: str, arrays: Mapping[str, npt.NDArray[Any]]) -> None:
        """Write ``arrays`` into group path ``group`` (replacing what was there). An array
        shorter than :data:`CHUNK_POINTS` rows is one chunk of its rows: a chunk is encoded
        whole, its fill too. The old arrays' removal, the new arrays' metadata and their
        chunks each go to the store as one batch of concurrent requests."""
        g = self._require_group(group)
        values = {name: np.ascontiguousarray(v) for name, v in arrays.items()}
        templates = [_template(shape=v.shape, dtype=v.dtype, chunks=(max(1, min(CHUNK_POINTS, len(v))),) + v.shape[1:])
                     for v in values.values()]

        async def write() -> None:
            ag = g._async_group
            old = [name async for name in ag.array_keys()]
            await asyncio.gather(*(ag.delitem(name) for name in old))
            new = await asyncio.gather(*(_put_array(ag.store_path / name, t) for name, t in zip(values, templates, strict=True)))
            await asyncio.gather(*(arr.setitem(..., v) for arr, v in zip(new, values.values(), strict=True) if v.size))

        sync(write())

    def unit_writer(self, group: str, *, n_rows: int | None = None) -> _UnitWriter:
        """An appending writer for group path ``group`` (its old arrays are removed).

        ``n_rows``: the final length of every array when known; they are then created at
        that length once instead of growing with each flush.
        """
        g = self._require_group(group)
        for name in list(g.array_keys()):
            del g[name]
        return _UnitWriter(g, n_rows=n_rows)

    def read_unit(self, group: str, names: Iterable[str] | None = None) -> dict[str, np.ndarray]:
        """Read arrays of group path ``group`` (all, or ``names``), as one batch of
        concurrent requests."""
        g = self._root[group]

        async def read() -> dict[str, np.ndarray]:
            ag = g._async_group
            keys = [name async for name in ag.array_keys()] if names is None else list(names)

            async def one(name: str) -> Any:
                arr = await ag.getitem(name)
                if not isinstance(arr, AsyncArray):
                    raise KeyError(f"{group}/{name} is a group, not an array")
                return await arr.getitem(...)

            return dict(zip(keys, await asyncio.gather(*(one(k) for k in keys)), strict=True))

        return sync(read())

    def unit_arrays(self, group: str) -> list[str]:
        """Names of the arrays in group path ``group``."""
        return sorted(self._root[group].array_keys())

    def create_array(self, path: str, *, shape: tuple[int, ...], dtype: Any,
                     chunks: int = CHUNK_POINTS) -> None:
        """Create (or replace) an empty array at ``path`` (``group/name``), filled with 0.

        Writers then fill it with :meth:`write_slice`, each writing whole chunks only.
        """
        group, _, name = path.rpartition("/")
        g = self._require_group(group) if group else self._root
        if name in g:
            del g[name]
        _new_array(g, name, shape=shape, dtype=dtype, chunks=(chunks, *shape[1:]))

    def write_slice(self, path: str, start: int, values: npt.NDArray[Any]) -> None:
        """Write ``values`` at rows ``[start, start + len(values))`` of the array at
        ``path``. Callers keep ``start`` on a chunk boundary and the end on one (or at
        the array's end), so concurrent writers never share a chunk."""
        arr = self._root[path]
        arr[start:start + len(values)] = np.ascontiguousarray(values)

    def read_slice(self, path: str, start: int = 0, stop: int | None = None) -> np.ndarray:
        """Rows ``[start, stop)`` of the array at ``path``."""
        arr = self._root[path]
        return arr[start:stop]

    def array_length(self, path: str) -> int:
        """Length of the array at ``path`` along its first axis."""
        return int(self._root[path].shape[0])

    def has(self, path: str) -> bool:
        """Whether a group or array exists at ``path``."""
        try:
            self._root[path]
        except KeyError:
            return False
        return True

    def delete(self, path: str) -> None:
        """Delete the group or array at ``path`` (no error when it is absent)."""
        if self.has(path):
            del self._root[path]

    # ------------------------------------------------------------------ tables
    def _files(self) -> tuple[Any, str]:
        import fsspec

        fs, root = fsspec.core.url_to_fs(self.url)
        return fs, root.rstrip("/")

    def write_table(self, rel: str, table: Any) -> None:
        """Write a ``pyarrow.Table`` as Parquet at ``<store>/<rel>`` (a segment or node table)."""
        import pyarrow.parquet as pq

        fs, root = self._files()
        path = f"{root}/{rel}"
        fs.makedirs(path.rsplit("/", 1)[0], exist_ok=True)
        with fs.open(path, "wb") as f:
            pq.write_table(table, f)

    def read_table(self, rel: str) -> Any:
        """The Parquet table at ``<store>/<rel>`` as a ``pyarrow.Table``."""
        import pyarrow.parquet as pq

        fs, root = self._files()
        with fs.open(f"{root}/{rel}", "rb") as f:
            return pq.read_table(f)

    def has_file(self, rel: str) -> bool:
        """Whether ``<store>/<rel>`` (a table or a folder of them) exists."""
        fs, root = self._files()
        return bool(fs.exists(f"{root}/{rel}"))

    def delete_files(self, rel: str) -> None:
        """Remove ``<store>/<rel>`` (a table or a folder of them) where it exists."""
        fs, root = self._files()
        if fs.exists(f"{root}/{rel}"):
            fs.rm(f"{root}/{rel}", recursive=True)

    # ------------------------------------------------------------------ fragments
    def _fs(self) -> tuple[Any, str]:
        import fsspec

        fs, root = fsspec.core.url_to_fs(self.url)
        return fs, root.rstrip("/") + "/fragments"

    def write_fragment(self, key: str, rows: npt.NDArray[np.void], groups: npt.NDArray[np.int64]) -> None:
        """Store a structured array ``rows`` as ``fragments/<key>.frag``.

        ``groups`` (int64, shape (g, 2)) lists ``(group key, first row)`` of the row groups
        the array is sorted by, so that a reader can fetch one run of groups without the
        rest (:meth:`read_fragment_rows`). The rows are compressed in blocks of
        ``FRAGMENT_BLOCK_ROWS`` (Blosc-lz4, byte shuffle over whole rows: about 3.4x on
        scans), each decompressible alone; the file is ``FRAGMENT_MAGIC``, the length of
        a JSON header (little-endian uint64), the header (dtype, rows, block sizes,
        groups), then the blocks. Fragments are scratch data between the map and the
        reduce phase: objects beside the Zarr hierarchy, through fsspec, so any store
        URL works. Measured on this machine's disk, writing files costs about 3 ms of CPU
        per MB, several times Blosc's own cost, so compressing pays.
        """
        rows = np.ascontiguousarray(rows)
        size = rows.dtype.itemsize
        raw = rows.view(np.uint8).reshape(-1) if len(rows) else np.zeros(0, np.uint8)
        codec = _fragment_codec(size)
        blocks = [codec.encode(raw[i * size:(i + FRAGMENT_BLOCK_ROWS) * size])
                  for i in range(0, len(rows), FRAGMENT_BLOCK_ROWS)]
        header = json.dumps({
            "dtype": np.lib.format.dtype_to_descr(rows.dtype), "rows": len(rows),
            "block_rows": FRAGMENT_BLOCK_ROWS, "block_bytes": [len(b) for b in blocks],
            "groups": np.asarray(groups, dtype=np.int64).reshape(-1, 2).tolist(),
        }).encode()
        fs, base = self._fs()
        if not _is_url(self.url):  # a store left without the folder by an older reset
            Path(base).mkdir(parents=True, exist_ok=True)
        with fs.open(f"{base}/{key}.frag", "wb") as f:
            f.write(FRAGMENT_MAGIC + np.uint64(len(header)).tobytes() + header)
            for block in blocks:
                f.write(block)

    def _fragment_header(self, key: str) -> dict[str, Any]:
        fs, base = self._fs()
        with fs.open(f"{base}/{key}.frag", "rb") as f:
            head = f.read(len(FRAGMENT_MAGIC) + 8)
            if len(head) < len(FRAGMENT_MAGIC) + 8 or not head.startswith(FRAGMENT_MAGIC):
                raise StoreError(f"fragment {key} of store {self.url} is damaged (bad magic)")
            n = int(np.frombuffer(head[len(FRAGMENT_MAGIC):], dtype="<u8")[0])
            info: dict[str, Any] = json.loads(f.read(n))
        info["data_start"] = len(FRAGMENT_MAGIC) + 8 + n
        info["block_start"] = np.concatenate([[0], np.cumsum(info["block_bytes"], dtype=np.int64)])
        descr = info["dtype"]
        if isinstance(descr, list):  # JSON turned the (name, format[, shape]) tuples into lists
            descr = [(f[0], f[1], tuple(f[2])) if len(f) > 2 else (f[0], f[1]) for f in descr]
        info["dtype"] = np.lib.format.descr_to_dtype(descr)
        return info

    def read_fragment_groups(self, key: str) -> npt.NDArray[np.int64]:
        """The ``(group key, first row)`` table of a fragment."""
        groups = self._fragment_header(key)["groups"]
        return np.asarray(groups, dtype=np.int64).reshape(-1, 2)

    def read_fragment_rows(self, key: str, start: int, stop: int,
                           out: npt.NDArray[np.void] | None = None) -> npt.NDArray[np.void]:
        """Rows ``[start, stop)`` of a fragment, reading and decompressing only the
        blocks that hold them.

        With ``out`` (a contiguous array of the fragment's dtype and ``stop - start``
        rows), the rows are written straight into it and ``out`` is returned.
        """
        info = self._fragment_header(key)
        dtype, size, per = info["dtype"], info["dtype"].itemsize, int(info["block_rows"])
        stop = min(stop, int(info["rows"]))
        if out is not None and (out.dtype != dtype or len(out) != max(stop - start, 0)):
            raise StoreError(f"fragment {key}: rows {start}-{stop} of {dtype} do not fit "
                             f"{len(out)} rows of {out.dtype}")
        if out is None:
            out = np.empty(max(stop - start, 0), dtype=dtype)
        if stop <= start:
            return out
        first, last = start // per, (stop - 1) // per
        lo, hi = int(info["block_start"][first]), int(info["block_start"][last + 1])
        fs, base = self._fs()
        with fs.open(f"{base}/{key}.frag", "rb") as f:
            f.seek(info["data_start"] + lo)
            data = f.read(hi - lo)
        if len(data) != hi - lo:
            raise StoreError(f"fragment {key} of store {self.url} is shorter than its header says")
        codec = _fragment_codec(size)
        dst = out.view(np.uint8).reshape(-1)
        at = 0
        for blk in range(first, last + 1):
            a = int(info["block_start"][blk]) - lo
            b = int(info["block_start"][blk + 1]) - lo
            r0 = blk * per  # first row of the block
            u, v = max(start, r0), min(stop, r0 + per)
            if u == r0 and v - u == per:  # a whole block: straight into place
                codec.decode(data[a:b], out=dst[at:at + (v - u) * size])
            else:
                whole = np.frombuffer(codec.decode(data[a:b]), dtype=np.uint8)
                dst[at:at + (v - u) * size] = whole[(u - r0) * size:(v - r0) * size]
            at += (v - u) * size
        return out

    def delete_fragments(self, keys: Iterable[str] | None = None) -> None:
        """Delete the given fragments (all when ``keys`` is None)."""
        fs, base = self._fs()
        if keys is None:
            paths = fs.glob(f"{base}/*.frag") + fs.glob(f"{base}/*.npy")  # .npy: older layouts
        else:
            paths = [f"{base}/{k}{suffix}" for k in keys for suffix in (".frag", ".npy", ".idx.npy")]
        for path in paths:
            if fs.exists(path):
                fs.rm(path)

    # ------------------------------------------------------------------ records
    def record(self, stage: str, unit: str, info: Mapping[str, Any], *, timed: bool = True) -> None:
        """Record unit ``unit`` of ``stage`` as done. Call only after its data is written.

        The record also holds where and how long the unit ran, unless ``info`` says so
        itself or ``timed`` is False (a record the driver writes for work its tasks did):
        ``wall_s`` and ``cpu_s`` (the seconds since this handle was opened or last
        recorded a unit; CPU seconds of the process, whose own pool threads count with
        it), ``worker`` (host and process id) and ``finished`` (Unix time).
        """
        wall0, cpu0, pid = self._clock
        timing = {} if not timed else {"wall_s": round(time.perf_counter() - wall0, 4),
                  # a forked child's CPU time starts at zero
                  "cpu_s": round(time.process_time() - (cpu0 if pid == os.getpid() else 0.0), 4),
                  "worker": f"{socket.gethostname()}:{os.getpid()}", "finished": round(time.time(), 3)}
        g = self._require_group(f"records/{stage}")
        # One write of one small object: the group and its attributes together.
        g.create_group(str(unit), attributes={**timing, **dict(info)}, overwrite=True)
        self._restart_clock()

    def records(self, stage: str) -> dict[str, dict[str, Any]]:
        """Completion records of ``stage``: unit -> info. Unreadable records are skipped."""
        self._forget_listings()
        try:
            g = self._root[f"records/{stage}"]
        except KeyError:
            return {}
        out: dict[str, dict[str, Any]] = {}
        with warnings.catch_warnings():
            # A writer killed mid-record leaves a unit folder without its zarr.json (or a
            # local store's temporary file): not a record, so not done.
            warnings.filterwarnings("ignore", message="Object at .* is not recognized", category=UserWarning)
            members = g.members()  # each unit's metadata read once, its attributes with it
        for unit, node in members:
            if not isinstance(node, zarr.Group):
                logger.warning("unreadable record %s/%s ignored", stage, unit)
                continue
            info = dict(node.attrs)
            if info:
                out[unit] = info
        return out

    def _forget_listings(self) -> None:
        """Drop cached directory listings of a remote store.

        Records are written by other processes (Dask workers); s3fs and other fsspec
        filesystems cache listings per instance, so without this a reader would not
        see records written since its last listing.
        """
        if not _is_url(self.url):
            return
        fs = getattr(self._root.store, "fs", None)
        if fs is not None and hasattr(fs, "invalidate_cache"):
            fs.invalidate_cache()
        self._fs()[0].invalidate_cache()

    def clear_records(self, stage: str) -> None:
        """Forget every record of ``stage``."""
        recs = self._root["records"]
        if stage in set(recs.group_keys()):
            del recs[stage]


class _UnitWriter:
    """Appends rows to the arrays of one group, piece by piece (bounded memory).

    Rows are held back until they fill whole chunks, so every chunk is compressed and
    written once (no read-modify-write of a partial last chunk) and each array's metadata
    is rewritten once per flush, not once per piece. At most ``FLUSH_CHUNKS`` chunks per
    array wait in memory.

    Chunks are encoded here with the array's own codecs (bytes, then Blosc) and handed
    to the store all at once: Zarr's general write path (a chunk buffer, a fill-value
    comparison and two thread hops per chunk) cost about three times Blosc's own time.
    Every chunk is written, the array's last one padded with the fill value as Zarr
    pads it; arrays with other codecs go through Zarr's path.
    """

    FLUSH_CHUNKS = 4

    def __init__(self, group: zarr.Group, *, n_rows: int | None = None) -> None:
        self._group = group
        self._n_rows = n_rows
        self._arrays: dict[str, zarr.Array] = {}
        self._pending: dict[str, list[npt.NDArray[Any]]] = {}
        self._n_pending: dict[str, int] = {}
        self._n_written: dict[str, int] = {}

    def _create(self, name: str, values: npt.NDArray[Any]) -> zarr.Array:
        # The group was emptied by RunStore.unit_writer: no node is at ``name``.
        arr = _new_array(self._group, name, shape=(self._n_rows or 0, *values.shape[1:]), dtype=values.dtype,
                         chunks=(CHUNK_POINTS, *values.shape[1:]))
        self._arrays[name] = arr
        self._pending[name], self._n_pending[name], self._n_written[name] = [], 0, 0
        return arr

    def _flush(self, name: str, *, final: bool) -> list[tuple[str, bytes]]:
        """Write the whole chunks held back for ``name`` (all rows when ``final``);
        returns the encoded chunks still to be stored (``(key, bytes)``).

        Pieces may be strided views (a field of a structured array): each chunk is
        made contiguous on its own, a chunk's worth of copying at a time, and never the
        whole pending run at once.
        """
        n = self._n_pending[name]
        take = n if final else (n // CHUNK_POINTS) * CHUNK_POINTS
        if take == 0:
            return []
        pieces = self._pending[name]
        first = pieces[0]
        arr, start = self._arrays[name], self._n_written[name]
        if self._n_rows is None:
            arr.resize((start + take, *first.shape[1:]))
        elif start + take > self._n_rows:
            raise StoreError(f"{self._group.path}/{name}: more than the {self._n_rows} rows announced")
        blosc = self._blosc(arr, start, first)
        encoded: list[tuple[str, bytes]] = []
        if blosc is None:  # Zarr's own path, whole
            values = np.concatenate(pieces)
            arr[start:start + take] = values[:take]
            rest = values[take:]
            pieces = [rest] if len(rest) else []
        else:
            for done in range(0, take, CHUNK_POINTS):
                need = min(CHUNK_POINTS, take - done)
                parts = []
                while need:
                    p = pieces[0]
                    if len(p) <= need:
                        parts.append(p)
                        pieces.pop(0)
                        need -= len(p)
                    else:
                        parts.append(p[:need])
                        pieces[0] = p[need:]
                        need = 0
                chunk = np.ascontiguousarray(parts[0]) if len(parts) == 1 else np.concatenate(parts)
                if len(chunk) < CHUNK_POINTS:  # the array's last chunk: padded with the fill value
                    full = np.zeros((CHUNK_POINTS, *chunk.shape[1:]), dtype=chunk.dtype)
                    full[:len(chunk)] = chunk
                    chunk = full
                key = arr.metadata.encode_chunk_key(((start + done) // CHUNK_POINTS,) + (0,) * (chunk.ndim - 1))
                encoded.append((f"{arr.store_path.path}/{key}", blosc.encode(chunk.reshape(-1).view(np.uint8))))
        self._pending[name] = pieces
        self._n_pending[name] = n - take
        self._n_written[name] = start + take
        return encoded

    @staticmethod
    def _blosc(arr: zarr.Array, start: int, values: npt.NDArray[Any]) -> Any:
        """The numcodecs Blosc codec that Zarr itself calls for this array's chunks, or
        None where the array's codecs are not the store's own (bytes + Blosc) or the
        rows do not start on a chunk boundary."""
        codecs = arr.metadata.codecs
        if not (len(codecs) == 2 and isinstance(codecs[0], BytesCodec) and isinstance(codecs[1], BloscCodec)
                and start % CHUNK_POINTS == 0 and arr.chunks[0] == CHUNK_POINTS
                and values.dtype.byteorder in "=|<" and arr.metadata.fill_value == 0):
            return None
        return codecs[1]._blosc_codec

    def _store(self, encoded: list[tuple[str, bytes]]) -> None:
        if not encoded:
            return
        store = self._group.store_path.store
        proto = default_buffer_prototype()

        async def put_all() -> None:
            await asyncio.gather(*(store.set(key, proto.buffer.from_bytes(data)) for key, data in encoded))

        sync(put_all())

    def append(self, arrays: Mapping[str, npt.NDArray[Any]]) -> None:
        encoded: list[tuple[str, bytes]] = []
        for name, values in arrays.items():
            values = np.asarray(values)
            if name not in self._arrays:
                self._create(name, values)
            if len(values):
                self._pending[name].append(values)
                self._n_pending[name] += len(values)
                if self._n_pending[name] >= self.FLUSH_CHUNKS * CHUNK_POINTS:
                    encoded += self._flush(name, final=False)
        self._store(encoded)

    def close(self, templates: Mapping[str, npt.NDArray[Any]]) -> None:
        """Write what is held back; create the arrays that never received rows, empty,
        from ``templates``."""
        encoded: list[tuple[str, bytes]] = []
        for name in list(self._arrays):
            encoded += self._flush(name, final=True)
            if self._n_rows is not None and self._n_written[name] != self._n_rows:
                raise StoreError(f"{self._group.path}/{name}: {self._n_written[name]} rows written, "
                                 f"{self._n_rows} announced")
        self._store(encoded)
        for name, values in templates.items():
            if name not in self._arrays:
                self._create(name, np.asarray(values))


def check_writable(url: str | Path, *, parents: bool = False) -> None:
    """Raise :class:`StoreError` if a local store path cannot be created or written, or
    an object store (fsspec URL) cannot be reached: one line, not the client's traceback.

    ``parents``: the store's missing parent folders will be made (``hollowtree run``: a
    workflow's folders are the run's to make); the nearest existing one must be writable."""
    url = str(url)
    if _is_url(url):
        import fsspec

        try:
            fs, root = fsspec.core.url_to_fs(url)
            fs.exists(root)
        except Exception as exc:  # any client's error (no endpoint, no credentials, no package)
            first = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
            raise StoreError(f"store {url} cannot be reached: {type(exc).__name__}: {first}") from None
        return
    p = Path(url)
    parent = p.resolve().parent
    if parents:
        while not parent.exists() and parent != parent.parent:
            parent = parent.parent
    if not parent.is_dir():
        raise StoreError(f"store {url}: folder {parent} does not exist")
    target = p if p.exists() else parent
    if not os.access(target, os.W_OK):
        raise StoreError(f"store {url} cannot be written (no write permission on {target})")
    if p.exists() and not p.is_dir():
        raise ConfigError(f"store {url} is a file, not a folder")
