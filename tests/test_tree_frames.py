"""Frames after the rows (tree/frames.py): a portal's face joins its passage, a lone
bay's intrados takes its piers up to half the pier to the next opening; a facade wall, a
face away from the passage, a door in a plain wall and a whole bay change nothing."""

from __future__ import annotations

import numpy as np
import pytest

from hollowtree.tree.frames import frame_cells

#: A facade wall 1.5 m thick along x (y from 0 to 1.5), scanned from y < 0.
THICK = 1.5


def _box(rng, x0, x1, y0, y1, z1, n):
    return np.column_stack([rng.uniform(x0, x1, n), rng.uniform(y0, y1, n), rng.uniform(0.0, z1, n)])


def _s(**parts):
    return {int(k[1:]): (p, np.ones(len(p))) for k, p in parts.items()}


def _passage(rng, x0=-2.5, x1=2.5, depth=3.0, top=9.0):
    """A passage's two jambs (planes across the wall) and its soffit."""
    return np.r_[_box(rng, x0 - 0.05, x0, 0, depth, 0.6 * top, 1500), _box(rng, x1, x1 + 0.05, 0, depth, 0.6 * top, 1500),
                 _box(rng, x0, x1, 0, depth, top, 1500) * [1, 1, 0] + [0, 0, top]]


def test_a_portal_face_joins_its_passage():
    rng = np.random.default_rng(0)
    passage = _passage(rng)
    face = _box(rng, -4.0, 4.0, -0.05, 0.0, 14.0, 3000)  # the pishtaq's frame, in front of the passage
    cells, joined = frame_cells(_s(a1=passage), _s(w2=face))
    assert joined == {2: 1}
    assert len(cells) == 0
    # an arch face (another element group's) joins the same way
    assert frame_cells(_s(a1=passage, a3=face), {})[1] == {3: 1}
    # a facade wall 2.4 times as wide as the passage is the wall it opens in
    wide = _box(rng, -4.0, 8.0, -0.05, 0.0, 14.0, 3000)
    assert frame_cells(_s(a1=passage), _s(w2=wide))[1] == {}
    # a plane 2 m in front of the passage is not its face, nor a plane that stops below its top
    assert frame_cells(_s(a1=passage), _s(w2=face - [0, 2.0, 0]))[1] == {}
    assert frame_cells(_s(a1=passage), _s(w2=face * [1, 1, 0.5]))[1] == {}
    # the wall band above the passage is no face either
    assert frame_cells(_s(a1=passage), _s(w2=_box(rng, -4.0, 4.0, -0.05, 0.0, 5.0, 3000) + [0, 0, 9.0]))[1] == {}


def _facade(rng, openings, x0=-12.0, x1=12.0, top=9.0, density=400):
    """The outer face (y = 0) and the upper band of a wall with arched ``openings``
    (x0, x1, height): no face points in an opening below its height."""
    n = int(density * (x1 - x0) * top / 10)
    p = _box(rng, x0, x1, -0.02, 0.0, top, n)
    keep = np.ones(len(p), bool)
    for a, b, h in openings:
        keep &= ~((p[:, 0] > a) & (p[:, 0] < b) & (p[:, 2] < h))
    return p[keep]


def _intrados(rng, a, b, h=4.8, spring=3.0):
    """A bay's intrados: its two jambs through the wall and its soffit."""
    return np.r_[_box(rng, a - 0.05, a, 0, THICK, spring, 500), _box(rng, b, b + 0.05, 0, THICK, spring, 500),
                 np.column_stack([rng.uniform(a, b, 600), rng.uniform(0, THICK, 600), rng.uniform(spring, h, 600)])]


def test_a_lone_piece_takes_half_its_piers():
    rng = np.random.default_rng(1)
    # two bays of an arcade (openings 2.2 m wide, piers 1.3 m): only the first one's intrados is an arch
    # instance, the rest (pier faces, the second opening's frame) is the facade's wall
    ops = [(-2.2, 0.0, 4.8), (1.3, 3.5, 4.8)]
    cells, joined = frame_cells(_s(a1=_intrados(rng, -2.2, 0.0)), _s(w5=_facade(rng, ops)))
    assert joined == {}
    assert cells.instance.tolist() == [1]
    assert cells.take.tolist() == [1]
    o, u = cells.frame[0, :2], cells.frame[0, 2:]
    t0, t1 = sorted(float(o @ u + t * np.sign(u[0])) for t in cells.box[0, :2])
    # half the pier to the next opening on the right (0.65 m), the same on the left (no opening there)
    assert t0 == pytest.approx(-2.2 - 0.65, abs=0.12)
    assert t1 == pytest.approx(0.0 + 0.65, abs=0.12)
    assert cells.box[0, 5] == pytest.approx(4.85, abs=0.15)
    y = sorted(o[1] + cells.box[0, 2:4] * u[0])  # across the row: (-uy, ux)
    assert y[0] < -0.1
    assert y[1] > THICK


