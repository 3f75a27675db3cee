"""The size rule of tree/tall.py: a pillar taller than the bound is a minaret."""

from __future__ import annotations

import numpy as np
import pytest

from hollowtree.classes import ClassId
from hollowtree.errors import ConfigError
from hollowtree.pipeline.tree_stage import TreeStageParams
from hollowtree.tree.build import build_tree
from hollowtree.tree.tall import TallPillars, tall_pillars

P, M, W = int(ClassId.PILLAR), int(ClassId.MINARET), int(ClassId.WALL)


class _Always:
    """A stand-in classifier that calls every part ``cls`` (score 0.8)."""

    def __init__(self, cls):
        self.cls = cls

    def predict(self, segments):
        n = len(segments)
        prob = np.zeros((n, 8))
        prob[:, self.cls - 1] = 0.8
        return np.full(n, self.cls), np.full(n, 0.8), prob


def test_tall_pillars_change_pillars_only():
    cls = np.array([P, P, P, M, W], dtype=np.uint8)
    out = tall_pillars(cls, [3.0, 10.0, 10.5, 30.0, 30.0], 10.0)
    assert out.tolist() == [P, P, M, M, W]
    assert cls.tolist() == [P, P, P, M, W]  # the input is not modified
    with pytest.raises(ValueError, match="height"):
        tall_pillars(cls, [1.0], 10.0)


def test_wrapper_uses_each_parts_height_and_keeps_scores():
    rng = np.random.default_rng(0)
    column = rng.uniform(0, 1, (500, 3)) * [0.5, 0.5, 6.0]
    minaret = rng.uniform(0, 1, (500, 3)) * [3.0, 3.0, 30.0]
    cls, score, prob = TallPillars(_Always(P), 10.0).predict([column, minaret, np.zeros((0, 3))])
    assert cls.tolist() == [P, M, P]
    np.testing.assert_array_equal(score, 0.8)
    assert prob.shape == (3, 8)
    with pytest.raises(ValueError, match="max_height"):
        TallPillars(_Always(P), 0.0)


def test_the_tree_labels_a_tall_pillar_a_minaret():
    rng = np.random.default_rng(1)
    t = rng.uniform(0, 2 * np.pi, 4000)
    z = rng.uniform(0, 25.0, 4000)
    xyz = np.c_[1.5 * np.cos(t), 1.5 * np.sin(t), z]  # a plain 25 m shaft
    plain = build_tree(xyz, _Always(P), rng=0)
    sized = build_tree(xyz, TallPillars(_Always(P), 10.0), rng=0)
    assert set(plain.class_id.tolist()) == {P}
    assert sized.nodes.class_id[0] == M
    assert (sized.instance > 0).all()


def test_a_tall_flat_strip_stays_a_pillar():
    """A portal's jamb (a vertical plane 2.4 m wide, 15 m tall) is no minaret; a minaret
    scanned from one side only (a half shaft) still is."""
    rng = np.random.default_rng(2)
    u, z = rng.uniform(0, 2.4, 3000), rng.uniform(0, 15.0, 3000)
    jamb = np.c_[u * 0.6, u * 0.8, z]
    t = rng.uniform(0, np.pi, 3000)
    half = np.c_[1.5 * np.cos(t), 1.5 * np.sin(t), z]
    cls, _, _ = TallPillars(_Always(P), 10.0).predict([jamb, half])
    assert cls.tolist() == [P, M]
    with pytest.raises(ValueError, match="ratio"):
        tall_pillars([P], [20.0], 10.0, ratio=[0.5, 0.5])


def test_tree_params_validate_the_bound():
    assert TreeStageParams().pillar_max_height is None  # off by default (tree-v35 validation)
    assert TreeStageParams(pillar_max_height=None).pillar_max_height is None
    for bad in (0.0, -1.0, float("inf")):
        with pytest.raises(ConfigError, match="pillar_max_height"):
            TreeStageParams(pillar_max_height=bad)


