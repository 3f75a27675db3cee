"""The split model (tree/split.py, tree/fit_split.py) and the tree's decision with it."""

from __future__ import annotations

import json

import numpy as np
import pytest

from hollowtree.tree.build import _per_point, build_tree
from hollowtree.tree.energy import load_energy_model
from hollowtree.tree.fit_split import (
    SplitSamples,
    _node_decisions,
    fit_split_model,
    proposal_samples,
    proposal_target,
)
from hollowtree.tree.split import (
    DEFAULT_SPLIT_PATH,
    FEATURE_NAMES,
    SplitModel,
    load_split_model,
    split_features,
)


def _features(rng, n):
    """Random proposals: right when the children agree on the arch class."""
    rows, good = [], []
    for _ in range(n):
        s = int(rng.integers(2, 12))
        agree = rng.random() < 0.3
        cls = np.full(s, 4) if agree else rng.integers(1, 9, s)
        probs = np.eye(8)[cls - 1] * 0.7 + 0.3 / 8
        rows.append(split_features(n_parent=int(rng.integers(2000, 200_000)), extent=rng.random(3) * 20, depth=0,
                                   key=int(rng.integers(1, 5)), parent_class=int(rng.integers(1, 9)),
                                   parent_probs=rng.dirichlet(np.ones(8)), child_sizes=rng.integers(100, 1000, s),
                                   child_classes=cls, child_probs=probs, cuts=np.sort(rng.random(s - 1))))
        good.append(agree)
    return np.asarray(rows), np.asarray(good, dtype=float)


def test_features_have_the_named_columns():
    f = split_features(n_parent=4000, extent=[12.0, 1.0, 6.0], depth=1, key=4, parent_class=2,
                       parent_probs=np.eye(8)[1], child_sizes=[1000, 1000, 2000], child_classes=[4, 4, 2],
                       child_probs=np.eye(8)[[3, 3, 1]], cuts=[2.0, 4.0])
    d = dict(zip(FEATURE_NAMES, f.tolist(), strict=True))
    assert d["n_children"] == 3
    assert d["seq_storeys"] == 1
    assert d["seq_s2"] == 0
    assert d["depth"] == 1
    assert d["children_element"] == pytest.approx(0.5)      # the two arch children hold half the points
    assert d["children_as_parent"] == pytest.approx(0.5)    # the wall child holds the other half
    assert d["children_agree"] == pytest.approx(0.5)
    assert d["cut_spacing_cv"] == -1.0                     # one gap: no spacing to compare
    assert d["log10_extent_long"] == pytest.approx(np.log10(12.001))
    assert d["p_parent_wall"] == 1.0
    assert d["p_children_arch"] == pytest.approx(0.5)
    with pytest.raises(ValueError, match="8 classes"):
        split_features(n_parent=4000, extent=[1, 1, 1], depth=0, key=1, parent_class=2, parent_probs=np.ones(9),
                       child_sizes=[1, 1], child_classes=[2, 2], child_probs=np.ones((2, 9)), cuts=[0.5])


def test_model_from_sklearn_gives_sklearn_probabilities_and_survives_json(tmp_path):
    from sklearn.ensemble import GradientBoostingClassifier

    x, y = _features(np.random.default_rng(0), 300)
    gb = GradientBoostingClassifier(n_estimators=20, max_depth=3, random_state=0).fit(x, y)
    m = SplitModel.from_sklearn(gb, threshold=0.4, info={"note": "test"})
    np.testing.assert_allclose(m.probability(x), gb.predict_proba(x)[:, 1], atol=1e-12)
    m.save(tmp_path / "m.json")
    back = load_split_model(tmp_path / "m.json")
    assert back.threshold == 0.4
    assert back.info == {"note": "test"}
    np.testing.assert_allclose(back.probability(x), m.probability(x), atol=1e-12)


def test_model_for_other_features_is_refused(tmp_path):
    d = json.loads(DEFAULT_SPLIT_PATH.read_text())
    d["feature_names"] = d["feature_names"][:-1]
    with pytest.raises(ValueError, match="other features"):
        SplitModel.from_dict(d)
    d = json.loads(DEFAULT_SPLIT_PATH.read_text()) | {"extra": 1}
    with pytest.raises(ValueError, match="unknown keys"):
        SplitModel.from_dict(d)


def test_shipped_model_is_versioned_and_cross_validated():
    m = load_split_model()
    assert m.version == 1
    assert 0 < m.threshold < 1
    assert len(m.trees) > 10
    assert m.info["cv_auc"] > 0.85
    assert m.info["right"] > 100
    assert m.info["scenes"] >= 50


