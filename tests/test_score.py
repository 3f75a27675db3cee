"""Fused scoring kernels (primitives/score.py) against the NumPy reference (shapes.compatible)."""

from __future__ import annotations

import numpy as np
import pytest

from hollowtree.primitives.score import (
    FUSED_KINDS,
    compatible_counts,
    compatible_mask,
    point_columns,
    shared_hits,
)
from hollowtree.primitives.shapes import (
    candidates_from_minimal_sets,
    compatible,
    distance_and_cosine,
)

EPS, COS_A = 0.05, 0.9


def _scene(seed: int, kind: str, n_points: int = 3000, n_candidates: int = 97):
    """Points on and near one surface of ``kind`` plus clutter, and candidates from minimal
    sets of those points (so that a good share of the pairs is compatible)."""
    rng = np.random.default_rng(seed)
    t = rng.uniform(0, 2 * np.pi, n_points)
    z = rng.uniform(0.2, 3, n_points)
    if kind == "plane":
        xyz = np.c_[rng.uniform(-3, 3, n_points), rng.uniform(-3, 3, n_points), np.zeros(n_points)]
        nrm = np.tile([0.0, 0, 1], (n_points, 1))
    elif kind == "sphere":
        u = rng.normal(size=(n_points, 3))
        nrm = u / np.linalg.norm(u, axis=1)[:, None]
        xyz = 2.0 * nrm + [1.0, -2, 0.5]
    elif kind == "cylinder":
        nrm = np.c_[np.cos(t), np.sin(t), np.zeros(n_points)]
        xyz = 1.5 * nrm + np.c_[np.zeros(n_points), np.zeros(n_points), z]
    else:  # cone, apex at the origin, axis +z, half-angle 0.5 rad
        w = 0.5
        rho = z * np.tan(w)
        xyz = np.c_[rho * np.cos(t), rho * np.sin(t), z]
        nrm = np.c_[np.cos(w) * np.cos(t), np.cos(w) * np.sin(t), -np.sin(w) * np.ones(n_points)]
    xyz = xyz + rng.normal(scale=0.03, size=xyz.shape)
    nrm = nrm + rng.normal(scale=0.2, size=nrm.shape)
    nrm /= np.linalg.norm(nrm, axis=1)[:, None]
    clutter = rng.uniform(-4, 4, (n_points // 3, 3))
    cn = rng.normal(size=clutter.shape)
    xyz = np.concatenate([xyz, clutter])
    nrm = np.concatenate([nrm, cn / np.linalg.norm(cn, axis=1)[:, None]])
    k = {"plane": 3, "sphere": 2, "cylinder": 2, "cone": 3}[kind]
    pick = rng.integers(0, n_points, (4 * n_candidates, k))
    params, ok = candidates_from_minimal_sets(kind, xyz[pick], nrm[pick])
    return xyz, nrm, params[ok][:n_candidates]


@pytest.mark.parametrize("kind", sorted(FUSED_KINDS))
@pytest.mark.parametrize("seed", [0, 1])
def test_fused_kernels_agree_with_the_reference(kind, seed):
    xyz, nrm, params = _scene(seed, kind)
    assert len(params) > 20
    ref = compatible(kind, params, xyz, nrm, epsilon=EPS, cos_alpha=COS_A)
    assert 0 < ref.sum() < ref.size  # the comparison is not vacuous
    cols = point_columns(xyz, nrm)
    mask = compatible_mask(kind, params, cols, epsilon=EPS, cos_alpha=COS_A)
    counts = compatible_counts(kind, params, cols, epsilon=EPS, cos_alpha=COS_A)
    assert mask.shape == ref.shape
    assert mask.dtype == bool
    np.testing.assert_array_equal(counts, mask.sum(axis=1))
    # Sums run in another order: a difference is allowed only on a threshold.
    d, c = distance_and_cosine(kind, params, xyz, nrm)
    on_edge = (np.abs(d - EPS) < 1e-9) | (np.abs(c - COS_A) < 1e-9)
    assert not np.any((mask != ref) & ~on_edge)


def test_fused_kernels_on_empty_input():
    cols = point_columns(np.zeros((0, 3)), np.zeros((0, 3)))
    plane = np.array([[0.0, 0, 1, 0, 0, 0, 0, 0]])
    assert compatible_counts("plane", plane, cols, epsilon=EPS, cos_alpha=COS_A).tolist() == [0]
    assert compatible_mask("plane", plane, cols, epsilon=EPS, cos_alpha=COS_A).shape == (1, 0)
    cols = point_columns(np.zeros((5, 3)), np.tile([0.0, 0, 1], (5, 1)))
    assert compatible_counts("sphere", np.zeros((0, 8)), cols, epsilon=EPS, cos_alpha=COS_A).shape == (0,)


def test_point_columns_take_and_rows_round_trip():
    rng = np.random.default_rng(3)
    xyz, nrm = rng.normal(size=(50, 3)), rng.normal(size=(50, 3))
    cols = point_columns(xyz, nrm)
    keep = rng.random(50) < 0.5
    sub = cols.take(keep)
    p, n, pp, npx = sub.rows(slice(0, len(sub)))
    np.testing.assert_array_equal(p, xyz[keep])
    np.testing.assert_array_equal(n, nrm[keep])
    np.testing.assert_allclose(pp, (xyz[keep] ** 2).sum(axis=1))
    np.testing.assert_allclose(npx, (xyz[keep] * nrm[keep]).sum(axis=1))


def test_shared_hits_matches_numpy():
    rng = np.random.default_rng(5)
    hits = rng.random((37, 301)) < 0.3
    mask = rng.random(301) < 0.5
    own, shared = shared_hits(hits, mask)
    np.testing.assert_array_equal(own, hits.sum(axis=1))
    np.testing.assert_array_equal(shared, (hits & mask).sum(axis=1))
    own, shared = shared_hits(np.zeros((0, 4), dtype=bool), np.ones(4, dtype=bool))
    assert own.shape == shared.shape == (0,)


def test_kernel_reads_columns_without_gathers():
    """The kernel's point index is unsigned: with a signed one numba cannot rule out a
    negative (wrapping) index and LLVM reads every column through vector gathers, about
    10x slower (docs/decisions/speed-and-memory.md, "Unsigned indices, subsets as slices, one
    thread per kernel"). Compiled afresh, since cached code has no assembly."""
    import numba

    from hollowtree.primitives import score

    fresh = numba.njit(nogil=True)(score._kernel.py_func)
    xyz, nrm, params = _scene(0, "plane")
    pts = point_columns(xyz, nrm)
    counts = np.zeros(len(params), dtype=np.int64)
    fresh(0, params, pts.x, pts.y, pts.z, pts.nx, pts.ny, pts.nz, pts.pp, pts.npx, EPS, COS_A, counts,
          np.zeros((0, 0), dtype=np.bool_), False)
    assert counts.tolist() == compatible_counts("plane", params, pts, epsilon=EPS, cos_alpha=COS_A).tolist()
    asm = "".join(fresh.inspect_asm().values())
    assert asm
    assert "gather" not in asm
