"""Tile grid arithmetic (tiling/grid.py): hand-worked toys and hypothesis properties."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hollowtree.errors import ConfigError
from hollowtree.tiling.grid import TileGrid, morton_order

# -- strategies -----------------------------------------------------------------------------

sizes = st.sampled_from([0.1, 0.25, 1.0, 3.0, 10.0, 25.0, 50.0, 0.3, 7.7])
buffer_fractions = st.sampled_from([0.0, 0.01, 0.1, 0.25, 0.5, 0.9])
# Large offsets mimic UTM coordinates, where float64 rounding at tile edges matters.
offsets = st.sampled_from([0.0, -1234.5, 500_000.0, 4_649_776.0])


@st.composite
def grids_and_points(draw):
    size = draw(sizes)
    buffer = draw(buffer_fractions) * size
    ox = draw(offsets)
    oy = draw(offsets)
    nx = draw(st.integers(1, 5))
    ny = draw(st.integers(1, 5))
    grid = TileGrid(origin=(ox, oy), tile_size=size, buffer=buffer, shape=(nx, ny))
    ex, ey = grid.edges()
    n = draw(st.integers(1, 60))
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    x = rng.uniform(ex[0], ex[-1], n)
    y = rng.uniform(ey[0], ey[-1], n)
    # Plant points exactly on edges and at buffer distance from edges, the hard cases.
    k = n // 2
    x[:k] = rng.choice(np.concatenate([ex, ex[1:-1] - buffer, ex[1:-1] + buffer]), k)
    y[: k // 2] = rng.choice(np.concatenate([ey, ey[1:-1] - buffer, ey[1:-1] + buffer]), k // 2)
    x = np.clip(x, ex[0], ex[-1])
    y = np.clip(y, ey[0], ey[-1])
    return grid, np.stack([x, y], axis=1)


def _in_box(xy, box, *, closed_top=(False, False)):
    x0, y0, x1, y1 = box
    inx = (xy[:, 0] >= x0) & ((xy[:, 0] <= x1) if closed_top[0] else (xy[:, 0] < x1))
    iny = (xy[:, 1] >= y0) & ((xy[:, 1] <= y1) if closed_top[1] else (xy[:, 1] < y1))
    return inx & iny


def _core_mask(grid, xy, tile):
    ix, iy = grid.tile_index(tile)
    closed = (ix == grid.shape[0] - 1, iy == grid.shape[1] - 1)
    return _in_box(xy, grid.core_bounds(tile), closed_top=closed)


# -- toys worked by hand --------------------------------------------------------------------


def test_toy_core_tiles_and_edges():
    grid = TileGrid(origin=(0.0, 0.0), tile_size=10.0, buffer=2.0, shape=(3, 2))
    xy = np.array([[0, 0], [9.999, 0], [10, 0], [30, 0], [30, 20], [15, 10], [29.9, 19.9]])
    assert grid.core_tile(xy).tolist() == [0, 0, 1, 2, 5, 4, 5]
    assert grid.tile_id(2, 1) == 5
    assert grid.tile_index(5) == (2, 1)
    assert grid.tile_id(np.array([0, 2]), np.array([1, 0])).tolist() == [3, 2]
    assert grid.core_bounds(4) == (10.0, 10.0, 20.0, 20.0)
    assert grid.buffered_bounds(4) == (8.0, 8.0, 22.0, 22.0)


def test_toy_route_by_hand():
    grid = TileGrid(origin=(0.0, 0.0), tile_size=10.0, buffer=2.0, shape=(3, 2))
    xy = np.array([[5.0, 5.0], [11.0, 9.0], [12.0, 5.0], [30.0, 20.0]])
    p, t, c = grid.route(xy)
    pairs = sorted(zip(p.tolist(), t.tolist(), c.tolist(), strict=True))
    assert pairs == [
        (0, 0, True),
        # (11, 9): core tile 1; within 2 of tile 0 (x < 12), of tiles 4 and 3 (y >= 8)
        (1, 0, False), (1, 1, True), (1, 3, False), (1, 4, False),
        # (12, 5): x == 10 + buffer is outside tile 0's half-open buffered box
        (2, 1, True),
        # the grid's top-right corner: core of the last tile, buffered in no other
        (3, 5, True),
    ]


def test_zero_buffer_route_is_core_tile():
    grid = TileGrid(origin=(0.0, 0.0), tile_size=1.0, buffer=0.0, shape=(2, 2))
    xy = np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 2.0], [2.0, 0.5], [0.999, 1.999]])
    p, t, c = grid.route(xy)
    assert p.tolist() == [0, 1, 2, 3, 4]
    assert t.tolist() == grid.core_tile(xy).tolist() == [0, 3, 3, 1, 2]
    assert c.all()


def test_outside_points_raise_or_flag():
    grid = TileGrid(origin=(0.0, 0.0), tile_size=1.0, buffer=0.5, shape=(2, 1))
    xy = np.array([[0.5, 0.5], [-0.1, 0.5], [2.0, 1.0], [2.0001, 0.0], [np.nan, 0.0], [0.0, np.inf]])
    with pytest.raises(ConfigError, match="4 of 6 points lie outside the tile grid"):
        grid.core_tile(xy)
    with pytest.raises(ConfigError, match="outside the tile grid"):
        grid.route(xy)
    assert grid.core_tile(xy, outside="flag").tolist() == [0, -1, 1, -1, -1, -1]
    p, t, c = grid.route(xy, outside="flag")
    # (0.5, 0.5) also lies in tile 1's buffered box [0.5, 2.5) x [-0.5, 1.5)
    assert p.tolist() == [0, 0, 2]
    assert t.tolist() == [0, 1, 1]
    assert c.tolist() == [True, False, True]


def test_covering_centres_the_fewest_tiles():
    g = TileGrid.covering(12.0, -3.0, 31.0, 9.0, tile_size=10.0, buffer=2.0)
    assert g.origin == (11.5, -7.0)
    assert g.shape == (2, 2)
    # Bounds that straddle a multiple of the tile size still fit in one tile.
    assert TileGrid.covering(-10.7, -17.9, 31.7, 24.4, tile_size=60.0, buffer=2.0).shape == (1, 1)
    # Degenerate bounds still give one tile; a span of exactly k tiles needs k + 1 (half-open cores).
    assert TileGrid.covering(5.0, 5.0, 5.0, 5.0, tile_size=10.0, buffer=0.0).shape == (1, 1)
    assert TileGrid.covering(0.0, 0.0, 20.0, 10.0, tile_size=10.0, buffer=0.0).shape == (3, 2)


@settings(max_examples=200, deadline=None)
@given(
    lo=st.tuples(st.floats(-1e6, 1e6), st.floats(-1e6, 1e6)),
    span=st.tuples(st.floats(0, 1e4), st.floats(0, 1e4)),
    at=st.tuples(st.floats(-1e6, 1e6), st.floats(-1e6, 1e6)),
    size=sizes,
)
def test_covering_aligned_puts_an_edge_through_the_point(lo, span, at, size):
    xmin, ymin = lo
    xmax, ymax = xmin + span[0], ymin + span[1]
    g = TileGrid.covering(xmin, ymin, xmax, ymax, tile_size=size, buffer=0.0, align=at)
    corners = np.array([[xmin, ymin], [xmax, ymax], [xmin, ymax], [xmax, ymin]])
    assert (g.core_tile(corners) >= 0).all()
    for axis in (0, 1):
        k = (g.origin[axis] - at[axis]) / size
        assert abs(k - round(k)) < 1e-6 * max(1.0, abs(k))  # an edge passes through ``at``
        assert g.shape[axis] <= math.floor((span[axis]) / size) + 2  # one tile more than centred at most


@settings(max_examples=200, deadline=None)
@given(
    lo=st.tuples(st.floats(-1e7, 1e7), st.floats(-1e7, 1e7)),
    span=st.tuples(st.floats(0, 1e4), st.floats(0, 1e4)),
    size=sizes,
)
def test_covering_property(lo, span, size):
    xmin, ymin = lo
    xmax, ymax = xmin + span[0], ymin + span[1]
    g = TileGrid.covering(xmin, ymin, xmax, ymax, tile_size=size, buffer=0.0)
    corners = np.array([[xmin, ymin], [xmax, ymax], [xmin, ymax], [xmax, ymin]])
    assert (g.core_tile(corners) >= 0).all()
    # fewest tiles (one more only where rounding at a large offset asks for it), centred
    for axis, (a, b) in enumerate(((xmin, xmax), (ymin, ymax))):
        assert g.shape[axis] - (math.floor((b - a) / size) + 1) in (0, 1)
        right = g.origin[axis] + g.shape[axis] * size - b
        assert g.origin[axis] <= a
        assert right > 0
        assert (a - g.origin[axis]) == pytest.approx(right, abs=1e-6 * max(1.0, abs(a), size))
    ex, ey = g.edges()
    # smallest: dropping a column or row would uncover the maximum (cores are half-open,
    # so a maximum exactly on the last inner edge belongs to the last column)
    assert ex[-2] <= xmax or g.shape[0] == 1
    assert ey[-2] <= ymax or g.shape[1] == 1


# -- properties -----------------------------------------------------------------------------


@settings(max_examples=300, deadline=None)
@given(grids_and_points())
def test_every_point_in_exactly_one_core(case):
    grid, xy = case
    core = grid.core_tile(xy)
    hits = np.stack([_core_mask(grid, xy, t) for t in range(grid.n_tiles)], axis=1)
    assert (hits.sum(axis=1) == 1).all()
    assert (np.argmax(hits, axis=1) == core).all()


@settings(max_examples=300, deadline=None)
@given(grids_and_points())
def test_route_is_exactly_the_buffered_boxes(case):
    grid, xy = case
    p, t, c = grid.route(xy)
    core = grid.core_tile(xy)
    got = np.zeros((len(xy), grid.n_tiles), dtype=bool)
    got[p, t] = True
    assert len(p) == got.sum(), "a (point, tile) pair was repeated"
    for tile in range(grid.n_tiles):
        want = _in_box(xy, grid.buffered_bounds(tile)) | (core == tile)
        assert (got[:, tile] == want).all(), tile
    # is_core marks exactly the core tile, once per point
    assert (t[c] == core[p[c]]).all()
    assert np.bincount(p[c], minlength=len(xy)).tolist() == [1] * len(xy)
    assert (np.bincount(p, minlength=len(xy)) <= 9).all()
    # sorted by point, then tile
    assert (np.lexsort((t, p)) == np.arange(len(p))).all()


@settings(max_examples=200, deadline=None)
@given(grids_and_points())
def test_route_matches_chebyshev_distance(case):
    """Away from the exact box boundaries, route == Chebyshev distance to the core <= buffer."""
    grid, xy = case
    p, t, _ = grid.route(xy)
    got = np.zeros((len(xy), grid.n_tiles), dtype=bool)
    got[p, t] = True
    eps = 1e-9 * max(1.0, np.abs(xy).max())
    for tile in range(grid.n_tiles):
        x0, y0, x1, y1 = grid.core_bounds(tile)
        dx = np.maximum.reduce([x0 - xy[:, 0], xy[:, 0] - x1, np.zeros(len(xy))])
        dy = np.maximum.reduce([y0 - xy[:, 1], xy[:, 1] - y1, np.zeros(len(xy))])
        dist = np.maximum(dx, dy)
        clear = np.abs(dist - grid.buffer) > eps
        assert (got[clear, tile] == (dist[clear] < grid.buffer)).all()


@settings(max_examples=200, deadline=None)
@given(
    origin=st.tuples(st.floats(-1e9, 1e9), st.floats(-1e9, 1e9)),
    size=st.floats(1e-3, 1e4),
    frac=st.floats(0, 0.999),
    shape=st.tuples(st.integers(1, 10_000), st.integers(1, 10_000)),
)
def test_to_dict_round_trip(origin, size, frac, shape):
    grid = TileGrid(origin=origin, tile_size=size, buffer=frac * size, shape=shape)
    d = grid.to_dict()
    assert TileGrid.from_dict(d) == grid
    assert sorted(d) == ["buffer", "origin", "shape", "tile_size"]
    for tile in (0, grid.n_tiles - 1):
        assert grid.tile_id(*grid.tile_index(tile)) == tile


# -- validation -----------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"tile_size": -3}, r"'tile_size' parameter of TileGrid must be > 0; got -3"),
        ({"tile_size": 0.0}, r"must be > 0; got 0.0"),
        ({"tile_size": float("nan")}, r"'tile_size' .* must be finite"),
        ({"tile_size": "10"}, r"'tile_size' .* must be a number; got '10'"),
        ({"buffer": -1.0}, r"'buffer' .* must be in \[0, tile_size=10.0\); got -1.0"),
        ({"buffer": 10.0}, r"'buffer' .* got 10.0"),
        ({"shape": (0, 2)}, r"'shape' .* two ints >= 1"),
        ({"shape": (2.0, 2)}, r"'shape'"),
        ({"shape": (True, 2)}, r"'shape'"),
        ({"shape": (1, 2, 3)}, r"'shape'"),
        ({"origin": (0.0,)}, r"'origin' .* must be \(x, y\)"),
        ({"origin": (0.0, float("inf"))}, r"'origin' .* finite"),
    ],
)
def test_validation_errors(kwargs, match):
    params = {"origin": (0.0, 0.0), "tile_size": 10.0, "buffer": 1.0, "shape": (2, 2)} | kwargs
    with pytest.raises(ConfigError, match=match):
        TileGrid(**params)


def test_more_validation_errors():
    grid = TileGrid(origin=(0.0, 0.0), tile_size=10.0, buffer=1.0, shape=(2, 2))
    with pytest.raises(ConfigError, match="unknown keys \\['extra'\\]"):
        TileGrid.from_dict(grid.to_dict() | {"extra": 1})
    with pytest.raises(ConfigError, match="missing keys \\['buffer'\\]"):
        TileGrid.from_dict({k: v for k, v in grid.to_dict().items() if k != "buffer"})
    with pytest.raises(ConfigError, match="tile id 4"):
        grid.tile_index(4)
    with pytest.raises(ConfigError, match="outside the grid"):
        grid.tile_id(2, 0)
    with pytest.raises(ConfigError, match="xmin <= xmax"):
        TileGrid.covering(1.0, 0.0, 0.0, 1.0, tile_size=1.0, buffer=0.0)
    with pytest.raises(ConfigError, match="shape \\(n_points, 2\\)"):
        grid.core_tile(np.zeros(3))
    with pytest.raises(ConfigError, match="'outside'"):
        grid.core_tile(np.zeros((1, 2)), outside="drop")
    with pytest.raises(dataclasses.FrozenInstanceError):
        grid.tile_size = 3.0


def test_inputs_not_modified():
    grid = TileGrid(origin=(0.0, 0.0), tile_size=1.0, buffer=0.2, shape=(3, 3))
    xy = np.random.default_rng(0).uniform(0, 3, (100, 3))
    before = xy.copy()
    grid.route(xy)
    morton_order(xy, origin=(0, 0, 0), cell=0.1)
    assert np.array_equal(xy, before)


# -- morton order ---------------------------------------------------------------------------


@settings(max_examples=100, deadline=None)
@given(n=st.integers(0, 500), dim=st.sampled_from([2, 3]), seed=st.integers(0, 2**32 - 1),
       cell=st.sampled_from([0.01, 0.5, 3.0]))
def test_morton_is_a_stable_permutation(n, dim, seed, cell):
    rng = np.random.default_rng(seed)
    pts = rng.uniform(-5, 50, (n, dim))  # some points below the origin: clipped, still sorted
    pts[: n // 3] = pts[0] if n else pts[: n // 3]  # duplicates must keep input order
    order = morton_order(pts, origin=np.zeros(dim), cell=cell)
    assert order.dtype == np.int64
    assert np.array_equal(np.sort(order), np.arange(n))
    dup = order[np.isin(order, np.arange(n // 3))]
    assert (np.diff(dup) > 0).all()


@pytest.mark.parametrize("dim", [2, 3])
def test_morton_groups_nearby_points(dim):
    rng = np.random.default_rng(42)
    pts = rng.uniform(0, 100, (20_000, dim))
    order = morton_order(pts, origin=np.zeros(dim), cell=0.01)

    def mean_step(p):
        return np.linalg.norm(np.diff(p, axis=0), axis=1).mean()

    assert mean_step(pts[order]) < 0.1 * mean_step(pts)


def test_morton_hand_worked_3d():
    # The eight unit cells of a 2x2x2 block come out in x, then y, then z order.
    cells = np.array([[x, y, z] for z in (0, 1) for y in (0, 1) for x in (0, 1)], dtype=float)
    shuffled = cells[::-1] + 0.5
    order = morton_order(shuffled, origin=(0, 0, 0), cell=1.0)
    assert np.array_equal(shuffled[order] - 0.5, cells)
    # 21 bits per axis: the highest representable cell sorts last
    far = np.array([[2**21 - 1, 2**21 - 1, 2**21 - 1], [0, 0, 0]], dtype=float)
    assert morton_order(far, origin=(0, 0, 0), cell=1.0).tolist() == [1, 0]


def test_morton_validation():
    with pytest.raises(ConfigError, match="'cell'"):
        morton_order(np.zeros((2, 3)), origin=(0, 0, 0), cell=0)
    with pytest.raises(ConfigError, match="origin must have shape \\(3,\\)"):
        morton_order(np.zeros((2, 3)), origin=(0, 0), cell=1.0)
    with pytest.raises(ConfigError, match="finite"):
        morton_order(np.array([[np.nan, 0.0]]), origin=(0, 0), cell=1.0)
    with pytest.raises(ConfigError, match="shape"):
        morton_order(np.zeros((2, 4)), origin=(0, 0, 0, 0), cell=1.0)
