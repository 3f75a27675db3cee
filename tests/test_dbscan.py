"""Tests of primitives.dbscan: equality with scikit-learn, toy cases, segments, eps."""

from __future__ import annotations

import numpy as np
import pytest
from sklearn.cluster import DBSCAN
from sklearn.datasets import make_blobs
from sklearn.metrics import adjusted_rand_score

import hollowtree.primitives.dbscan as dbscan_module
from hollowtree.errors import ConfigError
from hollowtree.primitives.dbscan import (
    dbscan_labels,
    dbscan_segments,
    default_eps,
    spacing_quantile,
    sparse_points,
    window_distances,
    window_spacing,
)


def _on_x(xs: list[float]) -> np.ndarray:
    return np.c_[np.asarray(xs, dtype=np.float64), np.zeros(len(xs)), np.zeros(len(xs))]


def _sklearn(xyz: np.ndarray, eps: float, min_samples: int) -> tuple[np.ndarray, np.ndarray]:
    est = DBSCAN(eps=eps, min_samples=min_samples).fit(xyz)
    core = np.zeros(len(xyz), dtype=bool)
    core[est.core_sample_indices_] = True
    return est.labels_.astype(np.int64), core


# -- toy cases worked out by hand (after sklearn's test_dbscan_core_samples_toy) ----------

TOY = _on_x([0, 2, 3, 4, 6, 8, 10])


@pytest.mark.parametrize(
    ("min_samples", "expected"),
    [
        (1, [0, 1, 1, 1, 2, 3, 4]),  # every point core; 2-3-4 chain
        (2, [-1, 0, 0, 0, -1, -1, -1]),  # 2, 3, 4 core (3 points within 1 of 3)
        (3, [-1, 0, 0, 0, -1, -1, -1]),  # only 3 core; 2 and 4 are its border points
        (4, [-1] * 7),  # no core point: all noise
    ],
)
def test_core_samples_toy(min_samples: int, expected: list[int]) -> None:
    labels = dbscan_labels(TOY, eps=1.0, min_samples=min_samples)
    assert labels.dtype == np.int64
    assert labels.tolist() == expected
    np.testing.assert_array_equal(labels, _sklearn(TOY, 1.0, min_samples)[0])


def test_border_point_takes_lowest_cluster_label() -> None:
    # Cluster A: 0.0 (index 0), 0.3, 0.6, 1.0 (index 9). Cluster B: 3.0 (index 1) .. 4.0.
    # The point at 2.0 (index 8) has 3 points within eps=1 (1.0, 2.0, 3.0) < 4: a border
    # point of both A (via index 9) and B (via index 1). A owns index 0, so A is cluster 0
    # and sklearn's search reaches 2.0 from A first: it gets 0, although its
    # lowest-index core neighbour (index 1) is in B.
    xs = [0.0, 3.0, 3.4, 3.7, 4.0, 0.3, 0.6, 9.0, 2.0, 1.0]
    xyz = _on_x(xs)
    labels = dbscan_labels(xyz, eps=1.0, min_samples=4)
    assert labels.tolist() == [0, 1, 1, 1, 1, 0, 0, -1, 0, 0]
    np.testing.assert_array_equal(labels, _sklearn(xyz, 1.0, min_samples=4)[0])


def test_clusters_numbered_by_lowest_core_point() -> None:
    xs = [10.0, 10.5, 0.0, 0.5, 11.0, 1.0]
    labels = dbscan_labels(_on_x(xs), eps=0.6, min_samples=2)
    assert labels.tolist() == [0, 0, 1, 1, 0, 1]


def test_distance_exactly_eps_counts() -> None:
    xyz = _on_x([0.0, 1.0, 2.0])
    assert dbscan_labels(xyz, eps=1.0, min_samples=3).tolist() == [0, 0, 0]
    assert dbscan_labels(xyz, eps=0.999, min_samples=2).tolist() == [-1, -1, -1]


# -- equality with scikit-learn -------------------------------------------------------------


