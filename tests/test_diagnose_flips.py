"""``benchmarks/diagnose_generalize.py --flips`` (the elements two runs of the same scans disagree on)
and ``--density`` (recall of the same sites at different densities)."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("hollowtree_diagnose", REPO / "benchmarks" / "diagnose_generalize.py")
diagnose = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(diagnose)


def _row(store: str, inst: int, bucket: str, points: int = 1000) -> dict:
    return {"store": store, "instance": inst, "class": "arch", "bucket": bucket, "points": points}


def test_flips_are_the_elements_found_in_one_run_only(tmp_path, capsys):
    a = [_row("s", 1, "found"), _row("s", 2, "found"), _row("s", 3, "tiny"), _row("t", 1, "not cut out")]
    b = [_row("s", 1, "found"), _row("s", 2, "coarse fragments"), _row("s", 3, "wrong class"), _row("t", 1, "found")]
    pairs = diagnose.flips(a, b)
    assert [(r["store"], r["instance"], s["bucket"]) for r, s in pairs] == [("s", 2, "coarse fragments"),
                                                                            ("t", 1, "found")]
    for name, rows in (("a", a), ("b", b)):
        (tmp_path / f"{name}.json").write_text(json.dumps({"lost": rows, "false_positives": []}))
    assert diagnose.main(["--flips", str(tmp_path / "a.json"), str(tmp_path / "b.json")]) == 0
    out = capsys.readouterr().out
    assert "found 2 and 2; found in one run only 2 (50.0 %)" in out
    assert "arch: found -> coarse fragments" in out


def test_density_counts_elements_visible_in_every_scan(tmp_path, capsys):
    sparse = [_row("gen-v2-100000-1000000.zarr", 1, "found", 400), _row("gen-v2-100000-1000000.zarr", 2, "tiny", 30),
              _row("gen-v2-100001-1000000.zarr", 1, "not cut out", 150)]
    dense = [_row("gen-v2-100000-10000000.zarr", 1, "found", 4000), _row("gen-v2-100000-10000000.zarr", 2, "found", 300),
             _row("gen-v2-100001-10000000.zarr", 1, "found", 1500),
             _row("gen-v2-100001-10000000.zarr", 3, "found", 120)]  # no point of it in the sparse scan
    res = diagnose.density([sparse, dense], tiny=100)
    assert res == [{"elements": 4, "found": 1, "visible": 2, "found_visible": 1},
                   {"elements": 4, "found": 4, "visible": 2, "found_visible": 2}]
    assert diagnose._site("gen-v2-100000-1000000.zarr") == "gen-v2-100000"
    assert diagnose._site("plain.zarr") == "plain"
    paths = []
    for name, rows in (("1m", sparse), ("10m", dense)):
        paths.append(tmp_path / f"{name}.json")
        paths[-1].write_text(json.dumps({"lost": rows, "false_positives": []}))
    assert diagnose.main(["--density", *map(str, paths), "--json", str(tmp_path / "d.json")]) == 0
    assert "1 / 2 (50.0 %)" in capsys.readouterr().out
    assert json.loads((tmp_path / "d.json").read_text())["runs"][1]["found_visible"] == 2


def test_density_names_a_file_that_is_not_a_diagnosis(tmp_path, capsys):
    bad = tmp_path / "bad.json"
    bad.write_text("[1, 2]")
    with pytest.raises(SystemExit) as e:
        diagnose.main(["--density", str(bad)])
    assert e.value.code == 2
    assert "--density " + str(bad) + ": not a --json output" in capsys.readouterr().err


def test_classes_before_the_check_come_from_the_batch_tables():
    """An instance's class before the element check: the batch tables' class of its nodes,
    weighted by their points (the nodes table holds the class after the check)."""
    import numpy as np

    node_key = np.array([[1, 0], [1, 1], [1, 2], [2, 0], [3, 0]])
    node_inst = np.array([7, 7, 7, 0, 9])
    node_points = np.array([10, 30, 15, 5, 40])
    table_key = np.array([[1, 2], [1, 1], [1, 0], [2, 0]])  # node (3, 0) is in no table
    table_class = np.array([8, 5, 5, 2])
    assert diagnose.classes_before_check(node_key, node_inst, node_points, table_key, table_class) == {7: 5}
    assert diagnose.classes_before_check(node_key, node_inst, np.array([10, 3, 15, 5, 40]), table_key,
                                         table_class) == {7: 8}


def test_post_cover_is_the_best_post_of_the_group_for_a_pillar():
    np = pytest.importorskip("numpy")
    rng = np.random.default_rng(0)
    cols = [rng.uniform(-0.15, 0.15, (800, 3)) * [1, 1, 0] + [x, 0, 0] + rng.uniform(0, 3, (800, 1)) * [0, 0, 1]
            for x in (0.0, 2.0, 4.0)]
    slab = rng.uniform(0, 1, (1500, 3)) * [5.0, 1.0, 0.3] + [-0.5, -0.5, 3.0]
    xyz = np.vstack(cols + [slab])
    which = np.arange(len(xyz)) // 800
    iou, j = diagnose.post_cover(xyz, which == 2)
    assert j == 2
    assert iou == pytest.approx(1.0, abs=0.01)
    # the pillar with the slab above it: its post covers 800 of its 2 300 points
    iou, j = diagnose.post_cover(xyz, (which == 0) | (which >= 3))
    assert j == 0
    assert iou == pytest.approx(800 / 2300, abs=0.01)
    assert diagnose.post_cover(slab, np.ones(len(slab), bool)) == (0.0, -1)
