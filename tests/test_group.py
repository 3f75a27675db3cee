"""Element groups: the contacts kernel (the stage's groups: tests/test_coarse.py)."""

from __future__ import annotations

import numpy as np
import pytest

from hollowtree.errors import ConfigError
from hollowtree.pipeline.coarse import CoarseParams
from hollowtree.primitives.group import (
    OUTLINE_DIRECTIONS,
    box_plane_distance,
    large_segments,
    outline_add,
    segment_contacts,
    segment_contacts_chunked,
    set_in_plane,
    stacked_pairs,
)


def _ring(n: int, r: float, z: float, rng: np.random.Generator) -> np.ndarray:
    t = rng.uniform(0, 2 * np.pi, n)
    return np.c_[r * np.cos(t), r * np.sin(t), z + rng.uniform(0, 1, n)]


def test_contacts_find_touching_segments_only():
    rng = np.random.default_rng(0)
    lower, upper = _ring(3000, 1.0, 0.0, rng), _ring(3000, 1.0, 1.1, rng)  # 0.1 m apart
    far = _ring(3000, 1.0, 5.0, rng)
    xyz = np.r_[lower, upper, far]
    seg = np.repeat([3, 1, 2], 3000)
    a, b, n = segment_contacts(xyz, seg, 0.3)
    assert (a.tolist(), b.tolist()) == ([1], [3])
    assert n[0] >= 3
    assert segment_contacts(xyz, seg, 0.05)[0].size == 0  # closer than the gap: none
    # unsegmented points (0) never make a contact, a single segment has none
    assert segment_contacts(xyz, np.where(seg == 2, 0, 1), 0.3)[0].size == 0


def test_contacts_need_min_contacts():
    xyz = np.array([[0.0, 0, 0], [0.2, 0, 0], [5.0, 0, 0], [5.2, 0, 0]])
    seg = np.array([1, 2, 3, 4])
    assert segment_contacts(xyz, seg, 0.3, min_contacts=1)[0].tolist() == [1, 3]
    assert segment_contacts(xyz, seg, 0.3, min_contacts=2)[0].size == 0


@pytest.mark.parametrize("cuts", [[], [1], [4000, 4001], [500, 3000, 6000, 8999], list(range(0, 9000, 700))])
def test_chunked_contacts_equal_the_whole(cuts):
    """Contacts taken chunk by chunk (a tile's rows, read a piece at a time) are those of
    all the points at once: the same pairs and the same counts, whatever the cuts."""
    rng = np.random.default_rng(3)
    xyz = np.r_[_ring(3000, 1.0, 0.0, rng), _ring(3000, 1.0, 1.1, rng), _ring(3000, 1.05, 0.5, rng)]
    seg = rng.choice([0, 1, 2, 3, 4], size=len(xyz), p=[0.1, 0.3, 0.3, 0.2, 0.1])
    order = rng.permutation(len(xyz))  # chunks cut across voxels and segments
    xyz, seg = xyz[order], seg[order]
    whole = segment_contacts(xyz, seg, 0.3, min_contacts=1)
    assert len(whole[0]) >= 3
    bounds = [0, *cuts, len(xyz)]
    chunks = [(xyz[a:b], seg[a:b]) for a, b in zip(bounds[:-1], bounds[1:], strict=True)]
    got = segment_contacts_chunked(chunks, 0.3, min_contacts=1)
    for w, g in zip(whole, got, strict=True):
        assert np.array_equal(w, g)
    assert segment_contacts_chunked([(xyz, np.zeros(len(xyz), int))], 0.3)[0].size == 0  # nothing segmented
    with pytest.raises(ConfigError, match="segment"):
        segment_contacts_chunked([(xyz, seg[:-1])], 0.3)


@pytest.mark.parametrize("bad", [0.0, -1.0, float("nan")])
def test_contacts_refuse_a_bad_gap(bad):
    with pytest.raises(ConfigError, match="gap"):
        segment_contacts(np.zeros((2, 3)), np.array([1, 2]), bad)


