"""The element check (tree/verify.py): features of merged instances, the decision, the file."""

from __future__ import annotations

import json

import numpy as np
import pytest

from hollowtree.classes import ClassId
from hollowtree.tree.verify import (
    DEFAULT_VERIFY_PATH,
    SHAPE_FEATURES,
    VERIFY_FEATURES,
    ElementCheck,
    VerifyModel,
    instance_features,
    load_verify_model,
    local_shape,
)

LEAF = {"feature": np.array([-2]), "threshold": np.array([0.0]), "left": np.array([-1]), "right": np.array([-1]),
        "value": np.array([0.0])}


def _stump(feature: str, cut: float, below: float, above: float) -> VerifyModel:
    """A one-split model: log-odds ``below`` where ``feature <= cut``, else ``above``."""
    tree = {"feature": np.array([VERIFY_FEATURES.index(feature), -2, -2]), "threshold": np.array([cut, 0.0, 0.0]),
            "left": np.array([1, -1, -1]), "right": np.array([2, -1, -1]), "value": np.array([0.0, below, above])}
    return VerifyModel(init=0.0, learning_rate=1.0, trees=(tree,))


def test_features_of_a_merged_instance_cover_all_its_nodes() -> None:
    # Instance 4 (a minaret) is two nodes stacked, of 100 and 300 points; instance 9 is a wall.
    ids, cls, f = instance_features(
        instance=[4, 4, 9, 0], class_id=[6, 6, 2, 6], score=[0.5, 1.0, 1.0, 1.0], n_points=[100, 300, 50, 10],
        bbox=[[0, 0, 2, 2, 1, 10], [0, 0, 10, 3, 2, 30], [0, 0, 0, 9, 1, 5], [0, 0, 0, 1, 1, 1]],
        depth=[2, 1, 0, 0], segment=[3, 3, 5, 6], ground=[1.0, 1.0, 0.0, 0.0])
    assert ids.tolist() == [4]
    assert cls.tolist() == [6]
    row = dict(zip(VERIFY_FEATURES, f[0].tolist(), strict=True))
    assert row["is_minaret"] == 1.0
    assert row["is_arch"] == 0.0
    assert row["score"] == pytest.approx((0.5 * 100 + 1.0 * 300) / 400)
    assert row["log10_points"] == pytest.approx(np.log10(400))
    assert row["log10_height"] == pytest.approx(np.log10(28 + 1e-3))
    assert row["log10_long"] == pytest.approx(np.log10(3 + 1e-3))
    assert row["log10_short"] == pytest.approx(np.log10(2 + 1e-3))
    assert row["base_above_ground"] == pytest.approx(1.0)
    assert row["top_above_ground"] == pytest.approx(29.0)
    assert (row["n_nodes"], row["n_segments"], row["min_depth"]) == (2.0, 1.0, 1.0)


def test_shape_features_are_the_point_weighted_mean_of_known_nodes() -> None:
    # Instance 4: nodes of 100 and 300 points with shapes, a third (unknown shape) ignored;
    # instance 6 has no known shape: -1 in every shape column.
    shape = np.array([[0.2] * 6, [0.6] * 6, [np.nan] * 6, [np.nan] * 6])
    ids, _, f = instance_features(
        instance=[4, 4, 4, 6], class_id=[6, 6, 6, 5], score=[1.0] * 4, n_points=[100, 300, 50, 80],
        bbox=[[0, 0, 0, 1, 1, 1]] * 4, depth=[1] * 4, segment=[1] * 4, ground=[0.0] * 4, shape=shape)
    assert ids.tolist() == [4, 6]
    at = [VERIFY_FEATURES.index(n) for n in SHAPE_FEATURES]
    assert f[0, at] == pytest.approx([0.5] * 6)
    assert f[1, at].tolist() == [-1.0] * 6
    _, _, without = instance_features([4], [6], [1.0], [10], [[0, 0, 0, 1, 1, 1]], [1], [1], [0.0])
    assert without[0, at].tolist() == [-1.0] * 6


