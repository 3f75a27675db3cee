"""``hollowtree train`` / ``hollowtree classify`` (pipeline/hollownet_cmd.py, through the CLI)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from plyfile import PlyData, PlyElement

from hollowtree.classes import CLASS_NAMES
from hollowtree.pipeline.cli import main
from hollowtree.pipeline.cli import main as hollowtree
from hollowtree.pipeline.coarse import CoarseParams, run_coarse
from hollowtree.pipeline.graph import task_runner
from hollowtree.pipeline.hollownet_cmd import _csr_points_from_tiles
from hollowtree.scenes.synth import synth
from hollowtree.tiling.ingest import IngestParams, ingest
from hollowtree.tiling.store import RunStore


def _write_ply(path, xyz):
    v = np.array([tuple(p) for p in xyz], dtype=[("x", "f8"), ("y", "f8"), ("z", "f8")])
    PlyData([PlyElement.describe(v, "vertex")]).write(str(path))


def _one_error_line(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "Traceback" not in err
    return err


def test_classify_a_segment_file(tmp_path, capsys):
    rng = np.random.default_rng(0)
    t = rng.uniform(0, 2 * np.pi, 3000)
    shaft = np.c_[0.3 * np.cos(t), 0.3 * np.sin(t), rng.uniform(0, 5, 3000)] + [1000.0, 2000.0, 50.0]
    path = tmp_path / "seg.ply"
    _write_ply(path, shaft)
    assert main(["classify", str(path), "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert len(rows) == 1
    assert rows[0]["n_points"] == 3000
    assert rows[0]["class"] in CLASS_NAMES
    assert 0 < rows[0]["score"] <= 1


def test_classify_degenerate_and_missing_input(tmp_path, capsys):
    path = tmp_path / "one.ply"
    _write_ply(path, [[1.0, 2.0, 3.0]])
    assert main(["classify", str(path)]) == 0
    out = capsys.readouterr().out
    assert "other" in out
    assert "0.000" in out
    assert "degenerate" in out
    assert main(["classify", str(tmp_path / "missing.laz")]) == 2
    assert "no such file" in _one_error_line(capsys)
    bad = tmp_path / "bad.ply"
    bad.write_text("not a ply file")
    assert main(["classify", str(bad)]) == 2
    _one_error_line(capsys)
    weights = tmp_path / "w.pt"
    weights.write_bytes(b"junk")
    assert main(["classify", str(path), "--weights", str(weights)]) == 2
    assert "not a HollowNet checkpoint" in _one_error_line(capsys)


def test_classify_a_run_store(tmp_path, capsys):
    scan = tmp_path / "pillar.laz"
    synth("pillar", scan, n_points=20_000, seed=3)
    store = tmp_path / "store"
    with task_runner("sync", progress=False) as run:
        ingest([str(scan)], str(store), IngestParams(tile_size=500.0, buffer=2.0), runner=run)
        assert main(["classify", str(store)]) == 2  # no coarse segments yet
        assert "hollowtree coarse" in _one_error_line(capsys)
        report = run_coarse(str(store), CoarseParams(eps=0.3), runner=run)
    assert hollowtree(["classify", str(store), "--json"]) == 0  # as wired into pipeline/cli.py
    rows = json.loads(capsys.readouterr().out)
    assert len(rows) == report.n_segments > 0
    assert sum(r["n_points"] for r in rows) > 10_000
    assert all(r["class"] in CLASS_NAMES for r in rows)
    # the coordinates stored with the CSR are those of the tiles' core rows
    s = RunStore.open(store)
    scale = np.asarray(s.attrs["coords"]["scale"])
    from_tiles = _csr_points_from_tiles(s, store, scale)
    np.testing.assert_array_equal(from_tiles, s.read_slice("coarse/csr/xyz").astype(np.float64) * scale)


@pytest.mark.parametrize(("text", "message"), [
    ("epochz: 3\n", "unknown training config keys"),
    ("amp: 'false'\n", "'amp' parameter"),
    ("[1, 2]\n", "mapping"),
    ("a: [\n", "not valid YAML"),
])
def test_train_config_errors(tmp_path, capsys, text, message):
    cfg = tmp_path / "c.yaml"
    cfg.write_text(text)
    assert main(["train", "--config", str(cfg), "--out", str(tmp_path / "w.pt"), "--no-progress"]) == 2
    assert message in _one_error_line(capsys)


def test_train_usage_errors(tmp_path, capsys):
    assert main(["train", "--config", str(tmp_path / "none.yaml")]) == 2
    assert "no such config file" in _one_error_line(capsys)
    assert main(["train", "--epochs", "0"]) == 2
    assert main(["train", "--device", "tpu"]) == 2