def test_short_minarets_are_pillars_per_instance_in_the_tree_stage():
    """A dome's finial (2 m) that HollowNet calls minaret is a pillar; a 25 m shaft stays a
    minaret. The rule works on whole instances, and the node table holds the result."""
    from hollowtree.pipeline.tree_stage import _group_tree
    from hollowtree.tree.tall import short_minarets

    assert short_minarets([M, M, P], [2.0, 25.0, 2.0], 10.0).tolist() == [P, M, P]
    with pytest.raises(ValueError, match="height"):
        short_minarets([M], [1.0, 2.0], 10.0)
    rng = np.random.default_rng(3)
    t = rng.uniform(0, 2 * np.pi, 3000)
    params = TreeStageParams(max_depth=0, roof_min_height=None, pillar_max_height=10.0)
    for height, want in ((2.0, P), (25.0, M)):
        xyz = np.c_[0.3 * np.cos(t), 0.3 * np.sin(t), rng.uniform(0, height, 3000)]
        values, cols, n_inst = _group_tree(xyz, 0, params, _Always(M), None, 0)
        assert set(values["class"].tolist()) == {want}
        assert cols["class_id"] == [want]
        assert n_inst == 1
    off = TreeStageParams(max_depth=0, roof_min_height=None, pillar_max_height=None)
    values, _, _ = _group_tree(np.c_[0.3 * np.cos(t), 0.3 * np.sin(t), rng.uniform(0, 2.0, 3000)], 0, off,
                               _Always(M), None, 0)
    assert set(values["class"].tolist()) == {M}


def test_slender_domes_are_minarets_per_instance_in_the_tree_stage():
    """A 23 m stretch of a minaret (4 m across) that HollowNet calls dome is a minaret; a
    dome on its drum (6 m across, 7 m high) and a chattri (2 m across, 3.8 m high) stay
    domes; the rule is off with the size rules."""
    from hollowtree.pipeline.tree_stage import _group_tree
    from hollowtree.tree.tall import slender_domes

    dome = int(ClassId.DOME)
    assert slender_domes([dome, dome, dome, M], [23.0, 7.0, 3.8, 30.0], [4.0, 6.0, 2.0, 4.0],
                         10.0).tolist() == [M, dome, dome, M]
    with pytest.raises(ValueError, match="height"):
        slender_domes([dome], [1.0, 2.0], [1.0], 10.0)
    rng = np.random.default_rng(4)
    t = rng.uniform(0, 2 * np.pi, 3000)
    params = TreeStageParams(max_depth=0, roof_min_height=None, pillar_max_height=10.0)
    for radius, height, want in ((2.0, 23.0, M), (3.0, 7.0, dome), (1.0, 3.8, dome)):
        xyz = np.c_[radius * np.cos(t), radius * np.sin(t), rng.uniform(0, height, 3000)]
        values, cols, _ = _group_tree(xyz, 0, params, _Always(dome), None, 0)
        assert set(values["class"].tolist()) == {want}
        assert cols["class_id"] == [want]
    off = TreeStageParams(max_depth=0, roof_min_height=None, pillar_max_height=None)
    values, _, _ = _group_tree(np.c_[2.0 * np.cos(t), 2.0 * np.sin(t), rng.uniform(0, 23.0, 3000)], 0, off,
                               _Always(dome), None, 0)
    assert set(values["class"].tolist()) == {dome}


OT, D = int(ClassId.OTHER), int(ClassId.DOME)


class _Clutter:
    """A stand-in classifier that calls every part other (0.7), dome second (0.3)."""

    def predict(self, segments):
        n = len(segments)
        prob = np.zeros((n, 8))
        prob[:, OT - 1], prob[:, D - 1] = 0.7, 0.3
        return np.full(n, OT), np.full(n, 0.7), prob


def test_not_clutter_moves_raised_or_tall_other_to_its_next_class():
    from hollowtree.tree.tall import not_clutter

    prob = np.zeros((5, 8))
    prob[:, OT - 1], prob[:, D - 1] = 0.7, 0.3
    prob[4] = 0.0  # HollowNet could not classify it
    cls = [OT, OT, OT, W, OT]
    out = not_clutter(cls, prob, [0.5, 3.0, np.nan, 9.0, 9.0], [4.0, 4.0, 20.0, 4.0, 4.0], max_base=2.0,
                      max_size=15.0)
    assert out.tolist() == [OT, D, D, W, OT]
    # A test set to None is off; an unknown base (NaN) never moves a part.
    assert not_clutter(cls, prob, [3.0] * 5, [20.0] * 5, max_base=None, max_size=None).tolist() == cls
    assert not_clutter(cls, prob, [np.nan] * 5, [4.0] * 5, max_base=2.0, max_size=None).tolist() == cls
    with pytest.raises(ValueError, match="base"):
        not_clutter(cls, prob, [0.0], [4.0] * 5, max_base=2.0, max_size=15.0)
    with pytest.raises(ValueError, match="probabilities"):
        not_clutter([OT], np.zeros((1, 3)), [0.0], [1.0], max_base=2.0, max_size=15.0)


