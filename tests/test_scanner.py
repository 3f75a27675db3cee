"""The virtual scanner: occlusion, range-dependent density, noise, hollow surfaces."""

from __future__ import annotations

import numpy as np
import pytest

from hollowtree.classes import ClassId
from hollowtree.errors import ConfigError
from hollowtree.scenes.scanner import ScanParams, range_sigma, scan
from hollowtree.scenes.sites import build_scene


def test_noise_matches_setting(scan_of):
    noise = 0.004
    s = scan_of("plane_wall", step_deg=0.1, noise=noise, n_stations=1)
    st = s.stations[0]
    # Front face of the wall is the plane y = 10; residuals along its normal.
    sel = (s.gt_class == ClassId.WALL) & (np.abs(s.xyz[:, 1] - 10.0) < 0.1)
    p = s.xyz[sel]
    assert len(p) > 20_000
    ray = p - st
    r = np.linalg.norm(ray, axis=1)
    expected = range_sigma(r, noise) * np.abs(ray[:, 1] / r)
    z = (p[:, 1] - 10.0) / expected
    assert abs(np.mean(z)) < 0.05
    assert np.std(z) == pytest.approx(1.0, abs=0.05)


def test_noise_free_scan_lies_on_the_surface(scan_of):
    s = scan_of("plane_wall", step_deg=0.2, noise=0.0, n_stations=1)
    sel = (s.gt_class == ClassId.WALL) & (np.abs(s.xyz[:, 1] - 10.0) < 0.1)
    # Only the 1 mm coordinate grid remains.
    assert np.abs(s.xyz[sel, 1] - 10.0).max() <= 0.0005 + 1e-9


def test_density_falls_with_range(scan_of):
    s = scan_of("plane_wall", step_deg=0.1, n_stations=1)
    st = s.stations[0]
    g = s.xyz[s.gt_class == ClassId.GROUND]
    d = np.linalg.norm(g[:, :2] - st[:2], axis=1)
    behind = g[:, 1] < st[1]  # the half-plane the wall does not shadow
    densities = []
    for lo, hi in [(3, 4), (6, 7), (12, 13)]:
        ring = behind & (d >= lo) & (d < hi)
        densities.append(ring.sum() / (0.5 * np.pi * (hi**2 - lo**2)))
    assert densities[0] > 2 * densities[1] > 4 * densities[2] > 0


def test_nothing_behind_walls_is_scanned(scan_of):
    s = scan_of("occluded", step_deg=0.25)
    assert len(s.xyz) > 10_000
    assert not np.any(s.gt_class == ClassId.PILLAR)
    assert np.any(s.gt_class == ClassId.WALL)


def test_dome_inner_and_outer_surfaces_are_sampled(scan_of):
    s = scan_of("dome", step_deg=0.2)
    dome = s.gt_class == ClassId.DOME
    xy = s.xyz[dome, :2]
    centre = (xy.min(axis=0) + xy.max(axis=0)) / 2
    # A station standing under the dome sees its inner surface ...
    under = np.linalg.norm(s.stations[:, :2] - centre, axis=1) < 2.0
    assert under.any(), "the dome scene needs a station inside under the dome"
    inner = dome & np.isin(s.station, np.flatnonzero(under))
    outer = dome & ~np.isin(s.station, np.flatnonzero(under))
    assert inner.sum() > 1000
    assert outer.sum() > 1000
    # ... which lies inside the outer one: compare radii at the same heights.
    z = s.xyz[:, 2]
    band = (z > np.quantile(z[dome], 0.5)) & (z < np.quantile(z[dome], 0.7))
    rad = np.linalg.norm(s.xyz[:, :2] - centre, axis=1)
    assert np.median(rad[inner & band]) < np.median(rad[outer & band]) - 0.05


def test_scan_does_not_depend_on_workers():
    scene = build_scene("minaret", rng=3)
    params = ScanParams(step_deg=0.5, seed=3)
    one = list(scan(scene, params, workers=1))
    two = list(scan(scene, params, workers=2, chunk_rays=50_000))
    a = np.concatenate([c.xyz for c in one])
    b = np.concatenate([c.xyz for c in two])
    assert a.shape == b.shape
    assert np.array_equal(a, b)


def test_registration_error_moves_stations_rigidly():
    scene = build_scene("plane_wall", rng=0)
    exact = np.concatenate([c.xyz for c in scan(scene, ScanParams(step_deg=0.5, noise=0.0))])
    moved = np.concatenate(
        [c.xyz for c in scan(scene, ScanParams(step_deg=0.5, noise=0.0, registration_error=0.02))]
    )
    shift = np.linalg.norm(moved - exact, axis=1)
    assert 0.001 < np.median(shift) < 0.2


@pytest.mark.parametrize(
    "kwargs",
    [{"step_deg": 0.0}, {"step_deg": 1.0, "noise": -1.0}, {"step_deg": 1.0, "n_stations": 0}],
)
def test_bad_scan_params(kwargs):
    with pytest.raises(ConfigError):
        ScanParams(**kwargs)