def test_local_shape_tells_tubes_from_surfaces_at_any_density() -> None:
    rng = np.random.default_rng(0)
    wall = lambda n: np.c_[rng.uniform(0, 3, n), rng.normal(0, 0.002, n), rng.uniform(0, 4, n)]  # noqa: E731
    crate_top = np.c_[rng.uniform(0, 1, 20_000), rng.uniform(0, 1, 20_000), np.full(20_000, 0.8)]
    # a scaffold's bay: four poles and two rails, tubes 5 cm across
    t = rng.uniform(0, 1, 40_000)
    a = rng.uniform(0, 2 * np.pi, 40_000)
    ring = 0.024 * np.c_[np.cos(a), np.sin(a)]
    poles = [np.c_[x + ring[:, 0], y + ring[:, 1], 4 * t] for x, y in ((0, 0), (2, 0), (0, 1), (2, 1))]
    rails = [np.c_[2 * t, y + ring[:, 0], z + ring[:, 1]] for y, z in ((0, 2), (1, 2))]
    names = {n: i for i, n in enumerate(SHAPE_FEATURES)}
    dense, sparse, scaffold, top = (local_shape(p) for p in (wall(200_000), wall(30_000), np.vstack(poles + rails),
                                                             crate_top))
    assert dense[names["vertical_share"]] > 0.95
    assert top[names["horizontal_share"]] > 0.95
    assert dense[names["planarity"]] > 0.6 > scaffold[names["planarity"]]
    assert scaffold[names["linearity"]] > 0.5 > dense[names["linearity"]]
    assert scaffold[names["scattering"]] > 0.1 > dense[names["scattering"]]
    np.testing.assert_allclose(dense, sparse, atol=0.08)  # thinned to one point per 3 cm cell
    assert np.array_equal(local_shape(wall(5)), np.full(len(SHAPE_FEATURES), np.nan, dtype=float), equal_nan=True)
    assert np.isnan(local_shape(np.zeros((0, 3)))).all()


def test_a_check_fitted_without_shape_features_still_decides() -> None:
    """A file fitted on the columns before SHAPE_FEATURES (the first check's) reads those
    columns of the full feature matrix."""
    old = VERIFY_FEATURES[:-len(SHAPE_FEATURES)]
    tree = {"feature": np.array([old.index("score"), -2, -2]), "threshold": np.array([0.5, 0.0, 0.0]),
            "left": np.array([1, -1, -1]), "right": np.array([2, -1, -1]), "value": np.array([0.0, -3.0, 3.0])}
    model = VerifyModel(init=0.0, learning_rate=1.0, trees=(tree,), feature_names=old)
    no = VerifyModel(init=-4.0, learning_rate=0.1, trees=(LEAF,))
    check = ElementCheck.from_dict(ElementCheck({4: no, 5: no, 6: model, 7: no}).to_dict())
    f = np.zeros((2, len(VERIFY_FEATURES)))
    f[:, -len(SHAPE_FEATURES):] = 9.0
    f[1, VERIFY_FEATURES.index("score")] = 0.9
    assert check.decide(f).tolist() == [int(ClassId.OTHER), int(ClassId.MINARET)]


def test_unknown_ground_is_the_instance_base() -> None:
    _, _, f = instance_features([1], [7], [1.0], [20], [[0, 0, 3, 1, 1, 6]], [0], [1], [np.nan])
    row = dict(zip(VERIFY_FEATURES, f[0].tolist(), strict=True))
    assert row["base_above_ground"] == 0.0
    assert row["top_above_ground"] == 3.0


def test_no_instances_gives_empty_features() -> None:
    ids, cls, f = instance_features([], [], [], [], np.zeros((0, 6)), [], [], [])
    assert len(ids) == len(cls) == 0
    assert f.shape == (0, len(VERIFY_FEATURES))


def test_decision_takes_the_most_probable_class_or_other() -> None:
    # Short things are pillars (P 0.88), tall ones minarets (P 0.73); arch and dome never.
    no = VerifyModel(init=-4.0, learning_rate=0.1, trees=(LEAF,))
    check = ElementCheck({4: no, 5: no, 6: _stump("log10_height", 1.0, -3.0, 1.0),
                          7: _stump("log10_height", 1.0, 2.0, -3.0)}, threshold=0.8)
    f = np.zeros((2, len(VERIFY_FEATURES)))
    f[1, VERIFY_FEATURES.index("log10_height")] = 1.5
    assert check.decide(f).tolist() == [int(ClassId.PILLAR), int(ClassId.OTHER)]
    assert ElementCheck(check.models, threshold=0.7).decide(f).tolist() == [int(ClassId.PILLAR), int(ClassId.MINARET)]
    assert check.decide(np.zeros((0, len(VERIFY_FEATURES)))).tolist() == []


