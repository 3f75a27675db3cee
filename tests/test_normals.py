"""Tests of primitives.normals: PCA normals, curvature, orientation, degenerate input."""

from __future__ import annotations

import numpy as np
import pytest

from hollowtree.errors import ConfigError
from hollowtree.primitives.normals import NormalResult, estimate_normals


def _plane(n: int, normal: np.ndarray, noise: float, rng: np.random.Generator) -> np.ndarray:
    normal = normal / np.linalg.norm(normal)
    u = np.cross(normal, [1.0, 0, 0] if abs(normal[0]) < 0.9 else [0, 1.0, 0])
    u /= np.linalg.norm(u)
    v = np.cross(normal, u)
    st = rng.uniform(-5, 5, (n, 2))
    return st[:, :1] * u + st[:, 1:] * v + rng.normal(0, noise, (n, 1)) * normal


def _sphere(n: int, radius: float, rng: np.random.Generator) -> np.ndarray:
    d = rng.normal(size=(n, 3))
    return radius * d / np.linalg.norm(d, axis=1, keepdims=True)


@pytest.mark.parametrize("noise", [0.0, 0.01])
def test_plane_normals_equal_plane_normal(noise: float) -> None:
    rng = np.random.default_rng(0)
    normal = np.array([1.0, 2.0, 2.0]) / 3.0
    xyz = _plane(5000, normal, noise, rng) + [500_000.0, 3_500_000.0, 200.0]
    res = estimate_normals(xyz, k=16)
    assert res.valid.all()
    np.testing.assert_allclose(np.linalg.norm(res.normals, axis=1), 1.0)
    cos = np.abs(res.normals @ normal)
    assert cos.min() > (0.999999 if noise == 0 else 0.98)
    assert np.median(res.curvature) < (1e-12 if noise == 0 else 2e-3)


def test_plane_orientation_toward_viewpoint() -> None:
    rng = np.random.default_rng(1)
    xyz = _plane(2000, np.array([0.0, 0, 1]), 0.005, rng)
    # Two stations, one above and one below: each point faces its own station.
    viewpoints = np.array([[0.0, 0, 10], [0.0, 0, -10]])
    station = (xyz[:, 0] > 0).astype(np.int64)
    res = estimate_normals(xyz, k=12, viewpoints=viewpoints, viewpoint_index=station)
    assert res.valid.all()
    toward = np.einsum("ij,ij->i", res.normals, viewpoints[station] - xyz)
    assert (toward >= 0).all()
    np.testing.assert_array_equal(np.sign(res.normals[:, 2]), np.where(station == 0, 1.0, -1.0))


def test_sphere_normals_point_outward() -> None:
    rng = np.random.default_rng(2)
    center = np.array([10.0, -4.0, 3.0])
    xyz = _sphere(4000, 2.0, rng) + center
    res = estimate_normals(xyz, k=16)
    radial = (xyz - center) / 2.0
    cos = np.einsum("ij,ij->i", res.normals, radial)
    assert res.valid.all()
    assert cos.min() > 0.99
    # Surface variation of a sphere: small but positive.
    assert 0 < np.median(res.curvature) < 0.01


def test_curvature_larger_at_box_edge() -> None:
    # Two faces of a box meeting at the edge x = 0, z = 0.
    g = np.linspace(0.0, 1.0, 41)
    a, b = np.meshgrid(g, g)
    top = np.c_[a.ravel(), b.ravel(), np.zeros(a.size)]  # z = 0 face, x in [0, 1]
    side = np.c_[np.zeros(a.size), b.ravel(), -a.ravel()][a.ravel() > 0]  # x = 0 face
    xyz = np.r_[top, side]
    res = estimate_normals(xyz, k=16)
    flat = (top[:, 0] > 0.3) & (top[:, 1] > 0.2) & (top[:, 1] < 0.8)
    edge = (top[:, 0] == 0) & (top[:, 1] > 0.2) & (top[:, 1] < 0.8)
    curv_top = res.curvature[: len(top)]
    assert curv_top[flat].max() < 1e-12
    assert curv_top[edge].min() > 0.05


def test_radius_makes_isolated_points_invalid() -> None:
    rng = np.random.default_rng(3)
    xyz = np.r_[_plane(500, np.array([0.0, 0, 1]), 0.0, rng), [[100.0, 100, 100], [-50, 0, 7]]]
    res = estimate_normals(xyz, k=8, radius=2.0)
    assert res.valid[:500].all()
    assert not res.valid[500:].any()
    np.testing.assert_array_equal(res.normals[500:], 0.0)
    assert np.isnan(res.curvature[500:]).all()


def test_duplicates_and_collinear_are_invalid() -> None:
    dup = np.repeat([[1.0, 2.0, 3.0]], 10, axis=0)
    res = estimate_normals(dup, k=5)
    assert not res.valid.any()
    line = np.c_[np.arange(10.0), np.zeros(10), np.zeros(10)]
    res = estimate_normals(line, k=5)
    assert not res.valid.any()
    assert np.isfinite(res.normals).all()


@pytest.mark.parametrize("n", [0, 1, 2])
def test_fewer_than_three_points(n: int) -> None:
    xyz = np.arange(3.0 * n).reshape(n, 3)
    res = estimate_normals(xyz)
    assert res.normals.shape == (n, 3)
    assert res.curvature.shape == (n,)
    assert not res.valid.any()


