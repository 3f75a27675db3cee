"""``benchmarks/bench_generalize.py``: which procedural seeds a run takes."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("hollowtree_bench_generalize", REPO / "benchmarks" / "bench_generalize.py")
bench = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(bench)


def test_seeds_after_the_first_ones_of_the_split():
    assert bench.pick_seeds("test", 3, skip=30) == [200030, 200031, 200032]


def test_several_families_take_as_many_seeds_each_after_their_own_first_ones():
    from hollowtree.scenes.procedural import family_of

    seeds = bench.pick_seeds("val", 6, skip=4, families=["courtyard_mosque", "pavilion_garden", "monument"])
    assert seeds == sorted(seeds)
    assert len(seeds) == 18
    assert sorted({family_of(s) for s in seeds}) == ["courtyard_mosque", "monument", "pavilion_garden"]
    assert min(seeds) >= 100028  # the first 28 validation seeds hold the first 4 of every family


def test_an_unknown_family_is_refused_by_the_command_line(capsys):
    with pytest.raises(SystemExit) as e:
        bench.main(["--family", "cathedral"])
    assert e.value.code == 2
    assert "cathedral" in capsys.readouterr().err
