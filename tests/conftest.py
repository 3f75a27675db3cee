"""Shared fixtures: small seeded scans made once per test session."""

from __future__ import annotations

from pathlib import Path

import laspy
import numpy as np
import pytest

from hollowtree.scenes.synth import read_scan_metadata, synth

REPO = Path(__file__).resolve().parents[1]
EXTERNAL = REPO.parent / "shared" / "data" / "external"


class Scan:
    """A synthetic scan read back from disk."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.las = laspy.read(path)
        self.meta = read_scan_metadata(path)
        origin = np.asarray(self.meta["survey_origin"])
        self.xyz = np.stack([self.las.x, self.las.y, self.las.z], axis=1) - origin
        self.stations = np.asarray(self.meta["stations"]) - origin
        self.gt_class = np.asarray(self.las.gt_class)
        self.gt_instance = np.asarray(self.las.gt_instance)
        self.station = np.asarray(self.las.point_source_id).astype(np.int64) - 1


@pytest.fixture(scope="session")
def scan_of(tmp_path_factory: pytest.TempPathFactory):
    """``scan_of(site, **kwargs)`` -> Scan; each distinct call is generated once."""
    cache: dict[tuple, Scan] = {}
    root = tmp_path_factory.mktemp("scans")

    def make(site: str, **kwargs) -> Scan:
        key = (site, tuple(sorted(kwargs.items())))
        if key not in cache:
            out = root / f"{site}-{len(cache)}.laz"
            synth(site, out, **kwargs)
            cache[key] = Scan(out)
        return cache[key]

    return make
