"""Efficient RANSAC (Schnabel, Wahl and Klein 2007) for planes, spheres, cylinders, cones, tori.

The loop follows the paper, vectorised in NumPy:

1. **Local sampling (§4.3).** The points are Morton-sorted once; an octree cell at any
   level is then a contiguous run of that order, found by two ``searchsorted`` calls. A
   minimal set is a random point, a random level ``l`` (probabilities ``p_l``) and the
   other points drawn from the point's cell at that level. ``p_l`` adapts to the levels
   whose candidates scored well: ``p_l = x * s_l / sum(s) + (1 - x) / D`` with ``x = 0.9``
   and ``s_l`` the importance-weighted score of level ``l``'s candidates.
2. **Candidates (§4.2).** Every minimal set gives one candidate of each requested kind
   (:mod:`primitives.shapes`), kept only if every point of the set lies within
   ``epsilon`` with its normal within ``alpha``.
3. **Score on subsets (§4.4).** The live points are split into disjoint random subsets
   of sizes ``s0, s0, 2 s0, 4 s0, ...``. A candidate is scored on the first; its score
   on all points is the inverse-hypergeometric estimate with a one-sigma interval. Only
   candidates whose interval overlaps the best one's are scored on more subsets.
4. **Extraction.** The best candidate is taken when the probability of having missed a
   better one, ``(1 - n / (N D 2^(k-1)))^T`` (eq. 2 with local sampling; ``T`` minimal
   sets drawn so far, ``D`` octree levels, ``k`` points per minimal set, ``N`` live
   points), is below ``probability``. Its inliers are the live points within
   ``epsilon`` whose normals deviate less than ``alpha``, restricted to the largest
   connected component of a 2-D bitmap (cell ``cluster_epsilon``) in the primitive's
   parameter space. The primitive is refitted by least squares, its inliers recomputed
   once, and they are removed. The search stops when a primitive of ``min_support``
   points would have been found with probability ``1 - probability``, or when fewer
   than ``min_support`` points remain.

Deviations from the paper (see also :mod:`primitives.shapes`):

* The bitmap connectivity is applied when a candidate is about to be extracted (its score
  then becomes exact and it is compared again), not on every subset score (as CGAL).
* Periodic parametrisations are labelled twice with seams half a turn apart and the two
  labellings joined, instead of the paper's explicit wrap-around handling.
* After an extraction the surviving candidates are re-scored on the first subset only,
  and the subsets are redrawn from the live points whenever half of them are gone.
* Candidates whose scores lie within ``SCORE_TOLERANCE`` (5 %) of the best are not
  refined further to tell them apart (near-duplicates of one surface would otherwise be
  scored on every subset).
* When the bitmap cuts a candidate's score down, candidates sharing most of its
  first-subset hits are scaled by the same factor (now and when drawn later, until the
  next extraction); at most ``MAX_EXACT_TRIES`` bitmap scores are computed per batch
  before more candidates are drawn. This keeps fragmented leftovers (sparse far ground)
  from being bitmap-tested one candidate at a time.
* A refit is kept unless it loses more than 10 % of the inliers.
* Bitmaps much larger than their point count are labelled on the occupied cells only
  (same 8-connectivity, via ``scipy.sparse.csgraph``) instead of ``ndimage.label``.
* Tori (:mod:`primitives.torus`) are searched only when asked for (``shapes``
  containing ``"torus"``); the default ``shapes`` are
  :data:`~primitives.shapes.DEFAULT_KINDS`. A torus needs a minimal set of 4 points,
  so asking for it raises ``k`` of eq. 2 from 3 to 4: twice the minimal sets before the
  search may stop, and other random draws. On the 1 M-point wazir_khan scan (no tori)
  asking for tori drew 2.2 times the minimal sets, took 11 to 29 % longer (about 20 %
  over two interleaved pairs on the 2-core machine) and changed the result: 9 tori took
  surfaces found before as 20 spheres, 9 cylinders and 5 cones. So they stay out of the
  default; on scenes with pipes, elbows or mouldings pass ``shapes=KINDS``. Their
  bitmap unrolls ``(R * phi, r * theta)``, both periodic, labelled twice with both seams
  shifted by half a turn.

Examples
--------
>>> rng = np.random.default_rng(0)
>>> xyz = np.c_[rng.uniform(0, 2, (400, 2)), np.zeros(400)]
>>> normals = np.tile([0.0, 0.0, 1.0], (400, 1))
>>> res = efficient_ransac(xyz, normals, epsilon=0.01, alpha_deg=10, cluster_epsilon=0.3,
...                        min_support=50, rng=0)
>>> [p.kind for p in res.primitives], int((res.labels == 0).sum())
(['plane'], 400)
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterator, Sequence

import numpy as np
import numpy.typing as npt
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from hollowtree.columns import column_max, column_min, column_span
from hollowtree.errors import ConfigError
from hollowtree.params import check_values
from hollowtree.primitives.ransac_params import RansacParams, RansacResult
from hollowtree.primitives.score import (
    FUSED_KINDS,
    PointColumns,
    compatible_counts,
    compatible_mask,
    shared_hits,
)
from hollowtree.primitives.shapes import (
    KINDS,
    MINIMAL_SET_SIZE,
    FailedFit,
    PrimitiveFit,
    candidates_from_minimal_sets,
    compatible,
    distance_and_cosine,
    refine_params,
    surface_coordinates,
    to_fit,
)
from hollowtree.tiling.grid import morton_codes3

__all__ = ["RansacParams", "RansacResult", "efficient_ransac"]

logger = logging.getLogger(__name__)
F64 = npt.NDArray[np.float64]

# Tuning constants (not user parameters).
FIRST_SUBSET = 1024  # points in the first scoring subset
FIRST_BATCH = 512  # minimal sets per batch after an extraction; doubles up to MAX_BATCH
MAX_BATCH = 8192
MAX_POOL = 4096  # candidates kept between batches (the best by upper bound)
LEVEL_MIX = 0.9  # x of §4.3.1
# Scoring blocks are sized to stay in a core's L2 cache: a block's float64 temporaries
# (candidates x points) are 512 KB each. Blocks of 2 M elements were memory-bound and
# 2.5-3x slower.
CHUNK_ELEMENTS = 1 << 16  # candidate x point elements per scoring block
MIN_BLOCK_CANDIDATES = 32  # candidates per block at least (keeps the matrix products efficient)
POINT_CHUNK = 1 << 14  # points per block when one candidate meets all live points
SPARSE_FACTOR = 4  # bitmaps with more cells than 4x the points are labelled sparsely
SCORE_TOLERANCE = 0.05  # candidates within 5 % of the best are not told apart
DUPLICATE_SHARE = 0.5  # share of a candidate's first-subset hits that makes it a known surface
MAX_EXACT_TRIES = 4  # bitmap scores per batch or extraction before the best known one is taken
REFIT_KEEP = 0.9  # a refit is kept unless it loses more than 10 % of the inliers


# ------------------------------------------------------------------------ helpers
def _label_sparse(q: npt.NDArray[np.int64]) -> tuple[npt.NDArray[np.int64], int]:
    """8-connected labels of the occupied cells ``q`` without a dense bitmap."""
    width = int(q[:, 1].max()) + 3
    key = (q[:, 0] + 1) * width + (q[:, 1] + 1)
    cells, inverse = np.unique(key, return_inverse=True)
    rows, cols = [], []
    for offset in (1, width - 1, width, width + 1):  # right, and the three cells above
        pos = np.minimum(np.searchsorted(cells, cells + offset), len(cells) - 1)
        hit = cells[pos] == cells + offset
        rows.append(np.flatnonzero(hit))
        cols.append(pos[hit])
    r, c = np.concatenate(rows), np.concatenate(cols)
    graph = coo_matrix((np.ones(len(r)), (r, c)), shape=(len(cells), len(cells)))
    n_lab, lab = connected_components(graph, directed=False)
    return lab[inverse.ravel()].astype(np.int64), n_lab


def _largest_component(uvs: list[F64], cell: float) -> npt.NDArray[np.bool_]:
    """Mask of the points in the largest 8-connected bitmap component (joined over ``uvs``).

    A dense bitmap labelled by ``scipy.ndimage.label`` where the points fill it; the
    same labelling on the occupied cells only where the bitmap would be mostly empty.
    """
    labs, offset = [], 0
    for uv in uvs:
        q = np.floor((uv - column_min(uv)) / cell).astype(np.int64)
        shape = column_max(q) + 1
        cells = float(shape[0]) * float(shape[1])
        if cells > SPARSE_FACTOR * len(q):
            lab_pts, n_lab = _label_sparse(q)
        else:
            img = np.zeros(tuple(shape), dtype=bool)
            img[q[:, 0], q[:, 1]] = True
            lab, n_lab = ndimage.label(img, structure=np.ones((3, 3), dtype=bool))
            lab_pts = lab[q[:, 0], q[:, 1]].astype(np.int64) - 1
        labs.append(lab_pts + offset)
        offset += n_lab
    comp = labs[0]
    if len(labs) > 1:
        rows = np.concatenate([labs[0], labs[0]])
        cols = np.concatenate([labs[0], labs[1]])
        graph = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(offset, offset))
        _, merged = connected_components(graph, directed=False)
        comp = merged[labs[0]]
    return comp == np.argmax(np.bincount(comp))


def _empty(n: int, reason: str) -> RansacResult:
    return RansacResult(labels=np.full(n, -1, dtype=np.int64), primitives=(), n_candidates=0,
                        stop_reason=reason, failure=FailedFit(reason=reason))


def _blocks(rows: npt.NDArray[np.int64], n_points: int) -> Iterator[tuple[npt.NDArray[np.int64], slice]]:
    """Cache-sized blocks (candidate rows, point slice) covering ``rows`` x ``n_points``."""
    kb = max(MIN_BLOCK_CANDIDATES, CHUNK_ELEMENTS // max(n_points, 1))
    pb = max(1, CHUNK_ELEMENTS // kb)
    for a in range(0, len(rows), kb):
        for b in range(0, n_points, pb):
            yield rows[a:a + kb], slice(b, b + pb)


# ------------------------------------------------------------------------- search
class _Search:
    """The state of one run: live points, octree order, subsets and the candidate pool."""

    Cl: PointColumns  # the live points, subset by subset (``_new_subsets``)

    def __init__(self, P: F64, N: F64, *, kinds: tuple[str, ...], epsilon: float, alpha_deg: float,
                 cluster_epsilon: float, min_support: int, rng: np.random.Generator) -> None:
        self.P, self.N, self.kinds, self.rng = P, N, kinds, rng
        self.eps, self.cos_a = epsilon, math.cos(math.radians(alpha_deg))
        self.ce, self.min_support = cluster_epsilon, min_support
        m = len(P)
        self.alive = np.ones(m, dtype=bool)
        self.n_alive = m
        self.k = max(MINIMAL_SET_SIZE[k] for k in kinds)
        # Octree as one Morton order: every cell of every level is a contiguous run.
        lo = column_min(P)
        self.size = float(column_span(P).max()) * (1 + 1e-9) + 1e-12
        self.depth = int(np.clip(math.floor(math.log2(self.size / max(cluster_epsilon, 3 * epsilon))), 1, 20))
        self.n_levels = self.depth + 1
        q = np.minimum((P - lo) / self.size * (1 << self.depth), (1 << self.depth) - 1).astype(np.uint64)
        codes = morton_codes3(q)
        self.order = np.argsort(codes, kind="stable")
        self.codes = codes[self.order]
        self.level_p = np.full(self.n_levels, 1.0 / self.n_levels)
        self.level_score = np.zeros(self.n_levels)
        self.max_radius = self.size
        self._new_subsets()
        # Candidate pool.
        self.kind_id = np.zeros(0, dtype=np.int64)
        self.params = np.zeros((0, 8))
        self.level = np.zeros(0, dtype=np.int64)
        self.x = np.zeros(0)  # compatible points counted so far
        self.s = np.zeros(0)  # live points looked at so far
        self.n_eval = np.zeros(0, dtype=np.int64)  # subsets evaluated
        self.exact = np.zeros(0, dtype=bool)  # score is the connected component on all points
        # Cached compatibility with the live points of the first subset (for the templates),
        # valid where hits_ok, until the next extraction.
        self.hits = np.zeros((0, 0), dtype=bool)
        self.hits_ok = np.zeros(0, dtype=bool)
        self.templates: list[tuple[npt.NDArray[np.bool_], float]] = []  # (first-subset hits, cut)

    # --------------------------------------------------------------- subsets
    def _new_subsets(self) -> None:
        """Split the live points into random subsets and lay them out subset by subset.

        ``self.live`` lists the live points in that layout and ``self.Cl`` holds them as
        contiguous columns, so subset ``j`` is the slice ``sub_bounds[j]:sub_bounds[j + 1]``
        of the columns: scoring reads it in place. Extractions compact ``live`` and ``Cl``
        in order, which keeps every subset one slice.
        """
        perm = self.rng.permutation(np.flatnonzero(self.alive))
        bounds = [0]
        while bounds[-1] < len(perm):
            bounds.append(min(len(perm), bounds[-1] + max(FIRST_SUBSET, bounds[-1])))
        self.sub_bounds = np.asarray(bounds, dtype=np.int64)
        self.live = perm
        # Memory: the old columns go first, the rows are gathered once each, and |x|^2 and
        # n . x are taken on the gathered rows (the same row-wise products as on all points,
        # so the same values) rather than kept for every point.
        self.Cl = None  # type: ignore[assignment]
        P = self.P[perm]
        pp = np.einsum("ij,ij->i", P, P)
        x, y, z = (np.ascontiguousarray(P[:, j]) for j in range(3))
        N = self.N[perm]
        npx = np.einsum("ij,ij->i", N, P)
        del P
        nx, ny, nz = (np.ascontiguousarray(N[:, j]) for j in range(3))
        del N
        self.Cl = PointColumns(x, y, z, nx, ny, nz, pp, npx)
        self.n_at_subsets = self.n_alive

    @property
    def n_subsets(self) -> int:
        return len(self.sub_bounds) - 1

    def _subset_points(self, subset: int) -> PointColumns:
        """Live points of ``subset`` as columns: views into ``self.Cl``, no copy."""
        a, b = int(self.sub_bounds[subset]), int(self.sub_bounds[subset + 1])
        return PointColumns(*(c[a:b] for c in self.Cl.columns()))

    def _count(self, kind_id: npt.NDArray[np.int64], params: F64, subset: int) -> tuple[F64, int]:
        cols = self._subset_points(subset)
        n = len(cols)
        counts = np.zeros(len(params))
        for kid in np.unique(kind_id):
            rows = np.flatnonzero(kind_id == kid)
            if self.kinds[kid] in FUSED_KINDS:
                counts[rows] = compatible_counts(self.kinds[kid], params[rows], cols, epsilon=self.eps,
                                                 cos_alpha=self.cos_a)
                continue
            for r, sl in _blocks(rows, n):
                P, N, pp, npx = cols.rows(sl)
                ok = compatible(self.kinds[kid], params[r], P, N, epsilon=self.eps,
                                cos_alpha=self.cos_a, sq_norm=pp, normal_dot=npx)
                counts[r] += np.count_nonzero(ok, axis=1)
        return counts, n

    def _score_next(self, rows: npt.NDArray[np.int64]) -> None:
        """Score ``rows`` of the pool on their next subset."""
        for j in np.unique(self.n_eval[rows]):
            r = rows[self.n_eval[rows] == j]
            counts, size = self._count(self.kind_id[r], self.params[r], int(j))
            self.x[r] += counts
            self.s[r] += size
            self.n_eval[r] += 1

    def bounds(self) -> tuple[F64, F64, F64]:
        """Estimated score and its one-sigma interval (inverse hypergeometric, §4.4)."""
        n, s, x = float(self.n_alive), np.minimum(self.s, self.n_alive), np.minimum(self.x, self.s)
        est = -1.0 + (n + 2.0) * (x + 1.0) / (s + 2.0)
        var = (n + 2.0) * (x + 1.0) * (n - s) * (s + 1.0 - x) / ((s + 2.0) ** 2 * (s + 3.0))
        std = np.sqrt(np.maximum(var, 0.0))
        exact = self.exact | (s >= n)
        est = np.where(exact, x, est)
        std = np.where(exact, 0.0, std)
        return est, est - std, est + std

    # ------------------------------------------------------------- sampling
    def draw(self, n_sets: int) -> None:
        """Draw ``n_sets`` local minimal sets, build, verify and score their candidates."""
        rng, codes, k = self.rng, self.codes, self.k
        m = len(codes)
        pos0 = rng.integers(0, m, n_sets)
        lev = rng.choice(self.n_levels, n_sets, p=self.level_p)
        shift = (3 * (self.depth - lev)).astype(np.uint64)
        lo_code = (codes[pos0] >> shift) << shift
        lo = np.searchsorted(codes, lo_code, side="left")
        hi = np.searchsorted(codes, lo_code + (np.uint64(1) << shift), side="left")
        others = lo[:, None] + (rng.random((n_sets, k - 1)) * (hi - lo)[:, None]).astype(np.int64)
        pos = np.concatenate([pos0[:, None], np.minimum(others, m - 1)], axis=1)
        valid = hi - lo >= k
        for i in range(k):
            for j in range(i + 1, k):
                valid &= pos[:, i] != pos[:, j]
        pos, lev = pos[valid], lev[valid]
        pts_idx = self.order[pos]
        pts, nrm = self.P[pts_idx], self.N[pts_idx]
        new_kind, new_params, new_level = [], [], []
        for kid, kind in enumerate(self.kinds):
            kk = MINIMAL_SET_SIZE[kind]
            params, ok = candidates_from_minimal_sets(kind, pts[:, :kk], nrm[:, :kk])
            if kind in ("sphere", "cylinder"):
                r = params[:, 3] if kind == "sphere" else params[:, 6]
                ok &= (r >= self.eps) & (r <= self.max_radius)
            elif kind == "cone":
                ok &= np.linalg.norm(params[:, :3], axis=1) <= 2.0 * self.size
            elif kind == "torus":
                ok &= (params[:, 7] >= self.eps) & (params[:, 6] + params[:, 7] <= self.max_radius)
                ok &= np.linalg.norm(params[:, :3], axis=1) <= 2.0 * self.size
            if not ok.any():
                continue
            params, lv = params[ok], lev[ok]
            d, c = distance_and_cosine(kind, params, pts[ok], nrm[ok])
            keep = np.all((d < self.eps) & (c > self.cos_a), axis=1)
            new_kind.append(np.full(int(keep.sum()), kid))
            new_params.append(params[keep])
            new_level.append(lv[keep])
        if not new_kind:
            return
        kind_id = np.concatenate(new_kind)
        if len(kind_id) == 0:
            return
        start = len(self.kind_id)
        self.kind_id = np.concatenate([self.kind_id, kind_id])
        self.params = np.concatenate([self.params, *new_params])
        self.level = np.concatenate([self.level, *new_level])
        self.x = np.concatenate([self.x, np.zeros(len(kind_id))])
        self.s = np.concatenate([self.s, np.zeros(len(kind_id))])
        self.n_eval = np.concatenate([self.n_eval, np.zeros(len(kind_id), dtype=np.int64)])
        self.exact = np.concatenate([self.exact, np.zeros(len(kind_id), dtype=bool)])
        self.hits = np.concatenate([self.hits, np.zeros((len(kind_id), self.hits.shape[1]), dtype=bool)])
        self.hits_ok = np.concatenate([self.hits_ok, np.zeros(len(kind_id), dtype=bool)])
        new = np.arange(start, len(self.kind_id))
        self._score_next(new)
        if self.templates:
            self._apply_templates(new, self._compatible_first(new), self.templates)
        est, _, _ = self.bounds()
        # Level adaptation (§4.3.1): importance-weighted scores of each level's candidates.
        np.add.at(self.level_score, self.level[new], est[new] / self.level_p[self.level[new]])
        total = self.level_score.sum()
        if total > 0:
            self.level_p = LEVEL_MIX * self.level_score / total + (1.0 - LEVEL_MIX) / self.n_levels
        self.prune()

    def prune(self) -> None:
        """Drop candidates that cannot reach ``min_support``; keep the pool bounded."""
        _, _, upper = self.bounds()
        keep = upper >= self.min_support
        if keep.sum() > MAX_POOL:
            keep &= upper >= np.sort(upper[keep])[-MAX_POOL]
        self._take(np.flatnonzero(keep))

    def _take(self, rows: npt.NDArray[np.int64]) -> None:
        for name in ("kind_id", "params", "level", "x", "s", "n_eval", "exact", "hits", "hits_ok"):
            setattr(self, name, getattr(self, name)[rows])

    # ---------------------------------------------------------- selection
    def pick(self) -> int:
        """Index of the best candidate after refining every overlapping interval."""
        n_sub = self.n_subsets
        while True:
            est, low, upper = self.bounds()
            b = int(np.argmax(est))
            refinable = (self.n_eval < n_sub) & ~self.exact
            # Only a candidate that may beat the best by more than SCORE_TOLERANCE matters.
            overlap = refinable & ((1.0 - SCORE_TOLERANCE) * upper > low[b])
            overlap[b] = False
            if not overlap.any():
                return b
            overlap[b] = refinable[b]
            self._score_next(np.flatnonzero(overlap))

    def inliers(self, kind: str, params: F64) -> npt.NDArray[np.int64]:
        """Live points compatible with the primitive, in its largest bitmap component."""
        hits = []
        if kind in FUSED_KINDS:
            ok = compatible_mask(kind, params[None], self.Cl, epsilon=self.eps, cos_alpha=self.cos_a)
            hits.append(np.flatnonzero(ok[0]))
        else:
            for a in range(0, len(self.live), POINT_CHUNK):
                P, N, pp, npx = self.Cl.rows(slice(a, a + POINT_CHUNK))
                ok = compatible(kind, params[None], P, N, epsilon=self.eps, cos_alpha=self.cos_a,
                                sq_norm=pp, normal_dot=npx)
                hits.append(np.flatnonzero(ok[0]) + a)
        idx = np.sort(self.live[np.concatenate(hits)]) if hits else np.zeros(0, dtype=np.int64)
        if len(idx) < 2:
            return idx
        return idx[_largest_component(surface_coordinates(kind, params, self.P[idx]), self.ce)]

    def make_exact(self, b: int) -> None:
        """Replace candidate ``b``'s estimate by its connected score on all live points."""
        before = float(self.bounds()[0][b])
        self.x[b] = len(self.inliers(self.kinds[self.kind_id[b]], self.params[b]))
        self.s[b] = self.n_alive
        self.n_eval[b] = self.n_subsets
        self.exact[b] = True
        ratio = self.x[b] / max(before, 1.0)
        if ratio < 1.0 - SCORE_TOLERANCE:
            # Candidates that cover mostly the same points of the first subset are cut
            # down by the bitmap alike: remember the cut and scale them all, now and
            # when they are drawn later, instead of testing each in turn.
            hits = self._compatible_first(np.arange(len(self.kind_id)))
            self.templates.append((hits[b].copy(), ratio))
            self._apply_templates(np.arange(len(self.kind_id)), hits, self.templates[-1:])

    def _apply_templates(self, rows: npt.NDArray[np.int64], hits: npt.NDArray[np.bool_],
                         templates: list[tuple[npt.NDArray[np.bool_], float]]) -> None:
        for mask, ratio in templates:
            own, shared = shared_hits(hits, mask)
            same = (shared >= DUPLICATE_SHARE * np.maximum(own, 1)) & ~self.exact[rows]
            self.x[rows[same]] *= ratio

    def _compatible_first(self, rows: npt.NDArray[np.int64]) -> npt.NDArray[np.bool_]:
        """Compatibility of candidates ``rows`` with the live points of the first subset
        (cached per candidate until the next extraction)."""
        cols = self._subset_points(0)
        n = len(cols)
        if self.hits.shape[1] != n:
            self.hits = np.zeros((len(self.kind_id), n), dtype=bool)
            self.hits_ok[:] = False
        todo = rows[~self.hits_ok[rows]]
        for kid in np.unique(self.kind_id[todo]):
            sel = todo[self.kind_id[todo] == kid]
            if self.kinds[kid] in FUSED_KINDS:
                self.hits[sel] = compatible_mask(self.kinds[kid], self.params[sel], cols, epsilon=self.eps,
                                                 cos_alpha=self.cos_a)
                continue
            for r, sl in _blocks(sel, n):
                P, N, pp, npx = cols.rows(sl)
                self.hits[r, sl] = compatible(self.kinds[kid], self.params[r], P, N, epsilon=self.eps,
                                              cos_alpha=self.cos_a, sq_norm=pp, normal_dot=npx)
        self.hits_ok[todo] = True
        return self.hits[rows]

    def extract(self, b: int) -> tuple[str, F64, npt.NDArray[np.int64]] | None:
        """Refit candidate ``b``, take its inliers out; None if it falls below min_support."""
        kind, params = self.kinds[self.kind_id[b]], self.params[b]
        idx = self.inliers(kind, params)
        self._take(np.flatnonzero(np.arange(len(self.kind_id)) != b))
        if len(idx) >= 3:
            refit = refine_params(kind, params, self.P[idx], rng=self.rng)
            if np.all(np.isfinite(refit)):
                idx2 = self.inliers(kind, refit)
                if len(idx2) >= REFIT_KEEP * len(idx):  # guard against a diverged refit
                    params, idx = refit, idx2
        if len(idx) < self.min_support:
            return None
        self.alive[idx] = False
        self.hits_ok[:] = False
        self.n_alive -= len(idx)
        keep = self.alive[self.order]
        self.order, self.codes = self.order[keep], self.codes[keep]
        keep = self.alive[self.live]
        self.live = self.live[keep]
        cols = list(self.Cl.columns())
        self.Cl = None  # type: ignore[assignment]
        for i, c in enumerate(cols):  # one column at a time: 8 bytes a point at once, not 64
            cols[i] = c[keep]
        self.Cl = PointColumns(*cols)
        del cols
        self.sub_bounds = np.concatenate(([0], np.cumsum(keep)))[self.sub_bounds]
        self.level_score *= 0.5
        self.templates = []
        if self.n_alive < 0.5 * self.n_at_subsets:
            self._new_subsets()
        # Scores are stale: start every survivor again from the first subset.
        self.x[:] = 0.0
        self.s[:] = 0.0
        self.n_eval[:] = 0
        self.exact[:] = False
        if len(self.kind_id) and self.n_alive:
            self._score_next(np.arange(len(self.kind_id)))
            self.prune()
        return kind, params, idx

    def miss_probability(self, score: float, n_drawn: int) -> float:
        """Probability that local sampling missed a shape of ``score`` points (eq. 2)."""
        if self.n_alive <= 0:
            return 0.0
        p = score / (self.n_alive * self.n_levels * 2.0 ** (self.k - 1))
        p = min(max(p, 0.0), 1.0 - 1e-15)
        return math.exp(n_drawn * math.log1p(-p))


