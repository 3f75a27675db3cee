"""One element split over two element groups is one instance: the merge after the tree.

The tree works on one element group at a time (the coarse stage's connected segments),
so an arch whose front face went to one group and its soffit and back to another comes
out as two arch instances, each about half the arch: neither covers it with IoU 0.5
(Khudabad's 12 bays, docs/decisions/method.md). After every group's tree, two instances of the
same class from different groups are one when their bounding boxes, each widened by
``pad`` metres, overlap by at least ``min_overlap`` of the box that the smaller of the
two extents on each axis make (a portal's front face, 1 m deep, and its passage behind
it, 3 m deep, overlap by 0.8 m: most of the face's depth, a third of the passage's box)
and, along the wall (the horizontal axis on which the two boxes together are longer),
by at least ``min_overlap`` of their joint length: the two halves of a bay share its
span along the wall and its height, while neighbouring bays share only a pier's edge,
stacked storeys only a band, and a bay lying inside the box of a large instance of
another shape (a minaret's side called arch) only a small part of that box's length.
Minarets (``stacked``) are also one when their widened footprints overlap by at least
``min_overlap`` of the smaller footprint and their widened heights meet: a minaret is one
shaft, whose lower side face and far side, or lower and upper stretches, can come from
different groups. And a piece of another class that stands under or on a minaret the
same way, by ``into_overlap`` of the smaller footprint (``into``: an `arch`), is part of it and takes its class (:func:`merged_classes`):
HollowNet calls the lower 11 m of a Wazir Khan corner minaret, with its balcony, `arch`.
Within a group the tree's own split stands. This is not in the paper (its tree never
sees two groups at once).

Pure NumPy.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from hollowtree.classes import ClassId

__all__ = ["MERGE_CLASSES", "MERGE_INTO", "MERGE_INTO_OVERLAP", "MERGE_MIN_OVERLAP", "MERGE_PAD", "MERGE_SHAFT_SPREAD",
           "MERGE_STACKED", "merge_instances",
           "merged_classes"]

#: Classes whose instances are merged across element groups.
MERGE_CLASSES: tuple[int, ...] = (int(ClassId.ARCH), int(ClassId.DOME), int(ClassId.MINARET))
#: Classes whose instances are also merged when one stands on the other: a minaret is
#: one shaft, so two of its pieces (a side face and the far side, a lower and an upper
#: stretch) are one when their footprints overlap and their heights meet.
MERGE_STACKED: tuple[int, ...] = (int(ClassId.MINARET),)
#: Pairs ``(a, b)``: an instance of class ``a`` stacked with one of class ``b`` of another
#: group (as ``MERGE_STACKED``: footprints overlapping by ``min_overlap`` of the smaller,
#: heights meeting) is part of it and takes class ``b`` (:func:`merged_classes`).
MERGE_INTO: tuple[tuple[int, int], ...] = ((int(ClassId.ARCH), int(ClassId.MINARET)),)
#: Widening of each instance's box (metres): a face (a plane, its box flat) gets a body.
MERGE_PAD = 0.25
#: Share that the two widened boxes' intersection must cover of the box made by the
#: smaller extent on each axis, their overlap along the wall of their joint length, and
#: (``MERGE_STACKED``) their footprints' overlap of the smaller footprint.
MERGE_MIN_OVERLAP = 0.6
#: Share of the smaller footprint that an ``into`` piece and the instance it joins must
#: overlap by (since tree-v15; ``MERGE_MIN_OVERLAP`` before): a Wazir Khan corner minaret's
#: lower side with the wall strip beside it, called arch, covers 59 % of the shaft's
#: footprint on one seed (74 % on another); other arches meeting a minaret's box at most 30 %.
MERGE_INTO_OVERLAP = 0.5
#: ``MERGE_STACKED`` pieces side by side (one shaft's halves, cut apart at a tile's edge) are
#: one when their widened boxes meet and together they are at most this many times as long
#: in plan (the larger horizontal extent) as the longer of the two: two halves of a round
#: bastion make one as wide as either; two towers side by side make one twice as wide.
MERGE_SHAFT_SPREAD = 1.5
_PAIR_BLOCK = 1 << 21


def _find(parent: npt.NDArray[np.int64], i: int) -> int:
    while parent[i] != i:
        parent[i] = parent[parent[i]]
        i = int(parent[i])
    return i


def merge_instances(instance: npt.ArrayLike, class_id: npt.ArrayLike, group: npt.ArrayLike,
                    bbox: npt.ArrayLike, n_instances: int, *, classes: tuple[int, ...] = MERGE_CLASSES,
                    pad: float = MERGE_PAD, min_overlap: float = MERGE_MIN_OVERLAP,
                    stacked: tuple[int, ...] = MERGE_STACKED,
                    into: tuple[tuple[int, int], ...] = MERGE_INTO,
                    into_overlap: float = MERGE_INTO_OVERLAP,
                    shaft_spread: float = MERGE_SHAFT_SPREAD) -> npt.NDArray[np.uint32]:
    """The map from instance ids ``0..n_instances`` to merged ids (``map[0] == 0``; an
    instance kept alone maps to itself, a merged set to its smallest id).

    Parameters
    ----------
    instance : array-like of int, shape (m,)
        Instance id of each instance's node (> 0).
    class_id, group : array-like of int, shape (m,)
        Its class and its element group (any id, e.g. the group's first segment).
    bbox : array-like of float, shape (m, 6)
        Its bounding box, ``xmin, ymin, zmin, xmax, ymax, zmax`` (metres).
    n_instances : int
        The largest instance id.

    Examples
    --------
    >>> box = [[0, 0, 0, 4, 0, 6], [0, 0, 0, 4, 1.2, 8], [4, 0, 0, 8, 1.2, 8],  # a face, its bay, the next bay
    ...        [4, -3, 0, 11, 6, 12]]  # and a large box around the next bay, of another group
    >>> merge_instances([1, 2, 3, 4], [4, 4, 4, 4], [10, 11, 11, 12], box, 4).tolist()
    [0, 1, 1, 3, 4]
    >>> shaft = [[0, 0, 0, 2, 4, 11], [0, 0, 0, 5, 5, 23], [0, 0, 23.3, 5, 5, 31], [9, 0, 0, 14, 5, 30]]
    >>> merge_instances([1, 2, 3, 4], [6, 6, 6, 6], [10, 11, 12, 13], shaft, 4).tolist()  # a minaret's pieces
    [0, 1, 1, 1, 4]
    >>> merge_instances([1, 2, 3, 4], [4, 4, 4, 4], [10, 11, 12, 13], shaft, 4, into=()).tolist()  # arches do not
    [0, 1, 2, 3, 4]
    >>> merge_instances([1, 2, 3, 4], [4, 6, 6, 6], [10, 11, 12, 13], shaft, 4).tolist()  # an arch under a minaret
    [0, 1, 1, 1, 4]
    """
    inst = np.asarray(instance, dtype=np.int64).reshape(-1)
    cls = np.asarray(class_id, dtype=np.int64).reshape(-1)
    grp = np.asarray(group, dtype=np.int64).reshape(-1)
    box = np.asarray(bbox, dtype=np.float64).reshape(-1, 6)
    if not (len(inst) == len(cls) == len(grp) == len(box)):
        raise ValueError("merge_instances needs one class, group and box per instance; got "
                         f"{len(inst)} instances, {len(cls)} classes, {len(grp)} groups, {len(box)} boxes")
    if len(inst) and (inst.min() < 1 or inst.max() > n_instances):
        raise ValueError(f"The 'instance' parameter of merge_instances must hold ids in 1..{n_instances}.")
    parent = np.arange(n_instances + 1, dtype=np.int64)
    for c in classes:
        sel = np.flatnonzero(cls == c)
        if len(sel) < 2:
            continue
        lo, hi = box[sel, :3] - pad, box[sel, 3:] + pad
        ext = hi - lo
        area = ext[:, 0] * ext[:, 1]
        ids, g = inst[sel], grp[sel]
        # Every pair of the class, _PAIR_BLOCK pairs at a time.
        step = max(1, _PAIR_BLOCK // len(sel))
        for r0 in range(0, len(sel), step):
            r = slice(r0, r0 + step)
            side = np.clip(np.minimum(hi[r, None], hi[None]) - np.maximum(lo[r, None], lo[None]), 0, None)
            inter = np.prod(side, axis=2)
            # Along the wall: the horizontal axis on which the pair's union is longer.
            span = np.maximum(hi[r, None, :2], hi[None, :, :2]) - np.minimum(lo[r, None, :2], lo[None, :, :2])
            wall = np.argmax(span, axis=2)[..., None]
            common = np.take_along_axis(np.clip(np.minimum(hi[r, None, :2], hi[None, :, :2])
                                                - np.maximum(lo[r, None, :2], lo[None, :, :2]), 0, None), wall, 2)
            ok = ((inter >= min_overlap * np.prod(np.minimum(ext[r, None], ext[None]), axis=2))
                  & (common[..., 0] >= min_overlap * np.take_along_axis(span, wall, 2)[..., 0]))
            if c in stacked:  # one shaft: footprints that overlap, heights that meet, or side by side
                foot = side[..., 0] * side[..., 1]
                ok |= ((foot >= min_overlap * np.minimum(area[r, None], area[None])) & (side[..., 2] > 0))
                longest = np.maximum(ext[r, None, :2].max(axis=2), ext[None, :, :2].max(axis=2))
                ok |= (side > 0).all(axis=2) & (span.max(axis=2) <= shaft_spread * longest)
            ok &= g[r, None] != g[None]
            a, b = np.nonzero(ok)
            _union(parent, ids[r][a], ids[b])
    for ca, cb in into:  # a piece of class ca stacked with an instance of class cb
        sa, sb = np.flatnonzero(cls == ca), np.flatnonzero(cls == cb)
        if not len(sa) or not len(sb):
            continue
        la, ha, lb, hb = box[sa, :3] - pad, box[sa, 3:] + pad, box[sb, :3] - pad, box[sb, 3:] + pad
        area_a, area_b = np.prod(ha[:, :2] - la[:, :2], axis=1), np.prod(hb[:, :2] - lb[:, :2], axis=1)
        step = max(1, _PAIR_BLOCK // len(sb))
        for r0 in range(0, len(sa), step):
            r = slice(r0, r0 + step)
            side = np.clip(np.minimum(ha[r, None], hb[None]) - np.maximum(la[r, None], lb[None]), 0, None)
            ok = ((side[..., 0] * side[..., 1] >= into_overlap * np.minimum(area_a[r, None], area_b[None]))
                  & (side[..., 2] > 0) & (grp[sa][r, None] != grp[sb][None]))
            a, b = np.nonzero(ok)
            _union(parent, inst[sa][r][a], inst[sb][b])
    return np.array([_find(parent, i) for i in range(n_instances + 1)], dtype=np.uint32)


def _union(parent: npt.NDArray[np.int64], left: npt.NDArray[np.int64], right: npt.NDArray[np.int64]) -> None:
    """Join the sets of each pair; a set's id is its smallest member."""
    for i, j in zip(left.tolist(), right.tolist(), strict=True):
        ri, rj = _find(parent, i), _find(parent, j)
        if ri != rj:
            parent[max(ri, rj)] = min(ri, rj)


def merged_classes(instance: npt.ArrayLike, class_id: npt.ArrayLike, instance_map: npt.ArrayLike, *,
                   into: tuple[tuple[int, int], ...] = MERGE_INTO) -> npt.NDArray[np.uint8]:
    """The class of every instance id after the merge (:func:`merge_instances`'s map):
    its own, unless its merged set holds an instance of class ``b`` of a pair ``(a, b)``
    of ``into`` and it is of class ``a``; then ``b``. Index 0 (no instance) holds 0.

    >>> merged_classes([1, 2, 3], [4, 6, 4], [0, 1, 1, 3]).tolist()  # 1 (arch) joined 2 (minaret)
    [0, 6, 6, 4]
    """
    inst = np.asarray(instance, dtype=np.int64).reshape(-1)
    cls = np.asarray(class_id, dtype=np.int64).reshape(-1)
    imap = np.asarray(instance_map, dtype=np.int64).reshape(-1)
    out = np.zeros(len(imap), dtype=np.uint8)
    out[inst] = cls
    for ca, cb in into:
        has_b = np.zeros(len(imap), dtype=bool)
        has_b[imap[inst[cls == cb]]] = True
        member = np.flatnonzero((out == ca) & has_b[imap])
        out[member] = cb
    out[0] = 0
    return out
