"""Arcade rows after the tree (tree/rows.py): pieces take their piers, gaps get bays, end
bays lose their end wall, pieces inside a bay join it; curved or short rows change nothing."""

from __future__ import annotations

import numpy as np
import pytest

from hollowtree.classes import ClassId
from hollowtree.tree.rows import ArcadeCells, apply_cells, arcade_cells, instance_sample

PITCH = 3.6
ARCH, WALL = int(ClassId.ARCH), int(ClassId.WALL)


def _box(rng, x0, x1, z1=5.0, n=600, y=(-0.5, 0.5)):
    return np.column_stack([rng.uniform(x0, x1, n), rng.uniform(*y, n), rng.uniform(0.0, z1, n)])


def _samples(boxes):
    return {i: (p, np.ones(len(p))) for i, p in boxes.items()}


def _row(rng):
    """Bays 1-3 full, 4 a piece (its intrados: narrower and lower), 5 full, two bays
    missing, 6 and 7 full, 8 the last bay with a 1.2 m end wall; 20 a small arch piece
    mostly inside bay 2 (0.75 of it below the row's top), 21 one mostly above bay 3."""
    b = {}
    for i, k in ((1, 0), (2, 1), (3, 2), (5, 4), (6, 7), (7, 8)):
        b[i] = _box(rng, k * PITCH, (k + 1) * PITCH)
    b[4] = _box(rng, 3 * PITCH + 0.5, 4 * PITCH - 0.5, z1=3.5)
    b[8] = _box(rng, 9 * PITCH, 10 * PITCH + 1.2)
    b[20] = _box(rng, 1 * PITCH + 1.0, 1 * PITCH + 2.0, z1=6.7, n=400)
    b[21] = _box(rng, 2 * PITCH + 1.0, 2 * PITCH + 2.0, z1=12.5, n=400)
    return b


def _cell(cells, i):
    (k,) = np.flatnonzero(cells.instance == i)
    o, u = cells.frame[k, :2], cells.frame[k, 2:]
    t0, t1 = sorted(float(o @ u + t * (1 if u[0] > 0 else -1)) for t in cells.box[k, :2])
    return k, (t0, t1)


def test_a_row_of_bays_is_completed():
    rng = np.random.default_rng(0)
    cells, absorbed = arcade_cells(_samples(_row(rng)), 100)
    assert absorbed == {20: 2}
    # the piece takes up to its full neighbours' edges, to the row's top
    k, (t0, t1) = _cell(cells, 4)
    assert cells.take[k]
    assert not cells.trim[k]
    assert t0 == pytest.approx(3 * PITCH, abs=0.1)
    assert t1 == pytest.approx(4 * PITCH, abs=0.1)
    assert cells.box[k, 5] == pytest.approx(5.05, abs=0.1)
    # the gap of three pitches holds two new bays
    for i, a in ((100, 5), (101, 6)):
        k, (t0, t1) = _cell(cells, i)
        assert cells.take[k]
        assert t0 == pytest.approx(a * PITCH, abs=0.1)
        assert t1 == pytest.approx((a + 1) * PITCH, abs=0.1)
    # the last bay is cut to one pitch
    k, (t0, t1) = _cell(cells, 8)
    assert cells.trim[k]
    assert cells.take[k] == 2
    assert t1 - t0 == pytest.approx(PITCH, abs=0.15)
    # full bays take only dome points
    assert set(cells.instance[cells.take == 1].tolist()) == {4, 100, 101}
    assert set(cells.instance[cells.take == 2].tolist()) == {1, 2, 3, 5, 6, 7, 8}
    assert cells.instance[cells.trim].tolist() == [8]


def test_cells_change_the_points():
    rng = np.random.default_rng(1)
    cells, _ = arcade_cells(_samples(_row(rng)), 100)
    xyz = np.array([[3 * PITCH + 0.2, 0.45, 1.0],    # the piece's pier face, in the wall: joins bay 4
                    [3 * PITCH + 0.2, 2.0, 1.0],     # behind the row: stays
                    [5.5 * PITCH, 0.0, 2.0],         # the gap: a new bay
                    [10 * PITCH + 0.8, 0.0, 2.0],    # bay 8's end wall: back to the wall
                    [9.5 * PITCH, 0.0, 2.0],         # bay 8 itself
                    [3 * PITCH + 0.2, 0.0, 9.0],     # above the row's top: stays
                    [0.5 * PITCH, 0.0, 2.0],         # a dome point in full bay 1: joins it
                    [0.5 * PITCH, 0.2, 1.0],         # a wall point there: stays
                    [0.5 * PITCH, 0.0, 7.0]])        # a dome point above it: stays
    D = int(ClassId.DOME)
    cls = np.array([WALL, WALL, WALL, ARCH, ARCH, WALL, D, WALL, D])
    inst = np.array([50, 50, 50, 8, 8, 50, 60, 50, 60])
    c, i = apply_cells(xyz, cls, inst, cells)
    assert c.tolist() == [ARCH, WALL, ARCH, WALL, ARCH, WALL, ARCH, WALL, D]
    assert i.tolist() == [4, 50, 100, 0, 8, 50, 1, 50, 60]


