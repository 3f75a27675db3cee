"""``benchmarks/fit_verify.py``: which stores are training sites, and the per-class thresholds it writes."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("hollowtree_fit_verify", REPO / "benchmarks" / "fit_verify.py")
fit_verify = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(fit_verify)


@pytest.mark.parametrize(("name", "seed"), [("gen-v2-100000-637000.zarr", 100000), ("gen-v2-7-1500000.zarr", 7),
                                            ("gen-12-5000.zarr", 12), ("site.zarr", None), ("gen-v2-x-1.zarr", None)])
def test_the_seed_of_a_store_is_read_from_its_name_in_every_generator_version(name, seed):
    assert fit_verify._seed(Path(name)) == seed


def test_a_validation_store_is_refused_for_the_fit(tmp_path, monkeypatch):
    store = tmp_path / "gen-v2-100003-900000.zarr"
    monkeypatch.setattr(fit_verify, "_stores", lambda work: [store])
    with pytest.raises(SystemExit, match=r"gen-v2-100003-900000\.zarr: not a training seed"):
        fit_verify.fit([tmp_path], tmp_path / "check.json", 0.1)


@pytest.mark.parametrize("item", ["wall=0.3", "dome=2", "dome", "pillar=x"])
def test_a_class_threshold_must_name_an_element_class_and_a_share(item, tmp_path, capsys):
    with pytest.raises(SystemExit) as e:
        fit_verify.main(["fit", str(tmp_path), "--out", str(tmp_path / "c.json"), "--class-threshold", item])
    assert e.value.code == 2
    assert f"--class-threshold {item!r}" in capsys.readouterr().err


def test_work_folders_named_after_the_class_thresholds_are_still_work_folders(tmp_path, monkeypatch, capsys):
    a, b = tmp_path / "a", tmp_path / "b"
    a.mkdir()
    b.mkdir()
    seen = {}
    monkeypatch.setattr(fit_verify, "fit", lambda work, out, threshold, per, *rest: seen.update(work=work, per=per) or 0)
    assert fit_verify.main(["fit", "--out", str(tmp_path / "c.json"), "--class-threshold", "dome=0.35",
                            "pillar=0.4", str(a), str(b)]) == 0
    assert seen == {"work": [a, b], "per": {5: 0.35, 7: 0.4}}
    with pytest.raises(SystemExit) as e:
        fit_verify.main(["fit", "--out", str(tmp_path / "c.json"), "--class-threshold", "dome=0.35"])
    assert e.value.code == 2
    assert "name at least one work folder" in capsys.readouterr().err


def test_thresholds_are_chosen_to_drop_a_false_element_and_keep_a_true_one():
    import numpy as np

    # ten points of a true dome (instance 1) and ten of a tree (other), both predicted dome
    dome, other = 5, 8
    row = {"gc": np.r_[np.full(10, dome), np.full(10, other)], "gi": np.r_[np.full(10, 1), np.full(10, 2)],
           "pc": np.full(20, dome), "pi": np.r_[np.full(10, 1), np.full(10, 2)],
           "key": np.array([1 * 256 + dome, 2 * 256 + dome]), "cls": np.array([dome, dome]), "gt": {dome: 1}}
    probs = [np.array([[0.0, 0.9, 0.0, 0.0], [0.0, 0.3, 0.0, 0.0]])]
    start = np.full(4, 0.1)
    assert fit_verify._total([row], probs, start, True)[:2] == (1, 2)
    ts, f1 = fit_verify.choose_thresholds([row], probs, start, [0.1, 0.2, 0.5, 0.95])
    assert f1 == 1.0
    assert ts.tolist() == [0.1, 0.5, 0.1, 0.1]  # 0.5 drops the tree; 0.95 would drop the dome too
    ts, f1 = fit_verify.choose_thresholds([row], probs, start, [0.1, 0.2, 0.5, 0.95], keep=frozenset({dome}))
    assert ts.tolist() == [0.1, 0.1, 0.1, 0.1]
    assert f1 < 1.0


@pytest.mark.parametrize(("args", "message"), [(["--choose-thresholds", "--keep", "wall"], "--keep 'wall'"),
                                           (["--keep", "dome"], "--keep: only with --choose-thresholds")])
def test_keep_names_element_classes_and_needs_the_choice(args, message, tmp_path, capsys):
    with pytest.raises(SystemExit) as e:
        fit_verify.main(["fit", str(tmp_path), "--out", str(tmp_path / "c.json"), *args])
    assert e.value.code == 2
    assert message in capsys.readouterr().err


def test_fit_chooses_and_writes_the_thresholds_of_its_out_of_fold_decisions(tmp_path, monkeypatch):
    import numpy as np

    from hollowtree.tree.verify import VERIFY_FEATURES, load_verify_model

    # ten training sites; each holds, for every element class, one true element and one
    # false one (a tree called that class) that a feature tells apart
    rng = np.random.default_rng(0)

    def rows(store):
        feats, cls, target, gc, gi, pc, pi = [], [], [], [], [], [], []
        for j, c in enumerate((4, 5, 6, 7)):
            for true in (1, 0):
                f = rng.normal(0.0, 0.01, len(VERIFY_FEATURES))
                f[j], f[len(VERIFY_FEATURES) - 1] = 1.0, float(true)
                inst = 2 * j + 2 - true
                feats.append(f)
                cls.append(c)
                target.append(c if true else 0)
                gc += [c if true else 8] * 5
                gi += [inst] * 5
                pc += [c] * 5
                pi += [inst] * 5
        cls = np.array(cls)
        return {"features": np.array(feats), "cls": cls, "target": np.array(target),
                "key": np.array([(2 * j + 2 - t) * 256 + c for j, c in enumerate((4, 5, 6, 7)) for t in (1, 0)]),
                "gc": np.array(gc), "gi": np.array(gi), "pc": np.array(pc), "pi": np.array(pi),
                "gt": {c: 1 for c in (4, 5, 6, 7)}}

    stores = [tmp_path / f"gen-v2-{k}-1000.zarr" for k in range(10)]
    monkeypatch.setattr(fit_verify, "_stores", lambda work: stores)
    monkeypatch.setattr(fit_verify, "store_rows", rows)
    out = tmp_path / "check.json"
    assert fit_verify.main(["fit", str(tmp_path), "--out", str(out), "--threshold", "0",
                            "--choose-thresholds", "0", "0.5"]) == 0
    check = load_verify_model(out)
    # at 0 every false element is kept (F1 2/3); 0.5 drops them and keeps the true ones
    assert check.info["thresholds"]["start_f1"] < 0.7
    assert check.info["thresholds"]["f1"] == 1.0
    assert check.thresholds().tolist() == [0.5, 0.5, 0.5, 0.5]
    # --keep holds the named classes at their start
    assert fit_verify.main(["fit", str(tmp_path), "--out", str(out), "--threshold", "0",
                            "--choose-thresholds", "0", "0.5", "--keep", "arch", "pillar"]) == 0
    check = load_verify_model(out)
    assert check.thresholds().tolist() == [0.0, 0.5, 0.5, 0.0]
    assert check.info["thresholds"]["kept"] == ["arch", "pillar"]
