"""Operators of the tree (v1, psi, p, u, h, v2, rho) and the energy terms, on toy data."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hollowtree.tree.energy import e1, e2, e3, e4, e5, energy_terms
from hollowtree.tree.operators import (
    TransportCurve,
    _occupied,
    fit_circle,
    h,
    p,
    plateaus,
    psi,
    rho,
    split_at,
    u,
    v1,
    v2,
)
from hollowtree.tree.sequences import SequenceParams, s1, s2, s3, storeys


def _ring(rng, *, center=(0.0, 0.0), radius=1.0, n=500, noise=0.0, arc=(0.0, 2 * math.pi)):
    t = rng.uniform(*arc, n)
    xy = np.column_stack([center[0] + radius * np.cos(t), center[1] + radius * np.sin(t)])
    return xy + rng.normal(0.0, noise, xy.shape)


def _polygon(rng, *, n_sides, apothem, center, angle, n=800, noise=0.0):
    r = apothem / math.cos(math.pi / n_sides)
    a = angle - math.pi / n_sides + 2 * math.pi * np.arange(n_sides) / n_sides  # corners
    corners = np.column_stack([center[0] + r * np.cos(a), center[1] + r * np.sin(a)])
    k = rng.integers(0, n_sides, n)
    s = rng.uniform(0, 1, n)[:, None]
    xy = corners[k] * (1 - s) + corners[(k + 1) % n_sides] * s
    return xy + rng.normal(0.0, noise, xy.shape)


def test_v1_drops_z_and_leaves_input():
    xyz = np.arange(12, dtype=float).reshape(4, 3)
    before = xyz.copy()
    assert v1(xyz).tolist() == xyz[:, :2].tolist()
    assert np.array_equal(xyz, before)


def test_circle_ransac_recovers_centre_and_radius_with_outliers():
    rng = np.random.default_rng(1)
    xy = np.vstack([_ring(rng, center=(3.0, -2.0), radius=4.0, noise=0.01),
                    rng.uniform(-5, 10, (150, 2))])  # 23 % outliers
    c = fit_circle(xy, rng=0)
    assert c
    assert np.allclose(c.center, (3.0, -2.0), atol=0.01)
    assert c.radius == pytest.approx(4.0, abs=0.01)
    assert c.inlier_fraction > 0.7


@pytest.mark.parametrize("n_sides", [6, 8])
def test_ngon_ransac_recovers_polygon(n_sides):
    rng = np.random.default_rng(2)
    xy = _polygon(rng, n_sides=n_sides, apothem=2.5, center=(1.0, 1.5), angle=0.3, noise=0.005)
    g = psi(xy, rng=0)
    assert g
    assert g.n_sides == n_sides
    assert np.allclose(g.center, (1.0, 1.5), atol=0.02)
    assert g.radius == pytest.approx(2.5, abs=0.02)
    step = 2 * math.pi / n_sides
    assert abs((g.angle - 0.3 + step / 2) % step - step / 2) < 0.01
    # Every point of the prism's sides is at the apothem in the polygon's metric.
    assert np.abs(g.distance(xy) - 2.5).max() < 0.05


def test_psi_on_a_large_footprint_fits_its_sample_and_stays_accurate():
    """Over 2048 points psi fits a random sample; the curve must stay as exact."""
    rng = np.random.default_rng(12)
    xy = _polygon(rng, n_sides=8, apothem=2.0, center=(-3.0, 4.0), angle=0.2, n=60_000, noise=0.005)
    clutter = rng.uniform(-5.2, -0.8, (3000, 2)) + [0.0, 6.0]  # 5 %, inside the footprint's box
    g = psi(np.vstack([xy, clutter]), rng=0)
    assert g
    assert g.n_sides == 8
    assert np.allclose(g.center, (-3.0, 4.0), atol=0.02)
    assert g.radius == pytest.approx(2.0, abs=0.02)
    ring = _ring(rng, center=(1.0, 1.0), radius=11.0, n=80_000, noise=0.02, arc=(0.4, 2.6))
    c = psi(ring, rng=1)
    assert c
    assert c.n_sides == 0
    assert c.radius == pytest.approx(11.0, abs=0.05)
    x = rng.uniform(-10, 10, 50_000)
    assert not psi(np.column_stack([x, 0.3 * x + rng.normal(0, 0.01, 50_000)]), rng=0)


def test_round_footprint_stays_a_circle():
    rng = np.random.default_rng(3)
    c = psi(_ring(rng, radius=2.0, noise=0.005), rng=0)
    assert c
    assert c.n_sides == 0


def test_straight_footprint_has_no_transport_curve():
    rng = np.random.default_rng(4)
    x = rng.uniform(-10, 10, 2000)
    xy = np.column_stack([x, 0.3 * x + rng.normal(0, 0.01, 2000)])
    assert not psi(xy, rng=0)
    assert not fit_circle(xy[:2], rng=0)


def test_profile_is_distance_from_axis():
    c = TransportCurve(center=(1.0, 2.0), radius=3.0)
    xyz = np.array([[4.0, 2.0, 0.5], [1.0, 7.0, 2.0]])
    assert p(xyz, c).tolist() == [[3.0, 0.5], [5.0, 2.0]]


def test_unwarping_gives_arc_length_on_the_curve():
    rng = np.random.default_rng(5)
    theta = rng.uniform(math.radians(30), math.radians(150), 400)
    r = 12.0 + rng.uniform(-0.5, 0.5, 400)  # a 1 m thick curved wall
    xyz = np.column_stack([r * np.cos(theta), -6.0 + r * np.sin(theta), rng.uniform(0, 5, 400)])
    c = TransportCurve(center=(0.0, -6.0), radius=12.0)
    s = u(xyz, c)[:, 0]
    # Arc length grows with the angle, from the end after the gap, at radius 12.
    expected = 12.0 * (theta - theta.min())
    assert np.allclose(np.abs(s - s.min()), expected, atol=1e-9) or np.allclose(
        s.max() - s, expected, atol=1e-9)
    assert s.max() - s.min() == pytest.approx(12.0 * (theta.max() - theta.min()))


def test_unwarping_a_polygon_runs_along_its_sides():
    g = TransportCurve(center=(0.0, 0.0), radius=1.0, n_sides=4, angle=0.0)
    pts = np.array([[1.0, -1.0, 0], [1.0, 0.0, 0], [1.0, 1.0, 0], [0.0, 1.0, 0], [-1.0, 1.0, 0]])
    s = g.position(pts[:, :2])
    assert np.allclose(np.diff(s), 1.0)
    assert g.perimeter == pytest.approx(8.0)


def test_h_projects_on_the_principal_plane_of_any_orientation():
    rng = np.random.default_rng(6)
    t = rng.uniform(-5, 5, 300)
    a = math.radians(37)
    xyz = np.column_stack([t * math.cos(a), t * math.sin(a), rng.uniform(0, 3, 300)])
    tz = h(xyz)
    assert np.allclose(np.abs(tz[:, 0] - (t - t.mean()) * np.sign(tz[0, 0] * (t[0] - t.mean()))), 0, atol=1e-9)
    assert np.array_equal(tz[:, 1], xyz[:, 2])


def test_v2_bin_count_follows_zero_crossings():
    rng = np.random.default_rng(7)
    centres = [2.0, 5.0, 8.0]
    x = np.concatenate([rng.normal(c, 0.3, 3000) for c in centres] + [rng.uniform(0, 10, 3000)])
    hist = v2(x, sigma=2.0)
    assert hist.n_zero_crossings >= 5  # three peaks, two valleys
    assert hist.n_bins == hist.n_zero_crossings + 1
    assert hist.values.sum() > 0


@pytest.mark.parametrize("peaks", [[2.0, 5.0, 8.0], [1.3, 6.1]])
def test_rho_finds_known_peaks_with_refinement(peaks):
    rng = np.random.default_rng(8)
    x = np.concatenate([rng.normal(c, 0.15, 4000) for c in peaks] + [rng.uniform(0, 10, 4000)])
    cuts = rho(v2(x, sigma=1.0), prominence=0.1)
    assert len(cuts) == len(peaks)
    assert np.allclose(cuts, peaks, atol=0.1)


def test_rho_puts_a_plateau_cut_in_its_middle():
    """A pier: a plateau with a spike on one edge (its jamb); the cut is the plateau's middle."""
    rng = np.random.default_rng(9)
    x = np.concatenate([rng.uniform(0, 10, 2000), rng.uniform(4.0, 5.5, 3000), rng.uniform(4.0, 4.1, 300)])
    cuts = rho(v2(x, n_fine=100, sigma=0.5))
    assert len(cuts) == 1
    assert cuts[0] == pytest.approx(4.75, abs=0.15)


