"""Acceptance tests of the hierarchical tree (issue 6) on scenes scanned in memory.

The classifier here is a STAND-IN, not HollowNet: :class:`StandInClassifier` looks each
point's ground-truth class up in the labelled scan (nearest labelled point) and returns
the majority class and its share as the score. It is deterministic, so these tests are
about the tree, not about a classifier.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from hollowtree.classes import NUM_CLASSES, ClassId
from hollowtree.scenes.scanner import ScanParams, scan
from hollowtree.scenes.sites import build_scene
from hollowtree.tree import build_tree, load_energy_model
from hollowtree.tree.fit import minaret_stage_cuts, proposal_target

STEP = 0.2  # degrees: about 80 000 points on the minaret


class StandInClassifier:
    """Stand-in for HollowNet: ground-truth majority class by nearest labelled point."""

    def __init__(self, xyz, gt_class):
        self._tree = cKDTree(xyz)
        self._cls = np.asarray(gt_class, dtype=np.int64)

    def predict(self, segments):
        cls = np.zeros(len(segments), dtype=np.int64)
        prob = np.zeros((len(segments), NUM_CLASSES))
        for i, seg in enumerate(segments):
            if len(seg):
                _, j = self._tree.query(np.asarray(seg))
                prob[i] = np.bincount(self._cls[np.atleast_1d(j)], minlength=NUM_CLASSES) / len(seg)
            cls[i] = int(np.argmax(prob[i]))
        return cls, prob[np.arange(len(segments)), cls], prob


_CACHE: dict = {}


def _scan(name):
    if name not in _CACHE:
        chunks = list(scan(build_scene(name), ScanParams(step_deg=STEP, seed=0), workers=2))
        _CACHE[name] = tuple(np.concatenate([getattr(c, a) for c in chunks])
                             for a in ("xyz", "gt_class", "gt_instance"))
    return _CACHE[name]


def _segment(name, cls):
    xyz, gcls, ginst = _scan(name)
    keep = gcls == cls
    return xyz[keep], ginst[keep], StandInClassifier(xyz, gcls)


def _root_children(result):
    return result.nodes.children(0)


def test_minaret_with_7_balconies_gives_8_stages_by_s1():
    pts, _, clf = _segment("minaret", ClassId.MINARET)
    r = build_tree(pts, clf, rng=0)
    kids = _root_children(r)
    assert set(r.nodes.sequence[kids].tolist()) == {1}  # S1 won at the root
    assert len(kids) == 8
    # Every balcony holds exactly one cut: the top of each child but the last.
    balconies, cuts = minaret_stage_cuts()
    tops = np.sort(r.nodes.bbox[kids, 5])[:-1]
    for lo, hi in balconies:
        assert np.sum((tops >= lo - 0.3) & (tops <= hi + 0.3)) == 1, (lo, hi, tops)
    # The 8 stages (balcony middle to balcony middle) match the children one to one.
    stage = np.searchsorted(cuts, pts[:, 2])
    children = [np.flatnonzero(r.leaf == k) if r.nodes.is_leaf[k] else
                np.flatnonzero(np.isin(r.leaf, _descendants(r, k))) for k in kids]
    assert proposal_target(children, stage) >= 6 / 7
    # One element instance: the minaret; every point shares it.
    assert len(r.instance_node) == 1
    assert set(r.instance.tolist()) == {1}
    assert set(r.class_id.tolist()) == {int(ClassId.MINARET)}


def _descendants(r, k):
    out, stack = [], [k]
    while stack:
        n = stack.pop()
        out.append(n)
        stack.extend(r.nodes.children(n).tolist())
    return out


def _arches_matched(r, ginst, kids):
    ious = []
    for g in np.unique(ginst):
        gm = ginst == g
        best = 0.0
        for k in kids:
            cm = np.isin(r.leaf, _descendants(r, k))
            inter = np.sum(gm & cm)
            best = max(best, inter / np.sum(gm | cm))
        ious.append(best)
    return np.asarray(ious)


@pytest.mark.parametrize(("name", "n_bays", "sequence"), [("curved_arcade", 9, 3), ("arcade", 5, 2)])
def test_an_arcade_gives_one_child_per_bay(name, n_bays, sequence):
    """Curved: S3 (along the transport curve); straight: S2 (along the wall's plane)."""
    pts, ginst, clf = _segment(name, ClassId.ARCH)
    n = len(np.unique(ginst))
    assert n == n_bays
    r = build_tree(pts, clf, rng=0)
    kids = _root_children(r)
    assert set(r.nodes.sequence[kids].tolist()) == {sequence}
    assert len(kids) == n
    assert np.sum(_arches_matched(r, ginst, kids) >= 0.5) >= n - 1


@pytest.mark.parametrize(("name", "cls"), [("dome", ClassId.DOME), ("plane_wall", ClassId.WALL)])
def test_plain_dome_and_plain_wall_stay_leaves(name, cls):
    pts, _, clf = _segment(name, cls)
    r = build_tree(pts, clf, rng=0)
    assert len(r.nodes) == 1
    assert r.nodes.is_leaf[0]
    assert set(r.leaf.tolist()) == {0}


@pytest.mark.parametrize("n", [0, 1, 3])
def test_tiny_segments_are_leaves(n):
    pts = np.random.default_rng(0).uniform(0, 1, (n, 3))
    clf = StandInClassifier(np.zeros((1, 3)), [int(ClassId.WALL)])
    r = build_tree(pts, clf, rng=0)
    assert len(r.nodes) == 1
    assert len(r.leaf) == n
    assert r.nodes.n_points[0] == n


def test_same_input_and_seed_same_tree():
    pts, _, clf = _segment("minaret", ClassId.MINARET)
    a = build_tree(pts, clf, rng=3)
    b = build_tree(pts.copy(), clf, rng=3)
    for k, v in a.nodes.to_dict().items():
        np.testing.assert_array_equal(v, b.nodes.to_dict()[k], err_msg=k)
    np.testing.assert_array_equal(a.leaf, b.leaf)
    np.testing.assert_array_equal(a.instance, b.instance)


def test_node_table_records_every_node():
    pts, _, clf = _segment("arcade", ClassId.ARCH)
    r = build_tree(pts, clf, rng=0, max_depth=2)
    t = r.nodes
    assert t.parent[0] == -1
    assert t.sequence[0] == 0
    assert np.isnan(t.xi[0])
    assert np.all(t.depth[1:] == t.depth[t.parent[1:]] + 1)
    assert t.depth.max() <= 2
    assert np.all(t.xi[1:] >= load_energy_model().threshold)
    # Children partition their parent.
    for k in np.flatnonzero(~t.is_leaf):
        assert t.n_points[t.children(k)].sum() == t.n_points[k]
    assert np.all(t.bbox[:, :3] <= t.bbox[:, 3:])
    assert len(t.to_dict()["e5"]) == len(t)


def test_energy_model_file_is_versioned_and_complete():
    m = load_energy_model()
    assert m.version == 1
    assert len(m.weights) == 5
    assert m.W.shape == (NUM_CLASSES, 3)
    assert np.isfinite(m.r2)
    assert m.info["n_samples"] > 100


def test_a_kept_storeys_split_makes_its_bands_wall_children(monkeypatch):
    """A storeys proposal is judged by its children at the bands' middles and, kept, makes
    the children of its band ends; the band child is wall whatever the classifier says."""
    import hollowtree.tree.build as tb
    from hollowtree.tree.sequences import Proposal

    rng = np.random.default_rng(0)
    xyz = np.c_[rng.uniform(0, 20, 3000), np.zeros(3000), rng.uniform(0, 9, 3000)]
    z = xyz[:, 2]
    judged = (np.flatnonzero(z < 4.25), np.flatnonzero(z >= 4.25))
    kept = (np.flatnonzero(z < 3.5), np.flatnonzero((z >= 3.5) & (z < 5.0)), np.flatnonzero(z >= 5.0))
    calls = []

    def one_proposal(pts, **kw):
        if len(pts) < len(xyz):
            return {1: None, 2: None, 3: None, 4: None}
        return {4: Proposal(sequence=2, children=judged, cuts=np.array([4.25]), kept_children=kept,
                            kept_cuts=np.array([3.5, 5.0]), kept_bands=(1,))}

    class Arch:
        def predict(self, segments):
            calls.append([len(s) for s in segments])
            n = len(segments)
            prob = np.zeros((n, NUM_CLASSES - 1))
            prob[:, int(ClassId.ARCH) - 1], prob[:, int(ClassId.WALL) - 1] = 0.9, 0.1
            return np.full(n, int(ClassId.ARCH)), np.full(n, 0.9), prob

    monkeypatch.setattr(tb, "propose", one_proposal)
    res = build_tree(xyz, Arch(), max_depth=1, threshold=-np.inf)
    kids = res.nodes.children(0)
    assert [int(res.nodes.n_points[k]) for k in kids] == [len(c) for c in kept]
    assert [int(res.nodes.class_id[k]) for k in kids] == [int(ClassId.ARCH), int(ClassId.WALL), int(ClassId.ARCH)]
    assert res.nodes.score[kids[1]] == pytest.approx(0.1)
    assert calls[1] == [len(c) for c in judged]
    assert calls[2] == [len(c) for c in kept]


def _bastion(rng, center, n=20000, r=6.0, height=27.0):
    t = rng.uniform(0, 2 * np.pi, n)
    return np.c_[center[0] + r * np.cos(t), center[1] + r * np.sin(t), rng.uniform(0, height, n)]


def test_gaps_cut_parts_that_do_not_touch():
    """Two bastions 19 m apart (a 7 m gap) joined by a few points of a curtain wall are cut
    at the gap; one bastion, a gap under ``params.gap``, or stray points too few to be a
    part are not."""
    from hollowtree.tree.sequences import GAP_SEQUENCE, SequenceParams, gaps

    rng = np.random.default_rng(0)
    a, b = _bastion(rng, (0.0, 0.0)), _bastion(rng, (0.0, 19.0))
    bridge = np.c_[rng.uniform(-0.5, 0.5, 40), rng.uniform(6.0, 13.0, 40), rng.uniform(19.0, 20.0, 40)]
    pr = gaps(np.r_[a, bridge, b])
    assert pr is not None
    assert pr.sequence == GAP_SEQUENCE
    assert pr.n_children == 2
    sizes = sorted(len(c) for c in pr.children)
    assert sizes[0] >= 20000
    assert sum(sizes) == 40040
    assert gaps(a) is None
    near = _bastion(rng, (0.0, 13.5))  # 1.5 m between the two shells: under the 2 m default
    assert gaps(np.r_[a, near]) is None
    assert gaps(np.r_[a, near], params=SequenceParams(gap=1.0)) is not None
    assert gaps(np.r_[a, b], params=SequenceParams(gap=0.0)) is None
    stray = np.c_[np.zeros(5), np.full(5, 30.0), np.linspace(0, 20, 5)]
    assert gaps(np.r_[a, stray]) is None


def test_a_sparse_plain_wall_is_not_cut_at_its_noise(monkeypatch):
    """Where a wall is scanned thinner than the occupancy cell, each 0.1 m cell holds one
    point and S2's occupancy is the scan's noise: a plain wall gets cut into strips. The
    cells grow until they hold a few points each, and the same walls keep (almost) whole;
    a dense wall keeps the 0.1 m cell."""
    import hollowtree.tree.sequences as seq

    def plain_walls(spacing, n_walls=10):
        for k in range(n_walls):
            rng = np.random.default_rng(k)
            n = int(15.0 * 6.0 / spacing ** 2)
            yield np.c_[rng.uniform(0, 15, n), rng.normal(0, 0.005, n), rng.uniform(0, 6, n)]

    def cuts(walls):
        return sum(0 if (p := seq.s2(w)) is None else p.n_children - 1 for w in walls)

    dense = next(plain_walls(0.02, 1))
    assert seq.occupancy_grid(dense[:, 0], dense[:, 2], 0.1)[0] == 0.1
    sparse = next(plain_walls(0.25, 1))
    cell, kx, kz, _ = seq.occupancy_grid(sparse[:, 0], sparse[:, 2], 0.1)
    assert cell > 0.25
    assert np.median(np.unique(kx * (kz.max() + 1) + kz, return_counts=True)[1]) >= seq.CELL_MIN_POINTS
    grown = cuts(plain_walls(0.25))
    monkeypatch.setattr(seq, "CELL_MAX_STEPS", 0)  # the fixed 0.1 m cell
    fixed = cuts(plain_walls(0.25))
    assert grown <= 15, grown
    assert fixed >= 50, fixed


def _arcade(rng, bays=10, near=3, spacing=0.3, near_spacing=0.03):
    """A wall of ``bays`` 5 m bays (a 3 x 4 m opening each), 6 m tall, scanned at
    ``spacing`` except bay ``near`` (a station beside it): 100 times as many points there."""
    parts = []
    for k in range(bays):
        sp = near_spacing if k == near else spacing
        n = int(5.0 * 6.0 / sp ** 2)
        x, z = rng.uniform(5.0 * k, 5.0 * (k + 1), n), rng.uniform(0.0, 6.0, n)
        solid = (np.abs(x - 5.0 * k - 2.5) > 1.5) | (z > 4.0)
        parts.append(np.c_[x, rng.normal(0.0, 0.005, n), z][solid])
    return np.concatenate(parts)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_an_arcade_scanned_beside_one_bay_is_cut_at_every_pier(seed):
    """A station beside one bay puts most of a facade's points there. S2 still cuts every
    bay: the occupancy cells grow until few occupied cells hold a single point (not until
    their mean, which the close bay sets, is 3), and a child is small by its occupied
    cells, not its points (the far bays hold 1 % of the points each)."""
    import hollowtree.tree.sequences as seq

    a = _arcade(np.random.default_rng(seed))
    pr = seq.s2(a)
    assert pr is not None
    assert pr.n_children == 10, pr.cuts
    spans = sorted((a[c, 0].min(), a[c, 0].max()) for c in pr.children)
    cuts = [(hi + lo) / 2 for (_, hi), (lo, _) in zip(spans[:-1], spans[1:], strict=True)]
    assert np.allclose(cuts, np.arange(5.0, 50.0, 5.0), atol=1.0), cuts  # in each pier (2 m wide)


class _Always:
    def __init__(self, cls):
        self.cls = cls

    def predict(self, segments):
        prob = np.zeros((len(segments), NUM_CLASSES - 1))
        prob[:, self.cls - 1] = 1.0
        return np.full(len(segments), self.cls), np.ones(len(segments)), prob


class _ArchWholeMinaretParts:
    """Calls a part with points on both sides of y = 9.5 arch, any other minaret."""

    def predict(self, segments):
        both = np.array([len(s) > 0 and s[:, 1].min() < 9.5 < s[:, 1].max() for s in segments])
        cls = np.where(both, int(ClassId.ARCH), int(ClassId.MINARET))
        prob = np.zeros((len(segments), NUM_CLASSES - 1))
        prob[np.arange(len(segments)), cls - 1] = 1.0
        return cls, np.ones(len(segments)), prob


def test_the_tree_splits_the_root_at_its_gaps_first(monkeypatch):
    """Only the root: inside the tree a gap is more often the opening between two piers
    whose arch another cut took away."""
    import hollowtree.tree.build as tb
    from hollowtree.tree.sequences import GAP_SEQUENCE

    calls = []

    def gaps(pts, **kw):
        calls.append(len(pts))
        return tb_gaps(pts, **kw)

    tb_gaps = tb.gaps
    monkeypatch.setattr(tb, "gaps", gaps)
    rng = np.random.default_rng(1)
    xyz = np.r_[_bastion(rng, (0.0, 0.0)), _bastion(rng, (0.0, 19.0))]
    r = build_tree(xyz, _ArchWholeMinaretParts(), rng=0)
    assert calls == [len(xyz)]
    kids = r.nodes.children(0)
    assert len(kids) == 2
    assert set(r.nodes.sequence[kids].tolist()) == {GAP_SEQUENCE}
    assert np.isnan(r.nodes.xi[kids]).all()
    assert set(r.class_id.tolist()) == {int(ClassId.MINARET)}
    assert len(np.unique(r.instance)) == 2
    assert len(np.unique(r.instance[:20000])) == 1
    assert r.instance[0] != r.instance[-1]
    # A whole called minaret too: the parts still are two instances (they do not touch).
    r1 = build_tree(xyz, _Always(int(ClassId.MINARET)), rng=0)
    assert r1.nodes.sequence[r1.nodes.children(0)].tolist() == [GAP_SEQUENCE] * 2
    assert len(np.unique(r1.instance)) == 2
    r0 = build_tree(xyz, _ArchWholeMinaretParts(), rng=0, max_depth=0)
    assert len(r0.nodes) == 1


def _shaft_and_chattri(rng):
    """A minaret's shaft (r 1.5 m, 12 m tall) and a chattri beside it (a 2 m box of
    points from 8 to 11 m) 0.3 m off the shaft: side by side, overlapping in height."""
    shaft = _bastion(rng, (0.0, 0.0), r=1.5, height=12.0, n=12000)
    chattri = np.c_[rng.uniform(1.8, 3.8, 3000), rng.uniform(-1.0, 1.0, 3000), rng.uniform(8.0, 11.0, 3000)]
    return shaft, chattri


class _TallMinaretElseDome:
    """Calls a part with points on both sides of x = 1.65 (shaft and chattri together)
    ``whole``, one taller than 5 m minaret, any other dome."""

    def __init__(self, whole=int(ClassId.ARCH)):
        self.whole = whole

    def predict(self, segments):
        both = np.array([s[:, 0].min() < 1.65 < s[:, 0].max() for s in segments])
        tall = np.array([np.ptp(s[:, 2]) > 5.0 for s in segments])
        cls = np.where(both, self.whole, np.where(tall, int(ClassId.MINARET), int(ClassId.DOME)))
        prob = np.zeros((len(segments), NUM_CLASSES - 1))
        prob[np.arange(len(segments)), cls - 1] = 1.0
        return cls, np.ones(len(segments)), prob


class _Never:
    """A stand-in split model that keeps no proposal."""

    threshold = 0.5

    def probability(self, features):
        return np.zeros(len(features))


def test_parts_apart_are_found_in_any_direction():
    """The chattri 0.3 m off the shaft is a part (the gap cut along the wall does not see
    it: they overlap along every axis but x, by height); pieces under 5 % of the node go
    with the nearest part; nothing apart, or ``part_gap`` 0, gives None."""
    from hollowtree.tree.sequences import PART_SEQUENCE, SequenceParams, gaps, parts

    rng = np.random.default_rng(0)
    shaft, chattri = _shaft_and_chattri(rng)
    xyz = np.r_[shaft, chattri]
    assert gaps(xyz) is None
    pr = parts(xyz)
    assert pr is not None
    assert pr.sequence == PART_SEQUENCE
    assert [len(c) for c in pr.children] == [len(shaft), len(chattri)]
    crumbs = np.c_[np.full(50, 4.5), np.zeros(50), np.linspace(8, 11, 50)]  # 0.7 m off the chattri
    pr = parts(np.r_[xyz, crumbs])
    assert [len(c) for c in pr.children] == [len(shaft), len(chattri) + 50]
    assert parts(shaft) is None
    assert parts(xyz, params=SequenceParams(part_gap=0.0)) is None
    assert parts(xyz, params=SequenceParams(part_gap=0.5)) is None  # 0.3 m apart: one part at 0.5 m


def test_stacked_parts_of_a_frame_take_a_small_piece_whole_by_height():
    """The rest of a posts split (``stacked``) that is a frame's: a stub of a post the posts
    missed, under the dome's overhanging rim, goes whole with the slab it stands under,
    where point by point its top would go with the dome. Beside a wall as tall as the posts
    (not a frame), it goes point by point."""
    from hollowtree.tree.sequences import parts

    rng = np.random.default_rng(3)
    slab = rng.uniform(-1, 1, (900, 3)) * [1.0, 1.0, 0.2] + [0.0, 0.0, 2.2]  # 2 x 2 m, z 2.0-2.4
    u = rng.normal(size=(2500, 3))
    u[:, 2] = np.abs(u[:, 2])
    dome = u / np.linalg.norm(u, axis=1, keepdims=True) * 1.5 + [0.0, 0.0, 2.65]  # its rim overhangs the slab
    stub = np.c_[np.full(80, 1.45), np.zeros(80), np.linspace(0.0, 2.4, 80)]  # under 5 % of the node
    xyz = np.r_[slab, dome, stub]
    near = cKDTree(np.r_[slab, dome]).query(stub)[1]
    assert (near[-5:] >= len(slab)).all()  # the stub's top is nearest to the dome
    pr = parts(xyz, stacked=True, posts_z=(0.0, 2.0))
    assert pr is not None
    assert [len(c) for c in pr.children] == [len(slab) + len(stub), len(dome)]
    assert np.array_equal(pr.children[1], np.arange(len(slab), len(slab) + len(dome)))
    wall = rng.uniform(0, 1, (900, 3)) * [0.3, 2.0, 3.0] + [4.0, -1.0, 0.0]  # z 0-3 m, 2.5 m off the slab
    pr = parts(np.r_[xyz, wall], stacked=True, posts_z=(0.0, 2.0))
    assert pr is not None
    dome_child = next(c for c in pr.children if len(slab) in c)
    assert np.isin(np.arange(len(slab) + len(dome), len(xyz)), dome_child).any()  # the stub's top: with the dome
    assert parts(xyz, stacked=True).children[0].size == len(slab) + near[near < len(slab)].size


def test_a_root_nothing_splits_is_cut_into_parts_of_different_classes():
    """Only when HollowNet calls the parts different things, one a dome at least 2 m tall,
    and the whole no dome, minaret or other: a shaft and a chattri (minaret, dome) called
    arch together are two instances; called minaret both, or arch and pillar, a chattri
    1.5 m tall, or the whole called dome, the root stays whole."""
    from hollowtree.tree.sequences import PART_SEQUENCE

    rng = np.random.default_rng(1)
    shaft, chattri = _shaft_and_chattri(rng)
    xyz = np.r_[shaft, chattri]
    r = build_tree(xyz, _TallMinaretElseDome(), rng=0, split=_Never())
    kids = r.nodes.children(0)
    assert r.nodes.sequence[kids].tolist() == [PART_SEQUENCE] * 2
    assert r.class_id[: len(shaft)].tolist() == [int(ClassId.MINARET)] * len(shaft)
    assert r.class_id[len(shaft):].tolist() == [int(ClassId.DOME)] * len(chattri)
    assert len(np.unique(r.instance)) == 2
    r1 = build_tree(xyz, _Always(int(ClassId.MINARET)), rng=0, split=_Never())
    assert len(r1.nodes) == 1
    assert len(np.unique(r1.instance)) == 1
    # Parts that are no dome or minaret (a bay's jambs called arch and pillar): whole.
    r2 = build_tree(xyz, _TallArchElsePillar(), rng=0, split=_Never())
    assert len(r2.nodes) == 1
    # A part called dome under PART_MIN_HEIGHT (1.5 m): whole.
    low = np.r_[shaft, chattri * [1.0, 1.0, 0.5] + [0.0, 0.0, 4.0]]
    assert np.ptp(low[len(shaft):, 2]) < 2.0
    r4 = build_tree(low, _TallMinaretElseDome(), rng=0, split=_Never())
    assert len(r4.nodes) == 1
    # A root called dome, minaret or other: whole, whatever its parts are called.
    for whole in (ClassId.DOME, ClassId.MINARET, ClassId.OTHER):
        r3 = build_tree(xyz, _TallMinaretElseDome(int(whole)), rng=0, split=_Never())
        assert len(r3.nodes) == 1


class _TallArchElsePillar:
    """Calls a part taller than 5 m arch, any other pillar."""

    def predict(self, segments):
        tall = np.array([np.ptp(s[:, 2]) > 5.0 for s in segments])
        cls = np.where(tall, int(ClassId.ARCH), int(ClassId.PILLAR))
        prob = np.zeros((len(segments), NUM_CLASSES - 1))
        prob[np.arange(len(segments)), cls - 1] = 1.0
        return cls, np.ones(len(segments)), prob


class _ByProposal:
    """A stand-in split model: probability 0.9 for an S2 proposal, 0.1 for any other."""

    threshold = 0.5

    def __init__(self):
        from hollowtree.tree.split import FEATURE_NAMES

        self._s2 = FEATURE_NAMES.index("seq_s2")
        self.calls = 0

    def probability(self, features):
        self.calls += 1
        return np.where(np.asarray(features)[:, self._s2] > 0, 0.9, 0.1)


def test_a_storeys_split_is_kept_when_a_storey_splits(monkeypatch):
    """A wall's (or a minaret's) storey cut leaves two walls (the split model rejects it, as the S1 cut that
    ties with it), but the storey below splits into bays: the storey cut is judged by that
    look-ahead, not by its own score."""
    import hollowtree.tree.build as tb
    from hollowtree.tree.sequences import Proposal

    rng = np.random.default_rng(0)
    xyz = np.c_[rng.uniform(0, 12, 20000), np.zeros(20000), rng.uniform(0, 10, 20000)]
    xyz = xyz[~((xyz[:, 2] < 5.0) & (np.abs(xyz[:, 0] % 4.0 - 2.0) < 1.0))]  # three 2 x 5 m openings
    n = len(xyz)
    assert tb._solid_share(xyz[xyz[:, 2] < 6.0], tb.SequenceParams()) < tb.OPEN_STOREY
    only_storeys = {"on": False}

    def proposals(pts, **kw):
        if len(pts) == n:  # the root: its storeys
            lo, hi = np.flatnonzero(pts[:, 2] < 6.0), np.flatnonzero(pts[:, 2] >= 6.0)
            halves = (np.flatnonzero(pts[:, 0] < 6.0), np.flatnonzero(pts[:, 0] >= 6.0))
            return {1: Proposal(sequence=1, children=halves, cuts=np.array([6.0])), 2: None, 3: None,
                    4: Proposal(sequence=2, children=(lo, hi), cuts=np.array([6.0]))}
        if np.ptp(pts[:, 0]) < 6.0:  # a bay
            return {1: None, 2: None, 3: None, 4: None}
        bays = tuple(np.flatnonzero((pts[:, 0] >= a) & (pts[:, 0] < a + 4.0)) for a in (0.0, 4.0, 8.0))
        bays_prop = Proposal(sequence=2, children=bays, cuts=np.array([4.0, 8.0]))
        return {1: None, 2: None, 3: None, 4: bays_prop} if only_storeys["on"] else {2: bays_prop}

    monkeypatch.setattr(tb, "propose", proposals)
    wall = _Always(int(ClassId.WALL))
    split = _ByProposal()
    r = build_tree(xyz, wall, split=split, rng=0)
    kids = r.nodes.children(0)
    assert len(kids) == 2
    assert r.nodes.sequence[kids].tolist() == [2, 2]
    assert sorted(r.nodes.bbox[kids, 2].round().tolist()) == [0.0, 6.0]  # cut along z: the storeys
    assert r.nodes.xi[kids].tolist() == pytest.approx([0.1, 0.1])  # the storeys' own score
    assert sorted(len(r.nodes.children(k)) for k in kids) == [3, 3]
    assert len(r.nodes) == 1 + 2 + 6
    # Off, at depth 1, or when the storey's best is itself a storey cut: no look-ahead.
    assert len(build_tree(xyz, wall, split=_ByProposal(), rng=0, look_ahead=False).nodes) == 1
    assert len(build_tree(xyz, wall, split=_ByProposal(), rng=0, max_depth=1).nodes) == 1
    # whatever HollowNet calls the facade: a minaret, a dome
    for c in (ClassId.MINARET, ClassId.DOME):
        assert len(build_tree(xyz, _Always(int(c)), split=_ByProposal(), rng=0).nodes) == 1 + 2 + 6
    with monkeypatch.context() as m:  # no storey with openings (every storey solid): no look-ahead
        m.setattr(tb, "OPEN_STOREY", 0.0)
        assert len(build_tree(xyz, wall, split=_ByProposal(), rng=0).nodes) == 1
    only_storeys["on"] = True
    assert len(build_tree(xyz, wall, split=_ByProposal(), rng=0).nodes) == 1


class _Draws:
    """A stand-in split model that answers its calls in turn from ``answers``."""

    threshold = 0.5

    def __init__(self, *answers):
        self.answers = list(answers)
        self.calls = 0

    def probability(self, features):
        self.calls += 1
        return np.full(len(features), self.answers.pop(0))


def test_a_close_call_is_decided_by_its_one_draw(monkeypatch):
    """A node's proposals are scored once, however close the best is to the threshold: the
    settled circle (tree-v36) gives a second draw the same proposals, so tree-v32's second
    draw of close calls is gone."""
    import hollowtree.tree.build as tb
    from hollowtree.tree.sequences import Proposal

    rng = np.random.default_rng(0)
    xyz = np.c_[rng.uniform(0, 12, 3000), np.zeros(3000), rng.uniform(0, 5, 3000)]

    def proposals(pts, **kw):
        if len(pts) < len(xyz):
            return {1: None, 2: None, 3: None, 4: None}
        bays = tuple(np.flatnonzero((pts[:, 0] >= a) & (pts[:, 0] < a + 4.0)) for a in (0.0, 4.0, 8.0))
        return {2: Proposal(sequence=2, children=bays, cuts=np.array([4.0, 8.0]))}

    monkeypatch.setattr(tb, "propose", proposals)
    wall = _Always(int(ClassId.WALL))
    close = _Draws(0.45, 0.65)
    assert len(build_tree(xyz, wall, split=close, rng=0).nodes) == 1
    assert close.calls == 1
    kept = _Draws(0.55, 0.35)
    r = build_tree(xyz, wall, split=kept, rng=0)
    assert len(r.nodes.children(0)) == 3
    assert kept.calls == 1
    assert r.nodes.xi[r.nodes.children(0)].tolist() == pytest.approx([0.55] * 3)


def test_the_tree_stage_passes_look_ahead_from_the_workflow(monkeypatch):
    from pathlib import Path

    import hollowtree.tree.build as tb
    from hollowtree.errors import ConfigError
    from hollowtree.pipeline.tree_stage import TreeStageParams, _group_tree
    from hollowtree.pipeline.workflow import load_workflow

    local = Path(__file__).resolve().parent.parent / "workflows" / "local.yaml"
    assert TreeStageParams.from_workflow(load_workflow(local).tree).look_ahead is True
    off = TreeStageParams.from_workflow(load_workflow(local, ["tree.look_ahead=false"]).tree)
    assert off.look_ahead is False
    with pytest.raises(ConfigError, match="look_ahead"):
        TreeStageParams(look_ahead="yes")
    seen = []
    real = tb.build_tree

    def spy(*a, **kw):
        seen.append(kw["look_ahead"])
        return real(*a, **kw)

    monkeypatch.setattr(tb, "build_tree", spy)
    xyz = np.random.default_rng(0).uniform(0, 1, (500, 3))
    _group_tree(xyz, 0, TreeStageParams(max_depth=0, roof_min_height=None, look_ahead=False),
                _Always(int(ClassId.WALL)), None, 0)
    _group_tree(xyz, 0, TreeStageParams(max_depth=0, roof_min_height=None), _Always(int(ClassId.WALL)), None, 0)
    assert seen == [False, True]


def _posts_under_a_slab(rng, n_posts=4, floor=True):
    """A pavilion's frame: ``n_posts`` round posts (r 0.15 m, 3 m tall) on a ring 3 m
    across, a slab (4 x 4 x 0.3 m) on them, a dome-like cap on the slab and, if
    ``floor``, a platform under them. Returns the points and each point's part
    (1..n_posts a post, 0 anything else)."""
    pieces, part = [], []
    for k in range(n_posts):
        a = 2 * np.pi * k / n_posts
        t, z = rng.uniform(0, 2 * np.pi, 1500), rng.uniform(0.0, 3.0, 1500)
        pieces.append(np.c_[1.5 * np.cos(a) + 0.15 * np.cos(t), 1.5 * np.sin(a) + 0.15 * np.sin(t), z])
        part.append(np.full(1500, k + 1))
    pieces.append(rng.uniform(0, 1, (4000, 3)) * [4.0, 4.0, 0.3] + [-2.0, -2.0, 3.0])
    v = rng.normal(size=(3000, 3))
    v[:, 2] = np.abs(v[:, 2])
    pieces.append(1.5 * v / np.linalg.norm(v, axis=1, keepdims=True) + [0, 0, 3.3])  # a hemisphere
    part += [np.zeros(4000), np.zeros(3000)]
    if floor:
        pieces.append(rng.uniform(0, 1, (3000, 3)) * [5.0, 5.0, 0.05] + [-2.5, -2.5, -0.05])
        part.append(np.zeros(3000))
    return np.vstack(pieces), np.concatenate(part).astype(np.int64)


class _SlenderPillarElseDome:
    """Calls a part at least twice as tall as it is wide ``slender`` (pillar), any other
    ``other``: the posts of :func:`_posts_under_a_slab` pillars, the whole a dome."""

    def __init__(self, slender=int(ClassId.PILLAR), other=int(ClassId.DOME)):
        self.slender, self.other = slender, other

    def predict(self, segments):
        tall = np.array([np.ptp(s[:, 2]) >= 2 * np.ptp(s[:, :2], axis=0).max() for s in segments])
        cls = np.where(tall, self.slender, self.other)
        prob = np.zeros((len(segments), NUM_CLASSES - 1))
        prob[np.arange(len(segments)), cls - 1] = 1.0
        return cls, np.ones(len(segments)), prob


@pytest.mark.parametrize("floor", [True, False])
def test_posts_are_found_under_their_slab(floor):
    """Each post under the slab (on a platform or not) is one post, holding its own
    points; a slab, a ring of posts that touch and a solid block have none."""
    from hollowtree.tree.posts import posts
    from hollowtree.tree.sequences import SequenceParams

    xyz, part = _posts_under_a_slab(np.random.default_rng(0), floor=floor)
    found = posts(xyz)
    assert found is not None
    assert len(found) == 4
    for c in found:
        own = np.bincount(part[c], minlength=5)
        assert own[1:].max() >= 0.95 * len(c)  # one post's points
        assert own[1:].max() >= 0.8 * np.sum(part == np.argmax(own[1:]) + 1)  # most of them
    assert posts(xyz[part == 0]) is None  # slab, cap and floor alone
    assert posts(xyz, params=SequenceParams(part_gap=0.0)) is None
    rng = np.random.default_rng(1)
    assert posts(rng.uniform(0, 1, (20000, 3)) * [6.0, 1.0, 5.0]) is None  # a solid block
    wide = _posts_under_a_slab(rng)[0] * [1.0, 1.0, 0.2]  # posts 0.6 m tall: too short
    assert posts(wide) is None
    tubes = _posts_under_a_slab(rng)[0] * [0.3, 0.3, 1.0]  # posts 0.09 m across: a scaffold's
    assert posts(tubes) is None


def test_posts_are_found_above_a_slice_of_more_pieces():
    """Thirty tufts of grass around the platform make its slice the one with the most
    pieces; the posts still come from the slice that gives the most posts."""
    from hollowtree.tree.posts import posts

    rng = np.random.default_rng(4)
    xyz, part = _posts_under_a_slab(rng)
    angle = np.linspace(0, 2 * np.pi, 30, endpoint=False)
    tufts = np.vstack([rng.uniform(-0.05, 0.05, (40, 3)) + [3.5 * np.cos(t), 3.5 * np.sin(t), 0.0] for t in angle])
    found = posts(np.r_[xyz, tufts])
    assert found is not None
    assert len(found) == 4
    assert all((part[c[c < len(part)]] > 0).mean() > 0.95 for c in found)


def test_the_shafts_of_a_clustered_pillar_are_one_post():
    """Four shafts (0.5 m across, 0.14 m apart: touching at the posts' cells), two such
    pillars 3 m apart under a beam: two posts, each holding its four shafts."""
    from hollowtree.tree.posts import posts

    rng = np.random.default_rng(3)
    pieces = []
    for x0 in (0.0, 3.0):
        for dx, dy in ((0.45, 0), (-0.45, 0), (0, 0.45), (0, -0.45)):
            t, z = rng.uniform(0, 2 * np.pi, 600), rng.uniform(0.0, 4.0, 600)
            pieces.append(np.c_[x0 + dx + 0.25 * np.cos(t), dy + 0.25 * np.sin(t), z])
    pieces.append(rng.uniform(0, 1, (3000, 3)) * [6.0, 2.0, 0.4] + [-1.5, -1.0, 4.0])
    found = posts(np.vstack(pieces))
    assert found is not None
    assert [len(c) >= 4 * 550 for c in found] == [True, True]
    assert all(np.ptp(np.vstack(pieces)[c, 0]) < 2.0 for c in found)


@pytest.mark.parametrize("whole", [ClassId.DOME, ClassId.OTHER])
def test_a_root_called_dome_or_other_gives_up_the_posts_called_pillar(whole):
    """The posts of a frame HollowNet calls dome, or other (a whole pavilion often is,
    tree-v35), are pillar instances, the slab and the cap one more child; posts called
    something else, or a root called wall or arch (an arcade's piers), stay whole."""
    from hollowtree.tree.sequences import POST_SEQUENCE

    xyz, part = _posts_under_a_slab(np.random.default_rng(2))
    r = build_tree(xyz, _SlenderPillarElseDome(other=int(whole)), rng=0, split=_Never())
    kids = r.nodes.children(0)
    assert r.nodes.sequence[kids].tolist() == [POST_SEQUENCE] * 5
    own = []
    for k in range(1, 5):  # most of each post (not the slice in the platform) its own pillar
        inst, count = np.unique(r.instance[part == k], return_counts=True)
        own.append(int(inst[count.argmax()]))
        assert own[-1] > 0
        assert count.max() >= 0.8 * np.sum(part == k)
        assert (r.class_id[r.instance == own[-1]] == int(ClassId.PILLAR)).all()
    assert len(set(own)) == 4
    # The rest falls apart once its posts are out: the platform is no part of the slab and cap.
    from hollowtree.tree.sequences import PART_SEQUENCE

    rest = kids[-1]
    assert r.nodes.sequence[r.nodes.children(rest)].tolist() == [PART_SEQUENCE] * 2
    floor, top = np.arange(len(xyz))[-3000:], np.flatnonzero((part == 0) & (xyz[:, 2] >= 3.0))
    assert len(np.intersect1d(np.unique(r.leaf[floor]), np.unique(r.leaf[top]))) == 0
    for root, posts_as in ((whole, ClassId.OTHER), (ClassId.WALL, ClassId.PILLAR), (ClassId.ARCH, ClassId.PILLAR)):
        r2 = build_tree(xyz, _SlenderPillarElseDome(int(posts_as), int(root)), rng=0, split=_Never())
        assert len(r2.nodes) == 1


def test_a_storeys_band_is_cut_into_bays_before_storeys(monkeypatch):
    """A band a storeys proposal made is cut into storeys again only where no bay cut
    reaches the threshold: a curved facade's storey was cut at its arches' springing into
    two bands that the model scored above its bays; a band no bay cut passes may still hold
    two storeys."""
    import hollowtree.tree.build as tb
    from hollowtree.tree.sequences import Proposal

    rng = np.random.default_rng(0)
    xyz = np.c_[rng.uniform(0, 12, 4000), np.zeros(4000), rng.uniform(0, 8, 4000)]

    def proposals(pts, **kw):
        z0, z1 = pts[:, 2].min(), pts[:, 2].max()
        if z1 - z0 < 3.0:
            return {1: None, 2: None, 3: None, 4: None}
        mid = 0.5 * (z0 + z1)
        bands = (np.flatnonzero(pts[:, 2] < mid), np.flatnonzero(pts[:, 2] >= mid))
        storeys = Proposal(sequence=2, children=bands, cuts=np.array([mid]))
        if len(pts) == len(xyz):
            return {1: None, 2: None, 3: None, 4: storeys}
        bays = tuple(np.flatnonzero((pts[:, 0] >= a) & (pts[:, 0] < a + 4.0)) for a in (0.0, 4.0, 8.0))
        return {1: None, 2: Proposal(sequence=2, children=bays, cuts=np.array([4.0, 8.0])), 3: None, 4: storeys}

    class Model:  # the storeys above the bays wherever both are proposed
        threshold = 0.5

        def probability(self, features):
            return np.array([0.9]) if len(features) == 1 else np.array([0.6, 0.8])

    monkeypatch.setattr(tb, "propose", proposals)
    r = build_tree(xyz, _Always(int(ClassId.WALL)), split=Model(), rng=0)
    bands = r.nodes.children(0)
    assert len(bands) == 2
    assert [len(r.nodes.children(b)) for b in bands] == [3, 3]

    class NoBays(Model):  # the bays below the threshold: the band's storeys are kept
        def probability(self, features):
            return np.array([0.9]) if len(features) == 1 else np.array([0.3, 0.8])

    r = build_tree(xyz, _Always(int(ClassId.WALL)), split=NoBays(), rng=0)
    assert [len(r.nodes.children(b)) for b in r.nodes.children(0)] == [2, 2]
