"""Training: data set cache, one tiny epoch, resume equals uninterrupted, reports, refusals."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from hollowtree.errors import ConfigError, OutputExistsError
from hollowtree.hollownet.dataset import DatasetParams, build_dataset, load_dataset
from hollowtree.hollownet.model import OUTPUT_CLASSES, load_checkpoint, load_model
from hollowtree.hollownet.train import TrainConfig, train


@pytest.fixture(scope="module")
def data_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("hollownet-data")


def _config(data_dir, **kw) -> TrainConfig:
    base = {"n_train": 2, "n_test": 2, "variants": 2, "epochs": 2, "batch_size": 8, "amp": False,
            "threads": 1, "data_dir": str(data_dir)}
    return TrainConfig(**{**base, **kw})


def test_dataset_is_seeded_and_cached(data_dir):
    p = DatasetParams(seed=0, split="test", n_per_class=2, variants=2)
    folder = build_dataset(data_dir, p)
    info = json.loads((folder / "manifest.json").read_text())
    assert info["counts"] == {c.label: 2 for c in OUTPUT_CLASSES}
    d = load_dataset(folder)
    assert d["grids"].shape == (2 * len(OUTPUT_CLASSES), 30, 30, 30)
    assert d["grids"].dtype == bool
    assert sorted(set(d["labels"].tolist())) == [int(c) for c in OUTPUT_CLASSES]
    assert (d["grids"].reshape(len(d["grids"]), -1).sum(axis=1) > 20).all()  # no empty grids
    mtime = (folder / "manifest.json").stat().st_mtime_ns
    assert build_dataset(data_dir, p) == folder  # cached: not made again
    assert (folder / "manifest.json").stat().st_mtime_ns == mtime
    # the splits of one seed share no scene draw: other grids (the training run below
    # reuses this cached "train" split)
    other = load_dataset(build_dataset(data_dir, DatasetParams(seed=0, split="train", n_per_class=2, variants=2)))
    assert not any((g == d["grids"]).all() for g in other["grids"])


def test_resume_equals_uninterrupted(data_dir, tmp_path):
    straight = train(_config(data_dir), out=tmp_path / "a.pt", progress=False)
    assert straight.epochs == 2
    assert straight.resumed_from == 0
    first = train(_config(data_dir, epochs=1), out=tmp_path / "b.pt", progress=False)
    assert first.epochs == 1
    ck = load_checkpoint(tmp_path / "b.pt.ckpt")
    assert ck["meta"]["epoch"] == 1
    assert "optimizer" in ck
    resumed = train(_config(data_dir), out=tmp_path / "b.pt", resume=True, progress=False)
    assert resumed.resumed_from == 1
    a, _ = load_model(tmp_path / "a.pt")
    b, meta = load_model(tmp_path / "b.pt")
    for (k, va), vb in zip(a.state_dict().items(), b.state_dict().values(), strict=True):
        torch.testing.assert_close(va, vb, rtol=1e-5, atol=1e-6, msg=k)
    assert [h["epoch"] for h in meta["history"]] == [1, 2]
    assert meta["confusion"] == resumed.confusion
    assert np.sum(resumed.confusion) == 2 * len(OUTPUT_CLASSES)
    # the reports beside the weights
    report = json.loads((tmp_path / "b.json").read_text())
    assert report["classes"] == [c.label for c in OUTPUT_CLASSES]
    assert report["seed"] == 0
    assert (tmp_path / "b.confusion.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    table = (tmp_path / "b.confusion.txt").read_text()
    assert "recall" in table
    assert all(c.label in table for c in OUTPUT_CLASSES)
    assert "test accuracy" in resumed.summary()


def test_refusals(data_dir, tmp_path):
    out = tmp_path / "w.pt"
    out.write_bytes(b"x")
    with pytest.raises(OutputExistsError, match="--overwrite"):
        train(_config(data_dir), out=out, progress=False)
    with pytest.raises(ConfigError, match="nothing to resume"):
        train(_config(data_dir), out=out, resume=True, progress=False)
    train(_config(data_dir, epochs=1), out=out, overwrite=True, progress=False)
    with pytest.raises(ConfigError, match="other training settings"):
        train(_config(data_dir, lr=0.01), out=out, resume=True, progress=False)
    with pytest.raises(ConfigError, match="unknown training config keys"):
        TrainConfig.from_dict({"epochz": 3})
    with pytest.raises(ConfigError, match="'amp' parameter"):
        TrainConfig.from_dict({"amp": "false"})
    with pytest.raises(ConfigError, match="'epochs' parameter"):
        TrainConfig(epochs=0)
    with pytest.raises(ConfigError, match="does not exist"):
        train(_config(data_dir), out=tmp_path / "no" / "w.pt", progress=False)
