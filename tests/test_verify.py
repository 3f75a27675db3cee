"""The element check (tree/verify.py): features of merged instances, the decision, the file."""

from __future__ import annotations

import json

import numpy as np
import pytest

from hollowtree.classes import ClassId
from hollowtree.tree.verify import (
    DEFAULT_VERIFY_PATH,
    VERIFY_FEATURES,
    ElementCheck,
    VerifyModel,
    instance_features,
    load_verify_model,
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
    from hollowtree.pipeline.tree_stage import _check_fingerprint

    bad = tmp_path / "check.json"
    bad.write_text("{not json")
    with pytest.raises(ConfigError, match=r"^tree\.verify_model: .*check\.json is not a readable element check"):
        _check_fingerprint(TreeStageParams(verify=True, verify_model=str(bad)))
    assert _check_fingerprint(TreeStageParams(verify=False, verify_model=str(bad))) is None
    assert len(_check_fingerprint(TreeStageParams(verify=True))) == 16
