"""``hollowtree evaluate`` and the scoring kernels of scenes/metrics.py.

The kernel tests use hand-built labels whose scores are worked out by hand; the end-to-end
test runs the command on a small synthetic scene (in process scheduler) and then again
on the run store it made.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import laspy
import numpy as np
import pytest

from hollowtree.pipeline.tree_stage import TREE_ALGORITHM
from hollowtree.scenes.metrics import (
    VISIBLE_POINTS,
    ClassScore,
    Evaluation,
    LabelCounts,
    count_labels,
    evaluate_labels,
    score_counts,
)

REPO = Path(__file__).resolve().parents[1]
ARCH, DOME, MINARET, PILLAR, WALL, GROUND = 4, 5, 6, 7, 2, 1


def _cli(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "hollowtree", *args], capture_output=True, text=True, cwd=cwd)


# ------------------------------------------------------------------------------ kernels
def test_perfect_prediction_is_100_percent():
    gc = np.array([GROUND] * 4 + [ARCH] * 3 + [ARCH] * 3 + [DOME] * 5 + [MINARET] * 2)
    gi = np.array([1] * 4 + [2] * 3 + [3] * 3 + [4] * 5 + [5] * 2)
    ev = evaluate_labels(gc, gi, gc, gi + 100)  # instance ids need not agree, only the partition
    for name, n in (("arch", 2), ("dome", 1), ("minaret", 1), ("ground", 1)):
        s = ev.score(name)
        assert (s.n_gt, s.n_found, s.n_pred, s.accuracy_pct, s.precision_pct, s.iou_pct) == (n, n, n, 100.0, 100.0, 100.0)
    assert ev.mean_iou_pct == 100.0
    assert ev.n_points == len(gc)


def test_split_instance_is_not_found():
    gc = np.full(10, ARCH)
    gi = np.ones(10, np.int64)
    ev = evaluate_labels(gc, gi, gc, np.array([1] * 4 + [2] * 3 + [3] * 3))  # best IoU 4/10
    a = ev.score("arch")
    assert (a.n_gt, a.n_found, a.accuracy_pct, a.n_pred, a.precision_pct) == (1, 0, 0.0, 3, 0.0)
    assert a.iou_pct == 100.0  # every point still has the right class
    # a split into halves reaches IoU 0.5 exactly, which counts (>= 0.5), once
    half = evaluate_labels(gc, gi, gc, np.array([1] * 5 + [2] * 5)).score("arch")
    assert (half.n_found, half.n_pred, half.precision_pct) == (1, 2, 50.0)


def test_merged_prediction_has_iou_below_half():
    gc = np.full(12, DOME)
    gi = np.repeat([1, 2, 3], 4)
    d = evaluate_labels(gc, gi, gc, np.full(12, 7)).score("dome")  # IoU 4/12 with each dome
    assert (d.n_gt, d.n_found, d.accuracy_pct, d.n_pred, d.precision_pct) == (3, 0, 0.0, 1, 0.0)
    # two domes merged: IoU 0.5 with each; one-to-one matching finds one of them only
    two = evaluate_labels(gc[:8], gi[:8], gc[:8], np.full(8, 7)).score("dome")
    assert (two.n_found, two.accuracy_pct, two.precision_pct) == (1, 50.0, 100.0)


def test_unequal_merge_finds_the_larger_instance():
    gc = np.full(22, MINARET)
    gi = np.r_[np.full(10, 1), np.full(12, 2)]
    m = evaluate_labels(gc, gi, gc, np.full(22, 5)).score("minaret")  # IoU 10/22 and 12/22
    assert (m.n_gt, m.n_found, m.n_pred, m.n_pred_matched) == (2, 1, 1, 1)


def test_precision_counts_a_false_instance():
    gc = np.array([MINARET] * 6 + [GROUND] * 4)
    gi = np.array([1] * 3 + [2] * 3 + [3] * 4)
    pc = np.array([MINARET] * 6 + [MINARET] * 2 + [GROUND] * 2)  # two ground points called a minaret
    pi = np.array([10] * 3 + [11] * 3 + [12] * 2 + [13] * 2)
    ev = evaluate_labels(gc, gi, pc, pi)
    m = ev.score("minaret")
    assert (m.n_gt, m.n_found, m.accuracy_pct, m.n_pred, m.n_pred_matched) == (2, 2, 100.0, 3, 2)
    assert m.precision_pct == pytest.approx(200 / 3)
    assert m.iou_pct == pytest.approx(100 * 6 / 8)
    g = ev.score("ground")
    assert (g.n_found, g.n_pred, g.iou_pct) == (1, 1, 50.0)  # 2 of its 4 points: IoU 0.5 counts


def test_elements_the_scan_hardly_shows_are_counted_apart():
    v = VISIBLE_POINTS
    # pillars of v, v - 1 and v + 6 points; the first two found, the third cut in thirds
    gc = np.full(3 * v + 5, PILLAR)
    gi = np.repeat([1, 2, 3], [v, v - 1, v + 6])
    third = (v + 6) // 3
    pi = np.repeat([1, 2, 3, 4, 5], [v, v - 1, third, third, v + 6 - 2 * third])
    p = evaluate_labels(gc, gi, gc, pi).score("pillar")
    assert (p.n_gt, p.n_found, p.n_gt_visible, p.n_found_visible) == (3, 2, 2, 1)
    # scores saved before the visible elements were counted read back with None
    old = {k: x for k, x in p.to_dict().items() if not k.endswith("_visible")}
    assert ClassScore.from_dict(old).n_gt_visible is None


def test_na_when_there_is_no_ground_truth():
    gc = np.array([WALL] * 5)
    gi = np.ones(5, np.int64)
    ev = evaluate_labels(gc, gi, gc, gi)
    p = ev.score("pillar")
    assert (p.n_gt, p.n_found, p.accuracy_pct, p.n_pred, p.precision_pct, p.iou_pct) == (0, 0, None, 0, None, None)
    # a predicted pillar where there is none: precision 0 %, accuracy still NA, IoU 0
    pc = np.array([WALL] * 4 + [PILLAR])
    p2 = evaluate_labels(gc, gi, pc, np.array([1, 1, 1, 1, 2])).score("pillar")
    assert (p2.accuracy_pct, p2.precision_pct, p2.iou_pct) == (None, 0.0, 0.0)
    d = Evaluation.from_dict(json.loads(json.dumps(ev.to_dict())))
    assert d == ev


def test_point_iou_and_mean_over_classes_present():
    gc = np.array([ARCH] * 10 + [WALL] * 10)
    pc = np.array([ARCH] * 8 + [WALL] * 2 + [WALL] * 9 + [ARCH])
    ev = evaluate_labels(gc, np.zeros(20, int), pc, np.zeros(20, int))
    assert ev.score("arch").iou_pct == pytest.approx(100 * 8 / 11)
    assert ev.score("wall").iou_pct == pytest.approx(100 * 9 / 12)
    assert ev.mean_iou_pct == pytest.approx(50 * (8 / 11 + 9 / 12))  # dome etc. absent: not averaged
    assert ev.score("arch").n_gt == 0  # instance id 0 = no instance


def test_chunks_merge_to_the_whole_and_match_a_brute_force_reference():
    rng = np.random.default_rng(4)
    n = 5000
    gi = rng.integers(0, 40, n)
    gc = np.where(gi > 0, gi % 5 + 3, rng.integers(0, 9, n))
    pi = np.where(rng.random(n) < 0.8, gi * 3 + rng.integers(0, 2, n), rng.integers(0, 90, n))
    pc = np.where(rng.random(n) < 0.9, gc, rng.integers(0, 9, n))
    whole = count_labels(gc, gi, pc, pi)
    parts = LabelCounts.empty()
    for a in range(0, n, 777):
        parts = parts.merge(count_labels(gc[a:a + 777], gi[a:a + 777], pc[a:a + 777], pi[a:a + 777]))
    for f in ("confusion", "gt_keys", "gt_sizes", "pred_keys", "pred_sizes", "pair_gt", "pair_pred", "pair_count"):
        np.testing.assert_array_equal(getattr(parts, f), getattr(whole, f), err_msg=f)
    ev = score_counts(parts)
    assert ev == score_counts(whole)
    # brute force: per class, IoU of every (gt, pred) instance pair, greedy one-to-one
    for c in range(1, 9):
        gts = {i for i in np.unique(gi[(gc == c) & (gi > 0)])}
        preds = {i for i in np.unique(pi[(pc == c) & (pi > 0)])}
        cand = []
        for g in gts:
            gm = (gc == c) & (gi == g)
            for p in preds:
                pm = (pc == c) & (pi == p)
                iou = (gm & pm).sum() / (gm | pm).sum()
                if iou >= 0.5:
                    cand.append((iou, g, p))
        used_g, used_p = set(), set()
        for _, g, p in sorted(cand, reverse=True):
            if g not in used_g and p not in used_p:
                used_g.add(g)
                used_p.add(p)
        s = ev.score(c)
        assert (s.n_gt, s.n_pred, s.n_found) == (len(gts), len(preds), len(used_g)), c
        tp, fp, fn = ((gc == c) & (pc == c)).sum(), ((gc != c) & (pc == c)).sum(), ((gc == c) & (pc != c)).sum()
        assert s.iou_pct == (pytest.approx(100 * tp / (tp + fp + fn)) if tp + fp + fn else None)


def test_bad_arrays_are_one_line_errors():
    with pytest.raises(ValueError, match="'pred_class' parameter of count_labels must be an array of shape"):
        count_labels([1, 2], [1, 1], [1], [1, 1])
    with pytest.raises(ValueError, match=r"must be in the range \[0, 9\)"):
        count_labels([1, 12], [1, 1], [1, 1], [1, 1])
    with pytest.raises(ValueError, match="must be >= 0"):
        count_labels([1, 1], [1, -1], [1, 1], [1, 1])
    with pytest.raises(ValueError, match="iou_threshold"):
        evaluate_labels([1], [1], [1], [1], iou_threshold=0.0)


def test_inputs_are_not_modified():
    gc = np.array([5, 5, 6], np.uint8)
    gi = np.array([1, 1, 2], np.uint32)
    copies = [gc.copy(), gi.copy()]
    evaluate_labels(gc, gi, gc, gi)
    np.testing.assert_array_equal(gc, copies[0])
    np.testing.assert_array_equal(gi, copies[1])


# ------------------------------------------------------------------------------ the command
@pytest.fixture(scope="module")
def evaluated(tmp_path_factory):
    d = tmp_path_factory.mktemp("ev")
    proc = _cli("evaluate", "dome", "--store-dir", str(d / "stores"), "--json", str(d / "ev.json"), "--png-dir", str(d),
                "--scheduler", "sync", "--no-progress", "--set", "input.synth.points=60000",
                "--set", f"input.synth.out={d}/{{site}}-{{points}}.laz", "--set", "coarse.min_support=300",
                "--seeds", "2")
    assert proc.returncode == 0, proc.stderr
    return d, proc, json.loads((d / "ev.json").read_text())


@pytest.mark.slow
def test_evaluate_synthetic_scene_end_to_end(evaluated):
    d, proc, out = evaluated
    (site,) = out["sites"]
    assert site["name"] == "dome"
    assert site["n_points"] > 30_000
    assert out["machine"]["cpus"] >= 1
    assert out["machine"]["cpu"]  # labels can differ at the margin between CPU types
    assert out["machine"]["packages"]["numpy"] == np.__version__  # ... and between package versions
    assert list(site["methods"]) == ["ransac", "ransac+dbscan", "tree"]
    assert 0 < site["n_primitives"] <= site["n_segments"]
    for m in site["methods"].values():
        dome = m["classes"]["dome"]
        assert dome["n_gt"] == 1
        assert 0 <= dome["n_found"] <= 1
        assert m["classes"]["arch"]["accuracy_pct"] is None  # no arch in this scene: NA
        assert 0.0 <= m["mean_iou_pct"] <= 100.0
        assert m["n_points"] == site["n_points"]
    assert site["pipeline_seconds"] > 0
    assert "Acc %" in proc.stdout
    assert "ransac+dbscan" in proc.stdout
    assert "mean point IoU" in proc.stdout
    assert (d / "dome.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.slow
def test_evaluate_existing_store_reads_without_rerunning(evaluated, tmp_path):
    d, _, out = evaluated
    proc = _cli("evaluate", str(d / "stores" / "dome.zarr"), "--json", str(tmp_path / "again.json"), "--no-progress")
    assert proc.returncode == 0, proc.stderr
    assert "pipeline not run" in proc.stdout
    again = json.loads((tmp_path / "again.json").read_text())["sites"][0]
    assert again["pipeline_seconds"] is None
    assert again["methods"] == out["sites"][0]["methods"]
    assert (tmp_path / "dome.png").is_file()


@pytest.mark.slow
def test_evaluate_seeds_runs_each_input_once_per_seed(evaluated):
    d, proc, out = evaluated
    assert out["seeds"] == 2
    (first,), ((second,),) = out["sites"], out["repeats"]
    assert first["seeds"] == {"coarse": 0, "tree": 0}
    assert second["seeds"] == {"coarse": 1, "tree": 1}
    assert first["store"].endswith("dome.zarr")
    assert second["store"].endswith("dome-seed1.zarr")
    assert (d / "stores" / "dome-seed1.zarr").is_dir()
    spread = out["spread"]["sites"]["dome"]
    ious = [s["methods"]["tree"]["mean_iou_pct"] for s in (first, second)]
    assert spread["tree_mean_iou_pct"]["values"] == pytest.approx(ious)
    assert spread["found"]["dome"]["values"] == [s["methods"]["tree"]["classes"]["dome"]["n_found"]
                                                 for s in (first, second)]
    assert "over 2 seeds" in proc.stdout
    assert out["tree_algorithm"] == TREE_ALGORITHM
    assert out["coarse_algorithm"].startswith("coarse-v")


def test_seed_spread_by_hand():
    from hollowtree.pipeline.evaluate import SiteResult, format_spread, seed_spread

    gc = np.array([GROUND] * 4 + [DOME] * 4 + [DOME] * 4)
    gi = np.array([1] * 4 + [2] * 4 + [3] * 4)
    right = evaluate_labels(gc, gi, gc, gi)  # everything right: 100 %
    one_dome = evaluate_labels(gc, gi, gc, np.array([1] * 4 + [2] * 8))  # the domes merged: 1 found
    wrong = evaluate_labels(gc, gi, np.full(12, GROUND), np.ones(12, np.int64))  # all ground

    def site(name, tree, base):
        return SiteResult(name=name, input=name, store="", n_points=12, pipeline_seconds=None, evaluate_seconds=0.0,
                          methods={"ransac": base, "ransac+dbscan": base, "tree": tree}, n_segments=1, n_primitives=1)

    runs = [[site("a", right, wrong), site("b", one_dome, wrong)],
            [site("a", one_dome, wrong), site("b", one_dome, one_dome)]]
    s = seed_spread(runs)
    assert s["n_seeds"] == 2
    a = s["sites"]["a"]
    assert a["tree_mean_iou_pct"]["values"] == [100.0, 100.0]  # classes right either way
    assert a["found"]["dome"] == {"n_gt": 2, "values": [2.0, 1.0], "mean": 1.5, "min": 1.0, "max": 2.0}
    assert a["precision_pct"]["dome"]["values"] == [100.0, 100.0]
    assert "arch" not in a["found"]  # no arch in the ground truth
    b = s["sites"]["b"]
    assert b["tree_minus_ransac+dbscan"]["values"] == pytest.approx([100.0 - wrong.mean_iou_pct, 0.0])
    assert s["all"]["found"]["dome"] == {"n_gt": 4, "values": [3.0, 2.0], "mean": 2.5, "min": 2.0, "max": 3.0}
    assert s["all"]["precision_pct"]["dome"]["values"] == [100.0, 100.0]
    false_dome = evaluate_labels(gc, gi, np.full(12, DOME), np.array([9] * 4 + [2] * 4 + [3] * 4))
    pooled = seed_spread([[site("a", false_dome, wrong), site("b", one_dome, wrong)]])["all"]["precision_pct"]
    assert pooled["dome"]["values"] == pytest.approx([100 * 3 / 4])  # (2 + 1) matched of (3 + 1) predicted
    assert s["all"]["tree_minus_ransac+dbscan"]["values"] == pytest.approx(
        [100.0 - wrong.mean_iou_pct, (100.0 - wrong.mean_iou_pct) / 2])
    text = format_spread(s)
    assert "over 2 seeds" in text
    assert "2.5 (2.0 to 3.0) / 4" in text
    with pytest.raises(ValueError, match="same inputs"):
        seed_spread([runs[0], runs[1][:1]])


def test_seeds_with_a_run_store_is_one_line_exit_2(tmp_path):
    store = tmp_path / "s.zarr"
    store.mkdir()
    (store / "zarr.json").write_text("{}")
    proc = _cli("evaluate", str(store), "--seeds", "3")
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert str(store) in lines[0]
    assert "--seeds 3" in lines[0]
    proc = _cli("evaluate", "dome", "--seeds", "0", "--store-dir", str(tmp_path / "x"))
    assert proc.returncode == 2
    assert "--seeds" in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "x").exists()


def test_las_without_ground_truth_is_one_line_exit_2(tmp_path):
    header = laspy.LasHeader(point_format=6, version="1.4")
    las = laspy.LasData(header)
    las.x, las.y, las.z = np.arange(10.0), np.arange(10.0), np.zeros(10)
    path = tmp_path / "plain.las"
    las.write(path)
    proc = _cli("evaluate", str(path), "--store-dir", str(tmp_path / "stores"), "--no-progress")
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert str(path) in lines[0]
    assert "gt_class" in lines[0]
    assert not (tmp_path / "stores").exists()  # nothing written


def test_inputs_are_planned_before_anything_runs(tmp_path):
    from hollowtree.pipeline.evaluate import _plan
    from hollowtree.scenes.synth import synth

    scan = tmp_path / "pillar.laz"
    synth("pillar", scan, n_points=3000, seed=1)
    name, store, overrides = _plan(str(scan), str(tmp_path / "s"))
    assert (name, store) == ("pillar", str(tmp_path / "s" / "pillar.zarr"))
    assert overrides == [f'input.files=["{scan}"]', "input.synth=null"]
    name, store, overrides = _plan("temple", "out/x")
    assert (name, store, overrides[-1]) == ("temple", "out/x/temple.zarr", "input.synth.site=temple")
    assert not (tmp_path / "s").exists()


def test_unknown_input_is_one_line_exit_2(tmp_path):
    proc = _cli("evaluate", "wazir_kahn", "--store-dir", str(tmp_path / "s"))
    assert proc.returncode == 2
    assert len(proc.stderr.strip().splitlines()) == 1
    assert "wazir_kahn" in proc.stderr


def test_loss_buckets_names_where_each_element_was_lost():
    from hollowtree.scenes.metrics import loss_buckets

    # Six dome elements (class 5) of 10 points each and 40 wall points (class 2), then
    # labels that lose each dome in a different way.
    n_el = 10
    gc = np.r_[np.full(6 * n_el, 5), np.full(40, 2)]
    gi = np.r_[np.repeat(np.arange(1, 7), n_el), np.zeros(40, int)]
    pc, pi = np.full(len(gc), 2), np.zeros(len(gc), int)
    coarse, leaf = np.zeros(len(gc), int), np.zeros(len(gc), int)
    el = [np.arange(k * n_el, (k + 1) * n_el) for k in range(6)]
    wall = np.arange(6 * n_el, len(gc))
    # 1: found (its own segment, leaf and dome instance)
    coarse[el[0]], leaf[el[0]], pc[el[0]], pi[el[0]] = 1, 1, 5, 1
    # 2: cut out (its own leaf and instance) but called minaret
    coarse[el[1]], leaf[el[1]], pc[el[1]], pi[el[1]] = 2, 2, 6, 1
    # 3: cut into three leaves that lie inside it, never joined
    coarse[el[2]] = 3
    leaf[el[2][:3]], leaf[el[2][3:6]], leaf[el[2][6:]] = 3, 4, 5
    # 4: spread over five coarse segments, each shared with wall points
    for j, part in enumerate(np.array_split(el[3], 5)):
        coarse[part] = 10 + j
        coarse[wall[4 * j:4 * j + 4]] = 10 + j
        leaf[part] = leaf[wall[4 * j:4 * j + 4]] = 10 + j
    # 5: one segment with all the wall's other points, never split
    coarse[el[4]] = coarse[wall[20:]] = 20
    leaf[el[4]] = leaf[wall[20:]] = 20
    # 6: found, but with --tiny above its size it is still "found" (found comes first)
    coarse[el[5]], leaf[el[5]], pc[el[5]], pi[el[5]] = 6, 6, 5, 2
    rows = loss_buckets(gc, gi, pc, pi, coarse, leaf, classes=(5,), tiny=5)
    assert [r["bucket"] for r in rows] == ["found", "wrong class", "leaves, not grouped", "coarse fragments",
                                           "not cut out", "found"]
    assert rows[1]["predicted"] == 6
    assert rows[4]["share_of_segment"] == round(10 / 30, 3)
    tiny = loss_buckets(gc, gi, pc, pi, coarse, leaf, classes=(5,), tiny=11)
    assert [r["bucket"] for r in tiny] == ["found", "tiny", "tiny", "tiny", "tiny", "found"]