def test_flat_signal_has_no_peak():
    assert len(rho(v2(np.linspace(0, 1, 1000)))) == 0


def test_split_at_covers_every_point_once():
    x = np.random.default_rng(10).uniform(0, 10, 1000)
    parts = split_at(x, [2.5, 7.0])
    assert sorted(np.concatenate(parts).tolist()) == list(range(1000))
    assert [bool(np.all(x[c] < 2.5)) for c in parts[:1]] == [True]


def test_sequences_on_toy_shapes():
    rng = np.random.default_rng(11)
    # A round tower with two balconies: S1 cuts at both.
    z = rng.uniform(0, 12, 20000)
    r = np.where((np.abs(z - 4) < 0.4) | (np.abs(z - 8) < 0.4), 2.0, 1.5) + rng.normal(0, 0.005, 20000)
    t = rng.uniform(0, 2 * np.pi, 20000)
    tower = np.column_stack([r * np.cos(t), r * np.sin(t), z])
    prop = s1(tower, rng=0)
    assert prop is not None
    assert prop.n_children == 3
    assert np.allclose(prop.cuts, [4.0, 8.0], atol=0.3)
    # A straight wall has no transport curve: S1 and S3 propose nothing.
    wall = np.column_stack([rng.uniform(0, 20, 5000), rng.normal(0, 0.01, 5000), rng.uniform(0, 5, 5000)])
    assert s1(wall, rng=0) is None
    assert s3(wall, rng=0) is None
    # Too few points: no proposal, no crash.
    assert s2(wall[:3]) is None
    assert s1(wall[:1], rng=0) is None


