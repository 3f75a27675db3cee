"""The ingest's numba kernels (tiling/kernels.py) against the NumPy definitions they replace."""

from __future__ import annotations

import numpy as np
import pytest

from hollowtree.tiling.grid import TileGrid, morton_order
from hollowtree.tiling.kernels import morton_index_order, quantise, route_groups, split_rows


def _points(rng: np.random.Generator, grid: TileGrid, n: int) -> np.ndarray:
    ex, ey = grid.edges()
    xy = np.stack([rng.uniform(ex[0], ex[-1], n), rng.uniform(ey[0], ey[-1], n)], axis=1)
    # points exactly on edges, on edges +- buffer, and on the closed top/right border
    k = n // 10
    xy[:k, 0] = rng.choice(np.r_[ex, ex + grid.buffer, ex - grid.buffer], k).clip(ex[0], ex[-1])
    xy[k:2 * k, 1] = rng.choice(np.r_[ey, ey + grid.buffer, ey - grid.buffer], k).clip(ey[0], ey[-1])
    return xy


@pytest.mark.parametrize(("origin", "size", "buffer", "shape"), [
    ((500_000.0, 3_500_000.0), 20.0, 2.0, (4, 3)),
    ((0.0, 0.0), 0.7, 0.3, (5, 5)),
    ((-35.0, 10.0), 5.0, 0.0, (1, 6)),
    ((100.0, 100.0), 55.0, 2.0, (1, 1)),
])
def test_route_groups_matches_route_and_lexsort(origin, size, buffer, shape):
    rng = np.random.default_rng(3)
    grid = TileGrid(origin=origin, tile_size=size, buffer=buffer, shape=shape)
    xy = _points(rng, grid, 20_000)
    wanted = rng.random(grid.n_tiles) < 0.7
    wanted[0] = True
    width, off = size / 8, (origin[0] - 3.3, origin[1] + 1.7)
    core, point, is_core, g_tile, g_key, g_start = route_groups(
        xy[:, 0], xy[:, 1], *grid.edges(), tile_size=size, buffer=buffer, sub_offset=off,
        sub_width=width, wanted=wanted)

    assert np.array_equal(core, grid.core_tile(xy, outside="flag"))
    p, t, c = grid.route(xy, outside="flag", sort=False)
    keep = wanted[t]
    p, t, c = p[keep], t[keep], c[keep]
    gx = np.floor((xy[:, 0] - off[0]) / width).astype(np.int64) + (1 << 30)
    gy = np.floor((xy[:, 1] - off[1]) / width).astype(np.int64) + (1 << 30)
    sub = ((gy << 31) | gx)[p]
    order = np.lexsort((p, sub, t))
    assert np.array_equal(point, p[order])
    assert np.array_equal(is_core, c[order])
    first = np.flatnonzero(np.r_[True, (t[order][1:] != t[order][:-1]) | (sub[order][1:] != sub[order][:-1])])
    assert np.array_equal(g_start, first)
    assert np.array_equal(g_tile, t[order][first])
    assert np.array_equal(g_key, sub[order][first])


def test_route_groups_flags_points_outside():
    grid = TileGrid(origin=(0.0, 0.0), tile_size=10.0, buffer=1.0, shape=(2, 2))
    xy = np.array([[5.0, 5.0], [25.0, 5.0], [np.nan, 1.0], [20.0, 20.0]])
    core, point, *_ = route_groups(xy[:, 0], xy[:, 1], *grid.edges(), tile_size=10.0, buffer=1.0,
                                   sub_offset=(0.0, 0.0), sub_width=1.0, wanted=np.ones(4, bool))
    assert core.tolist() == [0, -1, -1, 3]
    assert sorted(set(point.tolist())) == [0, 3]


def test_quantise_matches_round():
    rng = np.random.default_rng(1)
    xyz = rng.uniform(-1000, 1000, (5000, 3))
    xyz[:100] = np.round(xyz[:100] * 2) / 2 * 0.001  # exact halves of the scale
    off, scale = np.array([1.0, -2.0, 0.5]), np.array([0.001, 0.001, 0.0005])
    assert np.array_equal(quantise(xyz, off, scale), np.round((xyz - off) / scale).astype(np.int32))


def test_split_rows():
    rng = np.random.default_rng(2)
    dt = np.dtype([("xyz", "<i4", (3,)), ("index", "<u8"), ("core", "?"), ("rgb", "<u2", (3,)), ("g", "<f8")])
    rows = np.zeros(1000, dt)
    for k in dt.names:
        rows[k] = rng.integers(0, 200, rows[k].shape)
    perm = rng.integers(0, len(rows), 700)
    out = split_rows(rows, list(dt.names), perm)
    for k in dt.names:
        assert out[k].dtype == dt[k].base
        assert np.array_equal(out[k], rows[k][perm])
    assert split_rows(rows, ["rgb"], np.zeros(0, np.int64))["rgb"].shape == (0, 3)


@pytest.mark.parametrize("dup", [False, True])
def test_morton_index_order_matches_index_then_morton(dup):
    rng = np.random.default_rng(4)
    n = 30_000
    xyz = rng.integers(0, 3000, (n, 3)).astype(np.int32)
    if dup:  # many points in one cell, and runs of a few
        xyz[: n // 3] = xyz[0]
        xyz[n // 3: n // 2] = xyz[rng.integers(n // 3, n // 2, n // 2 - n // 3)]
    index = rng.permutation(10 * n)[:n].astype(np.uint64)
    origin = np.array([-7.0, 3.0, float(xyz[:, 2].min())])
    perm = np.argsort(index)
    expected = perm[morton_order(xyz[perm], origin=origin, cell=10.0)]
    assert np.array_equal(morton_index_order(xyz, index, origin=origin, cell=10.0), expected)


def test_radix_sorts_agree_and_are_stable():
    from hollowtree.tiling.kernels import _radix_packed, _radix_pairs

    rng = np.random.default_rng(5)
    code = rng.integers(0, 2**20, 50_000).astype(np.uint64)
    code[::7] = code[0]  # ties
    expected = np.argsort(code, kind="stable")
    p1, c1 = _radix_packed(code.copy(), 20, 16)
    p2, c2 = _radix_pairs(code.copy(), 20)
    assert np.array_equal(p1, expected)
    assert np.array_equal(p2, expected)
    assert np.array_equal(c1, code[expected])
    assert np.array_equal(c2, code[expected])