def test_three_points_make_a_plane() -> None:
    res = estimate_normals([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]], k=16)
    assert res.valid.all()
    np.testing.assert_allclose(np.abs(res.normals[:, 2]), 1.0)


def test_core_mask_uses_buffer_as_neighbours() -> None:
    rng = np.random.default_rng(4)
    xyz = _plane(3000, np.array([0.0, 1, 1]), 0.002, rng)
    core = xyz[:, 0] < 0
    full = estimate_normals(xyz, k=10)
    part = estimate_normals(xyz, k=10, core_mask=core)
    assert not part.valid[~core].any()
    np.testing.assert_array_equal(part.valid[core], full.valid[core])
    np.testing.assert_allclose(part.normals[core], full.normals[core])
    np.testing.assert_allclose(part.curvature[core], full.curvature[core])


def test_input_not_modified() -> None:
    rng = np.random.default_rng(5)
    xyz = _sphere(300, 1.0, rng)
    vp = np.zeros((1, 3))
    vi = np.zeros(300, dtype=np.int64)
    copies = [xyz.copy(), vp.copy(), vi.copy()]
    estimate_normals(xyz, k=8, viewpoints=vp, viewpoint_index=vi)
    for before, after in zip(copies, [xyz, vp, vi], strict=True):
        np.testing.assert_array_equal(before, after)


def test_float32_and_list_input() -> None:
    xyz = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], dtype=np.float32)
    res = estimate_normals(xyz, k=4)
    assert res.normals.dtype == np.float64
    res2 = estimate_normals(xyz.tolist(), k=4)
    np.testing.assert_array_equal(res.normals, res2.normals)


def test_round_trip_dict() -> None:
    res = estimate_normals([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [5, 5, 5]], k=3)
    back = NormalResult.from_dict(res.to_dict())
    np.testing.assert_array_equal(back.normals, res.normals)
    np.testing.assert_array_equal(back.curvature, res.curvature)
    np.testing.assert_array_equal(back.valid, res.valid)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        (
            {"k": 1},
            r"^The 'k' parameter of estimate_normals must be an int in the range \[3, inf\)\. "
            r"Got 1 instead\.$",
        ),
        ({"k": 4.0}, r"'k' parameter .* Got 4\.0 instead"),
        ({"k": True}, r"'k' parameter"),
        ({"radius": 0.0}, r"'radius' parameter of estimate_normals must be a float in the range \(0\.0, inf\) or None"),
        ({"radius": float("nan")}, r"'radius' parameter"),
        ({"viewpoints": [[0.0, 0, 0]]}, r"must be given together"),
        ({"viewpoints": [[0.0, 0, 0]], "viewpoint_index": [0, 0, 1, 0]}, r"'viewpoint_index'"),
        ({"viewpoints": [0.0, 0, 0], "viewpoint_index": [0, 0, 0, 0]}, r"'viewpoints'"),
        ({"core_mask": [1, 0, 1, 0]}, r"'core_mask'"),
    ],
)
def test_bad_parameters(kwargs: dict, match: str) -> None:
    xyz = np.eye(4, 3)
    with pytest.raises(ConfigError, match=match):
        estimate_normals(xyz, **kwargs)


@pytest.mark.parametrize("xyz", [np.zeros((4, 2)), np.array([[0.0, np.nan, 0]])])
def test_bad_xyz(xyz: np.ndarray) -> None:
    with pytest.raises(ConfigError, match="'xyz' parameter of estimate_normals"):
        estimate_normals(xyz)


def test_closed_form_eigen_matches_lapack() -> None:
    """The closed-form 3 x 3 eigensolver of the PCA against np.linalg.eigh: random
    planar-ish and general neighbourhoods, and the degenerate cases (zero matrix, isotropic,
    rank one) that it hands to LAPACK."""
    from hollowtree.primitives.normals import _sym3_eigen

    rng = np.random.default_rng(7)
    m = 4000
    pts = rng.normal(size=(m, 16, 3)) * rng.choice([[1.0, 0.7, 0.01], [1.0, 1.0, 0.05], [1.0, 0.5, 0.3]], m)[:, None]
    rot = np.linalg.qr(rng.normal(size=(m, 3, 3)))[0]
    pts = np.einsum("mkj,mij->mki", pts, rot)
    pts -= pts.mean(axis=1, keepdims=True)
    cov = np.einsum("mki,mkj->mij", pts, pts)
    line = np.outer([1.0, 2, 3], [1.0, 2, 3])
    cov = np.concatenate([cov, [np.zeros((3, 3)), 2.5 * np.eye(3), line]])
    evals, vec = _sym3_eigen({(a, b): cov[:, a, b].copy() for a in range(3) for b in range(a, 3)})
    ref_vals, ref_vecs = np.linalg.eigh(cov)
    scale = ref_vals[:, 2:3] + 1e-300
    np.testing.assert_allclose(evals / scale, ref_vals / scale, atol=1e-9)
    planar = ref_vals[:m, 1] > 10 * ref_vals[:m, 0]  # a well-defined smallest eigenvector
    assert planar.mean() > 0.5
    dots = np.abs(np.einsum("ij,ij->i", vec[:m][planar], ref_vecs[:m, :, 0][planar]))
    assert dots.min() > 1 - 1e-9
    np.testing.assert_allclose(np.linalg.norm(vec[:m], axis=1), 1.0)
    assert evals[-1, 1] <= 1e-12 * evals[-1, 2]  # a line stays collinear (fails the normal test)