def test_a_colonnade_under_a_slab_has_no_transport_curve_whatever_the_seed():
    """psi's best circle on a slab over a grid of posts holds a tenth of the footprint and moves
    with the seed; below ``curve_min_inliers`` S1 and S3 propose nothing, for every seed."""
    rng = np.random.default_rng(5)
    slab = np.column_stack([rng.uniform(0, 6, 20000), rng.uniform(0, 7, 20000), rng.uniform(3.0, 3.4, 20000)])
    posts = []
    for x in (0.3, 3.0, 5.7):
        for y in (0.3, 2.4, 4.6, 6.7):
            t, z = rng.uniform(0, 2 * np.pi, 1500), rng.uniform(0, 3, 1500)
            posts.append(np.column_stack([x + 0.25 * np.cos(t), y + 0.25 * np.sin(t), z]))
    pavilion = np.vstack([slab, *posts])
    shares = [psi(pavilion[:, :2], rng=seed).inlier_fraction for seed in range(5)]
    assert 0 < max(shares) < SequenceParams().curve_min_inliers  # a fit, but no ring
    for seed in range(5):
        assert s1(pavilion, rng=seed) is None
        assert s3(pavilion, rng=seed) is None
        assert s3(pavilion, params=SequenceParams(curve_min_inliers=0.0), rng=seed) is not None  # what it stops
    # a round tower keeps its curve: its footprint is one ring
    z = rng.uniform(0, 12, 20000)
    t = rng.uniform(0, 2 * np.pi, 20000)
    tower = np.column_stack([1.5 * np.cos(t), 1.5 * np.sin(t), z])
    assert psi(tower[:, :2], rng=0).inlier_fraction > 0.9