def test_a_class_threshold_applies_to_instances_of_that_class_only(tmp_path) -> None:
    """``class_thresholds``: the most probable class must reach its own threshold; the other
    classes keep ``threshold``. The file keeps them, and names no class that is no element."""
    no = VerifyModel(init=-4.0, learning_rate=0.1, trees=(LEAF,))
    check = ElementCheck({4: no, 5: no, 6: _stump("log10_height", 1.0, -3.0, 1.0),
                          7: _stump("log10_height", 1.0, 2.0, -3.0)}, threshold=0.8, class_thresholds={6: 0.7})
    f = np.zeros((2, len(VERIFY_FEATURES)))
    f[1, VERIFY_FEATURES.index("log10_height")] = 1.5
    assert check.thresholds().tolist() == [0.8, 0.8, 0.7, 0.8]
    assert check.decide(f).tolist() == [int(ClassId.PILLAR), int(ClassId.MINARET)]
    strict = ElementCheck(check.models, threshold=0.8, class_thresholds={7: 0.9})
    assert strict.decide(f).tolist() == [int(ClassId.OTHER), int(ClassId.OTHER)]
    path = tmp_path / "check.json"
    check.save(path)
    again = load_verify_model(path)
    assert again.class_thresholds == {6: 0.7}
    assert np.array_equal(again.decide(f), check.decide(f))
    d = check.to_dict()
    d["class_thresholds"] = {"wall": 0.5}
    (tmp_path / "wall.json").write_text(json.dumps(d))
    with pytest.raises(ValueError, match="not an element class"):
        load_verify_model(tmp_path / "wall.json")


def test_a_check_survives_its_file(tmp_path) -> None:
    check = ElementCheck({c: _stump("score", 0.5, -1.0, 1.0) for c in (4, 5, 6, 7)}, threshold=0.6,
                         info={"sites": [1, 2]})
    path = tmp_path / "check.json"
    check.save(path)
    again = load_verify_model(path)
    f = np.random.default_rng(0).uniform(0, 1, (20, len(VERIFY_FEATURES)))
    assert np.array_equal(again.decide(f), check.decide(f))
    assert again.info == {"sites": [1, 2]}


def test_a_file_of_other_features_or_keys_is_refused(tmp_path) -> None:
    d = ElementCheck({4: _stump("score", 0.5, -1.0, 1.0)}).to_dict()
    d["models"]["arch"]["feature_names"] = ["score"]
    with pytest.raises(ValueError, match="other features"):
        ElementCheck.from_dict(d)
    d = ElementCheck({4: _stump("score", 0.5, -1.0, 1.0)}).to_dict() | {"colour": 1}
    (tmp_path / "bad.json").write_text(json.dumps(d))
    with pytest.raises(ValueError, match="unknown keys"):
        load_verify_model(tmp_path / "bad.json")


def test_the_shipped_check_loads_and_was_fitted_on_training_seeds() -> None:
    from hollowtree.scenes.procedural import SPLITS

    check = load_verify_model()
    assert load_verify_model(DEFAULT_VERIFY_PATH) is check
    lo, hi = SPLITS["train"]
    assert set(check.models) == {4, 5, 6, 7}
    assert check.info["sites"]
    assert all(lo <= s < hi for s in check.info["sites"])


def test_a_bad_check_file_is_one_line_naming_the_key(tmp_path) -> None:
    """``tree.verify_model`` naming a file that is no element check: the tree stage refuses it
    with one line that names the key and the file, before it runs anything."""
    from hollowtree.errors import ConfigError
    from hollowtree.pipeline.tree_params import TreeStageParams
    from hollowtree.pipeline.tree_stage import check_fingerprint

    bad = tmp_path / "check.json"
    bad.write_text("{not json")
    with pytest.raises(ConfigError, match=r"^tree\.verify_model: .*check\.json is not a readable element check"):
        check_fingerprint(TreeStageParams(verify=True, verify_model=str(bad)))
    assert check_fingerprint(TreeStageParams(verify=False, verify_model=str(bad))) is None
    assert len(check_fingerprint(TreeStageParams(verify=True))) == 16
