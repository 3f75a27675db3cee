"""``benchmarks/choose.py``: the selection rule of docs/generalize.md on a variant's JSONs."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("hollowtree_choose", REPO / "benchmarks" / "choose.py")
choose = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(choose)


SITES = 10


def _split(n: int, k: int = SITES) -> list[int]:
    """``n`` over ``k`` sites as evenly as integers go, the remainder on the first ones."""
    return [n // k + (i < n % k) for i in range(k)]


def _run(found: int, gt: int = 100, pred: int = 100, cpu: str = "CPU A", dome: int = 10) -> dict:
    """A bench_generalize JSON of :data:`SITES` validation sites: ``found`` of ``gt`` arches
    (all predictions that match one are right) and ``dome`` of 20 domes, spread evenly over
    the sites, with the totals and the per-site totals."""
    cols = {("arch", "gt"): _split(gt), ("arch", "found"): _split(found), ("arch", "pred"): _split(pred),
            ("dome", "gt"): _split(20), ("dome", "found"): _split(dome), ("dome", "pred"): _split(dome)}
    sites = []
    for i in range(SITES):
        t = {c: {"gt": 0, "found": 0, "pred": 0, "matched": 0} for c in choose.ELEMENTS}
        for (c, k), v in cols.items():
            t[c][k] = v[i]
        for c in ("arch", "dome"):
            t[c]["matched"] = t[c]["found"]
        sites.append({"seed": 100000 + i, "totals": t})
    totals = {c: {k: sum(x["totals"][c][k] for x in sites) for k in ("gt", "found", "pred", "matched")}
              for c in choose.ELEMENTS}
    return {"totals": {"tree": totals}, "sites": sites, "machine": {"cpu": cpu, "packages": {"numpy": "2.4.6"}}}


@pytest.fixture
def results(tmp_path, monkeypatch):
    monkeypatch.setattr(choose, "RESULTS", tmp_path)

    def put(name: str, seed: int, found: int, **kw) -> None:
        for row in choose.ROWS:
            choose.result_path(row, name, seed).write_text(json.dumps(_run(found, **kw)))

    return put


def test_f1_of_several_runs_pools_their_sites():
    a, b = _run(50), _run(100)
    r, p = 60 / 120, 60 / 110  # 50 + 10 found of 100 + 20, of 100 + 10 predicted
    assert choose.f1(a) == pytest.approx(2 * r * p / (r + p))
    r, p = 170 / 240, 170 / 220  # both: 150 + 20 found of 200 + 40, of 200 + 20 predicted
    assert choose.f1(a, b) == pytest.approx(2 * r * p / (r + p))
    assert 0 < choose.f1(a) < choose.f1(a, b) < choose.f1(b) <= 1


def test_seed_zero_has_no_suffix(tmp_path, monkeypatch):
    monkeypatch.setattr(choose, "RESULTS", tmp_path)
    assert choose.result_path("val-4m", "v9", 0).name == "generalize-val-4m-v9.json"
    assert choose.result_path("val-4m", "v9", 2).name == "generalize-val-4m-v9-seed2.json"


def test_a_variant_whose_gain_is_clear_of_site_noise_is_kept_an_equal_one_rejected(results):
    for s in range(3):
        results("base", s, 60)
        results("better", s, 80)  # two more arches on every site
        results("same", s, 60)
    verdict, lines = choose.judge("better", "base", [0, 1, 2])
    assert verdict.startswith("keep: macro mean +0.0500"), verdict  # arch F1 0.6 -> 0.8: +0.2 over four classes
    assert any(line.startswith("better") for line in lines)
    assert choose.judge("same", "base", [0, 1, 2])[0].startswith("reject: macro mean +0.0000")


def test_a_gain_on_one_site_of_ten_is_site_noise(tmp_path, monkeypatch):
    """Ten more arches on one site raise the mean as much as one on each of ten, but a
    resample of the sites that leaves that site out gains nothing: rejected."""
    monkeypatch.setattr(choose, "RESULTS", tmp_path)
    for name, extra in (("base", [0] * SITES), ("spread", [1] * SITES), ("one-site", [10] + [0] * (SITES - 1))):
        for s in range(3):
            for row in choose.ROWS:
                run = _run(60)
                for x, e in zip(run["sites"], extra, strict=True):
                    x["totals"]["arch"]["found"] += e
                    x["totals"]["arch"]["matched"] += e
                run["totals"]["tree"]["arch"]["found"] += sum(extra)
                run["totals"]["tree"]["arch"]["matched"] += sum(extra)
                choose.result_path(row, name, s).write_text(json.dumps(run))
    gain_spread, lo, _ = choose.macro_interval("spread", "base", [0, 1, 2], draws=500)
    gain_one, lo_one, _ = choose.macro_interval("one-site", "base", [0, 1, 2], draws=500)
    assert gain_one == pytest.approx(gain_spread)
    assert gain_one > 0
    assert lo > choose.ZERO >= lo_one
    assert choose.judge("spread", "base", [0, 1, 2])[0].startswith("keep")
    assert "reaches zero" in choose.judge("one-site", "base", [0, 1, 2])[0]


def test_more_domes_alone_are_kept(results):
    """The dome batch's domes rise on every site, arches equal: the three-row sum barely
    moves, the macro mean of the class F1s does."""
    for s in range(3):
        results("base", s, 60, dome=10)
        results("domes", s, 60, dome=20)
    verdict, lines = choose.judge("domes", "base", [0, 1, 2])
    assert verdict.startswith("keep"), verdict
    assert any("dome 0.667 -> 1.000" in line for line in lines)


def test_a_class_that_falls_rejects_whatever_the_mean(results):
    for s in range(3):
        results("base", s, 60)
        results("fewer-domes", s, 80, dome=8)
    verdict, _ = choose.judge("fewer-domes", "base", [0, 1, 2])
    assert verdict.startswith("reject")
    assert "dome F1 fell" in verdict


def test_a_class_may_fall_within_the_defaults_spread_over_the_seeds(results):
    for s, d in enumerate((10, 12, 11)):  # the default's dome F1 over the seeds: 0.667, 0.750, 0.710 (mean 0.709)
        results("base", s, 60, dome=d)
        results("within", s, 80, dome=d - 1 if s else d)  # mean 0.709 -> 0.681: less than the range 0.083
        results("beyond", s, 80, dome=d - 3)  # mean 0.709 -> 0.570
    assert choose.judge("within", "base", [0, 1, 2])[0].startswith("keep")
    verdict, lines = choose.judge("beyond", "base", [0, 1, 2])
    assert verdict.startswith("reject")
    assert "dome F1 fell" in verdict
    assert any("dome 0.709 -> 0.570 (0.083)" in line for line in lines)


def test_each_class_is_judged_over_the_sites_of_every_row_together(tmp_path, monkeypatch):
    """An arch lost in the dome batch but three gained in each sum row raises the arch F1
    over all the sites: kept. Two domes lost in the dome batch alone: rejected."""
    monkeypatch.setattr(choose, "RESULTS", tmp_path)

    def put(name: str, sums: int, domes_row: int, dome: int = 10) -> None:
        for s in range(3):
            for row in choose.ROWS:
                run = _run(domes_row, dome=dome) if row == "val-domes" else _run(sums)
                choose.result_path(row, name, s).write_text(json.dumps(run))

    put("base", 60, 60)
    put("arches", 80, 50)  # per site: two more arches in each of the four sum rows, one fewer in the dome batch
    put("domes", 80, 60, dome=8)
    assert choose.pooled_class_f1("arches", 0)["arch"] > choose.pooled_class_f1("base", 0)["arch"]
    assert choose.class_f1(_run(50))["arch"] < choose.class_f1(_run(60))["arch"]
    assert choose.judge("arches", "base", [0, 1, 2])[0].startswith("keep")
    verdict, _ = choose.judge("domes", "base", [0, 1, 2])
    assert verdict == "reject: the dome F1 fell by more than the default's range"
    assert choose.pooled_class_f1("nobody", 0) is None


def test_a_variant_without_the_dome_batch_at_every_seed_is_not_judged(results, tmp_path):
    for s in range(3):
        results("base", s, 60)
        results("no-domes", s, 80)
    choose.result_path("val-domes", "no-domes", 2).unlink()
    assert choose.judge("no-domes", "base", [0, 1, 2])[0].startswith("not judged: the dome batch is missing at seed 2")


def test_a_missing_seed_is_not_judged_and_other_environments_are_named(results):
    results("base", 0, 60)
    results("base", 1, 60)
    results("half", 0, 70, cpu="CPU B")
    verdict, lines = choose.judge("half", "base", [0, 1])
    assert verdict == "not judged: a row is missing"
    assert any("different environments" in line for line in lines)


def test_the_command_line_refuses_tree_seed_as_an_override(capsys):
    with pytest.raises(SystemExit) as e:
        choose.main(["v9", "--set", "tree.seed=3"])
    assert e.value.code == 2
    assert "tree.seed" in capsys.readouterr().err


def test_paired_interval_brackets_a_uniform_gain_and_needs_per_site_totals(tmp_path, monkeypatch):
    monkeypatch.setattr(choose, "RESULTS", tmp_path)

    def put(name: str, found: list[int], per_site: bool = True) -> None:
        sites = []
        for i, fd in enumerate(found):
            t = {c: {"gt": 0, "found": 0, "pred": 0, "matched": 0} for c in choose.ELEMENTS}
            t["arch"] = {"gt": 10, "found": fd, "pred": 10, "matched": fd}
            sites.append({"seed": 100000 + i, **({"totals": t} if per_site else {})})
        run = {"totals": {"tree": {c: {k: sum(x["totals"][c][k] for x in sites) if per_site else 0
                                       for k in ("gt", "found", "pred", "matched")} for c in choose.ELEMENTS}},
               "sites": sites}
        for row in choose.SUM_ROWS:
            choose.result_path(row, name, 0).write_text(json.dumps(run))

    put("base", [5, 6, 7, 8, 5, 6, 7, 8])
    put("up", [6, 7, 8, 9, 6, 7, 8, 9])  # one more arch on every site: every resample gains
    lo, hi = choose.paired_interval("up", "base", [0], draws=200)
    gain = sum(choose.three_rows("up", 0)) - sum(choose.three_rows("base", 0))
    assert 0 < lo <= gain + 1e-9
    assert gain - 1e-9 <= hi
    put("old", [5, 6, 7, 8, 5, 6, 7, 8], per_site=False)
    assert choose.paired_interval("up", "old", [0]) is None