def test_a_curved_wall_with_one_crowded_bay_keeps_its_curve():
    """A station beside one bay of a 20 m arc puts 70x the points there, 1 m deep: the points'
    best circle is that bay's own short arc, which reads straight. Refitted on the occupied
    cells, the wall's circle comes back, its inlier share still counted on the points.
    (Settling a circle on the cells rescues some points' fits too.)"""
    hits = {False: 0, True: 0}
    for seed in range(20):
        rng = np.random.default_rng(seed)
        wall = _ring(rng, radius=20.0, n=3000, noise=0.03, arc=(0.0, math.pi / 2))
        t = rng.uniform(math.pi / 4 - 0.075, math.pi / 4 + 0.075, 20_000)
        r = 20.0 - rng.uniform(0.0, 1.0, 20_000)
        xy = np.vstack([wall, np.column_stack([r * np.cos(t), r * np.sin(t)])])
        for refit in (False, True):
            c = psi(xy, refit_cells=refit, rng=seed)
            hits[refit] += bool(c) and abs(c.radius - 20.0) < 1.0
            if refit and c:  # the share is the points' (about half), not the cells' (over 0.8)
                thr = 0.01 * float(np.hypot(*np.ptp(xy, axis=0)))  # psi's default
                assert c.inlier_fraction < 0.7 < np.mean(c.residuals(_occupied(xy, thr / 2)) < thr)
    assert hits[False] < 10 <= hits[True], hits


def _facade(solid, *, top: float, step: float = 0.05) -> np.ndarray:
    """Points on a grid of a vertical facade in the x-z plane where ``solid(t, z)``."""
    t, z = np.meshgrid(np.arange(0, 20, step), np.arange(0, top, step))
    t, z = t.ravel(), z.ravel()
    keep = solid(t, z)
    return np.column_stack([t[keep], np.zeros(keep.sum()), z[keep]])


def test_storeys_cut_a_band_over_arches_that_reaches_the_top():
    """The band over a row of openings is a storey whether or not something stands above it:
    the occupancy is read as empty past the node's top (occupancy_cut's open_high)."""
    def bays(t, z):  # piers 1.4 m wide, openings to 4 m, the band above solid
        return (z > 4.0) | (np.abs(t % 4.0 - 2.0) > 1.3)

    alone = storeys(_facade(bays, top=7.0))
    assert alone is not None
    assert alone.n_children == 2
    assert alone.cuts[0] == pytest.approx(5.5, abs=0.5)
    # With a thin roof line standing above the band, the same cut comes out.
    roofed = storeys(_facade(lambda t, z: bays(t, z) & ((z < 7.0) | (np.abs(t - 10) < 0.2)), top=8.0))
    assert roofed is not None
    assert roofed.cuts[0] == pytest.approx(alone.cuts[0], abs=0.5)
    # A plain wall and a wall with one door have no storeys.
    assert storeys(_facade(lambda t, z: np.ones_like(t, dtype=bool), top=7.0)) is None
    assert storeys(_facade(lambda t, z: (z > 2.2) | (np.abs(t - 10) > 0.6), top=7.0)) is None
    # A band reaching the top has one end inside the node: no band child, the middle cut.
    assert alone.kept_children is None


def test_storeys_keep_the_band_between_two_storeys_as_a_child():
    """Two storeys of arcades with a band between them (3.5 to 5 m): judged by the cut at
    the band's middle, kept as bays / band / bays, the band marked (the tree calls it wall)."""
    def two(t, z):
        return ((z > 3.5) & (z < 5.0)) | (np.abs(t % 4.0 - 2.0) > 1.3)

    prop = storeys(_facade(two, top=8.5))
    assert prop is not None
    assert prop.n_children == 2  # cut at the band's middle
    assert prop.cuts[0] == pytest.approx(4.25, abs=0.3)
    assert prop.kept_children is not None
    assert len(prop.kept_children) == 3
    assert prop.kept_cuts[0] == pytest.approx(3.5, abs=0.25)
    assert prop.kept_cuts[1] == pytest.approx(5.0, abs=0.25)
    assert prop.kept_bands == (1,)
    kept = np.concatenate(prop.kept_children)
    assert np.array_equal(np.sort(kept), np.arange(len(kept)))
    off = storeys(_facade(two, top=8.5), params=SequenceParams(bands=False))
    assert off.kept_children is None
    np.testing.assert_array_equal(off.cuts, prop.cuts)


