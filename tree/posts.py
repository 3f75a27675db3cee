"""Posts under a slab (not in the paper): the columns of a pavilion, a colonnade or a
portico cut out of a node, one slice of the node at a time (docs/method.md, "Posts under
a slab"). :func:`tree.build.build_tree` cuts them out when HollowNet calls them pillars."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from scipy import ndimage

from hollowtree.arrays import IntArray
from hollowtree.tree.sequences import SequenceParams, _as_xyz

__all__ = ["posts"]


#: Height (metres) of the horizontal slices :func:`posts` looks at one by one.
POST_SLICE = 0.25
#: A post is at least this tall (metres), this many times taller than it is wide, and at
#: least :data:`POST_MIN_WIDTH` metres across (a scaffold's tube is no column).
POST_MIN_HEIGHT = 1.0
POST_SLENDER = 1.5
POST_MIN_WIDTH = 0.1
#: A post's slice above or below may cover at most this many times its first slice's cells
#: (a capital or a base); a wider one is the slab or the floor the post stands between.
POST_MAX_GROWTH = 4.0
#: A piece of a slice counts as a post's cross-section from this many points.
POST_MIN_SLICE_POINTS = 5
#: How many slices (those with the most pieces first) :func:`posts` grows posts from.
POST_TRIES = 16


def posts(xyz: npt.ArrayLike, *, params: SequenceParams | None = None) -> tuple[IntArray, ...] | None:
    """The posts of a node: columns standing apart under one slab or beam (a pavilion's
    columns, a colonnade), which touch through it and so are one part for :func:`parts`.

    The node is cut into horizontal slices :data:`POST_SLICE` high and each slice's
    occupied ``params.part_gap`` cells into pieces (8-connected). From each of the
    :data:`POST_TRIES` slices with the most pieces of at least :data:`POST_MIN_SLICE_POINTS`
    points, each piece grows into a post up and down one slice at a time while the slice
    holds exactly one piece over it, that piece over nothing else, and no wider than
    :data:`POST_MAX_GROWTH` times the first (a capital, not the slab). A post is kept when
    it is at least :data:`POST_MIN_HEIGHT` tall, :data:`POST_SLENDER` times its width,
    :data:`POST_MIN_WIDTH` wide and ``params.min_points`` points. The shafts of a clustered
    pillar touch: one piece, one post.

    Returns the posts' point indices (in the order of their lowest index), or None when
    fewer than two are found (or ``params.part_gap`` is 0). What the posts carry and stand
    on is the rest of the node. Like :func:`parts` this is not a split by itself:
    :func:`tree.build.build_tree` cuts the posts out when HollowNet calls them pillars.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> cols = [rng.uniform(-0.15, 0.15, (800, 3)) * [1, 1, 0] + [x, 0, 0] + rng.uniform(0, 3, (800, 1)) * [0, 0, 1]
    ...         for x in (0.0, 2.0, 4.0)]
    >>> slab = rng.uniform(0, 1, (1500, 3)) * [5.0, 1.0, 0.3] + [-0.5, -0.5, 3.0]
    >>> [round(len(c), -2) for c in posts(np.vstack(cols + [slab]))]
    [800, 800, 800]
    >>> posts(slab) is None
    True
    """
    a = _as_xyz(xyz)
    params = params or SequenceParams()
    cell = params.part_gap
    if cell <= 0 or len(a) < 2 * params.min_points:
        return None
    lo = a.min(axis=0)
    ij = ((a[:, :2] - lo[:2]) * (1.0 / cell)).astype(np.int64)
    k = ((a[:, 2] - lo[2]) * (1.0 / POST_SLICE)).astype(np.int64)
    shape = (int(ij[:, 0].max()) + 1, int(ij[:, 1].max()) + 1, int(k.max()) + 1)
    if shape[2] * POST_SLICE < POST_MIN_HEIGHT or np.prod(shape, dtype=np.float64) > 3e7:
        return None
    occ = np.zeros(shape, dtype=bool)
    occ[ij[:, 0], ij[:, 1], k] = True
    structure = np.zeros((3, 3, 3), dtype=bool)
    structure[:, :, 1] = True  # pieces within one slice, 8-connected
    lab, n_lab = ndimage.label(occ, structure=structure)
    piece = lab[ij[:, 0], ij[:, 1], k]  # 1..n_lab
    n_pts = np.bincount(piece, minlength=n_lab + 1)
    area = np.bincount(lab.ravel(), minlength=n_lab + 1)
    slice_of = np.zeros(n_lab + 1, dtype=np.int64)
    slice_of[piece] = k
    solid = n_pts >= POST_MIN_SLICE_POINTS
    solid[0] = False
    per_slice = np.bincount(slice_of[solid], minlength=shape[2])
    if per_slice.max() < 2:
        return None
    # Pieces of neighbouring slices that share a cell: (lower, upper) pairs.
    below, above = lab[:, :, :-1], lab[:, :, 1:]
    both = (below > 0) & (above > 0)
    up: dict[int, list[int]] = {}
    down: dict[int, list[int]] = {}
    for lower, upper in np.unique(np.c_[below[both], above[both]], axis=0).tolist():
        up.setdefault(lower, []).append(upper)
        down.setdefault(upper, []).append(lower)
    order = np.argsort(piece, kind="stable")
    first = np.searchsorted(piece[order], np.arange(n_lab + 2))

    def grown(k0: int) -> list[IntArray]:
        """The posts whose cross-sections are the pieces of slice ``k0``."""
        seeds = np.flatnonzero(solid & (slice_of == k0)).tolist()
        found = []
        for q in seeds:
            chain = [q]
            limit = POST_MAX_GROWTH * area[q] + 4
            for step, back in ((up, down), (down, up)):
                cur = q
                while True:
                    nxt = step.get(cur, [])
                    if len(nxt) != 1 or area[nxt[0]] > limit or back.get(nxt[0], []) != [cur]:
                        break
                    cur = nxt[0]
                    chain.append(cur)
            m = np.concatenate([order[first[c]:first[c + 1]] for c in chain])
            if len(m) < params.min_points:
                continue
            height = float(np.ptp(a[m, 2])) + POST_SLICE
            w = float(np.ptp(a[m, :2], axis=0).max())
            if height >= POST_MIN_HEIGHT and height >= POST_SLENDER * (w + cell) and w >= POST_MIN_WIDTH:
                found.append(np.sort(m).astype(np.int64))
        return found

    # The slices with the most pieces first; the one that gives the most posts wins.
    found: list[IntArray] = []
    for k0 in np.argsort(-per_slice, kind="stable")[:POST_TRIES]:
        if per_slice[k0] < max(2, len(found) + 1):
            break
        cand = grown(int(k0))
        if len(cand) > len(found):
            found = cand
    if len(found) < 2:
        return None
    return tuple(sorted(found, key=lambda c: int(c[0])))
