"""Fused compatibility kernels of Efficient RANSAC's scoring (numba).

The test is :func:`primitives.shapes.compatible`'s: a point is compatible with a
candidate when it lies within ``epsilon`` of the surface and its normal is within the
angle ``alpha`` (``|cos| > cos_alpha``). :func:`~primitives.shapes.compatible` is the
NumPy reference; it builds a handful of (candidates x points) temporaries per call and
is bound by memory traffic. The kernels here compute the same expressions point by point
in one pass, over blocks of points that stay in the L1/L2 cache, and either count the
compatible points per candidate (:func:`compatible_counts`, the score) or write the
boolean matrix (:func:`compatible_mask`). Planes, spheres, cylinders and cones; tori go
through the NumPy reference (they are searched only when asked).

Points come as a :class:`PointColumns`: coordinates and normals as separate contiguous
columns plus the precomputed ``|x|^2`` and ``n . x``, so that the inner loop reads
contiguous memory and vectorises.

Results agree with the reference except where a point sits on a threshold to within
rounding (a few units in the last place: the sums are evaluated in another order); the
tests check that.

Cost (docs/benchmarks.md, "Coarse segmentation"), one Zen 4 core: 0.45 ns per candidate
x point for a plane, 0.7 for a sphere, 0.8 for a cylinder, 1.5 for a cone, about 10x
less than the reference. The point index of the inner loops is unsigned: with a signed
one numba cannot rule out a negative (wrapping) index and every column read became a
gather (4.5 ns per plane pair). The first call in a process
compiles the kernels (a few seconds) unless numba's on-disk cache (next to this file)
already holds them.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numba
import numpy as np
import numpy.typing as npt

__all__ = ["FUSED_KINDS", "PointColumns", "compatible_counts", "compatible_mask", "point_columns", "shared_hits"]

F64 = npt.NDArray[np.float64]

#: Kinds with a fused kernel; their integer codes in the kernels.
FUSED_KINDS = {"plane": 0, "sphere": 1, "cylinder": 2, "cone": 3}

_TINY = 1e-12  # as primitives.shapes
_BLOCK = 2048  # points per block (6 columns + 2 scalars x 8 bytes x 2048 = 128 KB)


@dataclass(frozen=True)
class PointColumns:
    """Points as contiguous float64 columns (see :func:`point_columns`)."""

    x: F64
    y: F64
    z: F64
    nx: F64
    ny: F64
    nz: F64
    pp: F64  # |x|^2
    npx: F64  # n . x

    def __len__(self) -> int:
        return len(self.x)

    def take(self, idx: npt.NDArray[np.int64] | npt.NDArray[np.bool_]) -> PointColumns:
        """The rows ``idx`` (indices or a mask), as new contiguous columns."""
        return PointColumns(*(a[idx] for a in self.columns()))

    def columns(self) -> tuple[F64, ...]:
        return (self.x, self.y, self.z, self.nx, self.ny, self.nz, self.pp, self.npx)

    def rows(self, sl: slice) -> tuple[F64, F64, F64, F64]:
        """Rows ``sl`` as ``(xyz (n, 3), normals (n, 3), pp, npx)`` for the NumPy reference."""
        xyz = np.stack((self.x[sl], self.y[sl], self.z[sl]), axis=1)
        nrm = np.stack((self.nx[sl], self.ny[sl], self.nz[sl]), axis=1)
        return xyz, nrm, self.pp[sl], self.npx[sl]


@functools.lru_cache(maxsize=1)
def load_kernels() -> None:
    """Load (or compile) the kernels now, in this process: a worker calls it before it forks
    a task's child (``pipeline.graph.in_child``), whose kernels are then already loaded
    (shared copy-on-write) instead of loaded from numba's cache in every child (about
    0.35 s and 45 MB each)."""
    pts = point_columns(np.zeros((1, 3)), np.zeros((1, 3)))
    compatible_counts("plane", np.zeros((1, 8)), pts, epsilon=0.1, cos_alpha=0.9)
    compatible_mask("plane", np.zeros((1, 8)), pts, epsilon=0.1, cos_alpha=0.9)
    shared_hits(np.zeros((1, 1), dtype=bool), np.zeros(1, dtype=bool))


def point_columns(xyz: F64, normals: F64, sq_norm: F64 | None = None, normal_dot: F64 | None = None
                  ) -> PointColumns:
    """Columns of ``xyz (n, 3)`` and ``normals (n, 3)`` for the fused kernels."""
    pp = np.einsum("ij,ij->i", xyz, xyz) if sq_norm is None else sq_norm
    npx = np.einsum("ij,ij->i", normals, xyz) if normal_dot is None else normal_dot
    c = [np.ascontiguousarray(a, dtype=np.float64) for a in (*xyz.T, *normals.T, pp, npx)]
    return PointColumns(*c)


def compatible_counts(kind: str, params: F64, pts: PointColumns, *, epsilon: float, cos_alpha: float
                      ) -> npt.NDArray[np.int64]:
    """Compatible points per candidate: ``compatible(...).sum(axis=1)``, fused.

    Parameters
    ----------
    kind : {"plane", "sphere", "cylinder", "cone"}
    params : ndarray of shape (n_candidates, 8)
    pts : PointColumns
    epsilon, cos_alpha : float

    Returns
    -------
    ndarray of int64, shape (n_candidates,)

    Examples
    --------
    >>> xyz = np.array([[0.0, 0, 0.01], [0, 0, 0.5], [1, 0, 0]])
    >>> pts = point_columns(xyz, np.tile([0.0, 0, 1], (3, 1)))
    >>> planes = np.array([[0.0, 0, 1, 0, 0, 0, 0, 0], [0, 0, 1, -0.5, 0, 0, 0, 0]])
    >>> compatible_counts("plane", planes, pts, epsilon=0.1, cos_alpha=0.9).tolist()
    [2, 1]
    """
    out = np.zeros(len(params), dtype=np.int64)
    _run_kernel(kind, params, pts, epsilon, cos_alpha, out, np.zeros((0, 0), dtype=np.bool_), False)
    return out


def compatible_mask(kind: str, params: F64, pts: PointColumns, *, epsilon: float, cos_alpha: float
                    ) -> npt.NDArray[np.bool_]:
    """``compatible(...)`` of :mod:`primitives.shapes`, fused: bool of shape (n_candidates, n_points)."""
    out = np.zeros((len(params), len(pts)), dtype=np.bool_)
    _run_kernel(kind, params, pts, epsilon, cos_alpha, np.zeros(len(params), dtype=np.int64), out, True)
    return out


def _run_kernel(kind: str, params: F64, pts: PointColumns, epsilon: float, cos_alpha: float,
                counts: npt.NDArray[np.int64], mask: npt.NDArray[np.bool_], write_mask: bool) -> None:
    _kernel(FUSED_KINDS[kind], np.ascontiguousarray(params, dtype=np.float64), pts.x, pts.y, pts.z, pts.nx,
            pts.ny, pts.nz, pts.pp, pts.npx, float(epsilon), float(cos_alpha), counts, mask, write_mask)


def shared_hits(hits: npt.NDArray[np.bool_], mask: npt.NDArray[np.bool_]
                ) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """Per row of ``hits (k, n)``: its True count and how many of them ``mask (n,)`` shares.

    ``(hits.sum(axis=1), (hits & mask).sum(axis=1))`` in one pass without temporaries.

    Examples
    --------
    >>> shared_hits(np.array([[True, True, False], [False, True, True]]), np.array([True, False, True]))
    (array([2, 2]), array([1, 1]))
    """
    own = np.zeros(len(hits), dtype=np.int64)
    shared = np.zeros(len(hits), dtype=np.int64)
    if hits.size:
        _shared(np.ascontiguousarray(hits).view(np.uint8), np.ascontiguousarray(mask).view(np.uint8), own, shared)
    return own, shared


@numba.njit(cache=True, nogil=True)
def _shared(hits, mask, own, shared):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    for k in range(hits.shape[0]):
        a = 0
        b = 0
        for i in range(hits.shape[1]):
            h = hits[k, i]
            a += h
            b += h & mask[i]
        own[k] = a
        shared[k] = b


@numba.njit(cache=True, nogil=True, inline="always")
def _score_block(kind, prm, b0, b1, X, Y, Z, NX, NY, NZ, PP, NPX, eps, cos_a, counts, mask, write_mask):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """Every candidate against points ``b0:b1``: counts added to ``counts[k]``."""
    cos2 = cos_a * cos_a
    # Unsigned point indices: with signed ones numba cannot rule out a negative (wrapping)
    # index, and LLVM turns every column read into a gather (5x slower on Zen 4).
    u0, u1 = numba.uint64(b0), numba.uint64(b1)
    for k in range(prm.shape[0]):
        c = 0
        if kind == 0:
            n0, n1, n2, d0 = prm[k, 0], prm[k, 1], prm[k, 2], prm[k, 3]
            for i in range(u0, u1):
                d = X[i] * n0 + Y[i] * n1 + Z[i] * n2 + d0
                cc = NX[i] * n0 + NY[i] * n1 + NZ[i] * n2
                ok = (abs(d) < eps) & (abs(cc) > cos_a)
                c += ok
                if write_mask:
                    mask[k, i] = ok
        elif kind == 3:
            c0, c1, c2 = prm[k, 0], prm[k, 1], prm[k, 2]
            a0, a1, a2 = prm[k, 3], prm[k, 4], prm[k, 5]
            cc2 = c0 * c0 + c1 * c1 + c2 * c2
            ca = c0 * a0 + c1 * a1 + c2 * a2
            cw, sw = np.cos(prm[k, 6]), np.sin(prm[k, 6])
            for i in range(u0, u1):
                h = X[i] * a0 + Y[i] * a1 + Z[i] * a2 - ca
                v2 = max(PP[i] - 2.0 * (X[i] * c0 + Y[i] * c1 + Z[i] * c2) + cc2, 0.0)
                rho = np.sqrt(max(v2 - h * h, 0.0))
                if h * cw + rho * sw >= 0.0:  # on the nappe's side of the apex
                    dist = abs(rho * cw - h * sw)
                else:
                    dist = np.sqrt(v2)
                na = NX[i] * a0 + NY[i] * a1 + NZ[i] * a2
                nw = NPX[i] - (NX[i] * c0 + NY[i] * c1 + NZ[i] * c2) - h * na
                cos = abs(cw * nw / max(rho, _TINY) - sw * na)
                ok = (dist < eps) & (cos > cos_a)
                c += ok
                if write_mask:
                    mask[k, i] = ok
        else:
            c0, c1, c2 = prm[k, 0], prm[k, 1], prm[k, 2]
            cc2 = c0 * c0 + c1 * c1 + c2 * c2
            if kind == 1:
                r = prm[k, 3]
                a0 = a1 = a2 = ca = 0.0
            else:
                r = prm[k, 6]
                a0, a1, a2 = prm[k, 3], prm[k, 4], prm[k, 5]
                ca = c0 * a0 + c1 * a1 + c2 * a2
            lo = max(r - eps, 0.0) ** 2
            hi = (r + eps) ** 2
            for i in range(u0, u1):
                v2 = PP[i] - 2.0 * (X[i] * c0 + Y[i] * c1 + Z[i] * c2) + cc2
                nv = NPX[i] - (NX[i] * c0 + NY[i] * c1 + NZ[i] * c2)
                if kind == 2:
                    h = X[i] * a0 + Y[i] * a1 + Z[i] * a2 - ca
                    nv -= h * (NX[i] * a0 + NY[i] * a1 + NZ[i] * a2)
                    v2 -= h * h
                ok = (v2 > lo) & (v2 < hi) & (nv * nv > cos2 * v2)
                c += ok
                if write_mask:
                    mask[k, i] = ok
        counts[k] += c


@numba.njit(cache=True, nogil=True)
def _kernel(kind, prm, X, Y, Z, NX, NY, NZ, PP, NPX, eps, cos_a, counts, mask, write_mask):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    m = X.shape[0]
    for b0 in range(0, m, _BLOCK):
        b1 = min(m, b0 + _BLOCK)
        _score_block(kind, prm, b0, b1, X, Y, Z, NX, NY, NZ, PP, NPX, eps, cos_a, counts,
                     mask, write_mask)