def test_plateau_ends_from_each_side():
    """A band between a low stretch (left) and a slightly lower one (right): per side,
    the left end is found and the right one is NaN under min_drop."""
    x = np.r_[np.linspace(0, 4, 400), np.repeat(np.linspace(4, 6, 200), 3), np.linspace(6, 10, 1000)]
    hist = v2(x, n_fine=100, sigma=0.5)
    pk = np.array([int(np.argmax(hist.values))])
    start, stop = plateaus(hist, pk, level=0.9, per_side=True, min_drop=0.25)
    assert start[0] == pytest.approx(4.0, abs=0.3)
    assert np.isnan(stop[0])


def test_robust_plateau_ends_past_an_edge_spike():
    """A band 4-6 with a spike on its low edge: the plain ends stop round the spike, the
    robust ones (the plateau's median as its top, the outermost bins at the level) reach
    the band's far end."""
    rng = np.random.default_rng(0)
    x = np.r_[rng.uniform(0, 10, 2000), rng.uniform(4, 6, 1000), rng.uniform(4.0, 4.2, 60)]
    hist = v2(x, n_fine=100, sigma=0.5)
    pk = np.array([int(np.argmax(hist.values))])
    start, stop = plateaus(hist, pk, level=0.9, per_side=True, min_drop=0.25)
    assert stop[0] < 5.0
    start, stop = plateaus(hist, pk, level=0.9, per_side=True, min_drop=0.25, robust=True)
    assert start[0] == pytest.approx(4.0, abs=0.3)
    assert stop[0] == pytest.approx(6.0, abs=0.3)


# --------------------------------------------------------------------------- energy
def test_energy_terms_as_method_md_writes_them():
    assert e1([10, 10, 10]) == 1.0
    assert e1([1, 29]) == pytest.approx(0.0)
    assert e1([5, 10, 15]) == pytest.approx(1 - np.std([5, 10, 15]) / np.std([1, 29]))
    assert e2(50, 100) == 0.5
    assert e2(500, 100) == 1.0
    assert e3(1) == 0.0
    assert e3(2) == pytest.approx(1 - math.exp(-0.5))
    W = np.arange(27, dtype=float).reshape(9, 3) / 27
    assert e4(W, 6, 1) == W[6, 0]
    assert e4(W, 4, 3) == W[4, 2]
    assert e5([0.2, 0.4, 0.9]) == pytest.approx(0.5)
    e = energy_terms([10, 20], n_min=100, prior=W, parent_class=6, sequence=2, scores=[0.5, 1.0])
    assert e.tolist() == pytest.approx([e1([10, 20]), 0.3, e3(2), W[6, 1], 0.75])
    with pytest.raises(ValueError, match="sequence"):
        e4(W, 6, 4)


def test_a_thick_curved_wall_gives_one_circle_whatever_the_draw():
    """A 30 m arc of a wall with depth (a face at 30 m, piers 1.2 m in front of it every
    4 m): RANSAC's best circle moves from draw to draw (several circles hold about as
    many points), the settled one does not, and S3 cuts the same bays every draw."""
    rng = np.random.default_rng(3)
    t = rng.uniform(0.0, 1.0, 40_000)
    on_pier = (t * 30.0) % 4.0 < 1.0
    r = np.where(on_pier, 28.8, 30.0) + rng.normal(0.0, 0.03, len(t))
    xy = np.column_stack([r * np.cos(t), r * np.sin(t)])
    ransac = [fit_circle(xy, residual_threshold=0.01 * float(np.hypot(*np.ptp(xy, axis=0))), rng=d)
              for d in range(8)]
    settled = [psi(xy, sides=(), rng=d) for d in range(8)]
    spread = lambda cs: max(float(np.hypot(*(np.subtract(a.center, b.center)))) for a in cs for b in cs)  # noqa: E731
    assert spread(ransac) > 0.05
    assert spread(settled) < 1e-3
    z = rng.uniform(0.0, 6.0, len(t))
    xyz = np.column_stack([xy, z])
    cuts = {tuple(np.round(s3(xyz, rng=d).cuts, 3)) for d in range(4)}
    assert len(cuts) == 1
