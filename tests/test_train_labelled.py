"""``hollowtree train --from``: HollowNet trained on a user's labelled scan, and a workflow
that names the weights it writes (issue 43, item 7)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import laspy
import numpy as np
import pytest

from hollowtree.errors import ConfigError
from hollowtree.hollownet.dataset import labelled_samples

pytestmark = pytest.mark.slow


def _cli(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "hollowtree", *args], capture_output=True, text=True, cwd=cwd)


@pytest.fixture(scope="module")
def labelled(tmp_path_factory):
    d = tmp_path_factory.mktemp("labelled")
    proc = _cli("synth", "gen-pavilion_garden", "--seed", "3", "--points", "120000", "--out", str(d / "lab.laz"),
                "--no-progress")
    assert proc.returncode == 0, proc.stderr
    (d / "cfg.yaml").write_text("epochs: 1\nn_train: 8\nn_test: 4\n")
    return d


def test_instances_are_held_out_whole():
    rng = np.random.default_rng(1)
    pts = np.concatenate([rng.normal([3 * i, 0, 2], 0.4, (400, 3)) for i in range(30)])
    cls = np.repeat(np.where(np.arange(30) % 2 == 0, 5, 7), 400)
    inst = np.repeat(np.arange(1, 31), 400)
    tr, te = labelled_samples(pts, cls, inst, holdout=0.3, variants=2)
    assert set(tr["scene"].tolist()).isdisjoint(te["scene"].tolist())
    assert len(te["labels"]) > 0
    assert set(tr["labels"].tolist()) | set(te["labels"].tolist()) == {5, 7}
    # an instance takes the majority class of its points
    cls2 = cls.copy()
    cls2[:100] = 2
    tr2, _ = labelled_samples(pts, cls2, inst, holdout=0.0, variants=1)
    assert tr2["labels"][tr2["scene"] == 1].tolist() == [5]


def test_no_usable_instance_is_a_clear_error():
    with pytest.raises(ConfigError, match="no labelled instance"):
        labelled_samples(np.zeros((50, 3)), np.full(50, 5), np.ones(50))


def test_train_from_a_labelled_scan_and_run_with_its_weights(labelled, tmp_path):
    d = labelled
    proc = _cli("train", "--from", str(d / "lab.laz"), "--no-synthetic", "--config", str(d / "cfg.yaml"),
                "--out", str(tmp_path / "mine.pt"), "--no-progress")
    assert proc.returncode == 0, proc.stderr
    assert "training and" in proc.stdout
    info = json.loads((tmp_path / "mine.json").read_text())
    assert info["labelled"][0]["source"].endswith("lab.laz")
    assert info["labelled"][0]["train_samples"] > 0
    assert info["datasets"] == {}
    wf = tmp_path / "wf.yaml"
    wf.write_text(f"input: {{files: [{d / 'lab.laz'}]}}\nstore: {tmp_path / 's.zarr'}\n"
                  f"coarse: {{min_support: 300}}\ntree: {{weights: {tmp_path / 'mine.pt'}}}\n"
                  "cluster: {scheduler: sync}\n")
    run = _cli("run", str(wf), "--no-progress")
    assert run.returncode == 0, run.stderr
    assert "labels:" in run.stdout


def test_fit_split_from_a_labelled_scan_and_run_with_the_model(labelled, tmp_path):
    d = labelled
    arcade = tmp_path / "arcade.laz"
    assert _cli("synth", "arcade", "--seed", "1", "--points", "150000", "--out", str(arcade),
                "--no-progress").returncode == 0
    proc = _cli("fit-split", "--from", str(arcade), "--no-synthetic", "--work", str(tmp_path / "work"),
                "--out", str(tmp_path / "split.json"), "--no-progress")
    assert proc.returncode == 0, proc.stderr
    assert "0 procedural sites and 1 labelled scans" in proc.stdout
    model = json.loads((tmp_path / "split.json").read_text())
    assert model["info"]["files"] == [str(arcade)]
    wf = tmp_path / "wf.yaml"
    wf.write_text(f"input: {{files: [{d / 'lab.laz'}]}}\nstore: {tmp_path / 's.zarr'}\n"
                  f"tree: {{split_model: {tmp_path / 'split.json'}}}\ncluster: {{scheduler: sync}}\n")
    run = _cli("run", str(wf), "--no-progress")
    assert run.returncode == 0, run.stderr
    missing = tmp_path / "wf2.yaml"
    missing.write_text(wf.read_text().replace("split.json", "nope.json"))
    bad = _cli("run", str(missing), "--no-progress")
    assert bad.returncode == 2
    assert f"tree.split_model: file {tmp_path / 'nope.json'} does not exist" in bad.stderr


def test_fit_split_on_scans_without_a_right_split_is_one_line(tmp_path):
    """A scan whose groups give no right split (a lone minaret: every cut of it is wrong)
    cannot make a split model: one line, exit 2, no file written."""
    scan = tmp_path / "minaret.laz"
    assert _cli("synth", "minaret", "--seed", "2", "--points", "60000", "--out", str(scan),
                "--no-progress").returncode == 0
    proc = _cli("fit-split", "--from", str(scan), "--no-synthetic", "--work", str(tmp_path / "work"),
                "--out", str(tmp_path / "split.json"), "--no-progress")
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [
        next(line for line in proc.stderr.splitlines() if "split proposals, 0 of them right" in line)]
    assert not (tmp_path / "split.json").exists()


def test_classification_with_a_class_map_and_a_named_instance_dim(labelled, tmp_path):
    src = laspy.read(labelled / "lab.laz")
    codes = {1: 2, 2: 6, 3: 6, 5: 65, 7: 67, 8: 1}  # hollowtree class -> LAS code
    header = laspy.LasHeader(point_format=6, version="1.4")
    header.add_extra_dims([laspy.ExtraBytesParams("object_id", np.uint32)])
    header.scales, header.offsets = src.header.scales, src.header.offsets
    las = laspy.LasData(header)
    las.x, las.y, las.z = src.x, src.y, src.z
    gt = np.asarray(src.gt_class)
    las.classification = np.array([codes.get(int(c), 1) for c in range(9)], dtype=np.uint8)[gt]
    las.object_id = np.asarray(src.gt_instance)
    las.write(tmp_path / "mine.las")
    proc = _cli("train", "--from", str(tmp_path / "mine.las"), "--class-dim", "classification",
                "--instance-dim", "object_id", "--class-map", "2=ground,6=wall,65=dome,67=pillar",
                "--no-synthetic", "--config", str(labelled / "cfg.yaml"), "--out", str(tmp_path / "w.pt"),
                "--no-progress")
    assert proc.returncode == 0, proc.stderr


@pytest.mark.parametrize(("args", "message"), [
    (["--instance-dim", "tree_id"], "no dimension 'tree_id'"),
    (["--class-map", "2=ground,6=castle"], "--class-map: '6=castle' is not CODE=CLASS"),
    (["--class-dim", "gt_instance"], "not a hollowtree class id"),
])
def test_bad_labelled_input_is_one_line_exit_2(labelled, tmp_path, args, message):
    proc = _cli("train", "--from", str(labelled / "lab.laz"), *args, "--no-synthetic", "--out",
                str(tmp_path / "w.pt"), "--no-progress")
    assert proc.returncode == 2
    assert len(proc.stderr.strip().splitlines()) == 1
    assert message in proc.stderr


def test_no_synthetic_needs_a_labelled_scan(tmp_path):
    proc = _cli("train", "--no-synthetic", "--out", str(tmp_path / "w.pt"))
    assert proc.returncode == 2
    assert "--no-synthetic needs at least one --from FILE" in proc.stderr


def test_the_split_model_fits_on_training_seeds_only(tmp_path):
    from hollowtree.pipeline.split_fit import procedural_groups

    with pytest.raises(ConfigError, match="procedural seed 200000 is not a training seed"):
        procedural_groups(200_000, tmp_path)


def test_fit_split_draws_each_procedural_sites_points_from_a_range(tmp_path, monkeypatch):
    """``fit-split --procedural-points MIN MAX`` scans each site at the count its seed draws
    (``site_points``), as ``bench_generalize --points MIN MAX`` does; a reversed range is one line."""
    from hollowtree.pipeline import split_fit
    from hollowtree.scenes.procedural import site_points

    asked = []

    def groups(seed, work, *, n_points):
        asked.append((seed, n_points))
        raise RuntimeError("stop here")

    monkeypatch.setattr(split_fit, "procedural_groups", groups)
    with pytest.raises(RuntimeError, match="stop here"):
        split_fit.fit_split_from_scenes(tmp_path, scenes=(), procedural=(4,), procedural_points=(500_000, 20_000_000))
    assert asked == [(4, site_points(4, 500_000, 20_000_000))]
    assert 500_000 <= asked[0][1] <= 20_000_000
    assert site_points(4, 3e6, 3e6) == 3_000_000
    assert {site_points(s, 5e5, 2e7) for s in range(20)} != {asked[0][1]}  # the seed draws it
    proc = _cli("fit-split", "--procedural", "2", "--procedural-points", "900000", "800000",
                "--out", str(tmp_path / "s.json"))
    assert proc.returncode == 2
    assert len(proc.stderr.strip().splitlines()) == 1
    assert "--procedural-points takes N or MIN MAX with MIN <= MAX; got 900000 800000" in proc.stderr


def test_train_draws_each_procedural_sites_points_from_a_range(tmp_path, monkeypatch):
    """``train --procedural-points MIN MAX`` cuts each site's samples from a scan at the count
    its seed draws, the count ``fit-split`` scans it at; one number stays one count."""
    from hollowtree.pipeline import cli, hollownet_cmd
    from hollowtree.scenes.procedural import site_points

    asked = []

    def samples(site_seed, n_points, cache, **kw):
        asked.append((site_seed, n_points))
        raise RuntimeError("stop here")

    monkeypatch.setattr(hollownet_cmd, "procedural_samples", samples)
    for pts in (["500000", "20000000"], ["700000"]):
        with pytest.raises(RuntimeError, match="stop here"):
            cli.main(["train", "--procedural", "3", "--procedural-points", *pts, "--data-dir", str(tmp_path),
                      "--out", str(tmp_path / "w.pt")])
    assert asked == [(0, site_points(0, 500_000, 20_000_000)), (0, 700_000)]
    proc = _cli("train", "--procedural", "2", "--procedural-points", "5", "6", "7", "--out", str(tmp_path / "w.pt"))
    assert proc.returncode == 2
    assert proc.stderr.strip() == "hollowtree train: error: --procedural-points takes N or MIN MAX with MIN <= MAX; got 5 6 7"


def test_procedural_samples_are_the_ones_train_from_takes_of_the_same_scan(tmp_path):
    """``train --procedural N`` cuts the samples ``--from`` cuts from the same procedural
    scan (cached once), and takes training seeds only."""
    from hollowtree.pipeline.hollownet_cmd import procedural_samples, read_labelled
    from hollowtree.scenes.procedural import GENERATOR, scan_draw
    from hollowtree.scenes.synth import synth

    with pytest.raises(ConfigError, match="procedural seed 100000 is not a training seed"):
        procedural_samples(100_000, 50_000, tmp_path, seed=0, variants=1)
    name, tr, te = procedural_samples(3, 60_000, tmp_path, seed=0, variants=1)
    assert (tmp_path / "procedural" / f"samples-{GENERATOR}-3-60000-s0-v1.npz").is_file()
    d = scan_draw(3)
    synth("gen", tmp_path / name, n_points=60_000, seed=3, noise=d.noise, registration_error=d.registration_error,
          workers=2)
    xyz, _, cls, inst = read_labelled(tmp_path / name, "gt_class", "gt_instance")
    tr2, te2 = labelled_samples(xyz, cls, inst, seed=0, variants=1, source=name)
    assert len(tr["labels"]) > 0
    for a, b in ((tr, tr2), (te, te2)):
        np.testing.assert_array_equal(a["labels"], b["labels"])
        np.testing.assert_array_equal(a["grids"], b["grids"])
    again = procedural_samples(3, 60_000, tmp_path, seed=0, variants=1)[1]  # from the cache
    np.testing.assert_array_equal(again["grids"], tr["grids"])
    proc = _cli("train", "--procedural", "-1", "--out", str(tmp_path / "w.pt"))
    assert proc.returncode == 2
    assert "--procedural must be a count >= 0" in proc.stderr
