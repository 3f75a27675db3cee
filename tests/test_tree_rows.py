"""Arcade rows after the tree (tree/rows.py): pieces take their piers, gaps get bays, end
bays lose their end wall, pieces inside a bay join it, straight or curved; short rows
change nothing."""

from __future__ import annotations

import numpy as np
import pytest

from hollowtree.classes import ClassId
from hollowtree.tree import rows
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
    assert cells.take[k] == 3
    assert t1 - t0 == pytest.approx(PITCH, abs=0.15)
    # pieces and gaps take wall, other, pillar, dome and arch points; full bays wall, dome and arch
    assert set(cells.instance[cells.take == 2].tolist()) == {4, 100, 101}
    assert set(cells.instance[cells.take == 3].tolist()) == {1, 2, 3, 5, 6, 7, 8}
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
                    [0.5 * PITCH, 0.2, 1.0],         # a wall point there (a pier face): joins it
                    [0.5 * PITCH, 0.0, 7.0],         # a dome point above it: stays
                    [0.9 * PITCH, 0.0, 2.0],         # bay 2's overreach into bay 1's cell: bay 1's
                    [0.5 * PITCH, 0.0, 2.0]])        # a pillar point in a full bay's cell: stays
    D, P = int(ClassId.DOME), int(ClassId.PILLAR)
    cls = np.array([WALL, WALL, WALL, ARCH, ARCH, WALL, D, WALL, D, ARCH, P])
    inst = np.array([50, 50, 50, 8, 8, 50, 60, 50, 60, 2, 70])
    c, i = apply_cells(xyz, cls, inst, cells)
    assert c.tolist() == [ARCH, WALL, ARCH, WALL, ARCH, WALL, ARCH, ARCH, D, ARCH, P]
    assert i.tolist() == [4, 50, 100, 0, 8, 50, 1, 1, 60, 1, 70]


def test_a_bay_that_is_one_face_takes_the_rest_of_its_bay():
    """A bay found as its front face alone (a pitch wide but 0.15 m of the wall's 1 m deep)
    is a piece: its cell spans the wall's depth and takes the intrados and back face that
    were left in the wall."""
    rng = np.random.default_rng(5)
    row = {i + 1: _box(rng, i * PITCH, (i + 1) * PITCH) for i in range(6)}
    row[3] = _box(rng, 2 * PITCH, 3 * PITCH, y=(0.35, 0.5))
    cells, absorbed = arcade_cells(_samples(row), 100)
    assert absorbed == {}
    assert set(cells.instance[cells.take == 2].tolist()) == {3}
    k, (t0, t1) = _cell(cells, 3)
    assert (t0, t1) == (pytest.approx(2 * PITCH, abs=0.1), pytest.approx(3 * PITCH, abs=0.1))
    xyz = np.array([[2.5 * PITCH, -0.45, 1.0], [2.5 * PITCH, 0.0, 4.0], [1.5 * PITCH, -0.45, 1.0],
                    [2.5 * PITCH, 0.0, 2.0]])
    c, i = apply_cells(xyz, [WALL, WALL, WALL, int(ClassId.OTHER)], [50, 50, 50, 0], cells)
    assert c.tolist() == [ARCH, ARCH, ARCH, ARCH]
    assert i.tolist() == [3, 3, 2, 3]


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


def _curved(rng, radius=34.0, step=6.0, n=12):
    """An arcade of ``n`` bays of ``step`` degrees on a circle (3.6 m on 34 m: neighbours
    are parallel); bay 6 is a piece (its intrados, its pier faces left in the wall)."""
    curved = {}
    for k in range(n):
        a0, a1 = np.radians(step * k), np.radians(step * (k + 1))
        a = rng.uniform(a0, a1, 600)
        r = rng.uniform(radius - 0.5, radius + 0.5, 600)
        pts = np.column_stack([r * np.cos(a), r * np.sin(a), rng.uniform(0, 5, 600)])
        curved[k + 1] = pts if k != 5 else pts[(a > a0 + 0.015) & (a < a1 - 0.015)]
    return curved


