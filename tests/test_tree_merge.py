"""tree/merge.py: one element split over two element groups is one instance."""

from __future__ import annotations

import numpy as np
import pytest

from hollowtree.classes import ClassId
from hollowtree.tree.merge import merge_instances

A, D = int(ClassId.ARCH), int(ClassId.DOME)


def _bay(u0, u1, *, y0=0.0, y1=1.2, z1=8.0):
    return [u0, y0, 0.0, u1, y1, z1]


def test_the_face_of_a_bay_joins_its_bay_and_nothing_else():
    """Khudabad's arcade: each bay's front face (a plane, flat box, 5.8 m) went to one
    group, its soffit and back (8 m) to another; neighbouring bays share only a pier."""
    faces = [_bay(4.8 * k, 4.8 * (k + 1), y0=0.0, y1=0.0, z1=5.8) for k in range(4)]
    bays = [_bay(4.8 * k, 4.8 * (k + 1)) for k in range(4)]
    m = merge_instances(np.arange(1, 9), [A] * 8, [1] * 4 + [2] * 4, faces + bays, 8)
    assert m.tolist() == [0, 1, 2, 3, 4, 1, 2, 3, 4]


def test_storeys_neighbours_same_group_and_other_classes_stay_apart():
    lower, upper = _bay(0, 4, z1=6.0), [0, 0, 6.0, 4, 1.2, 12.0]
    nxt = _bay(4, 8)
    boxes = [lower, upper, nxt, _bay(0, 4), _bay(0, 4)]
    # storeys (groups 1, 2), neighbour (3), a twin in the same group as `lower` (1), a dome (4)
    m = merge_instances([1, 2, 3, 4, 5], [A, A, A, A, D], [1, 2, 3, 1, 4], boxes, 5)
    assert m.tolist() == [0, 1, 2, 3, 4, 5]


def test_a_bay_inside_a_large_box_of_another_shape_stays_apart():
    """A minaret's side called arch spans 8 m along the wall; a 3.6 m bay lying in its box
    shares 3D volume with it but not the wall's length."""
    m = merge_instances([1, 2], [A, A], [1, 2], [[0, 0, 0, 3.6, 1.0, 5.2], [-1, -2, 0, 6.1, 6.0, 11.9]], 2)
    assert m.tolist() == [0, 1, 2]


def test_chains_take_the_smallest_id_and_ids_out_of_range_fail():
    boxes = [_bay(0, 4)] * 3
    m = merge_instances([7, 3, 5], [A] * 3, [1, 2, 3], boxes, 9)
    assert m.tolist() == [0, 1, 2, 3, 4, 3, 6, 3, 8, 9]
    with pytest.raises(ValueError, match="1..2"):
        merge_instances([3], [A], [1], [_bay(0, 4)], 2)
    with pytest.raises(ValueError, match="one class, group and box"):
        merge_instances([1, 2], [A], [1, 2], boxes[:2], 2)


def test_many_instances_are_compared_in_blocks(monkeypatch):
    """The pairs are compared _PAIR_BLOCK at a time: the same map as all at once."""
    import hollowtree.tree.merge as tm

    rng = np.random.default_rng(0)
    lo = rng.uniform(0, 60, (300, 3))
    boxes = np.c_[lo, lo + rng.uniform(0.2, 6, (300, 3))]
    cls, grp = rng.choice([A, D], 300), rng.integers(0, 40, 300)
    whole = merge_instances(np.arange(1, 301), cls, grp, boxes, 300)
    monkeypatch.setattr(tm, "_PAIR_BLOCK", 1000)
    np.testing.assert_array_equal(merge_instances(np.arange(1, 301), cls, grp, boxes, 300), whole)
    assert (whole != np.arange(301)).sum() > 0


def test_a_portals_face_joins_the_passage_behind_it():
    """Wazir Khan's gateway portal: the front face (1 m deep, 14 m high) went to one group,
    the passage behind it (2.4 m deep, 9 m high) to another. They share most of the face's
    depth but a third of the passage's box: the volume of the smaller box would not do."""
    face, passage = [45.5, -4.3, 0.0, 46.1, 4.0, 14.1], [43.5, -2.5, 0.0, 45.9, 2.5, 9.1]
    m = merge_instances([1, 2], [A, A], [1, 2], [face, passage], 2)
    assert m.tolist() == [0, 1, 1]