def test_a_bay_that_is_one_face_takes_the_rest_of_its_bay():
    """A bay found as its front face alone (a pitch wide but 0.15 m of the wall's 1 m deep)
    is a piece: its cell spans the wall's depth and takes the intrados and back face that
    were left in the wall. Without the depth test it would be full and take nothing."""
    rng = np.random.default_rng(5)
    row = {i + 1: _box(rng, i * PITCH, (i + 1) * PITCH) for i in range(6)}
    row[3] = _box(rng, 2 * PITCH, 3 * PITCH, y=(0.35, 0.5))
    cells, absorbed = arcade_cells(_samples(row), 100)
    assert absorbed == {}
    assert set(cells.instance[cells.take == 1].tolist()) == {3}
    k, (t0, t1) = _cell(cells, 3)
    assert (t0, t1) == (pytest.approx(2 * PITCH, abs=0.1), pytest.approx(3 * PITCH, abs=0.1))
    xyz = np.array([[2.5 * PITCH, -0.45, 1.0], [2.5 * PITCH, 0.0, 4.0], [1.5 * PITCH, -0.45, 1.0]])
    c, i = apply_cells(xyz, [WALL, WALL, WALL], [50, 50, 50], cells)
    assert c.tolist() == [ARCH, ARCH, WALL]
    assert i.tolist() == [3, 3, 50]


def test_the_row_may_run_any_way():
    """The same row turned by 37 degrees and moved gives the same cells in its own frame."""
    rng = np.random.default_rng(2)
    row = _row(rng)
    a = np.radians(37.0)
    rot = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    turned = {i: p @ rot.T + (100.0, -40.0, 3.0) for i, p in row.items()}
    c0, a0 = arcade_cells(_samples(row), 100)
    c1, a1 = arcade_cells(_samples(turned), 100)
    assert a0 == a1
    np.testing.assert_array_equal(c0.instance, c1.instance)
    np.testing.assert_allclose(np.diff(c0.box[:, :2], axis=1), np.diff(c1.box[:, :2], axis=1), atol=0.15)


def test_curved_short_and_portal_rows_change_nothing():
    rng = np.random.default_rng(3)
    # a curved arcade: 12 bays of 3.6 m on a 34 m radius (6 degrees each: neighbours are parallel)
    curved = {}
    for k in range(12):
        a0, a1 = np.radians(6.0 * k), np.radians(6.0 * (k + 1))
        a = rng.uniform(a0, a1, 600)
        r = rng.uniform(33.5, 34.5, 600)
        pts = np.column_stack([r * np.cos(a), r * np.sin(a), rng.uniform(0, 5, 600)])
        curved[k + 1] = pts if k != 5 else pts[(a > a0 + 0.015) & (a < a1 - 0.015)]
    cells, absorbed = arcade_cells(_samples(curved), 100)
    assert len(cells) == 0
    assert absorbed == {}
    # two bays are no row
    two = {1: _box(rng, 0, PITCH), 2: _box(rng, PITCH + 0.5, 2 * PITCH - 0.5, z1=3.5)}
    assert len(arcade_cells(_samples(two), 100)[0]) == 0
    # a portal at the row's end (1.5 pitches wide but taller than the row) is not cut
    row = {i: _box(rng, k * PITCH, (k + 1) * PITCH) for i, k in ((1, 0), (2, 1), (3, 2), (4, 3))}
    row[5] = _box(rng, 4 * PITCH, 5.5 * PITCH, z1=9.0)
    cells, _ = arcade_cells(_samples(row), 100)
    assert len(cells)
    assert (cells.take == 2).all()
    assert not cells.trim.any()


def test_instance_sample_is_seeded_and_weighted():
    rng = np.random.default_rng(4)
    xyz = rng.normal(size=(10_000, 3))
    inst = np.repeat([3, 5, 9], [6000, 3000, 1000])
    cls = np.repeat([ARCH, WALL, ARCH], [6000, 3000, 1000])
    a = instance_sample(xyz, inst, cls, np.random.default_rng(7), n=2000)
    b = instance_sample(xyz, inst, cls, np.random.default_rng(7), n=2000)
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x, y)
    i, p, w, c = a
    assert (c == ARCH).all()
    assert np.bincount(i).tolist()[3] == 2000
    assert np.bincount(i).tolist()[9] == 1000
    assert 5 not in i
    assert w[i == 3].sum() == pytest.approx(6000)
    assert w[i == 9].sum() == pytest.approx(1000)


def test_cells_survive_the_store_array():
    rng = np.random.default_rng(5)
    cells, _ = arcade_cells(_samples(_row(rng)), 100)
    back = ArcadeCells.from_array(cells.to_arrays()["cells"])
    for f in ("frame", "box", "instance", "take", "trim"):
        np.testing.assert_array_equal(getattr(back, f), getattr(cells, f))
    assert len(ArcadeCells.from_array(ArcadeCells.empty().to_arrays()["cells"])) == 0


def test_a_dome_in_a_row_is_part_of_a_bay():
    """A piece of two bays that HollowNet calls dome (in the row's band, below its top) is
    no dome instance (its points there join the bays); a dome above the row or behind it is."""
    rng = np.random.default_rng(6)
    row = _row(rng)
    domes = {30: (_box(rng, 1.2 * PITCH, 2.4 * PITCH, z1=3.5), np.ones(600)),
             31: (_box(rng, 1.0 * PITCH, 2.0 * PITCH, z1=4.0, y=(3.0, 5.0)), np.ones(600)),
             32: (_box(rng, 1.0 * PITCH, 2.0 * PITCH, z1=4.0) + (0, 0, 8.0), np.ones(600))}
    _, absorbed = arcade_cells(_samples(row), 100, domes=domes)
    assert absorbed[30] == 0
    assert 31 not in absorbed
    assert 32 not in absorbed