@pytest.mark.parametrize("seed", range(12))
def test_equals_sklearn_on_blobs(seed: int) -> None:
    rng = np.random.default_rng(seed)
    xyz, _ = make_blobs(
        n_samples=int(rng.integers(50, 800)),
        centers=int(rng.integers(1, 6)),
        n_features=3,
        cluster_std=float(rng.uniform(0.2, 2.0)),
        random_state=seed,
    )
    xyz = np.r_[xyz, rng.uniform(-15, 15, (40, 3))]  # planted outliers
    if seed % 3 == 0:
        xyz = np.round(xyz, 1)  # duplicates and ties
    eps = float(rng.uniform(0.2, 2.0))
    min_samples = int(rng.integers(1, 15))
    ours = dbscan_labels(xyz, eps=eps, min_samples=min_samples)
    theirs, core = _sklearn(xyz, eps, min_samples)
    assert adjusted_rand_score(theirs[core], ours[core]) == 1.0
    np.testing.assert_array_equal(ours == -1, theirs == -1)
    np.testing.assert_array_equal(ours, theirs)  # border points and numbering too


def test_equals_sklearn_on_dense_surface() -> None:
    # A scanned-like surface: many points per grid cell (count shortcut, subsample stage,
    # pruning), two walls apart by more than eps and a gap that splits one of them.
    rng = np.random.default_rng(7)
    wall = np.c_[rng.uniform(0, 4, 6000), rng.normal(0, 0.002, 6000), rng.uniform(0, 2, 6000)]
    wall = wall[np.abs(wall[:, 0] - 2.0) > 0.08]
    other = wall[:3000] + [0.0, 0.5, 0.0]
    xyz = np.r_[wall, other, rng.uniform(0, 4, (50, 3))]
    for eps, min_samples in [(0.05, 5), (0.1, 10), (0.2, 30)]:
        ours = dbscan_labels(xyz, eps=eps, min_samples=min_samples)
        np.testing.assert_array_equal(ours, _sklearn(xyz, eps, min_samples)[0])


@pytest.mark.parametrize("gap", [0.98, 1.02])
def test_dense_cells_joined_by_one_pair(gap: float) -> None:
    # Two dense cells two cells apart; only one point of A comes within eps of B, so the
    # subsample stage misses it and the exhaustive k-d tree stage decides.
    rng = np.random.default_rng(8)
    a = np.c_[rng.uniform(0, 0.01, 120), rng.uniform(0, 0.01, 120), rng.uniform(0, 0.01, 120)]
    a = np.r_[a, [[0.56, 0.005, 0.005]]]
    b = a[:120] + [0.56 + gap, 0.0, 0.0]
    xyz = np.r_[a, b][rng.permutation(241)]
    ours = dbscan_labels(xyz, eps=1.0, min_samples=3)
    np.testing.assert_array_equal(ours, _sklearn(xyz, 1.0, 3)[0])
    assert ours.max() + 1 == (1 if gap < 1 else 2)


def test_far_apart_points_use_compressed_grid() -> None:
    # Extent / eps ~ 1e11 per axis: the plain cell key would overflow int64.
    rng = np.random.default_rng(9)
    blob = rng.normal(0, 0.01, (200, 3))
    xyz = np.r_[blob, blob[:100] + 1e9, blob[:50] - [1e9, 0, 2e9], blob[:30] + [0.035, 0, 0]]
    ours = dbscan_labels(xyz, eps=0.01, min_samples=4)
    np.testing.assert_array_equal(ours, _sklearn(xyz, 0.01, 4)[0])
    assert ours.max() >= 2


def test_deterministic_and_order_independent_partition() -> None:
    rng = np.random.default_rng(10)
    xyz, _ = make_blobs(n_samples=600, centers=4, n_features=3, random_state=10)
    a = dbscan_labels(xyz, eps=0.8, min_samples=6)
    np.testing.assert_array_equal(a, dbscan_labels(xyz, eps=0.8, min_samples=6))
    perm = rng.permutation(len(xyz))
    b = dbscan_labels(xyz[perm], eps=0.8, min_samples=6)
    _, core = _sklearn(xyz, 0.8, 6)
    assert adjusted_rand_score(a[perm][core[perm]], b[core[perm]]) == 1.0


