"""Efficient RANSAC: recovery of each primitive, bitmap connectivity, scenes, edge cases, tori."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from hollowtree.errors import ConfigError
from hollowtree.primitives.ransac import RansacParams, RansacResult, efficient_ransac
from hollowtree.primitives.shapes import (
    DEFAULT_KINDS,
    KINDS,
    FailedFit,
    PrimitiveFit,
    candidates_from_minimal_sets,
    compatible,
    distance_and_cosine,
    fit_primitive,
    surface_coordinates,
)

PARAMS = RansacParams().to_dict()


# ------------------------------------------------------------------ synthetic surfaces
def _frame(axis):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    h = np.array([1.0, 0, 0]) if abs(axis[0]) < 0.9 else np.array([0, 1.0, 0])
    e1 = np.cross(axis, h)
    e1 /= np.linalg.norm(e1)
    return axis, e1, np.cross(axis, e1)


def _plane(rng, n, centre, normal, size=(4.0, 4.0)):
    nrm, e1, e2 = _frame(normal)
    u = rng.uniform(-size[0] / 2, size[0] / 2, n)
    v = rng.uniform(-size[1] / 2, size[1] / 2, n)
    return np.asarray(centre) + u[:, None] * e1 + v[:, None] * e2, np.tile(nrm, (n, 1))


def _sphere(rng, n, centre, r):
    v = rng.normal(size=(n, 3))
    v /= np.linalg.norm(v, axis=1)[:, None]
    return np.asarray(centre) + r * v, v


def _cylinder(rng, n, point, axis, r, length):
    a, e1, e2 = _frame(axis)
    phi, t = rng.uniform(0, 2 * np.pi, n), rng.uniform(0, length, n)
    radial = np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2
    return np.asarray(point) + t[:, None] * a + r * radial, radial


def _cone(rng, n, apex, axis, half_angle, s0, s1):
    a, e1, e2 = _frame(axis)
    phi = rng.uniform(0, 2 * np.pi, n)
    s = np.sqrt(rng.uniform(s0**2, s1**2, n))
    radial = np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2
    gen = np.cos(half_angle) * a + np.sin(half_angle) * radial
    return np.asarray(apex) + s[:, None] * gen, np.cos(half_angle) * radial - np.sin(half_angle) * a


def _torus(rng, n, centre, axis, big_r, small_r, phi_range=(0.0, 2 * np.pi)):
    """Area-uniform samples of a torus (or of the sector ``phi_range`` of it)."""
    a, e1, e2 = _frame(axis)
    phi, theta = rng.uniform(*phi_range, 4 * n), rng.uniform(0, 2 * np.pi, 4 * n)
    keep = rng.uniform(0, 1, 4 * n) < (big_r + small_r * np.cos(theta)) / (big_r + small_r)
    phi, theta = phi[keep][:n], theta[keep][:n]
    assert len(phi) == n
    radial = np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2
    nrm = np.cos(theta)[:, None] * radial + np.sin(theta)[:, None] * a
    return np.asarray(centre) + big_r * radial + small_r * nrm, nrm


def _noisy(rng, xyz, nrm, sigma=0.002):
    nrm = nrm + rng.normal(0, 0.02, nrm.shape)
    return xyz + rng.normal(0, sigma, xyz.shape), nrm / np.linalg.norm(nrm, axis=1)[:, None]


def _noisy_parts(rng, parts):
    """The (points, normals) of ``parts`` one after the other, with noise (:func:`_noisy`)."""
    return _noisy(rng, np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts]))


def _with_outliers(rng, xyz, nrm, n_out):
    lo, hi = xyz.min(0), xyz.max(0)
    out = rng.uniform(lo, hi, (n_out, 3))
    on = rng.normal(size=(n_out, 3))
    return np.r_[xyz, out], np.r_[nrm, on / np.linalg.norm(on, axis=1)[:, None]]


def _pca_normals(xyz, k=12):
    _, nb = cKDTree(xyz).query(xyz, k=k)
    nbr = xyz[nb] - xyz[nb].mean(axis=1, keepdims=True)
    return np.linalg.eigh(np.einsum("nki,nkj->nij", nbr, nbr))[1][:, :, 0]


def _unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def _axis_close(a, b, deg):
    return abs(np.dot(_unit(a), _unit(b))) > np.cos(np.radians(deg))


def _line_distance(p, a, q):
    """Distance of point q from the line p + t a."""
    a = _unit(a)
    v = np.asarray(q) - np.asarray(p)
    return np.linalg.norm(v - (v @ a) * a)


# ----------------------------------------------------------------------- recovery
N_SURF, N_OUT = 4000, 400


def _one(kind, rng):
    if kind == "plane":
        return _plane(rng, N_SURF, [1.0, 2.0, 3.0], [0.2, 0.3, 1.0])
    if kind == "sphere":
        return _sphere(rng, N_SURF, [1.0, 2.0, 3.0], 1.5)
    if kind == "cylinder":
        return _cylinder(rng, N_SURF, [1.0, 2.0, 3.0], [0.3, 0.1, 1.0], 0.8, 4.0)
    if kind == "torus":
        return _torus(rng, N_SURF, [1.0, 2.0, 3.0], [0.2, -0.3, 1.0], 1.2, 0.35)
    return _cone(rng, N_SURF, [1.0, 2.0, 3.0], [0.1, 0.2, 1.0], np.radians(30), 0.5, 4.0)


@pytest.mark.parametrize("kind", ["plane", "sphere", "cylinder", "cone"])
def test_recovers_each_primitive_with_noise_and_outliers(kind):
    rng = np.random.default_rng(7)
    xyz, nrm = _with_outliers(rng, *_noisy(rng, *_one(kind, rng)), N_OUT)
    res = efficient_ransac(xyz, nrm, **PARAMS, rng=1)
    assert res.failure is None
    assert [p.kind for p in res.primitives] == [kind]
    fit = res.primitives[0]
    recall = np.mean(res.labels[:N_SURF] == 0)
    assert recall > 0.9
    assert np.mean(res.labels[N_SURF:] == 0) < 0.1  # few outliers taken
    assert fit.rms < 0.004  # 2 mm noise
    p = fit.named()
    if kind == "plane":
        n = _unit([0.2, 0.3, 1.0])
        assert _axis_close([p["nx"], p["ny"], p["nz"]], n, 0.5)
        assert abs(abs(p["d"]) - abs(n @ [1.0, 2.0, 3.0])) < 0.005
    elif kind == "sphere":
        assert np.allclose([p["cx"], p["cy"], p["cz"]], [1, 2, 3], atol=0.01)
        assert p["radius"] == pytest.approx(1.5, abs=0.005)
    elif kind == "cylinder":
        assert _axis_close([p["ax"], p["ay"], p["az"]], [0.3, 0.1, 1.0], 0.5)
        assert _line_distance([p["px"], p["py"], p["pz"]], [p["ax"], p["ay"], p["az"]], [1, 2, 3]) < 0.01
        assert p["radius"] == pytest.approx(0.8, abs=0.005)
    else:
        assert np.allclose([p["apex_x"], p["apex_y"], p["apex_z"]], [1, 2, 3], atol=0.02)
        assert np.dot([p["ax"], p["ay"], p["az"]], _unit([0.1, 0.2, 1.0])) > np.cos(np.radians(0.5))
        assert p["half_angle"] == pytest.approx(np.radians(30), abs=np.radians(0.5))


def test_two_coplanar_patches_are_two_primitives():
    rng = np.random.default_rng(3)
    a = _plane(rng, 3000, [0.0, 0.0, 0.0], [0, 0, 1], size=(3.0, 3.0))
    b = _plane(rng, 2000, [6.0, 0.0, 0.0], [0, 0, 1], size=(3.0, 2.0))  # 4.5 m gap
    xyz, nrm = _noisy_parts(rng, [a, b])
    res = efficient_ransac(xyz, nrm, **PARAMS, rng=0)
    assert [p.kind for p in res.primitives] == ["plane", "plane"]
    assert np.all(res.labels[:3000] == 0)  # the larger patch first
    assert np.all(res.labels[3000:] == 1)
    n0, n1 = (np.array(p.params[:3]) for p in res.primitives)
    assert _axis_close(n0, n1, 0.5)


def test_box_gives_six_planes():
    rng = np.random.default_rng(11)
    size = np.array([4.0, 3.0, 2.5])
    parts, gt = [], []
    for axis in range(3):
        for sign in (-1, 1):
            normal = np.eye(3)[axis]
            centre = sign * size / 2 * normal
            dims = tuple(np.delete(size, axis)[::-1] if axis == 1 else np.delete(size, axis))
            xyz, nrm = _plane(rng, 2500, centre, normal, size=dims)
            keep = np.all(np.abs(xyz) <= size / 2 + 1e-9, axis=1)
            parts.append((xyz[keep], nrm[keep]))
            gt.append(np.full(keep.sum(), len(gt)))
    xyz, nrm = _noisy_parts(rng, parts)
    gt = np.concatenate(gt)
    res = efficient_ransac(xyz, nrm, **PARAMS, rng=0)
    assert [p.kind for p in res.primitives] == ["plane"] * 6
    # Each face maps to its own primitive (edges within epsilon may go either way).
    for face in range(6):
        labels = res.labels[gt == face]
        assert np.mean(labels == np.bincount(labels[labels >= 0]).argmax()) > 0.9
    assert len({np.bincount(res.labels[gt == f][res.labels[gt == f] >= 0]).argmax() for f in range(6)}) == 6


def test_cylinder_standing_on_a_plane():
    rng = np.random.default_rng(5)
    xyz, nrm = _noisy_parts(rng, [_plane(rng, 6000, [0.0, 0.0, 0.0], [0, 0, 1], size=(6.0, 6.0)),
                                  _cylinder(rng, 4000, [0.5, -0.5, 0.0], [0, 0, 1], 0.4, 3.0)])
    res = efficient_ransac(xyz, nrm, **PARAMS, rng=2)
    assert sorted(p.kind for p in res.primitives) == ["cylinder", "plane"]
    kinds = [p.kind for p in res.primitives]
    assert np.mean(res.labels[:6000] == kinds.index("plane")) > 0.95
    assert np.mean(res.labels[6000:] == kinds.index("cylinder")) > 0.9
    cyl = res.primitives[kinds.index("cylinder")].named()
    assert cyl["radius"] == pytest.approx(0.4, abs=0.005)


def test_mixed_scene_with_all_kinds():
    rng = np.random.default_rng(8)
    parts = [
        _plane(rng, 6000, [0.0, 0.0, 0.0], [0, 0, 1], size=(12.0, 12.0)),
        _sphere(rng, 3000, [-3.0, -3.0, 2.5], 1.2),
        _cylinder(rng, 3000, [3.0, -3.0, 0.5], [0, 0, 1], 0.5, 3.0),
        _cone(rng, 3000, [0.0, 3.0, 4.0], [0, 0, -1], np.radians(35), 0.4, 3.0),
    ]
    xyz, nrm = _noisy_parts(rng, parts)
    gt = np.repeat(np.arange(4), [len(p[0]) for p in parts])
    res = efficient_ransac(xyz, nrm, **PARAMS, rng=3)
    kinds = [p.kind for p in res.primitives]
    assert sorted(kinds) == ["cone", "cylinder", "plane", "sphere"]
    for g, kind in enumerate(["plane", "sphere", "cylinder", "cone"]):
        assert np.mean(res.labels[gt == g] == kinds.index(kind)) > 0.9


# -------------------------------------------------------------- contracts and edges
def test_same_rng_same_result_and_inputs_unmodified():
    rng = np.random.default_rng(4)
    xyz, nrm = _noisy(rng, *_cylinder(rng, 3000, [0, 0, 0], [0, 1, 0], 0.6, 3.0))
    xyz.flags.writeable = False
    before = (xyz.copy(), nrm.copy())
    a = efficient_ransac(xyz, nrm, **PARAMS, rng=5)
    b = efficient_ransac(xyz, nrm, **PARAMS, rng=np.random.default_rng(5))
    assert np.array_equal(a.labels, b.labels)
    assert a.primitives == b.primitives
    assert a.labels.dtype == np.int64
    assert a.labels.shape == (3000,)
    assert np.array_equal(xyz, before[0])
    assert np.array_equal(nrm, before[1])


def test_fewer_points_than_min_support():
    rng = np.random.default_rng(0)
    xyz, nrm = _plane(rng, 50, [0, 0, 0], [0, 0, 1])
    res = efficient_ransac(xyz, nrm, **PARAMS)
    assert np.all(res.labels == -1)
    assert res.primitives == ()
    assert isinstance(res.failure, FailedFit)
    assert not res.failure
    assert "min_support" in res.failure.reason


@pytest.mark.parametrize("case", ["identical", "collinear"])
def test_degenerate_points_report_a_reason(case):
    rng = np.random.default_rng(0)
    if case == "identical":
        xyz = np.tile([1.0, 2.0, 3.0], (500, 1))
    else:
        xyz = np.outer(rng.uniform(0, 5, 500), [1.0, 2.0, 0.5])
    nrm = np.tile([0.0, 0.0, 1.0], (500, 1))
    res = efficient_ransac(xyz, nrm, **PARAMS, rng=0)
    assert np.all(res.labels == -1)
    assert res.primitives == ()
    assert case in res.failure.reason
    assert res.stop_reason == res.failure.reason


def test_nan_normals_are_left_out():
    rng = np.random.default_rng(1)
    xyz, nrm = _noisy(rng, *_plane(rng, 3000, [0, 0, 0], [0, 0, 1]))
    nrm[::10] = np.nan
    res = efficient_ransac(xyz, nrm, **PARAMS, rng=0)
    assert np.all(res.labels[::10] == -1)
    others = np.ones(3000, bool)
    others[::10] = False
    assert np.mean(res.labels[others] == 0) > 0.95
    res = efficient_ransac(xyz, np.full_like(nrm, np.nan), **PARAMS, rng=0)
    assert np.all(res.labels == -1)
    assert res.failure is not None


def test_zero_normals_give_the_labels_of_the_rows_left():
    """A zero normal leaves its point out exactly as dropping the row would: the same
    primitives and the same labels on the other rows (pipeline.coarse relies on it to
    pass a tile's points without copying the ones that have a normal)."""
    rng = np.random.default_rng(3)
    parts = [_plane(rng, 4000, [0, 0, 0], [0, 0, 1]), _plane(rng, 3000, [0, 2, 1], [0, 1, 0.2])]
    xyz, nrm = _noisy_parts(rng, parts)
    has = rng.random(len(xyz)) > 0.1
    nrm[~has] = 0.0
    whole = efficient_ransac(xyz, nrm, **PARAMS, rng=5)
    rows = efficient_ransac(xyz[has], nrm[has], **PARAMS, rng=5)
    assert np.all(whole.labels[~has] == -1)
    np.testing.assert_array_equal(whole.labels[has], rows.labels)
    assert [p.to_dict() for p in whole.primitives] == [p.to_dict() for p in rows.primitives]
    assert len(rows.primitives) == 2


def _box_room(n, seed=0):
    """Floor and two walls of a 10 m room, 3 mm noise, their exact normals."""
    rng = np.random.default_rng(seed)
    a = rng.random((n, 2)) * 10
    k = rng.integers(0, 3, n)
    zero = np.zeros(n)
    xyz = np.where((k == 0)[:, None], np.c_[a, zero], np.where((k == 1)[:, None], np.c_[a[:, 0], zero, a[:, 1]],
                                                                np.c_[zero, a[:, 0], a[:, 1]]))
    return xyz + rng.normal(0, 0.003, xyz.shape), np.eye(3)[[2, 1, 0]][k]


def test_memory_per_point_searched():
    """The search holds about 150 bytes per point (the docstring's budget) plus an
    extraction's transients: traced peak under 280 bytes per point on 200 k points
    (293 when |x|^2 and n . x were kept for every point and the columns were copied
    whole at each extraction; 249 now)."""
    import tracemalloc

    xyz, nrm = _box_room(200_000)
    tracemalloc.start()
    try:
        res = efficient_ransac(xyz, nrm, epsilon=0.02, alpha_deg=20, cluster_epsilon=0.1, min_support=500, rng=0)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert [p.kind for p in res.primitives] == ["plane"] * 3
    assert peak / len(xyz) < 280, f"{peak / len(xyz):.0f} bytes per point"


def test_stops_on_max_iterations_and_unstructured_noise():
    rng = np.random.default_rng(2)
    xyz = rng.uniform(0, 3, (2000, 3))
    nrm = rng.normal(size=(2000, 3))
    nrm /= np.linalg.norm(nrm, axis=1)[:, None]
    res = efficient_ransac(xyz, nrm, **{**PARAMS, "max_iterations": 1000}, rng=0)
    assert res.n_candidates <= 1000
    assert res.primitives == ()
    res = efficient_ransac(xyz, nrm, **PARAMS, rng=0)  # the probabilistic stop ends it
    assert res.primitives == ()
    assert "min_support" in res.stop_reason


@pytest.mark.parametrize(
    ("key", "value", "message"),
    [
        ("epsilon", -1, "The 'epsilon' parameter of efficient_ransac must be a float in the range (0.0, inf). Got -1 instead."),
        ("alpha_deg", 120.0, "'alpha_deg' parameter of efficient_ransac must be a float in the range (0.0, 90.0]"),
        ("min_support", 2.5, "'min_support' parameter of efficient_ransac must be an int in the range [3, inf)"),
        ("probability", 1.0, "'probability'"),
        ("shapes", ("plane", "ellipsoid"), "'shapes' parameter of efficient_ransac must be a non-empty"),
        ("max_iterations", 0, "'max_iterations'"),
    ],
)
def test_parameter_errors(key, value, message):
    xyz = np.zeros((10, 3))
    with pytest.raises(ConfigError) as err:
        efficient_ransac(xyz, xyz, **{**PARAMS, key: value})
    assert message in str(err.value)
    with pytest.raises(ConfigError):
        RansacParams(**{key: value})


def test_round_trips():
    p = RansacParams(epsilon=0.02, shapes=("plane", "cylinder"))
    assert RansacParams.from_dict(p.to_dict()) == p
    with pytest.raises(ConfigError, match="Unknown"):
        RansacParams.from_dict({"eps": 1.0})
    fit = PrimitiveFit(kind="cone", params=(0, 0, 0, 0, 0, 1, 0.5), n_points=10, rms=0.1)
    assert PrimitiveFit.from_dict(fit.to_dict()) == fit
    res = RansacResult(labels=np.array([0, -1]), primitives=(fit,), n_candidates=3, stop_reason="done")
    back = RansacResult.from_dict(res.to_dict())
    assert np.array_equal(back.labels, res.labels)
    assert back.primitives == res.primitives


@pytest.mark.parametrize("kind", ["plane", "sphere", "cylinder", "cone", "torus"])
def test_fast_compatibility_matches_distances(kind):
    rng = np.random.default_rng(9)
    xyz, nrm = _one(kind, rng)
    xyz, nrm = _with_outliers(rng, *_noisy(rng, xyz, nrm, sigma=0.03), 500)
    fit = fit_primitive(xyz[:N_SURF], nrm[:N_SURF], kind=kind)
    assert fit
    params = np.zeros((1, 8))
    params[0, : len(fit.params)] = fit.params
    d, c = distance_and_cosine(kind, params, xyz, nrm)
    fast = compatible(kind, params, xyz, nrm, epsilon=0.03, cos_alpha=np.cos(np.radians(20)))
    slow = (d < 0.03) & (c > np.cos(np.radians(20)))
    assert np.mean(fast == slow) > 0.999
    assert fit_primitive(xyz[:2], nrm[:2], kind=kind).reason


# ------------------------------------------------------------------ a scanned scene
def test_scanned_minaret_scene():
    from hollowtree.classes import ClassId
    from hollowtree.scenes.scanner import ScanParams, scan
    from hollowtree.scenes.sites import build_scene

    chunks = list(scan(build_scene("minaret"), ScanParams(step_deg=0.3, n_stations=2, seed=1)))
    xyz = np.concatenate([c.xyz for c in chunks])
    cls = np.concatenate([c.gt_class for c in chunks])
    res = efficient_ransac(xyz, _pca_normals(xyz), **PARAMS, rng=0)
    ground = res.primitives[0]
    assert ground.kind == "plane"
    assert abs(ground.params[2]) > 0.999
    planes = [i for i, p in enumerate(res.primitives) if p.kind == "plane" and abs(p.params[2]) > 0.999]
    assert np.mean(np.isin(res.labels[cls == ClassId.GROUND], planes)) > 0.9
    minaret = cls == ClassId.MINARET
    assert np.mean(res.labels[minaret] >= 0) > 0.6
    # Primitives do not straddle ground and minaret.
    for i in range(res.n_primitives):
        members = cls[res.labels == i]
        assert np.mean(members == np.bincount(members).argmax()) > 0.98
    kinds = {res.primitives[i].kind for i in np.unique(res.labels[minaret & (res.labels >= 0)])}
    assert kinds & {"cylinder", "cone"}


# --------------------------------------------------------------------------- tori
TORUS = dict(centre=[1.0, 2.0, 3.0], axis=[0.2, -0.3, 1.0], big_r=1.2, small_r=0.35)
ALL = {**PARAMS, "shapes": KINDS}


def _check_torus(p, centre, axis, big_r, small_r):
    assert np.allclose([p["cx"], p["cy"], p["cz"]], centre, atol=0.01)
    assert _axis_close([p["ax"], p["ay"], p["az"]], axis, 0.5)
    assert p["major_radius"] == pytest.approx(big_r, abs=0.005)
    assert p["minor_radius"] == pytest.approx(small_r, abs=0.005)


def test_torus_is_available_but_not_a_default():
    assert "torus" in KINDS
    assert "torus" not in DEFAULT_KINDS
    assert RansacParams().shapes == DEFAULT_KINDS
    assert RansacParams(shapes=KINDS).shapes[-1] == "torus"


def test_torus_from_exact_minimal_sets():
    rng = np.random.default_rng(12)
    xyz, nrm = _torus(rng, 2000, **TORUS)
    sets = rng.integers(0, len(xyz), (500, 4))
    params, ok = candidates_from_minimal_sets("torus", xyz[sets], nrm[sets])
    assert ok.mean() > 0.95
    want = np.r_[TORUS["centre"], _unit(TORUS["axis"]), TORUS["big_r"], TORUS["small_r"]]
    assert np.allclose(params[ok], want, atol=1e-6)
    d, c = distance_and_cosine("torus", params[ok][:1], xyz, nrm)
    assert d.max() < 1e-9
    assert c.min() > 1 - 1e-9


@pytest.mark.parametrize("kind", ["plane", "sphere", "cylinder"])
def test_torus_minimal_sets_reject_other_surfaces(kind):
    # Their normal lines have infinitely many common transversals (plane, sphere) or
    # parallel meridian normals (cylinder): no torus. Cones can pass (a torus with a
    # large tube approximates a cone patch): the scores decide, see the next test.
    rng = np.random.default_rng(13)
    xyz, nrm = _one(kind, rng)
    sets = rng.integers(0, len(xyz), (500, 4))
    _, ok = candidates_from_minimal_sets("torus", xyz[sets], nrm[sets])
    assert not ok.any()


@pytest.mark.parametrize("kind", ["plane", "sphere", "cylinder", "cone"])
def test_other_kinds_are_not_taken_for_tori(kind):
    rng = np.random.default_rng(7)
    xyz, nrm = _with_outliers(rng, *_noisy(rng, *_one(kind, rng)), N_OUT)
    res = efficient_ransac(xyz, nrm, **ALL, rng=1)
    assert [p.kind for p in res.primitives] == [kind]
    assert np.mean(res.labels[:N_SURF] == 0) > 0.9


def test_torus_distance_and_normal_match_a_dense_sample():
    rng = np.random.default_rng(14)
    surf, surf_n = _torus(rng, 200_000, **TORUS)
    q = rng.uniform(-0.5, 0.5, (300, 3)) * [4, 4, 1.5] + TORUS["centre"]
    params = np.r_[TORUS["centre"], _unit(TORUS["axis"]), TORUS["big_r"], TORUS["small_r"]][None]
    dist_nb, nb = cKDTree(surf).query(q)
    d, c = distance_and_cosine("torus", params, q, surf_n[nb])
    assert np.allclose(d[0], dist_nb, atol=0.02)  # the sample's spacing
    assert np.mean(c[0] > np.cos(np.radians(5))) > 0.95  # the nearest sample's normal


def test_torus_bitmap_joins_both_seams():
    rng = np.random.default_rng(15)
    xyz, _ = _torus(rng, 6000, **TORUS)
    params = np.r_[TORUS["centre"], _unit(TORUS["axis"]), TORUS["big_r"], TORUS["small_r"]]
    uvs = surface_coordinates("torus", params, xyz)
    assert len(uvs) == 2
    span = [np.ptp(uv, axis=0) for uv in uvs]
    # (R phi, r theta) each spans a full turn, both seams cut by both parametrisations.
    for s in span:
        assert s == pytest.approx([2 * np.pi * 1.2, 2 * np.pi * 0.35], rel=0.02)


def test_recovers_a_torus_with_noise_and_outliers():
    rng = np.random.default_rng(7)
    xyz, nrm = _with_outliers(rng, *_noisy(rng, *_one("torus", rng)), N_OUT)
    res = efficient_ransac(xyz, nrm, **ALL, rng=1)
    assert res.failure is None
    assert [p.kind for p in res.primitives] == ["torus"]
    fit = res.primitives[0]
    assert np.mean(res.labels[:N_SURF] == 0) > 0.9
    assert np.mean(res.labels[N_SURF:] == 0) < 0.1
    assert fit.rms < 0.004
    _check_torus(fit.named(), **TORUS)
    direct = fit_primitive(xyz[:N_SURF], nrm[:N_SURF], kind="torus")
    _check_torus(direct.named(), **TORUS)


def test_elbow_quarter_torus_is_one_patch():
    rng = np.random.default_rng(16)
    # A pipe elbow: a quarter of a torus across the phi seam of the first parametrisation.
    xyz, nrm = _noisy(rng, *_torus(rng, 3000, [0.0, 0.0, 0.0], [0, 1, 0], 0.6, 0.2,
                                   phi_range=(0.75 * np.pi, 1.25 * np.pi)))
    res = efficient_ransac(xyz, nrm, **ALL, rng=0)
    assert [p.kind for p in res.primitives] == ["torus"]
    assert np.mean(res.labels == 0) > 0.9
    _check_torus(res.primitives[0].named(), [0, 0, 0], [0, 1, 0], 0.6, 0.2)


def test_torus_lying_on_a_plane():
    rng = np.random.default_rng(17)
    xyz, nrm = _noisy_parts(rng, [_plane(rng, 6000, [0.0, 0.0, 0.0], [0, 0, 1], size=(6.0, 6.0)),
                                  _torus(rng, 4000, [0.5, -0.5, 0.3], [0, 0, 1], 1.0, 0.3)])
    res = efficient_ransac(xyz, nrm, **ALL, rng=2)
    kinds = [p.kind for p in res.primitives]
    assert sorted(kinds) == ["plane", "torus"]
    assert np.mean(res.labels[:6000] == kinds.index("plane")) > 0.95
    # The plane, larger and extracted first, takes the torus' contact band (within
    # epsilon of the ground with the normal within alpha: about 11 % of the torus).
    on_ring = res.labels[6000:] == kinds.index("torus")
    assert np.mean(on_ring) > 0.85
    assert np.mean(on_ring[xyz[6000:, 2] > 0.05]) > 0.97
    _check_torus(res.primitives[kinds.index("torus")].named(), [0.5, -0.5, 0.3], [0, 0, 1], 1.0, 0.3)


def test_torus_search_is_deterministic():
    rng = np.random.default_rng(18)
    xyz, nrm = _with_outliers(rng, *_noisy(rng, *_torus(rng, 3000, **TORUS)), 300)
    a = efficient_ransac(xyz, nrm, **ALL, rng=5)
    b = efficient_ransac(xyz, nrm, **ALL, rng=np.random.default_rng(5))
    assert np.array_equal(a.labels, b.labels)
    assert a.primitives == b.primitives
    assert a.primitives[0].kind == "torus"