# ----------------------------------------------------------------------- the kernel
def efficient_ransac(
    xyz: F64,
    normals: F64,
    *,
    epsilon: float,
    alpha_deg: float,
    cluster_epsilon: float,
    min_support: int,
    probability: float = RansacParams.probability,
    shapes: Sequence[str] = RansacParams.shapes,
    max_iterations: int | None = RansacParams.max_iterations,
    rng: int | np.random.Generator | None = None,
) -> RansacResult:
    """Detect planes, spheres, cylinders, cones and (when asked) tori with Efficient RANSAC.

    Parameters
    ----------
    xyz : ndarray of shape (n_points, 3)
        Local coordinates in metres (float64). Not modified.
    normals : ndarray of shape (n_points, 3)
        Unit normals, orientation free. Points with non-finite or zero normals stay
        unassigned (``-1``).
    epsilon : float
        Largest distance of an inlier to the surface (m).
    alpha_deg : float
        Largest deviation of an inlier's normal from the surface normal (degrees).
    cluster_epsilon : float
        Cell of the connectivity bitmap (m): inliers must form one connected patch.
    min_support : int
        Fewest points of a primitive.
    probability : float, default 0.01
        Accepted probability of missing a primitive (of the best score when extracting,
        of ``min_support`` points when stopping).
    shapes : sequence of str, default :data:`~primitives.shapes.DEFAULT_KINDS`
        Kinds to look for, from :data:`~primitives.shapes.KINDS`. The default leaves
        tori out (they slow the search; see the module notes): pass ``KINDS`` or include
        ``"torus"`` to find them.
    max_iterations : int or None
        Cap on minimal sets drawn (None: only the probabilistic stop).
    rng : int, Generator or None
        Seed; the result depends only on the inputs and ``rng``.

    Returns
    -------
    RansacResult
        ``labels`` and ``primitives``; ``failure`` (a falsy :class:`FailedFit`) says why
        when the input could not be searched (too few finite points, all points
        identical or collinear).

    Raises
    ------
    ConfigError
        If a parameter is out of range or the arrays have the wrong shape.

    Notes
    -----
    Memory: ``O(n_points)``, about 150 bytes per point searched: the centred points and
    unit normals (48), the Morton order (16), the subsets' columns (64: points, normals,
    ``|x|^2`` and ``n . x``, the last two taken per layout rather than kept for every point),
    the live list and the labels (16); the inputs are not copied beyond that, and a row
    index is kept only when some points are left out. Plus ``CHUNK_ELEMENTS`` (2 M)
    float64 elements per scoring block and one bitmap of at most 4 cells per inlier.

    Examples
    --------
    >>> xyz = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [0.5, 0.5, 0], [0.2, 0.7, 0]])
    >>> res = efficient_ransac(xyz, np.tile([0.0, 0, 1], (6, 1)), epsilon=0.01, alpha_deg=10,
    ...                        cluster_epsilon=1.0, min_support=5, rng=0)
    >>> res.labels.tolist(), res.primitives[0].kind
    ([0, 0, 0, 0, 0, 0], 'plane')
    """
    shapes = tuple(shapes) if isinstance(shapes, (list, tuple)) else shapes
    check_values(RansacParams, dict(epsilon=epsilon, alpha_deg=alpha_deg, cluster_epsilon=cluster_epsilon,
                                    min_support=min_support, probability=probability, shapes=shapes,
                                    max_iterations=max_iterations), "efficient_ransac")
    kinds = tuple(k for k in KINDS if k in shapes)
    rng = np.random.default_rng(rng)
    xyz = np.asarray(xyz, dtype=np.float64)
    normals = np.asarray(normals, dtype=np.float64)
    if xyz.ndim != 2 or xyz.shape[1] != 3 or normals.shape != xyz.shape:
        raise ConfigError(f"efficient_ransac needs xyz and normals of the same shape (n_points, 3); "
                          f"got {xyz.shape} and {normals.shape}.")
    n = len(xyz)
    norm = np.linalg.norm(normals, axis=1)
    ok = np.isfinite(xyz).all(axis=1) & np.isfinite(norm) & (norm > 1e-6)
    idx = np.flatnonzero(ok)
    if len(idx) < min_support:
        return _empty(n, f"{len(idx)} points with finite coordinates and normals; fewer than "
                         f"min_support={min_support}")
    centre = xyz[idx].mean(axis=0)
    P = xyz[idx] - centre
    N = normals[idx] / norm[idx, None]
    # Every point searched (the usual case): the labels need no row index (8 bytes a point).
    rows: npt.NDArray[np.int64] | None = None if len(idx) == n else idx
    del norm, ok, idx
    spread = np.sqrt(np.maximum(np.linalg.eigvalsh(np.cov(P.T)), 0.0))
    if spread[-1] < 0.1 * epsilon:
        return _empty(n, "all points are identical (within epsilon / 10)")
    if spread[-2] < 0.1 * epsilon:
        return _empty(n, "all points are collinear (within epsilon / 10)")

    search = _Search(P, N, kinds=kinds, epsilon=epsilon, alpha_deg=alpha_deg,
                     cluster_epsilon=cluster_epsilon, min_support=min_support, rng=rng)
    local_labels = np.full(len(P), -1, dtype=np.int64)
    fits: list[PrimitiveFit] = []
    drawn, batch, tries = 0, FIRST_BATCH, 0
    while True:
        if search.n_alive < min_support:
            reason = "fewer than min_support points remain"
            break
        if search.miss_probability(min_support, drawn) < probability:
            reason = "a primitive of min_support points would have been found"
            break
        if max_iterations is not None and drawn >= max_iterations:
            reason = "max_iterations minimal sets drawn"
            break
        n_sets = batch if max_iterations is None else min(batch, max_iterations - drawn)
        search.draw(n_sets)
        drawn += n_sets
        extracted, tries = False, 0
        while len(search.kind_id) and search.n_alive >= min_support:
            b = search.pick()
            est, _, _ = search.bounds()
            if search.miss_probability(est[b], drawn) > probability:
                break
            if not search.exact[b] and tries >= MAX_EXACT_TRIES and not search.exact.any():
                break  # the estimates are not trustworthy here: draw more candidates first
            if not search.exact[b] and tries >= MAX_EXACT_TRIES:
                # The subset estimates keep collapsing under the bitmap test: take the
                # best candidate whose connected score is known.
                exact_rows = np.flatnonzero(search.exact)
                b = int(exact_rows[np.argmax(search.x[exact_rows])])
                if search.miss_probability(search.x[b], drawn) > probability:
                    break
            elif not search.exact[b]:
                search.make_exact(b)
                tries += 1
                est, _, _ = search.bounds()
                if est[b] < min_support:
                    search.prune()
                    continue
                if est[b] < (1.0 - SCORE_TOLERANCE) * est.max():
                    continue  # the bitmap cut it down; others may now be better
            out = search.extract(b)
            if out is None:
                continue
            kind, params, inl = out
            tries = 0
            local_labels[inl] = len(fits)
            fits.append(to_fit(kind, params, P[inl], centre))
            logger.debug("extracted %s with %d points after %d minimal sets", kind, len(inl), drawn)
            extracted = True
        batch = FIRST_BATCH if extracted else min(2 * batch, MAX_BATCH)
    del search
    if rows is None:
        labels = local_labels
    else:
        labels = np.full(n, -1, dtype=np.int64)
        labels[rows] = local_labels
    return RansacResult(labels=labels, primitives=tuple(fits), n_candidates=drawn, stop_reason=reason)
