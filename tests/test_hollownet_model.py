"""HollowNet layers, K from the vocabulary, shipped weights, refused checkpoints."""

from __future__ import annotations

import json

import pytest
import torch

from hollowtree.classes import ELEMENT_CLASSES, NUM_CLASSES, PLANAR_CLASSES, ClassId
from hollowtree.errors import InputFileError
from hollowtree.hollownet.model import (
    DEFAULT_WEIGHTS,
    NUM_OUTPUTS,
    OUTPUT_CLASSES,
    HollowNet,
    WeightsError,
    get_model,
    load_checkpoint,
    load_model,
    save_checkpoint,
)


def test_k_comes_from_the_vocabulary():
    assert NUM_OUTPUTS == len(ELEMENT_CLASSES) + len(PLANAR_CLASSES) + 1 == NUM_CLASSES - 1
    assert ClassId.UNCLASSIFIED not in OUTPUT_CLASSES
    assert ClassId.OTHER in OUTPUT_CLASSES
    assert list(OUTPUT_CLASSES) == sorted(OUTPUT_CLASSES)


def test_small_grid_forward_and_backward():
    torch.manual_seed(0)
    net = HollowNet(widths=(4, 8), hidden=16, num_classes=NUM_OUTPUTS, grid_size=16)
    x = torch.randn(1, 1, 16, 16, 16, requires_grad=True)
    out = net(x)
    assert out.shape == (1, NUM_OUTPUTS)
    out.sum().backward()
    assert x.grad is not None
    assert all(p.grad is not None for p in net.parameters())


def test_paper_layers():
    net = get_model("hollownet_v1")
    convs = [m for m in net.modules() if isinstance(m, torch.nn.Conv3d)]
    assert [(c.out_channels, c.kernel_size, c.stride) for c in convs] == [
        (32, (5, 5, 5), (1, 1, 1)), (64, (5, 5, 5), (2, 2, 2))]
    assert sum(isinstance(m, torch.nn.LeakyReLU) for m in net.features) == 2
    fcs = [m for m in net.modules() if isinstance(m, torch.nn.Linear)]
    assert len(fcs) == 2
    assert fcs[-1].out_features == NUM_OUTPUTS
    with torch.inference_mode():
        assert net(torch.zeros(3, 1, 30, 30, 30)).shape == (3, NUM_OUTPUTS)
    with pytest.raises(WeightsError, match="unknown HollowNet architecture"):
        get_model("resnet")


def test_shipped_weights_are_small_and_load():
    assert DEFAULT_WEIGHTS.is_file()
    assert DEFAULT_WEIGHTS.stat().st_size < 8 * 1024 * 1024
    model, meta = load_model()
    assert not model.training
    assert meta["seed"] == 0
    assert meta["canonical_yaw"] is True
    assert meta["grid_size"] == 30
    report = json.loads(DEFAULT_WEIGHTS.with_suffix(".json").read_text())
    assert report["classes"] == [c.label for c in OUTPUT_CLASSES]
    assert report["test_accuracy"] >= 0.95


def _rewrite(src, dst, **changes):
    ck = torch.load(src, map_location="cpu", weights_only=True)
    ck.update(changes)
    torch.save(ck, dst)


def test_other_k_or_version_is_refused(tmp_path):
    good = tmp_path / "good.pt"
    save_checkpoint(good, get_model("hollownet_v1"), arch="hollownet_v1", meta={"seed": 1})
    assert load_checkpoint(good)["meta"] == {"seed": 1}

    seven = tmp_path / "seven.pt"
    _rewrite(good, seven, classes=["bench", "car", "bicycle", "arch", "dome", "minaret", "pillar"])
    with pytest.raises(WeightsError, match=r"K=7 classes.*needs K=8"):
        load_model(seven)
    v2 = tmp_path / "v2.pt"
    _rewrite(good, v2, version=2)
    with pytest.raises(WeightsError, match="version 2; this hollowtree reads version 1"):
        load_model(v2)
    arch = tmp_path / "arch.pt"
    _rewrite(good, arch, arch="hollownet_v9")
    with pytest.raises(WeightsError, match="hollownet_v9"):
        load_model(arch)
    junk = tmp_path / "junk.pt"
    junk.write_bytes(b"not a checkpoint")
    with pytest.raises(WeightsError, match="not a HollowNet checkpoint"):
        load_model(junk)
    with pytest.raises(InputFileError, match="no such weights file"):
        load_model(tmp_path / "missing.pt")
    small = tmp_path / "small.pt"
    save_checkpoint(small, HollowNet(widths=(4, 8), hidden=16), arch="hollownet_v1", meta={})
    with pytest.raises(WeightsError, match="do not fit architecture"):
        load_model(small)
