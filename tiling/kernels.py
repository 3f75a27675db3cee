"""Compiled (numba) kernels of the ingest: routing points to tiles, moving rows, Morton order.

Pure NumPy in, NumPy out; no I/O. Each kernel reproduces, bit for bit, the NumPy
definition it replaces (``TileGrid.route`` and ``core_tile``, the sub-cell key of the
map phase, ``morton_order`` after an index sort), so the store an ingest writes does not
depend on which of the two computed it; ``tests/test_ingest_kernels.py`` checks that.
All kernels release the GIL (``nogil``), so threads of one process run them side by side,
and are cached on disk next to this file (the first use compiles them, a few seconds).

- :func:`route_groups`: every (point, tile) pair whose buffered box holds the point,
  ordered by tile, then by x-y sub-cell, then by point (a stable counting sort); the
  groups of equal (tile, sub-cell) with their first rows;
- :func:`quantise`: world coordinates to the store's integer grid (round half to even,
  like ``np.round``);
- :func:`split_rows`: fields of structured rows in a given order (NumPy: whole rows
  taken, each field a view of them);
- :func:`morton_index_order`: the permutation that sorts rows by 3-D Morton code and,
  within a code, by original index (LSD radix sort of code and row packed in one word,
  then the rare ties).
"""

from __future__ import annotations

import numba
import numpy as np
import numpy.typing as npt

__all__ = ["route_groups", "quantise", "split_rows", "morton_index_order"]

_SUB_BIAS = 1 << 30  # keeps sub-cell indices positive in the 31-bit halves of the key


@numba.njit(cache=True, nogil=True, inline="always")
def _core_axis(v: float, e: npt.NDArray[np.float64], size: float) -> int:
    """``TileGrid._core_axis`` for one value: i with e[i] <= v < e[i+1] (last closed), -1 outside."""
    n = len(e) - 1
    if not (v >= e[0] and v <= e[n]):  # also NaN
        return -1
    g = np.floor((v - e[0]) / size)
    if g < 0.0:
        g = 0.0
    if g > n - 1:
        g = n - 1
    i = int(g)
    if v < e[i] and i > 0:
        i -= 1
    if v >= e[i + 1] and i < n - 1:
        i += 1
    return i


