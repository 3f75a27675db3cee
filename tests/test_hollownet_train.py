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


def test_a_contaminated_sample_takes_the_nearest_strip_of_one_neighbour():
    from hollowtree.hollownet.dataset import _with_neighbour

    rng = np.random.default_rng(3)
    # an element (instance 1, a 1 m column) between a wall (2) touching it and a far wall (3)
    col = np.c_[rng.uniform(-0.2, 0.2, (2000, 2)), rng.uniform(0, 3, 2000)]
    wall = np.c_[rng.uniform(0.25, 4.0, 3000), rng.uniform(-1, 1, 3000), rng.uniform(0, 3, 3000)]
    far = np.c_[rng.uniform(-9, -8, 500), rng.uniform(-1, 1, 500), rng.uniform(0, 3, 500)]
    xyz = np.concatenate([col, wall, far])
    inst = np.r_[np.full(2000, 1), np.full(3000, 2), np.full(500, 3)]
    out = _with_neighbour(col, xyz, inst, 1, rng)
    added = out[len(col):]
    assert (out[:len(col)] == col).all()
    assert 0.03 * len(col) - 1 <= len(added) <= 0.25 * len(col) + 1
    assert (added[:, 0] >= 0.25).all()  # wall points only, none of the far wall
    # the nearest of the wall's points: none left out is nearer the column than one taken
    from scipy.spatial import cKDTree

    taken = {tuple(p) for p in added}
    rest = np.array([p for p in wall if tuple(p) not in taken])
    near = cKDTree(col)
    assert near.query(rest)[0].min() >= near.query(added)[0].max()
    # nothing within reach: the sample unchanged
    alone = _with_neighbour(col, np.concatenate([col, far]), np.r_[np.full(2000, 1), np.full(500, 3)], 1, rng)
    assert len(alone) == len(col)


def test_contamination_is_off_by_default_and_keeps_the_old_cache_and_fingerprint():
    assert DatasetParams().contaminate == 0.0
    p = DatasetParams(seed=0, n_per_class=2, variants=2)
    assert p.key() != DatasetParams(seed=0, n_per_class=2, variants=2, contaminate=0.4).key()
    assert TrainConfig().fingerprint() != TrainConfig(contaminate=0.4).fingerprint()
    # the test set is never contaminated, so test accuracies stay comparable
    train_set, test_set = TrainConfig(contaminate=0.4).datasets()
    assert train_set.contaminate == 0.4
    assert test_set.contaminate == 0.0
    with pytest.raises(ConfigError):
        TrainConfig.from_dict({"contaminate": 1.5})