def test_the_next_opening_is_a_bay_a_shadow_is_not():
    rng = np.random.default_rng(3)
    ops = [(-2.2, 0.0, 4.8), (1.3, 3.5, 4.8)]
    piece = _intrados(rng, -2.2, 0.0)
    cells, _ = frame_cells(_s(a1=piece), _s(w5=_facade(rng, ops)), next_id=50)
    assert cells.instance.tolist() == [1, 50]
    o, u = cells.frame[1, :2], cells.frame[1, 2:]
    t0, t1 = sorted(float(o @ u + t * np.sign(u[0])) for t in cells.box[1, :2])
    # one pitch (opening 2.2 m and pier 1.3 m) from the middle of the pier
    assert t0 == pytest.approx(0.65, abs=0.12)
    assert t1 == pytest.approx(0.65 + 3.5, abs=0.15)
    # no next bay without next_id, nor where an arch instance already has that bay
    assert frame_cells(_s(a1=piece), _s(w5=_facade(rng, ops)))[0].instance.tolist() == [1]
    there = _intrados(rng, 1.3, 3.5)
    assert frame_cells(_s(a1=piece, a2=there), _s(w5=_facade(rng, ops)), skip={2}, next_id=50)[0].instance.tolist() == [1]
    # two pieces with the bay between them missing: one next bay, not two
    ops3 = [*ops, (4.8, 7.0, 4.8)]
    two = frame_cells(_s(a1=piece, a3=_intrados(rng, 4.8, 7.0)), _s(w5=_facade(rng, ops3)), next_id=50)[0]
    assert two.instance.tolist() == [1, 3, 50]
    # a shadow (no wall over the break at any height) is no opening: no next bay
    shadow = _facade(rng, [(-2.2, 0.0, 4.8), (1.3, 3.5, 9.0)])
    assert frame_cells(_s(a1=piece), _s(w5=shadow), next_id=50)[0].instance.tolist() == [1]


def test_a_door_a_whole_bay_and_a_row_member_stay():
    rng = np.random.default_rng(2)
    # a lone opening in a plain wall: no pier width to take
    door = frame_cells(_s(a1=_intrados(rng, -2.2, 0.0)), _s(w5=_facade(rng, [(-2.2, 0.0, 4.8)])))
    assert len(door[0]) == 0
    assert door[1] == {}
    # a whole bay (its pier faces with it) is no piece
    ops = [(-2.2, 0.0, 4.8), (1.3, 3.5, 4.8)]
    wall = _facade(rng, ops)
    bay = np.r_[_intrados(rng, -2.2, 0.0), wall[(wall[:, 0] > -2.85) & (wall[:, 0] < 0.65) & (wall[:, 2] < 5.0)]]
    rest = wall[~((wall[:, 0] > -2.85) & (wall[:, 0] < 0.65) & (wall[:, 2] < 5.0))]
    assert len(frame_cells(_s(a1=bay), _s(w5=rest))[0]) == 0
    # a face's piece (thin across the wall: no jambs through it) is no piece
    edges = np.r_[_box(rng, -2.3, -2.2, -0.05, 0.0, 3.0, 500), _box(rng, 0.0, 0.1, -0.05, 0.0, 3.0, 500),
                  _box(rng, -2.2, 0.0, -0.05, 0.0, 1.0, 300) + [0, 0, 3.8]]
    assert len(frame_cells(_s(a1=edges), _s(w5=wall))[0]) == 0
    # nor is a piece with no wall beside one jamb (the facade ends there)
    assert len(frame_cells(_s(a1=_intrados(rng, -2.2, 0.0)), _s(w5=wall[wall[:, 0] > -2.2]))[0]) == 0
    # a piece in a row is the row's (tree/rows.py)
    assert len(frame_cells(_s(a1=_intrados(rng, -2.2, 0.0)), _s(w5=wall), skip={1})[0]) == 0
