"""Contacts between segments: which segments touch, for grouping them into elements.

An architectural element is rarely one primitive: RANSAC cuts an onion dome into sphere
patches and a free cluster, a minaret into cylinder and cone stages and the balconies
between them. :func:`segment_contacts` finds the pairs of segments whose points come
within ``gap`` of each other (counted on a voxel subsample, so a dense scan costs little
more than a sparse one); the coarse stage joins the touching segments that are not large
planes into one element group, the unit the hierarchical tree then splits
(docs/method.md, "Element groups").
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from scipy.spatial import cKDTree

from primitives._validation import as_xyz
from tiling.errors import ConfigError

__all__ = ["segment_contacts"]


def _voxel_representatives(xyz: npt.NDArray[np.float64], segment: npt.NDArray[np.int64], size: float
                           ) -> npt.NDArray[np.int64]:
    """Row of one point per (voxel of edge ``size``, segment) pair."""
    v = np.floor(xyz / size).astype(np.int64)
    v -= v.min(axis=0)
    dims = v.max(axis=0) + 1
    n_seg = int(segment.max()) + 1
    if float(np.prod(dims.astype(np.float64))) * n_seg < 2.0**62:
        key = ((v[:, 0] * dims[1] + v[:, 1]) * dims[2] + v[:, 2]) * n_seg + segment
        _, first = np.unique(key, return_index=True)
    else:  # an extent too large for one int64 key: unique rows (slower, same answer)
        _, first = np.unique(np.c_[v, segment], axis=0, return_index=True)
    return np.sort(first)


def segment_contacts(
    xyz: npt.ArrayLike, segment: npt.ArrayLike, gap: float, *, min_contacts: int = 3
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """Pairs of segments that touch: points of both within ``gap`` of each other.

    The points of each segment are thinned to one per voxel of edge ``gap / 2`` first;
    a pair of representatives of two segments within ``gap`` is one contact.

    Parameters
    ----------
    xyz : array-like of shape (n, 3)
        Point coordinates (metres).
    segment : array-like of int, shape (n,)
        Segment of each point; 0 = none (ignored).
    gap : float
        Largest distance between two points of touching segments, metres (> 0).
    min_contacts : int
        Pairs with fewer contacts are dropped (a stray point is not a contact).

    Returns
    -------
    a, b, count : ndarrays of int64
        Segment pairs with ``a < b`` in ascending order, and their contact counts.

    Examples
    --------
    >>> x = np.c_[np.linspace(0, 1, 11), np.zeros(11), np.zeros(11)]
    >>> pts = np.r_[x, x + [1.1, 0, 0], x + [5, 0, 0]]
    >>> a, b, n = segment_contacts(pts, np.repeat([1, 2, 3], 11), 0.3, min_contacts=1)
    >>> a.tolist(), b.tolist()
    ([1], [2])
    """
    p = as_xyz(xyz, "segment_contacts")
    seg = np.asarray(segment, dtype=np.int64).reshape(-1)
    if len(seg) != len(p):
        raise ConfigError(f"The 'segment' parameter of segment_contacts must have one entry per point "
                         f"({len(p)}). Got {len(seg)} instead.")
    if not (np.isfinite(gap) and gap > 0):
        raise ConfigError(f"The 'gap' parameter of segment_contacts must be a float in the range (0.0, inf). "
                         f"Got {gap!r} instead.")
    empty = np.zeros(0, dtype=np.int64)
    has = np.flatnonzero(seg > 0)
    if len(np.unique(seg[has])) < 2:
        return empty, empty, empty
    p, seg = p[has], seg[has]
    rep = _voxel_representatives(p, seg, gap / 2.0)
    q, s = p[rep], seg[rep]
    pairs = cKDTree(q).query_pairs(gap, output_type="ndarray")
    if not len(pairs):
        return empty, empty, empty
    sa, sb = s[pairs[:, 0]], s[pairs[:, 1]]
    other = sa != sb
    lo, hi = np.minimum(sa[other], sb[other]), np.maximum(sa[other], sb[other])
    n_seg = int(seg.max()) + 1
    code, count = np.unique(lo * n_seg + hi, return_counts=True)
    keep = count >= min_contacts
    code, count = code[keep], count[keep]
    return code // n_seg, code % n_seg, count.astype(np.int64)