def test_not_clutter_wrapper_measures_each_part_from_the_ground():
    """A bush on the ground stays other; the same shape on a roof (a dome on its drum), a
    27 m part (a bastion seen from one side) and a 20 m long one do not. Scores stay
    HollowNet's."""
    from hollowtree.tree.tall import NotClutter

    rng = np.random.default_rng(4)
    bush = rng.uniform(0, 1, (400, 3)) * [3.0, 3.0, 2.5]
    raised = bush + [0, 0, 11.0]
    tall = rng.uniform(0, 1, (400, 3)) * [6.0, 12.0, 27.0]
    clf = NotClutter(_Clutter(), ground=0.0, max_base=2.0, max_size=15.0)
    cls, score, _ = clf.predict([bush, raised, tall])
    assert cls.tolist() == [OT, D, D]
    wide = rng.uniform(0, 1, (400, 3)) * [4.0, 20.0, 3.0]  # 20 m long, on the ground: no clutter either
    assert clf.predict([wide])[0].tolist() == [D]
    np.testing.assert_array_equal(score, 0.7)
    # One ground per part; no ground: only the height test.
    assert NotClutter(_Clutter(), ground=[0.0, 11.0, 0.0], max_base=2.0,
                      max_size=15.0).predict([bush, raised, tall])[0].tolist() == [OT, OT, D]
    assert NotClutter(_Clutter(), ground=None, max_base=2.0,
                      max_size=15.0).predict([bush, raised, tall])[0].tolist() == [OT, OT, D]
    with pytest.raises(ValueError, match="ground"):
        NotClutter(_Clutter(), ground=[0.0, 1.0], max_base=2.0, max_size=None).predict([bush, raised, tall])
    with pytest.raises(ValueError, match="max_base"):
        NotClutter(_Clutter(), ground=0.0, max_base=0.0, max_size=None)


def test_size_rules_compose_and_turn_off():
    from hollowtree.tree.tall import NotClutter, size_rules

    base = _Clutter()
    assert size_rules(base, pillar_max_height=None, other_max_base=None, other_max_size=None) is base
    both = size_rules(base, pillar_max_height=10.0, other_max_base=2.0, other_max_size=15.0, ground=0.0)
    assert isinstance(both, TallPillars)
    assert isinstance(both.classifier, NotClutter)


def test_the_tree_stage_reads_the_clutter_rule_from_its_params():
    """A raised 'bush' (a dome on a roof, 11 m above the ground) is a dome instance in the
    tree stage when the ground is known, and stays other with the rule off."""
    from hollowtree.pipeline.tree_stage import _group_tree

    rng = np.random.default_rng(5)
    xyz = rng.uniform(0, 1, (3000, 3)) * [4.0, 4.0, 3.0] + [0, 0, 11.0]
    params = TreeStageParams(max_depth=0, roof_min_height=None, pillar_max_height=10.0)
    values, cols, n_inst = _group_tree(xyz, 0, params, _Clutter(), 0.0, 0)
    assert cols["class_id"] == [D]
    assert set(values["class"].tolist()) == {D}
    assert n_inst == 1
    off = TreeStageParams(max_depth=0, roof_min_height=None, other_max_base=None)
    values, cols, _ = _group_tree(xyz, 0, off, _Clutter(), 0.0, 0)
    assert cols["class_id"] == [OT]
    assert TreeStageParams().other_max_base == 2.0
    assert TreeStageParams().other_max_size == 15.0
    for bad in (0.0, -1.0, float("inf"), True):
        with pytest.raises(ConfigError, match="other_max_size"):
            TreeStageParams(other_max_size=bad)