def test_group_params_are_validated():
    with pytest.raises(ConfigError, match="group_gap"):
        CoarseParams(group_gap=-0.1)
    with pytest.raises(ConfigError, match="group_min_contacts"):
        CoarseParams(group_min_contacts=0)
    with pytest.raises(ConfigError, match="group_max_plane"):
        CoarseParams(group_max_plane=0.0)
    with pytest.raises(ConfigError, match="group_set_in"):
        CoarseParams(group_set_in=-1.0)
    with pytest.raises(ConfigError, match="group_stack"):
        CoarseParams(group_stack=float("nan"))


def test_box_plane_distance_is_the_farthest_corner():
    rng = np.random.default_rng(1)
    lo = rng.uniform(-5, 5, (50, 3))
    boxes = np.c_[lo, lo + rng.uniform(0, 3, (50, 3))]
    normal, d = rng.normal(size=3), 0.7
    corners = np.stack([np.c_[boxes[:, 0 + 3 * i], boxes[:, 1 + 3 * j], boxes[:, 2 + 3 * k]]
                        for i in (0, 1) for j in (0, 1) for k in (0, 1)])  # (8, 50, 3)
    brute = np.abs(corners @ (normal / np.linalg.norm(normal)) + d / np.linalg.norm(normal)).max(axis=0)
    np.testing.assert_allclose(box_plane_distance(boxes, normal, d), brute, rtol=1e-12)
    with pytest.raises(ConfigError, match="normal"):
        box_plane_distance(boxes, [0, 0, 0], 1.0)


def test_set_in_plane_takes_jambs_not_neighbours():
    wall = [0.0, -0.02, 0.0, 30.0, 0.02, 8.0]  # the face y = 0 of a 1 m thick wall (y > 0)
    boxes = [
        [4.0, 0.0, 0.0, 5.0, 1.0, 3.5],     # a jamb and its intrados, inside the wall
        [4.0, -0.5, 0.0, 5.0, 1.2, 4.0],    # the same, reaching a little out of the face
        [-3.0, -2.0, 0.0, 1.0, 2.0, 30.0],  # a minaret at the wall's end: too deep and tall
        [10.0, 1.0, 0.0, 14.0, 5.0, 0.1],   # floor behind the wall: too far from the plane
        [35.0, 0.0, 0.0, 36.0, 1.0, 3.0],   # in the plane but beyond the wall's end
    ]
    assert set_in_plane(boxes, [0, 1, 0], 0.0, wall, 1.5).tolist() == [True, True, False, False, False]
    assert set_in_plane(boxes, [0, 1, 0], 0.0, wall, 0.5).tolist() == [False, False, False, False, False]
    with pytest.raises(ConfigError, match="tol"):
        set_in_plane(boxes, [0, 1, 0], 0.0, wall, 0.0)