def test_fit_learns_a_separable_rule_and_reports_cross_validation():
    x, y = _features(np.random.default_rng(1), 400)
    scene = np.asarray([f"s{i % 8}" for i in range(len(y))])
    samples = SplitSamples(features=x, target=y, node=np.asarray([f"n{i}" for i in range(len(y))]), scene=scene)
    m = fit_split_model(samples, threshold=0.5)
    assert m.info["cv_auc"] > 0.95
    assert m.info["samples"] == 400
    x2, y2 = _features(np.random.default_rng(2), 200)
    assert ((m.probability(x2) >= 0.5) == (y2 >= 0.5)).mean() > 0.95
    with pytest.raises(ValueError, match="both right and wrong"):
        fit_split_model(SplitSamples(features=x, target=np.zeros(len(y)), node=samples.node, scene=scene))


def test_node_decisions_count_false_and_missed_splits():
    p = np.array([0.9, 0.1, 0.2, 0.6, 0.1])
    good = np.array([True, False, True, False, False])
    node = np.array(["a", "a", "b", "c", "c"])
    d = _node_decisions(p, good, node, 0.5)
    # a: splits with its good proposal; b: misses its good one; c: splits with a wrong one.
    assert d == {"nodes": 3, "need_split": 2, "right": 1, "false_split": 1, "missed": 1}


def test_proposal_target_counts_unions_of_whole_parts_once():
    parts = np.repeat([0, 1, 2, 3], 10)
    storeys = [np.arange(0, 20), np.arange(20, 40)]
    assert proposal_target(storeys, parts) == 1.0
    assert proposal_target([np.arange(40)], parts) == 0.0
    # One part cut in three (IoU 0.3 each), the rest one union of whole parts: one right child.
    cut_one = [np.arange(0, 3), np.arange(3, 6), np.arange(6, 9), np.arange(9, 40)]
    assert proposal_target(cut_one, parts) == 0.0


class _Agreeing:
    """Stand-in classifier: a child is "arch" when it is narrower than 3 m, else "wall"."""

    def predict(self, segments):
        cls = np.array([4 if np.ptp(s[:, 0]) < 3.0 else 2 for s in segments])
        prob = np.full((len(segments), 8), 0.02)
        prob[np.arange(len(segments)), cls - 1] = 0.86
        return cls, prob[np.arange(len(segments)), cls], prob


def _piers(n_bays=6, pitch=2.0, height=4.0, step=0.05):
    """A straight wall of ``n_bays`` bays: solid piers, openings below 3 m between them."""
    t, z = np.meshgrid(np.arange(0, n_bays * pitch, step), np.arange(0, height, step))
    t, z = t.ravel(), z.ravel()
    solid = (np.abs((t % pitch) - pitch / 2) > 0.6) | (z > 3.0)
    noise = np.random.default_rng(0).normal(0.0, 0.01, (len(t), 3))
    return (np.column_stack([t, np.zeros_like(t), z]) + noise)[solid]


