"""Tile grid arithmetic and spatial ordering: pure NumPy, no I/O.

A :class:`TileGrid` cuts the plane into ``nx * ny`` square tiles of side ``tile_size``.
Each tile has a *core* (the points it owns) and a *buffered* extent (its core grown by
``buffer`` on every side: the points it may read for context, lidR's buffer and dask's
``map_overlap`` depth).

Conventions
-----------
Tile edges along x are ``origin[0] + i * tile_size`` for ``i = 0 .. nx`` (and likewise
along y), computed once by :meth:`TileGrid.edges` and used by every method, so a point's
tile never depends on which method asked.

* **Cores are half-open** ``[lo, hi)`` on both axes, except that the last column and row
  are closed at the top so that points on the grid's top/right edge still belong to a
  tile. Every point inside the closed grid extent lies in exactly one core.
* **Buffered extents are half-open** ``[lo - buffer, hi + buffer)``, so ``buffer=0``
  routes every point to its core tile only. The core tile is always among a point's
  routed tiles (this only matters on the grid's top/right edge when ``buffer=0``).
* **Points outside the grid** (or with non-finite coordinates) raise
  :class:`~hollowtree.errors.ConfigError` by default; ``outside="flag"`` returns tile
  ``-1`` from :meth:`TileGrid.core_tile` and leaves them out of :meth:`TileGrid.route`.
* Tile ids are row-major with x fastest: ``tile = iy * nx + ix``.

Examples
--------
>>> grid = TileGrid.covering(0.0, 0.0, 25.0, 8.0, tile_size=10.0, buffer=1.0)
>>> grid.origin, grid.shape, grid.n_tiles
((-2.5, -1.0), (3, 1), 3)
>>> grid.core_tile(np.array([[0.0, 0.0], [10.0, 5.0], [25.0, 8.0]])).tolist()
[0, 1, 2]
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from hollowtree.errors import ConfigError

__all__ = ["GRID_ALGORITHM", "TileGrid", "morton_codes3", "morton_order"]

#: The label of :meth:`TileGrid.covering`'s rule, carried by benchmark results: ``grid-v2``
#: centres the fewest tiles on the bounds (``grid-v1`` snapped the origin to the tile size).
GRID_ALGORITHM = "grid-v2"

_GRID_KEYS = ("origin", "tile_size", "buffer", "shape")


def _number(name: str, value: object) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ConfigError(f"The '{name}' parameter of TileGrid must be a number; got {value!r}.")
    if not math.isfinite(float(value)):
        raise ConfigError(f"The '{name}' parameter of TileGrid must be finite; got {value!r}.")
    return float(value)


@dataclass(frozen=True, kw_only=True)
class TileGrid:
    """A regular grid of square tiles with a buffer around each.

    Parameters
    ----------
    origin : tuple of 2 floats
        World x, y of the grid's lower-left corner (float64).
    tile_size : float
        Side of a tile's core, > 0.
    buffer : float
        Width of the ring around each core that the tile also reads,
        ``0 <= buffer < tile_size``.
    shape : tuple of 2 ints
        Number of tiles along x and y, each >= 1.

    Raises
    ------
    ConfigError
        If a parameter breaks the rules above.

    Examples
    --------
    >>> grid = TileGrid(origin=(100.0, 200.0), tile_size=50.0, buffer=5.0, shape=(2, 3))
    >>> grid.n_tiles, grid.tile_id(1, 2), grid.tile_index(5)
    (6, 5, (1, 2))
    >>> grid.core_bounds(5), grid.buffered_bounds(5)
    ((150.0, 300.0, 200.0, 350.0), (145.0, 295.0, 205.0, 355.0))
    >>> TileGrid.from_dict(grid.to_dict()) == grid
    True
    >>> TileGrid(origin=(0.0, 0.0), tile_size=-3, buffer=0.0, shape=(1, 1))
    Traceback (most recent call last):
    ...
    hollowtree.errors.ConfigError: The 'tile_size' parameter of TileGrid must be > 0; got -3.
    """

    origin: tuple[float, float]
    tile_size: float
    buffer: float
    shape: tuple[int, int]

    def __post_init__(self) -> None:
        origin = tuple(self.origin) if isinstance(self.origin, (tuple, list, np.ndarray)) else ()
        if len(origin) != 2:
            raise ConfigError(f"The 'origin' parameter of TileGrid must be (x, y); got {self.origin!r}.")
        origin = (_number("origin", origin[0]), _number("origin", origin[1]))
        size = _number("tile_size", self.tile_size)
        if not size > 0:
            raise ConfigError(f"The 'tile_size' parameter of TileGrid must be > 0; got {self.tile_size!r}.")
        buffer = _number("buffer", self.buffer)
        if not 0 <= buffer < size:
            raise ConfigError(
                f"The 'buffer' parameter of TileGrid must be in [0, tile_size={size!r}); "
                f"got {self.buffer!r}."
            )
        shape = tuple(self.shape) if isinstance(self.shape, (tuple, list)) else ()
        if len(shape) != 2 or not all(
            isinstance(n, (int, np.integer)) and not isinstance(n, bool) and n >= 1 for n in shape
        ):
            raise ConfigError(
                f"The 'shape' parameter of TileGrid must be two ints >= 1 (nx, ny); got {self.shape!r}."
            )
        object.__setattr__(self, "origin", origin)
        object.__setattr__(self, "tile_size", size)
        object.__setattr__(self, "buffer", buffer)
        object.__setattr__(self, "shape", (int(shape[0]), int(shape[1])))

    # -- construction and serialisation ---------------------------------------------------

    @classmethod
    def covering(
        cls, xmin: float, ymin: float, xmax: float, ymax: float, *, tile_size: float, buffer: float,
        align: tuple[float, float] | None = None,
    ) -> TileGrid:
        """Return the grid of fewest tiles whose cores cover ``[xmin, xmax] x [ymin, ymax]``,
        centred on the bounds, or with edges through the point ``align`` where given.

        Along each axis ``floor(span / tile_size) + 1`` tiles (cores are half-open, so the
        maximum needs the slack), with the slack split evenly on both sides. A grid
        snapped to multiples of ``tile_size`` would need one more tile along an axis
        whenever the bounds straddle a multiple (a 42 m scan on 60 m tiles: 4 tiles
        instead of 1, and a third more points in their buffers).

        Examples
        --------
        >>> g = TileGrid.covering(12.0, -3.0, 31.0, 9.0, tile_size=10.0, buffer=2.0)
        >>> g.origin, g.shape
        ((11.5, -7.0), (2, 2))
        >>> TileGrid.covering(-10.7, -17.9, 31.7, 24.4, tile_size=60.0, buffer=2.0).shape
        (1, 1)
        >>> g = TileGrid.covering(12.0, -3.0, 31.0, 9.0, tile_size=10.0, buffer=2.0, align=(0.0, 5.0))
        >>> g.origin, g.shape
        ((10.0, -5.0), (3, 2))
        """
        lo = [_number("xmin", xmin), _number("ymin", ymin)]
        hi = [_number("xmax", xmax), _number("ymax", ymax)]
        size = _number("tile_size", tile_size)
        if not size > 0:
            raise ConfigError(f"The 'tile_size' parameter of TileGrid must be > 0; got {tile_size!r}.")
        at = None if align is None else (_number("align", align[0]), _number("align", align[1]))
        origin, shape = [], []
        for axis, (a, b) in enumerate(zip(lo, hi, strict=True)):
            if b < a:
                name = "xy"[axis]
                raise ConfigError(f"TileGrid.covering needs {name}min <= {name}max; got {a!r} > {b!r}.")
            if at is not None:
                o = at[axis] + math.floor((a - at[axis]) / size) * size
                n = max(1, math.floor((b - o) / size) + 1)
            else:
                n = max(1, math.floor((b - a) / size) + 1)
                o = a - (n * size - (b - a)) / 2.0
            while not (o <= a and b < o + n * size):  # guard against rounding at large offsets
                if at is not None:
                    o, n = (o - size, n + 1) if a < o else (o, n + 1)
                else:
                    n += 1
                    o = a - (n * size - (b - a)) / 2.0
            origin.append(o)
            shape.append(n)
        return cls(origin=(origin[0], origin[1]), tile_size=size, buffer=buffer,
                   shape=(shape[0], shape[1]))

    def to_dict(self) -> dict[str, Any]:
        """Return a JSON-ready dict; :meth:`from_dict` inverts it."""
        return {
            "origin": [self.origin[0], self.origin[1]],
            "tile_size": self.tile_size,
            "buffer": self.buffer,
            "shape": [self.shape[0], self.shape[1]],
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> TileGrid:
        """Build a grid from :meth:`to_dict` output; unknown or missing keys are errors."""
        if not isinstance(data, Mapping):
            raise ConfigError(f"TileGrid.from_dict expects a mapping; got {type(data).__name__}.")
        unknown = sorted(set(data) - set(_GRID_KEYS))
        missing = [k for k in _GRID_KEYS if k not in data]
        if unknown or missing:
            raise ConfigError(
                f"TileGrid.from_dict: unknown keys {unknown}, missing keys {missing}; "
                f"expected exactly {list(_GRID_KEYS)}."
            )
        return cls(origin=tuple(data["origin"]), tile_size=data["tile_size"],
                   buffer=data["buffer"], shape=tuple(data["shape"]))

    # -- tile ids ---------------------------------------------------------------------------

    @property
    def n_tiles(self) -> int:
        """Number of tiles, ``nx * ny``."""
        return self.shape[0] * self.shape[1]

    def tile_id(self, ix: Any, iy: Any) -> Any:
        """Return the tile id ``iy * nx + ix`` (ints or int arrays); out of range raises."""
        ix_, iy_ = np.asarray(ix), np.asarray(iy)
        nx, ny = self.shape
        if np.any((ix_ < 0) | (ix_ >= nx) | (iy_ < 0) | (iy_ >= ny)):
            raise ConfigError(f"tile index ({ix}, {iy}) lies outside the grid of shape {self.shape}.")
        out = iy_.astype(np.int64) * nx + ix_.astype(np.int64)
        return int(out) if out.ndim == 0 else out

    def tile_index(self, tile: int) -> tuple[int, int]:
        """Return ``(ix, iy)`` of ``tile``, the inverse of :meth:`tile_id`."""
        t = int(tile)
        if not 0 <= t < self.n_tiles:
            raise ConfigError(f"tile id {tile!r} lies outside [0, {self.n_tiles}) for this grid.")
        return t % self.shape[0], t // self.shape[0]

    # -- geometry ---------------------------------------------------------------------------

    def edges(self) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """Return the tile edges along x (``nx + 1`` values) and y (``ny + 1`` values)."""
        s = self.tile_size
        ex = self.origin[0] + np.arange(self.shape[0] + 1, dtype=np.float64) * s
        ey = self.origin[1] + np.arange(self.shape[1] + 1, dtype=np.float64) * s
        return ex, ey

    def core_bounds(self, tile: int) -> tuple[float, float, float, float]:
        """Return ``(xmin, ymin, xmax, ymax)`` of ``tile``'s core (half-open, see module)."""
        ix, iy = self.tile_index(tile)
        ex, ey = self.edges()
        return float(ex[ix]), float(ey[iy]), float(ex[ix + 1]), float(ey[iy + 1])

    def buffered_bounds(self, tile: int) -> tuple[float, float, float, float]:
        """Return ``(xmin, ymin, xmax, ymax)`` of ``tile``'s core grown by ``buffer``."""
        ix, iy = self.tile_index(tile)
        ex, ey = self.edges()
        b = self.buffer
        return (float(ex[ix] - b), float(ey[iy] - b), float(ex[ix + 1] + b), float(ey[iy + 1] + b))

    def _core_axis(self, v: npt.NDArray[np.float64], e: npt.NDArray[np.float64]) -> npt.NDArray[np.int64]:
        """Index i with ``e[i] <= v < e[i+1]`` (last interval closed), -1 outside."""
        n = len(e) - 1
        with np.errstate(invalid="ignore"):
            guess = np.floor((v - e[0]) / self.tile_size)
        i = np.clip(np.nan_to_num(guess, nan=0.0), 0, n - 1).astype(np.int64)
        # exact correction against the stored edges: rounding in the division is at most one cell
        i -= (v < e[i]) & (i > 0)
        i += (v >= e[i + 1]) & (i < n - 1)
        inside = (v >= e[0]) & (v <= e[n])
        return np.where(inside, i, -1)

    def core_tile(
        self, xy: npt.ArrayLike, *, outside: Literal["raise", "flag"] = "raise"
    ) -> npt.NDArray[np.int64]:
        """Return the id of the one tile whose core holds each point.

        Parameters
        ----------
        xy : ndarray of shape (n_points, 2) or (n_points, 3)
            Point coordinates; only x and y are used.
        outside : {"raise", "flag"}, default "raise"
            What to do with points outside the closed grid extent or with non-finite
            x or y: raise :class:`ConfigError`, or return tile ``-1`` for them.

        Returns
        -------
        tile : ndarray of shape (n_points,), int64

        Notes
        -----
        Memory: a few int64 temporaries of length ``n_points``.

        Examples
        --------
        >>> g = TileGrid(origin=(0.0, 0.0), tile_size=1.0, buffer=0.0, shape=(2, 2))
        >>> xy = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 2.0], [0.5, 1.5], [2.5, 0.0], [np.nan, 0]])
        >>> g.core_tile(xy, outside="flag").tolist()
        [0, 1, 3, 2, -1, -1]
        """
        if outside not in ("raise", "flag"):
            raise ConfigError(f"The 'outside' parameter of core_tile must be 'raise' or 'flag'; got {outside!r}.")
        pts = _as_points(xy)
        ex, ey = self.edges()
        ix = self._core_axis(pts[:, 0], ex)
        iy = self._core_axis(pts[:, 1], ey)
        bad = (ix < 0) | (iy < 0)
        if outside == "raise" and bad.any():
            raise ConfigError(
                f"{int(bad.sum())} of {len(pts)} points lie outside the tile grid "
                f"x in [{ex[0]}, {ex[-1]}], y in [{ey[0]}, {ey[-1]}] or are not finite; "
                "build the grid with TileGrid.covering over the data bounds or pass outside='flag'."
            )
        return np.where(bad, -1, iy * self.shape[0] + ix)

    def route(
        self, xy: npt.ArrayLike, *, outside: Literal["raise", "flag"] = "raise", sort: bool = True
    ) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64], npt.NDArray[np.bool_]]:
        """Return every (point, tile) pair whose buffered extent holds the point.

        A point appears once with its core tile (``is_core=True``) and once more for each
        neighbour whose half-open buffered box ``[lo - buffer, hi + buffer)`` holds it (at
        most 8, since ``buffer < tile_size``).

        Parameters
        ----------
        xy : ndarray of shape (n_points, 2) or (n_points, 3)
        outside : {"raise", "flag"}, default "raise"
            As in :meth:`core_tile`; flagged points appear in no pair.
        sort : bool, default True
            Sort the pairs by point (then tile). ``False`` skips that sort for callers that
            reorder the pairs anyway: core-only points first, then the rest.

        Returns
        -------
        point_index : ndarray of shape (n_pairs,), int64
            Row of ``xy``; with ``sort``, pairs are sorted by point, then by tile.
        tile : ndarray of shape (n_pairs,), int64
        is_core : ndarray of shape (n_pairs,), bool

        Notes
        -----
        Memory: a few arrays of length ``n_points`` and ``n_pairs``; the 3 x 3
        neighbourhood is built only for points within ``buffer`` of an inner edge.

        Examples
        --------
        >>> g = TileGrid(origin=(0.0, 0.0), tile_size=10.0, buffer=1.0, shape=(2, 2))
        >>> p, t, c = g.route(np.array([[5.0, 5.0], [9.5, 5.0], [10.0, 10.5]]))
        >>> p.tolist(), t.tolist(), c.tolist()
        ([0, 1, 1, 2, 2, 2, 2], [0, 0, 1, 0, 1, 2, 3], [True, True, False, False, False, False, True])
        """
        pts = _as_points(xy)
        core = self.core_tile(pts, outside=outside)
        nx, ny = self.shape
        ex, ey = self.edges()
        b = self.buffer
        ok = core >= 0
        cix, ciy = np.where(ok, core % nx, 0), np.where(ok, core // nx, 0)
        x, y = pts[:, 0], pts[:, 1]
        # Only points within `buffer` of an inner edge of their core reach a neighbour:
        # route those through the 3 x 3 neighbourhood, every other point to its core only.
        near = ok & (
            ((x - ex[cix] < b) & (cix > 0))
            | ((x >= ex[np.minimum(cix + 1, nx)] - b) & (cix < nx - 1))
            | ((y - ey[ciy] < b) & (ciy > 0))
            | ((y >= ey[np.minimum(ciy + 1, ny)] - b) & (ciy < ny - 1))
        )
        far = np.flatnonzero(ok & ~near)
        sub = np.flatnonzero(near)
        d = np.array([-1, 0, 1])

        def axis_mask(v: npt.NDArray[np.float64], ci: npt.NDArray[np.int64],
                      e: npt.NDArray[np.float64], n: int) -> tuple[npt.NDArray[np.bool_], npt.NDArray[np.int64]]:
            j = ci[:, None] + d[None, :]
            valid = (j >= 0) & (j < n)
            jc = np.clip(j, 0, n - 1)
            inside = (e[jc] - b <= v[:, None]) & (v[:, None] < e[jc + 1] + b)
            inside[:, 1] = True  # the core column/row, also on the closed top edge
            return valid & inside, jc

        mx, jx = axis_mask(x[sub], cix[sub], ex, nx)
        my, jy = axis_mask(y[sub], ciy[sub], ey, ny)
        pair = my[:, :, None] & mx[:, None, :]  # (n, dy, dx): tile ids ascend per point
        ps, ky, kx = np.nonzero(pair)
        p = np.concatenate([far, sub[ps]])
        tile = np.concatenate([core[far], jy[ps, ky] * nx + jx[ps, kx]])
        is_core = np.concatenate([np.ones(len(far), dtype=bool), (ky == 1) & (kx == 1)])
        if not sort:
            return p.astype(np.int64), tile.astype(np.int64), is_core
        order = np.argsort(p, kind="stable")  # one group per point: tiles stay ascending
        return p[order].astype(np.int64), tile[order].astype(np.int64), is_core[order]


def _as_points(xy: npt.ArrayLike) -> npt.NDArray[np.float64]:
    pts = np.asarray(xy, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] < 2:
        raise ConfigError(f"points must have shape (n_points, 2) or (n_points, 3); got {pts.shape}.")
    return pts


def _spread3(v: npt.NDArray[np.uint64]) -> npt.NDArray[np.uint64]:
    """Put the low 21 bits of ``v`` at every third bit."""
    v = v & np.uint64(0x1FFFFF)
    for shift, mask in ((32, 0x1F00000000FFFF), (16, 0x1F0000FF0000FF), (8, 0x100F00F00F00F00F),
                        (4, 0x10C30C30C30C30C3), (2, 0x1249249249249249)):
        v = (v | (v << np.uint64(shift))) & np.uint64(mask)
    return v


def morton_codes3(q: npt.NDArray[np.uint64]) -> npt.NDArray[np.uint64]:
    """Morton (Z-order) codes of integer cell coordinates ``q`` of shape (n, 3), 21 bits each
    (x in the lowest bit of every three).

    Examples
    --------
    >>> morton_codes3(np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]], dtype=np.uint64)).tolist()
    [1, 2, 4, 7]
    """
    return _spread3(q[:, 0]) | (_spread3(q[:, 1]) << np.uint64(1)) | (_spread3(q[:, 2]) << np.uint64(2))


def _spread2(v: npt.NDArray[np.uint64]) -> npt.NDArray[np.uint64]:
    """Put the low 32 bits of ``v`` at every second bit."""
    v = v & np.uint64(0xFFFFFFFF)
    for shift, mask in ((16, 0x0000FFFF0000FFFF), (8, 0x00FF00FF00FF00FF),
                        (4, 0x0F0F0F0F0F0F0F0F), (2, 0x3333333333333333), (1, 0x5555555555555555)):
        v = (v | (v << np.uint64(shift))) & np.uint64(mask)
    return v


def morton_order(xyz_or_xy: npt.ArrayLike, *, origin: npt.ArrayLike, cell: float) -> npt.NDArray[np.int64]:
    """Return the permutation that sorts points by their Morton (Z-order) code.

    Coordinates are quantised to ``floor((p - origin) / cell)`` and clipped to the code's
    range (21 bits per axis in 3D, 32 in 2D), then their bits are interleaved; the sort is
    stable, so points in the same cell keep their input order. Clipped points still sort
    (the result is always a permutation), only less locally.

    Parameters
    ----------
    xyz_or_xy : ndarray of shape (n_points, 3) or (n_points, 2)
        Finite coordinates.
    origin : array-like of shape (3,) or (2,)
        Lower corner of the quantisation grid, usually the tile's lower-left corner.
    cell : float
        Quantisation step, > 0. In 3D a tile spans at most ``2**21 * cell``.

    Returns
    -------
    order : ndarray of shape (n_points,), int64
        ``xyz[order]`` is in Z-order.

    Raises
    ------
    ConfigError
        On a bad shape, ``cell <= 0`` or non-finite coordinates.

    Notes
    -----
    Memory: about five uint64 arrays of length ``n_points``.

    Examples
    --------
    >>> xy = np.array([[1.5, 1.5], [0.2, 0.1], [1.2, 0.3], [0.1, 1.9], [0.3, 0.4], [1.9, 0.9]])
    >>> morton_order(xy, origin=(0.0, 0.0), cell=1.0).tolist()
    [1, 4, 2, 5, 3, 0]
    """
    pts = np.asarray(xyz_or_xy, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] not in (2, 3):
        raise ConfigError(f"morton_order needs points of shape (n_points, 2 or 3); got {pts.shape}.")
    o = np.asarray(origin, dtype=np.float64)
    if o.shape != (pts.shape[1],):
        raise ConfigError(f"morton_order: origin must have shape ({pts.shape[1]},); got {o.shape}.")
    if isinstance(cell, bool) or not isinstance(cell, (int, float, np.integer, np.floating)) or not (
        math.isfinite(cell) and cell > 0
    ):
        raise ConfigError(f"The 'cell' parameter of morton_order must be a float > 0; got {cell!r}.")
    if not np.isfinite(pts).all():
        raise ConfigError("morton_order: coordinates must be finite; drop NaN/inf points first.")
    bits = 21 if pts.shape[1] == 3 else 32
    q = np.clip(np.floor((pts - o) / float(cell)), 0, 2**bits - 1).astype(np.uint64)
    if pts.shape[1] == 3:
        code = morton_codes3(q)
    else:
        code = _spread2(q[:, 0]) | (_spread2(q[:, 1]) << np.uint64(1))
    return _stable_argsort_codes(code, code_bits=(int(q.max(initial=0)).bit_length()) * pts.shape[1])


def _stable_argsort_codes(code: npt.NDArray[np.uint64], *, code_bits: int) -> npt.NDArray[np.int64]:
    """Stable argsort of non-negative codes below ``2**code_bits``.

    When code and position fit in 64 bits together, ``code << k | position`` is sorted
    with NumPy's (SIMD) unstable sort and the positions read back: the same order as a
    stable argsort, measured 8x faster on 1 M points. Otherwise a stable argsort.

    >>> _stable_argsort_codes(np.array([3, 1, 3, 0], dtype=np.uint64), code_bits=2).tolist()
    [3, 1, 0, 2]
    """
    n = len(code)
    pos_bits = max(1, (n - 1).bit_length())
    if code_bits + pos_bits > 64:
        return np.argsort(code, kind="stable").astype(np.int64)
    packed = (code << np.uint64(pos_bits)) | np.arange(n, dtype=np.uint64)
    packed.sort()
    return (packed & np.uint64((1 << pos_bits) - 1)).astype(np.int64)
