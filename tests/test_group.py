"""Element groups: the contacts kernel (the stage's groups: tests/test_coarse.py)."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.coarse import CoarseParams
from primitives.group import segment_contacts
from tiling.errors import ConfigError


def _ring(n: int, r: float, z: float, rng: np.random.Generator) -> np.ndarray:
    t = rng.uniform(0, 2 * np.pi, n)
    return np.c_[r * np.cos(t), r * np.sin(t), z + rng.uniform(0, 1, n)]


def test_contacts_find_touching_segments_only():
    rng = np.random.default_rng(0)
    lower, upper = _ring(3000, 1.0, 0.0, rng), _ring(3000, 1.0, 1.1, rng)  # 0.1 m apart
    far = _ring(3000, 1.0, 5.0, rng)
    xyz = np.r_[lower, upper, far]
    seg = np.repeat([3, 1, 2], 3000)
    a, b, n = segment_contacts(xyz, seg, 0.3)
    assert (a.tolist(), b.tolist()) == ([1], [3])
    assert n[0] >= 3
    assert segment_contacts(xyz, seg, 0.05)[0].size == 0  # closer than the gap: none
    # unsegmented points (0) never make a contact, a single segment has none
    assert segment_contacts(xyz, np.where(seg == 2, 0, 1), 0.3)[0].size == 0


def test_contacts_need_min_contacts():
    xyz = np.array([[0.0, 0, 0], [0.2, 0, 0], [5.0, 0, 0], [5.2, 0, 0]])
    seg = np.array([1, 2, 3, 4])
    assert segment_contacts(xyz, seg, 0.3, min_contacts=1)[0].tolist() == [1, 3]
    assert segment_contacts(xyz, seg, 0.3, min_contacts=2)[0].size == 0


@pytest.mark.parametrize("bad", [0.0, -1.0, float("nan")])
def test_contacts_refuse_a_bad_gap(bad):
    with pytest.raises(ConfigError, match="gap"):
        segment_contacts(np.zeros((2, 3)), np.array([1, 2]), bad)


def test_group_params_are_validated():
    with pytest.raises(ConfigError, match="group_gap"):
        CoarseParams(group_gap=-0.1)
    with pytest.raises(ConfigError, match="group_min_contacts"):
        CoarseParams(group_min_contacts=0)
    with pytest.raises(ConfigError, match="group_max_plane"):
        CoarseParams(group_max_plane=0.0)