def test_proposal_samples_mark_the_bays_of_an_arcade_right():
    pts = _piers()
    bay = np.minimum((pts[:, 0] // 2.0).astype(int), 5)
    gc = np.full(len(pts), 4)
    s = proposal_samples(pts, gc, bay + 1, np.array([0, len(pts)]), _Agreeing(), scene="piers", min_node=100)
    assert s.features.shape[1] == len(FEATURE_NAMES)
    assert len(s) >= 2
    wall = s.node == "piers/0/0"
    assert s.target[wall].max() >= 0.5     # S2 cuts the wall at its piers: one child per bay
    assert np.all(s.target[~wall] == 0.0)   # the bays are nodes too, and no split of one bay is right


def test_proposal_samples_meet_a_large_group_as_a_sample_as_the_tree_stage_does():
    pts = _piers()
    bay = np.minimum((pts[:, 0] // 2.0).astype(int), 5)
    gc = np.full(len(pts), 4)
    args = (pts, gc, bay + 1, np.array([0, len(pts)]), _Agreeing())
    whole = proposal_samples(*args, scene="piers", min_node=100)
    cap = len(pts) // 2
    sampled = proposal_samples(*args, scene="piers", min_node=100, max_group_points=cap)
    n_parent = FEATURE_NAMES.index("log10_n_parent")
    root = sampled.node == "piers/0/0"
    assert np.allclose(whole.features[whole.node == "piers/0/0", n_parent], np.log10(len(pts)))
    assert np.all(np.abs(10 ** sampled.features[root, n_parent] / cap - 1) < 0.1)  # about cap points
    assert sampled.target[root].max() >= 0.5   # the sample's bays are still right
    again = proposal_samples(*args, scene="piers", min_node=100, max_group_points=cap)
    np.testing.assert_array_equal(again.features, sampled.features)  # seeded
    same = proposal_samples(*args, scene="piers", min_node=100, max_group_points=len(pts))
    np.testing.assert_array_equal(same.features, whole.features)     # at or under the cap: whole


def test_tree_with_the_split_model_keeps_or_refuses_by_its_probability():
    pts = _piers()
    always = SplitModel(init=5.0, learning_rate=0.1, trees=(), threshold=0.5)
    never = SplitModel(init=-5.0, learning_rate=0.1, trees=(), threshold=0.5)
    r = build_tree(pts, _Agreeing(), split=always, rng=0, max_depth=1)
    assert len(r.nodes.children(0)) >= 2
    assert np.all(r.nodes.xi[1:] > 0.99)
    r = build_tree(pts, _Agreeing(), split=never, rng=0)
    assert len(r.nodes) == 1
    r = build_tree(pts, _Agreeing(), split=never, threshold=0.001, rng=0, max_depth=1)
    assert len(r.nodes) > 1                 # an explicit threshold overrides the model's


def test_split_node_is_an_instance_only_when_its_children_agree():
    pts = _piers()
    always = SplitModel(init=5.0, learning_rate=0.1, trees=(), threshold=0.5)
    r = build_tree(pts, _Agreeing(), split=always, rng=0, max_depth=1)
    kids = r.nodes.children(0)
    assert r.nodes.class_id[0] == 2                       # the whole wall is "wall"
    arch_kids = kids[r.nodes.class_id[kids] == 4]
    assert len(arch_kids) >= 4
    assert set(r.instance_node.tolist()) == set(arch_kids.tolist())  # each bay its own arch
    # The same tree with the root relabelled "arch": its children disagree (walls and arches
    # by points), so the root is still no instance unless at least half agree.
    nodes = r.nodes
    cls = nodes.class_id.copy()
    cls[0] = 4
    relabelled = type(nodes)(**{**{k: getattr(nodes, k) for k in nodes.__dataclass_fields__}, "class_id": cls})
    same = nodes.n_points[arch_kids].sum()
    res = _per_point(relabelled, r.leaf)
    assert (0 in res.instance_node.tolist()) == (2 * same >= nodes.n_points[0])


def test_fit_split_cli_refuses_bad_arguments_before_any_work(tmp_path):
    import subprocess
    import sys

    out = tmp_path / "m.json"
    out.write_text("{}")
    work = tmp_path / "work"
    for args, words in ((["--out", str(out)], "exists"),
                        (["--out", str(tmp_path / "no" / "m.json")], "does not exist"),
                        (["--out", str(tmp_path / "n.json"), "--threshold", "1.5"], "--threshold")):
        proc = subprocess.run([sys.executable, "-m", "hollowtree", "fit-split", "--work", str(work), *args,
                               "--no-progress"], capture_output=True, text=True, timeout=120)
        assert proc.returncode == 2, proc.stderr
        assert words in proc.stderr
        assert len(proc.stderr.strip().splitlines()) == 1
    assert out.read_text() == "{}"
    assert not work.exists()


def test_energy_decision_is_still_the_papers(tmp_path):
    pts = _piers()
    r_energy = build_tree(pts, _Agreeing(), rng=0)             # split=None: xi = w . e
    assert np.all(np.isnan(r_energy.nodes.xi[:1]))
    kept = r_energy.nodes.xi[1:]
    assert np.all(kept >= load_energy_model().threshold)


def test_storeyed_arcades_are_seeded_storeys_of_arch_bays():
    from hollowtree.classes import ClassId
    from hollowtree.hollownet._scenes import storeyed_arcades

    a = storeyed_arcades(np.random.default_rng([7, 100]))
    b = storeyed_arcades(np.random.default_rng([7, 100]))
    assert np.array_equal(a.vertices, b.vertices)
    assert np.array_equal(a.face_instance, b.face_instance)
    names = [e.name for e in a.elements]
    storeys = {n.split(" bay ")[0] for n in names if " bay " in n}
    assert len(storeys) in (2, 3)
    for st in storeys:   # each storey: its bays (arches) and one wall band above them
        assert all(e.class_id == ClassId.ARCH for e in a.elements if e.name.startswith(st + " bay "))
        assert [e.class_id for e in a.elements if e.name == st + " wall above"] == [ClassId.WALL]
