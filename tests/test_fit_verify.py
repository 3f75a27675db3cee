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