@numba.njit(cache=True, nogil=True)
def _route_points(x, y, ex, ey, size, b, off_x, off_y, width, wanted):  # type: ignore[no-untyped-def]
    """Per point: core tile (-1 outside), 9-bit mask of the tiles of its 3 x 3
    neighbourhood that take it (bit ky * 3 + kx; 4 = its core), sub-cell (gx, gy)."""
    n = len(x)
    nx, ny = len(ex) - 1, len(ey) - 1
    core = np.empty(n, np.int64)
    mask = np.zeros(n, np.uint16)
    gx = np.empty(n, np.int64)
    gy = np.empty(n, np.int64)
    for i in range(n):
        xi, yi = x[i], y[i]
        gx[i] = np.int64(np.floor((xi - off_x) / width)) + _SUB_BIAS
        gy[i] = np.int64(np.floor((yi - off_y) / width)) + _SUB_BIAS
        ix = _core_axis(xi, ex, size)
        iy = _core_axis(yi, ey, size)
        if ix < 0 or iy < 0:
            core[i] = -1
            continue
        core[i] = iy * nx + ix
        near = ((xi - ex[ix] < b) and ix > 0) or ((xi >= ex[min(ix + 1, nx)] - b) and ix < nx - 1) \
            or ((yi - ey[iy] < b) and iy > 0) or ((yi >= ey[min(iy + 1, ny)] - b) and iy < ny - 1)
        m = 0
        if not near:
            m = 1 << 4
        else:
            for ky in range(3):
                jy = iy + ky - 1
                if jy < 0 or jy >= ny:
                    continue
                if ky != 1 and not (ey[jy] - b <= yi and yi < ey[jy + 1] + b):
                    continue
                for kx in range(3):
                    jx = ix + kx - 1
                    if jx < 0 or jx >= nx:
                        continue
                    if kx != 1 and not (ex[jx] - b <= xi and xi < ex[jx + 1] + b):
                        continue
                    m |= 1 << (ky * 3 + kx)
        # keep only the tiles asked for
        for k in range(9):
            if m & (1 << k):
                t = (iy + k // 3 - 1) * nx + (ix + k % 3 - 1)
                if not wanted[t]:
                    m &= ~(1 << k)
        mask[i] = m
    return core, mask, gx, gy


@numba.njit(cache=True, nogil=True)
def _group_pairs(core, mask, gx, gy, nx, n_tiles):  # type: ignore[no-untyped-def]
    n = len(core)
    cnt = np.zeros(n_tiles, np.int64)
    big = np.int64(1) << 62
    gx0 = np.full(n_tiles, big)
    gy0 = np.full(n_tiles, big)
    gx1 = np.full(n_tiles, -big)
    gy1 = np.full(n_tiles, -big)
    for i in range(n):
        m = mask[i]
        if m == 0:
            continue
        c = core[i]
        for k in range(9):
            if m & (1 << k):
                t = c + (k // 3 - 1) * nx + (k % 3 - 1)
                cnt[t] += 1
                gx0[t] = min(gx0[t], gx[i])
                gx1[t] = max(gx1[t], gx[i])
                gy0[t] = min(gy0[t], gy[i])
                gy1[t] = max(gy1[t], gy[i])
    base = np.zeros(n_tiles + 1, np.int64)  # first bin of each tile
    for t in range(n_tiles):
        bins = 0
        if cnt[t] > 0:
            bins = (gx1[t] - gx0[t] + 1) * (gy1[t] - gy0[t] + 1)
        base[t + 1] = base[t] + bins
    n_bins = base[n_tiles]
    counts = np.zeros(n_bins + 1, np.int64)
    for i in range(n):
        m = mask[i]
        if m == 0:
            continue
        c = core[i]
        for k in range(9):
            if m & (1 << k):
                t = c + (k // 3 - 1) * nx + (k % 3 - 1)
                counts[base[t] + (gy[i] - gy0[t]) * (gx1[t] - gx0[t] + 1) + (gx[i] - gx0[t]) + 1] += 1
    for j in range(n_bins):
        counts[j + 1] += counts[j]
    n_pairs = counts[n_bins]
    # groups: the non-empty bins, in bin order (tile, then sub-cell key)
    n_groups = 0
    for j in range(n_bins):
        if counts[j + 1] > counts[j]:
            n_groups += 1
    g_tile = np.empty(n_groups, np.int64)
    g_key = np.empty(n_groups, np.int64)
    g_start = np.empty(n_groups, np.int64)
    g = 0
    for t in range(n_tiles):
        if cnt[t] == 0:
            continue
        w = gx1[t] - gx0[t] + 1
        for j in range(base[t], base[t + 1]):
            if counts[j + 1] > counts[j]:
                r = j - base[t]
                g_tile[g] = t
                g_key[g] = ((gy0[t] + r // w) << 31) | (gx0[t] + r % w)
                g_start[g] = counts[j]
                g += 1
    point = np.empty(n_pairs, np.int64)
    is_core = np.empty(n_pairs, np.bool_)
    pos = counts[:n_bins].copy()
    for i in range(n):  # in point order: stable within each (tile, sub-cell)
        m = mask[i]
        if m == 0:
            continue
        c = core[i]
        for k in range(9):
            if m & (1 << k):
                t = c + (k // 3 - 1) * nx + (k % 3 - 1)
                j = base[t] + (gy[i] - gy0[t]) * (gx1[t] - gx0[t] + 1) + (gx[i] - gx0[t])
                point[pos[j]] = i
                is_core[pos[j]] = k == 4
                pos[j] += 1
    return point, is_core, g_tile, g_key, g_start


def route_groups(
    x: npt.NDArray[np.float64], y: npt.NDArray[np.float64], ex: npt.NDArray[np.float64],
    ey: npt.NDArray[np.float64], *, tile_size: float, buffer: float, sub_offset: tuple[float, float],
    sub_width: float, wanted: npt.NDArray[np.bool_],
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64], npt.NDArray[np.bool_], npt.NDArray[np.int64],
           npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """Route points to tiles and order the pairs by (tile, sub-cell, point).

    Parameters
    ----------
    x, y : ndarray of shape (n,), float64
        World coordinates.
    ex, ey : ndarray
        The grid's tile edges (``TileGrid.edges()``).
    tile_size, buffer : float
        As in the grid.
    sub_offset, sub_width : (float, float), float
        Sub-cell ``(gx, gy)`` of a point is ``floor((x - sub_offset) / sub_width)``.
    wanted : ndarray of shape (n_tiles,), bool
        Pairs are made only for these tiles.

    Returns
    -------
    core : ndarray of shape (n,), int64
        Core tile of every point; -1 outside the grid (such points get no pair).
    point : ndarray of shape (n_pairs,), int64
        Row of every pair, pairs sorted by tile, sub-cell key, row.
    is_core : ndarray of shape (n_pairs,), bool
    g_tile, g_key, g_start : ndarray of shape (n_groups,), int64
        Every run of equal (tile, sub-cell): its tile, its sub-cell key
        ``(gy + 2**30) << 31 | (gx + 2**30)`` and its first pair.
    """
    wanted_u8 = np.ascontiguousarray(wanted, dtype=np.bool_)
    core, mask, gx, gy = _route_points(
        np.ascontiguousarray(x, np.float64), np.ascontiguousarray(y, np.float64),
        np.ascontiguousarray(ex, np.float64), np.ascontiguousarray(ey, np.float64),
        float(tile_size), float(buffer), float(sub_offset[0]), float(sub_offset[1]), float(sub_width), wanted_u8,
    )
    point, is_core, g_tile, g_key, g_start = _group_pairs(core, mask, gx, gy, len(ex) - 1, len(wanted_u8))
    return core, point, is_core, g_tile, g_key, g_start


@numba.njit(cache=True, nogil=True)
def _quantise(xyz, offset, scale, out):  # type: ignore[no-untyped-def]
    for i in range(xyz.shape[0]):
        for a in range(3):
            out[i, a] = np.int32(np.rint((xyz[i, a] - offset[a]) / scale[a]))


def quantise(xyz: npt.NDArray[np.float64], offset: npt.NDArray[np.float64],
             scale: npt.NDArray[np.float64]) -> npt.NDArray[np.int32]:
    """``np.round((xyz - offset) / scale).astype(np.int32)`` in one pass (callers check
    the int32 range beforehand)."""
    out = np.empty(xyz.shape, np.int32)
    _quantise(np.ascontiguousarray(xyz, np.float64), np.asarray(offset, np.float64),
              np.asarray(scale, np.float64), out)
    return out


def split_rows(rows: np.ndarray, names: list[str], perm: npt.NDArray[np.int64]) -> dict[str, np.ndarray]:
    """``{name: rows[name][perm]}``: whole rows are taken in ``perm``'s order (one pass
    of record copies), and each field is returned as a view of them (strided; the tile
    writer makes each chunk contiguous as it encodes it, so no field is copied twice)."""
    taken = rows.take(np.asarray(perm, np.int64))
    return {name: taken[name] for name in names}


@numba.njit(cache=True, nogil=True, inline="always")
def _spread3(v):  # type: ignore[no-untyped-def]
    v = v & np.uint64(0x1FFFFF)
    v = (v | (v << np.uint64(32))) & np.uint64(0x1F00000000FFFF)
    v = (v | (v << np.uint64(16))) & np.uint64(0x1F0000FF0000FF)
    v = (v | (v << np.uint64(8))) & np.uint64(0x100F00F00F00F00F)
    v = (v | (v << np.uint64(4))) & np.uint64(0x10C30C30C30C30C3)
    v = (v | (v << np.uint64(2))) & np.uint64(0x1249249249249249)
    return v


@numba.njit(cache=True, nogil=True)
def _radix_packed(code, bits, pos_bits):  # type: ignore[no-untyped-def]
    """Stable LSD radix sort of ``code`` (below ``2**bits``) with each row's position
    packed below it (``bits + pos_bits <= 64``): one array moves per pass. Returns the
    permutation and the sorted codes."""
    n = len(code)
    key = np.empty(n, np.uint64)
    for i in range(n):
        key[i] = (code[i] << np.uint64(pos_bits)) | np.uint64(i)
    passes = (bits + 10) // 11
    if passes > 0:
        digit = (bits + passes - 1) // passes
        size = 1 << digit
        mask = np.uint64(size - 1)
        count = np.zeros((passes, size + 1), np.int64)
        for i in range(n):  # every pass's histogram in one read
            k = key[i] >> np.uint64(pos_bits)
            for p in range(passes):
                count[p, ((k >> np.uint64(p * digit)) & mask) + 1] += 1
        tmp = np.empty(n, np.uint64)
        for p in range(passes):
            c = count[p]
            for d in range(size):
                c[d + 1] += c[d]
            sh = np.uint64(pos_bits + p * digit)
            for i in range(n):
                d = (key[i] >> sh) & mask
                j = c[d]
                tmp[j] = key[i]
                c[d] = j + 1
            key, tmp = tmp, key
    low = np.uint64((1 << pos_bits) - 1)
    perm = np.empty(n, np.int64)
    out = np.empty(n, np.uint64)
    for i in range(n):
        perm[i] = np.int64(key[i] & low)
        out[i] = key[i] >> np.uint64(pos_bits)
    return perm, out


@numba.njit(cache=True, nogil=True)
def _radix_pairs(code, bits):  # type: ignore[no-untyped-def]
    """Stable LSD radix sort of ``code`` carrying the row numbers alongside (any size)."""
    n = len(code)
    perm = np.arange(n).astype(np.int64)
    tmp_p = np.empty(n, np.int64)
    tmp_c = np.empty(n, np.uint64)
    digit = 11
    mask = np.uint64((1 << digit) - 1)
    count = np.empty((1 << digit) + 1, np.int64)
    shift = 0
    while shift < bits:
        count[:] = 0
        sh = np.uint64(shift)
        for i in range(n):
            count[((code[i] >> sh) & mask) + 1] += 1
        for d in range(1 << digit):
            count[d + 1] += count[d]
        for i in range(n):
            d = (code[i] >> sh) & mask
            j = count[d]
            tmp_c[j] = code[i]
            tmp_p[j] = perm[i]
            count[d] = j + 1
        code, tmp_c = tmp_c, code
        perm, tmp_p = tmp_p, perm
        shift += digit
    return perm, code


@numba.njit(cache=True, nogil=True)
def _morton_index_order(xyz, index, origin, cell):  # type: ignore[no-untyped-def]
    n = xyz.shape[0]
    top = 2.0**21 - 1
    code = np.empty(n, np.uint64)
    hi = np.uint64(0)
    for i in range(n):
        c = np.uint64(0)
        for a in range(3):
            q = np.floor((np.float64(xyz[i, a]) - origin[a]) / cell)
            if q < 0.0:
                q = 0.0
            if q > top:
                q = top
            c |= _spread3(np.uint64(q)) << np.uint64(a)
        code[i] = c
        hi |= c
    bits = 0
    while bits < 64 and (hi >> np.uint64(bits)) != np.uint64(0):
        bits += 1
    pos_bits = 1
    while (1 << pos_bits) < n:
        pos_bits += 1
    if bits + pos_bits <= 64:
        perm, code = _radix_packed(code, bits, pos_bits)
    else:
        perm, code = _radix_pairs(code, bits)
    # equal codes (points in one cell): by original index, as after an index sort
    i = 0
    while i < n:
        j = i + 1
        while j < n and code[j] == code[i]:
            j += 1
        if j - i > 32:  # many points in one cell (duplicates): a real sort
            run = perm[i:j].copy()
            keys = np.empty(j - i, np.uint64)
            for a in range(j - i):
                keys[a] = index[run[a]]
            o = np.argsort(keys)
            for a in range(j - i):
                perm[i + a] = run[o[a]]
        elif j - i > 1:
            for a in range(i + 1, j):  # insertion sort: such runs are short
                p = perm[a]
                key = index[p]
                b = a - 1
                while b >= i and index[perm[b]] > key:
                    perm[b + 1] = perm[b]
                    b -= 1
                perm[b + 1] = p
        i = j
    return perm


def morton_index_order(xyz: npt.NDArray[np.int32], index: npt.NDArray[np.uint64], *,
                       origin: npt.ArrayLike, cell: float) -> npt.NDArray[np.int64]:
    """Rows sorted by 3-D Morton code of ``floor((xyz - origin) / cell)`` (clipped to
    21 bits per axis), equal codes by ``index``: the order of
    ``perm = argsort(index); perm[morton_order(xyz[perm], origin=origin, cell=cell)]``."""
    return _morton_index_order(np.ascontiguousarray(xyz), np.ascontiguousarray(index, np.uint64),
                               np.asarray(origin, np.float64), float(cell))