def test_input_not_modified() -> None:
    xyz, _ = make_blobs(n_samples=300, centers=3, n_features=3, random_state=0)
    prim = np.arange(300) % 3
    before, prim_before = xyz.copy(), prim.copy()
    dbscan_labels(xyz, eps=0.5, min_samples=5)
    dbscan_segments(xyz, prim, eps=0.5, min_samples=5)
    default_eps(xyz)
    np.testing.assert_array_equal(xyz, before)
    np.testing.assert_array_equal(prim, prim_before)


# -- edge cases ----------------------------------------------------------------------------


def test_empty_input() -> None:
    labels = dbscan_labels(np.empty((0, 3)), eps=1.0, min_samples=2)
    assert labels.shape == (0,)
    assert labels.dtype == np.int64
    assert dbscan_segments(np.empty((0, 3)), np.empty(0, dtype=np.int64), eps=1.0, min_samples=2).shape == (0,)


def test_one_point() -> None:
    assert dbscan_labels([[1.0, 2.0, 3.0]], eps=1.0, min_samples=1).tolist() == [0]
    assert dbscan_labels([[1.0, 2.0, 3.0]], eps=1.0, min_samples=2).tolist() == [-1]


def test_all_identical_points() -> None:
    xyz = np.repeat([[5.0, 5.0, 5.0]], 10, axis=0)
    assert dbscan_labels(xyz, eps=1e-6, min_samples=10).tolist() == [0] * 10
    assert dbscan_labels(xyz, eps=1e-6, min_samples=11).tolist() == [-1] * 10


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        (
            {"eps": -1, "min_samples": 5},
            r"^The 'eps' parameter of dbscan_labels must be a float in the range \(0\.0, inf\)\. "
            r"Got -1 instead\.$",
        ),
        ({"eps": float("inf"), "min_samples": 5}, r"'eps' parameter"),
        ({"eps": "1", "min_samples": 5}, r"'eps' parameter .* Got '1' instead"),
        (
            {"eps": 1.0, "min_samples": 0},
            r"^The 'min_samples' parameter of dbscan_labels must be an int in the range "
            r"\[1, inf\)\. Got 0 instead\.$",
        ),
        ({"eps": 1.0, "min_samples": 2.5}, r"'min_samples' parameter"),
    ],
)
def test_bad_parameters(kwargs: dict, match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        dbscan_labels(np.zeros((3, 3)), **kwargs)


def test_bad_xyz() -> None:
    with pytest.raises(ConfigError, match="'xyz' parameter of dbscan_labels"):
        dbscan_labels(np.zeros((3, 2)), eps=1.0, min_samples=2)


# -- default_eps ---------------------------------------------------------------------------


def test_default_eps_from_spacing() -> None:
    g = np.arange(20.0)
    x, y = np.meshgrid(g, g)
    xyz = np.c_[x.ravel(), y.ravel(), np.zeros(x.size)]
    assert default_eps(xyz, k=1, factor=2.0) == pytest.approx(2.0)
    assert default_eps(xyz, k=4, factor=1.0) == pytest.approx(1.0)
    assert default_eps(xyz, k=8) == pytest.approx(3.0 * np.sqrt(2.0))


def test_default_eps_errors() -> None:
    with pytest.raises(ConfigError, match="more than k=8 points"):
        default_eps(np.zeros((8, 3)))
    with pytest.raises(ConfigError, match="Set eps explicitly"):
        default_eps(np.zeros((20, 3)))
    with pytest.raises(ConfigError, match=r"'factor' parameter of default_eps"):
        default_eps(np.eye(3), factor=0)


# -- window_spacing ------------------------------------------------------------------------


def _grid(n: int, h: float, x0: float = 0.0) -> np.ndarray:
    g = np.arange(n) * h
    x, y = np.meshgrid(g, g)
    return np.c_[x.ravel() + x0, y.ravel(), np.zeros(x.size)]


def test_window_spacing_of_a_grid() -> None:
    xyz = _grid(30, 0.1)
    # interior points: 4 neighbours at h and 4 at h * sqrt(2), so the 8th is h * sqrt(2)
    assert window_spacing([(xyz, np.ones(len(xyz), bool))], k=8, quantile=0.5) == pytest.approx(0.1 * np.sqrt(2))
    # the mask picks the measured rows; the others still serve as neighbours
    edge = (xyz[:, 0] == 0) & (xyz[:, 1] > 0.5) & (xyz[:, 1] < 2.0)
    assert window_spacing([(xyz, edge)], k=5, quantile=0.5) == pytest.approx(0.1 * np.sqrt(2))


def test_window_distances_measured_apart_and_pooled_give_the_window_spacing() -> None:
    rng = np.random.default_rng(4)
    windows = [(rng.random((n, 3)) * [3.0, 3.0, 0.1], rng.random(n) < 0.8) for n in (5, 200, 900, 40)]
    whole = window_spacing(windows, k=8, quantile=0.25)
    apart = [window_distances(windows[:2], k=8), window_distances(windows[2:], k=8)]
    assert len(window_distances(windows[:1], k=8)) == 0  # a window of k points or fewer: none
    assert spacing_quantile(apart, k=8, quantile=0.25) == whole
    with pytest.raises(ConfigError, match="measured point with 8 neighbours"):
        spacing_quantile([window_distances(windows[:1], k=8)], k=8)


def test_window_spacing_low_quantile_keeps_the_dense_mode() -> None:
    """Two surfaces, one dense and one 5x sparser: the median follows whichever holds more
    points, the 25 % quantile stays with the dense one until the dense one is a quarter."""
    sparse = _grid(40, 0.25, x0=100.0)  # 1 600 points
    on = np.ones
    for n in (45, 30, 28):  # the dense surface holds 56 %, 36 %, 33 % of the points
        dense = _grid(n, 0.05)
        windows = [(dense, on(len(dense), bool)), (sparse, on(len(sparse), bool))]
        assert window_spacing(windows, quantile=0.25) == pytest.approx(0.05 * np.sqrt(2)), n
        median = window_spacing(windows, quantile=0.5)
        assert median == pytest.approx(0.05 * np.sqrt(2) if n == 45 else 0.25 * np.sqrt(2)), n


def test_window_spacing_pools_windows_and_skips_small_ones() -> None:
    a, b = _grid(20, 0.1), _grid(20, 0.1, x0=50.0)
    both = window_spacing([(a, np.ones(len(a), bool)), (b, np.ones(len(b), bool)),
                           (a[:5], np.ones(5, bool))], quantile=0.5)
    assert both == pytest.approx(window_spacing([(a, np.ones(len(a), bool))], quantile=0.5))


def test_window_spacing_errors() -> None:
    xyz = _grid(10, 0.1)
    ones = np.ones(len(xyz), bool)
    with pytest.raises(ConfigError, match=r"'quantile' parameter of window_spacing .*\(0.0, 1.0\]"):
        window_spacing([(xyz, ones)], quantile=1.5)
    with pytest.raises(ConfigError, match=r"'quantile' parameter of window_spacing"):
        window_spacing([(xyz, ones)], quantile=0)
    with pytest.raises(ConfigError, match="a mask of one entry per point"):
        window_spacing([(xyz, ones[:5])])
    with pytest.raises(ConfigError, match="Got none instead"):
        window_spacing([(xyz[:8], ones[:8]), (xyz, ~ones)])
    with pytest.raises(ConfigError, match="Set eps explicitly"):
        window_spacing([(np.zeros((20, 3)), np.ones(20, bool))])


# -- dbscan_segments -----------------------------------------------------------------------


def test_segments_split_each_primitive(monkeypatch: pytest.MonkeyPatch) -> None:
    rng = np.random.default_rng(11)

    def blob(center: list[float], n: int) -> np.ndarray:
        return rng.normal(0, 0.05, (n, 3)) + center

    # Primitive 3: two separate patches; primitive 1: two patches, one overlapping a patch
    # of primitive 3 in space (must stay apart: primitives are clustered separately).
    xyz = np.r_[blob([0, 0, 0], 40), blob([5, 0, 0], 30), blob([0, 0, 0], 20), blob([0, 9, 0], 25),
                [[50.0, 50, 50]]]
    prim = np.r_[np.full(40, 3), np.full(30, 3), np.full(20, 1), np.full(25, 1), [3]]
    prim[5] = -1  # no primitive
    sizes: list[int] = []
    real = dbscan_module.dbscan_labels

    def spy(points: np.ndarray, **kw: object) -> np.ndarray:
        sizes.append(len(points))
        return real(points, **kw)

    monkeypatch.setattr(dbscan_module, "dbscan_labels", spy)
    seg = dbscan_segments(xyz, prim, eps=0.5, min_samples=4)
    assert sorted(sizes) == [45, 70]  # once per primitive, never all points
    assert seg.dtype == np.int64
    # Primitive 1 first (ids 1, 2), then primitive 3 (ids 3, 4); noise and -1 get 0.
    assert set(seg[80:90]) == {1}
    assert set(seg[90:115]) == {2}
    assert set(np.r_[seg[:5], seg[6:40]]) == {3}
    assert set(seg[40:70]) == {4}
    assert seg[5] == 0
    assert seg[115] == 0


def test_segments_bad_labels() -> None:
    with pytest.raises(ConfigError, match="'primitive_labels' parameter of dbscan_segments"):
        dbscan_segments(np.zeros((3, 3)), [0.5, 1, 2], eps=1.0, min_samples=2)
    with pytest.raises(ConfigError, match="'primitive_labels'"):
        dbscan_segments(np.zeros((3, 3)), [0, 1], eps=1.0, min_samples=2)


def test_sparse_points_use_every_point_as_neighbour() -> None:
    """Edge points of a dense surface are not sparse; a far, thinly scanned one is."""
    rng = np.random.default_rng(0)
    dense = np.c_[rng.uniform(0, 10, (40_000, 2)), np.zeros(40_000)]  # ~0.05 m spacing
    far = np.c_[rng.uniform(30, 40, (400, 2)), np.zeros(400)]  # ~0.5 m spacing
    xyz = np.r_[dense, far]
    mask = np.r_[rng.random(40_000) < 0.05, np.ones(400, bool)]  # stray dense rows + the far ones
    rows, med = sparse_points(xyz, mask, 0.05, 4.0)
    assert set(rows.tolist()) == set(range(40_000, 40_400))
    assert 0.4 < med < 1.0
    assert sparse_points(xyz, np.zeros(len(xyz), bool), 0.05, 4.0)[0].size == 0


def test_sparse_points_equal_the_unbounded_query() -> None:
    """The bounded first query changes nothing: rows and median as from every point's
    exact k-th neighbour distance, also for points whose k-th neighbour lies exactly at
    factor x spacing (a line of points 0.25 m apart: the 8th neighbour at 1.0 m)."""
    from scipy.spatial import cKDTree

    rng = np.random.default_rng(1)
    line = np.c_[20.0 + 0.25 * np.arange(100), np.zeros(100), np.zeros(100)]
    xyz = np.r_[rng.normal(0, 1, (3000, 3)), rng.uniform(-8, 8, (300, 3)), line]
    mask = rng.random(len(xyz)) < 0.5
    mask[-100:] = True
    for spacing, factor in ((0.1, 3.0), (0.5, 2.0), (0.05, 50.0)):
        rows, med = sparse_points(xyz, mask, spacing, factor)
        cand = np.flatnonzero(mask)
        d = cKDTree(xyz).query(xyz[cand], k=9)[0][:, 8]
        want = cand[d >= factor * spacing]
        assert np.array_equal(rows, want)
        if factor * spacing == 1.0:  # the tie: interior points of the line are sparse
            assert np.isin(np.arange(len(xyz) - 90, len(xyz) - 10), rows).all()
        assert med == (float(np.median(d[d >= factor * spacing])) if len(want) else 0.0)
