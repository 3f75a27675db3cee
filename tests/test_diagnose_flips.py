"""``benchmarks/diagnose_generalize.py --flips``: the elements two runs of the same scans disagree on."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("hollowtree_diagnose", REPO / "benchmarks" / "diagnose_generalize.py")
diagnose = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(diagnose)


def _row(store: str, inst: int, bucket: str) -> dict:
    return {"store": store, "instance": inst, "class": "arch", "bucket": bucket}


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