def test_a_minarets_pieces_join_when_one_stands_on_the_other():
    """A minaret's side face (0-11 m), its far side (0-23 m) and its top (23.3-31 m) from
    three groups are one minaret; a second minaret beside it, and a dome above the first
    one's footprint (another class), stay apart."""
    M = int(ClassId.MINARET)
    side, far, top = [0, 0, 0, 2, 4, 11], [0, 0, 0, 5, 5, 23], [0.5, 0.5, 23.3, 4.5, 4.5, 31]
    other = [9, 0, 0, 14, 5, 30]
    m = merge_instances([1, 2, 3, 4, 5], [M, M, M, M, D], [1, 2, 3, 4, 5], [side, far, top, other, top], 5)
    assert m.tolist() == [0, 1, 1, 1, 4, 5]
    # 1 m between the heights (more than the two pads): not one shaft
    apart = merge_instances([1, 2], [M, M], [1, 2], [far, [0, 0, 24.0, 5, 5, 31]], 2)
    assert apart.tolist() == [0, 1, 2]
    # footprints side by side, each under 60 % of the other's: two minarets
    beside = merge_instances([1, 2], [M, M], [1, 2], [far, [3.5, 0, 0, 8.5, 5, 23]], 2)
    assert beside.tolist() == [0, 1, 2]


def test_an_arch_stacked_with_a_minaret_is_part_of_it():
    """Wazir Khan's corner minaret: its lower 11 m with the balcony (a group HollowNet calls
    arch, 4.5 x 9.7 m with a strip of wall) under the shaft's upper 20 m (another group,
    4.5 x 4.5 m) is one minaret and takes its class. An arcade's end bay beside the
    minaret (a quarter of its footprint), an arch of the minaret's own group, an arch
    1 m below, and (``into=()``) the rule off: apart."""
    from hollowtree.tree.merge import merged_classes

    M = int(ClassId.MINARET)
    lower, upper = [32.8, 16.8, 0.0, 37.3, 26.5, 10.8], [33.0, 17.0, 11.0, 39.0, 23.0, 31.6]
    end_bay = [28.9, 19.5, 0.0, 33.5, 20.5, 4.1]
    m = merge_instances([1, 2, 3], [A, M, A], [1, 2, 3], [lower, upper, end_bay], 3)
    assert m.tolist() == [0, 1, 1, 3]
    assert merged_classes([1, 2, 3], [A, M, A], m).tolist() == [0, M, M, A]
    assert merge_instances([1, 2], [A, M], [1, 1], [lower, upper], 2).tolist() == [0, 1, 2]
    below = [32.8, 16.8, 0.0, 37.3, 26.5, 9.5]
    assert merge_instances([1, 2], [A, M], [1, 2], [below, upper], 2).tolist() == [0, 1, 2]
    assert merge_instances([1, 2], [A, M], [1, 2], [lower, upper], 2, into=()).tolist() == [0, 1, 2]
    # The other corner minaret on seed 2 (tree-v15): its lower side with 10 m of wall,
    # 59 % of it over the shaft's footprint, joins at MERGE_INTO_OVERLAP 0.5, not at 0.6.
    side, shaft = [-31.69, 16.69, 0.0, -28.8, 26.5, 12.0], [-34.83, 17.0, 10.99, -29.0, 22.99, 31.38]
    assert merge_instances([1, 2], [A, M], [1, 2], [side, shaft], 2).tolist() == [0, 1, 1]
    assert merge_instances([1, 2], [A, M], [1, 2], [side, shaft], 2, into_overlap=0.6).tolist() == [0, 1, 2]
    # An arch that joined another arch which stands under a minaret: both take its class;
    # a dome in a set without a minaret keeps its own.
    assert merged_classes([1, 2, 3, 4], [A, A, M, D], [0, 1, 1, 1, 4]).tolist() == [0, M, M, M, D]


def test_a_shafts_halves_side_by_side_are_one_and_two_towers_are_not():
    """A round bastion (8 m across) cut in two at a tile's edge: its halves' boxes meet and
    together are as wide as either, so they are one; two such bastions 0.4 m apart make a
    footprint twice as wide and stay two, as do halves of one group or of another class."""
    M = int(ClassId.MINARET)
    west, east = [0, 0, 0, 4.1, 8, 15], [3.9, 0, 0, 8, 8, 15]
    other = [8.4, 0, 0, 16.4, 8, 15]
    assert merge_instances([1, 2, 3], [M] * 3, [1, 2, 3], [west, east, other], 3).tolist() == [0, 1, 1, 3]
    assert merge_instances([1, 2], [M] * 2, [1, 1], [west, east], 2).tolist() == [0, 1, 2]
    assert merge_instances([1, 2], [D] * 2, [1, 2], [west, east], 2).tolist() == [0, 1, 2]
    assert merge_instances([1, 2], [M] * 2, [1, 2], [west, east], 2, shaft_spread=0.9).tolist() == [0, 1, 2]