def test_set_in_does_not_turn_with_the_scan():
    """A jamb 1.4 m deep and an intrados 2 m along a wall's face are set in it whatever the
    wall's heading: by their outlines, not their boxes, whose corners stand off a turned wall."""
    rng = np.random.default_rng(3)
    pieces = [np.c_[rng.uniform(4, 4.3, 3000), rng.uniform(0, 1.4, 3000), rng.uniform(0, 3.5, 3000)],  # jamb
              np.c_[rng.uniform(4.3, 6.3, 3000), rng.uniform(0, 1.4, 3000), rng.uniform(3.4, 3.6, 3000)],  # intrados
              np.c_[rng.uniform(10, 14, 3000), rng.uniform(1.0, 5.0, 3000), rng.uniform(0, 0.1, 3000)]]  # floor
    face = np.c_[rng.uniform(0, 30, 20000), np.zeros(20000), rng.uniform(0, 8, 20000)]
    box_says = []
    for deg in (0, 15, 30, 45, 60, 90, 135):
        t = np.radians(deg)
        rot = np.array([[np.cos(t), -np.sin(t), 0], [np.sin(t), np.cos(t), 0], [0, 0, 1]])
        ps = [p @ rot.T for p in pieces]
        wall = face @ rot.T
        wall_box = np.r_[wall.min(axis=0), wall.max(axis=0)]
        normal = rot @ [0.0, 1.0, 0.0]
        boxes = [np.r_[p.min(axis=0), p.max(axis=0)] for p in ps]
        lo = np.full((len(ps) + 1, OUTLINE_DIRECTIONS), np.inf)
        hi = np.full_like(lo, -np.inf)
        outline_add(lo, hi, np.concatenate(ps)[:, :2], np.repeat(np.arange(1, len(ps) + 1), 3000))
        outlines = np.hstack([lo[1:], hi[1:]])
        assert set_in_plane(boxes, normal, 0.0, wall_box, 1.5, outlines=outlines).tolist() == [True, True, False], deg
        box_says.append(set_in_plane(boxes, normal, 0.0, wall_box, 1.5).tolist())
    assert box_says[0] == [True, True, False]  # along the axes the box was right
    assert any(b != [True, True, False] for b in box_says)  # what the outline fixes


def test_stacked_pairs_join_stages_not_neighbours():
    stages = [[0, 0, 0, 4, 4, 10], [0.3, 0.3, 10.4, 3.7, 3.7, 17], [0.6, 0.6, 17.8, 3.4, 3.4, 24]]
    others = [
        [6, 0, 10.4, 10, 4, 17],      # beside stage 0, not above it
        [0, 0, 12.5, 4, 4, 20],       # above stage 0 but 2.5 m up
        [1, 1, 2, 3, 3, 8],           # inside stage 0 (overlapping in height)
        [-20, -20, 10.2, 20, 20, 11],  # a wide slab on top: covers stage 0's plan, 100 x its area
        [0, 0, 10.3, 6, 6, 12],       # a wider stage: 2.25 x stage 0's area
    ]
    lo, up = stacked_pairs(stages + others, 1.0)
    pairs = sorted(zip(lo.tolist(), up.tolist(), strict=True))
    assert {(0, 1), (1, 2), (0, 7)} <= set(pairs)
    assert not {(0, 3), (0, 4), (0, 5), (5, 0), (0, 6)} & set(pairs)
    assert stacked_pairs([stages[0], others[3]], 1.0, area_ratio=200.0)[0].size == 1
    assert stacked_pairs(stages, 0.2)[0].size == 0  # gaps of 0.4 and 0.8 m
    with pytest.raises(ConfigError, match="overlap"):
        stacked_pairs(stages, 1.0, overlap=0.0)
    with pytest.raises(ConfigError, match="area_ratio"):
        stacked_pairs(stages, 1.0, area_ratio=0.5)


def test_large_segments_planes_and_strips():
    boxes = [
        [0, 0, 0, 5, 3, 8],     # a 5.8 m wall piece: not large
        [0, 0, 0, 30, 1, 8],    # a facade: large
        [0, 0, 0, 10, 10, 6],   # a dome's free cluster, 14 m across: not large
        [0, 0, 0, 41, 4, 11],   # a free strip along a facade, 41 m: large
        [0, 0, 0, 28, 3, 20],   # a curved arcade's cylinder, 28 m: groupable
    ]
    kinds = ["plane", "plane", "free", "free", "cylinder"]
    assert large_segments(kinds, boxes, 6.0).tolist() == [False, True, False, True, False]
    assert large_segments(kinds, boxes, 6.0, strip_factor=10.0).tolist() == [False, True, False, False, False]
    with pytest.raises(ConfigError, match="one entry per box"):
        large_segments(kinds[:2], boxes, 6.0)
    with pytest.raises(ConfigError, match="strip_factor"):
        large_segments(kinds, boxes, 6.0, strip_factor=0.5)