def test_a_curved_row_is_completed_in_its_own_frames():
    """A curved arcade is a row along its circle: the piece takes its pier faces, each cell
    has its own frame (the tangent at its middle), and the cells tile the arc."""
    rng = np.random.default_rng(3)
    cells, absorbed = arcade_cells(_samples(_curved(rng)), 100)
    assert absorbed == {}
    assert sorted(cells.instance.tolist()) == list(range(1, 13))
    assert set(cells.instance[cells.take == 2].tolist()) == {6}
    assert not cells.trim.any()
    # every frame is a point on the circle with its tangent
    o, u = cells.frame[:, :2], cells.frame[:, 2:]
    np.testing.assert_allclose(np.hypot(*o.T), 34.0, atol=0.3)
    np.testing.assert_allclose(np.abs(np.sum(o * u, axis=1)) / 34.0, 0.0, atol=0.02)
    # the piece's cell reaches its neighbours' edges: one pitch (3.56 m of arc) wide
    (k,) = np.flatnonzero(cells.instance == 6)
    assert cells.box[k, 1] - cells.box[k, 0] == pytest.approx(np.radians(6.0) * 34.0, abs=0.15)
    # a pier face of bay 6 left in the wall joins it; wall behind the arcade stays
    a = np.radians([30.3, 30.3, 33.0])
    r = np.array([34.2, 37.0, 34.0])
    xyz = np.column_stack([r * np.cos(a), r * np.sin(a), [2.0, 2.0, 2.0]])
    c, i = apply_cells(xyz, [WALL, WALL, ARCH], [0, 0, 6], cells)
    assert c.tolist() == [ARCH, WALL, ARCH]
    assert i.tolist() == [6, 0, 6]


def test_the_storeys_of_a_curved_facade_share_its_circle():
    """Two storeys of one curved facade: the upper one's bays lie on the lower row's circle
    and make a row of their own, at their own base."""
    rng = np.random.default_rng(5)
    lower = _curved(rng)
    upper = {100 + i: p + (0.0, 0.0, 6.0) for i, p in _curved(rng).items()}
    cells, absorbed = arcade_cells(_samples({**lower, **upper}), 1000)
    assert absorbed == {}
    assert sorted(cells.instance.tolist()) == [*range(1, 13), *range(101, 113)]
    assert set(cells.instance[cells.take == 2].tolist()) == {6, 106}
    for i, z0 in ((6, 0.0), (106, 6.0)):
        (k,) = np.flatnonzero(cells.instance == i)
        assert cells.box[k, 4] == pytest.approx(z0 - 0.2, abs=0.1)


def test_a_straight_stretch_of_a_curved_row_gives_way_to_it(monkeypatch):
    """Bays 1-3 of a curved arcade (10 degrees each on 30 m) linked apart from the rest
    (bay 3 pushed 0.5 m out) are straight to 0.6 m, a row of their own; the curved row
    grown from bays 4-12 holds them, and the straight row gives way to it."""
    rng = np.random.default_rng(6)
    b = _curved(rng, radius=30.0, step=10.0, n=12)
    a = np.arctan2(b[3][:, 1], b[3][:, 0])
    b[3] = b[3] + np.column_stack([0.5 * np.cos(a), 0.5 * np.sin(a), np.zeros(len(a))])
    bays = [rows._bay(i, p, np.ones(len(p))) for i, p in sorted(b.items())]
    assert sorted(sorted(x.id for x in r) for r in rows._rows(bays)) == [[1, 2, 3], list(range(4, 13))]
    ((row, line),) = rows._lines(bays)
    assert isinstance(line, rows._Arc)
    assert line.r == pytest.approx(30.0, abs=0.3)
    assert sorted(x.id for x in row) == list(range(1, 13))
    monkeypatch.setattr(rows, "_arc", lambda seed, free: None)
    ((row, line),) = rows._lines(bays)
    assert isinstance(line, rows._Line)
    assert sorted(x.id for x in row) == [1, 2, 3]


def test_a_circle_too_small_or_too_few_bays_is_no_row():
    rng = np.random.default_rng(4)
    # three bays on a 6 m circle: neighbours' axes 35 degrees apart, never linked
    assert len(arcade_cells(_samples(_curved(rng, radius=6.0, step=35.0, n=3)), 100)[0]) == 0
    # two bays of the curved arcade are no row
    two = {i: p for i, p in _curved(rng).items() if i <= 2}
    assert len(arcade_cells(_samples(two), 100)[0]) == 0


def test_short_and_portal_rows_change_nothing():
    rng = np.random.default_rng(3)
    # two bays are no row
    two = {1: _box(rng, 0, PITCH), 2: _box(rng, PITCH + 0.5, 2 * PITCH - 0.5, z1=3.5)}
    assert len(arcade_cells(_samples(two), 100)[0]) == 0
    # a portal at the row's end (1.5 pitches wide but taller than the row) is not cut
    row = {i: _box(rng, k * PITCH, (k + 1) * PITCH) for i, k in ((1, 0), (2, 1), (3, 2), (4, 3))}
    row[5] = _box(rng, 4 * PITCH, 5.5 * PITCH, z1=9.0)
    cells, _ = arcade_cells(_samples(row), 100)
    assert len(cells)
    assert (cells.take == 3).all()
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
