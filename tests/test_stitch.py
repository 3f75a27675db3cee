"""Tests of primitives.stitch: union-find, joining tile segments, CSR gathering."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from hollowtree.errors import ConfigError
from hollowtree.primitives.stitch import StitchResult, UnionFind, csr_by_segment, stitch_segments

# -- UnionFind -----------------------------------------------------------------------------


def _scipy_labels(n: int, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    graph = coo_matrix((np.ones(len(a)), (a, b)), shape=(n, n))
    return connected_components(graph, directed=False)[1]


def _same_partition(x: np.ndarray, y: np.ndarray) -> bool:
    # Equal partitions <=> the pairing x -> y is a bijection.
    pairs = np.unique(np.c_[x, y], axis=0)
    return len(pairs) == len(np.unique(x)) == len(np.unique(y))


@settings(max_examples=200, deadline=None)
@given(
    st.integers(1, 60).flatmap(
        lambda n: st.tuples(
            st.just(n),
            st.lists(st.tuples(st.integers(0, n - 1), st.integers(0, n - 1)), max_size=120),
            st.integers(1, 4),
        )
    )
)
def test_union_find_matches_connected_components(case: tuple[int, list, int]) -> None:
    n, pairs, n_batches = case
    arr = np.array(pairs, dtype=np.int64).reshape(-1, 2)
    uf = UnionFind(n)
    for part in np.array_split(arr, n_batches):  # several calls accumulate
        uf.union_pairs(part[:, 0], part[:, 1])
    labels = uf.labels()
    expected = _scipy_labels(n, arr[:, 0], arr[:, 1])
    assert _same_partition(labels, expected)
    # Dense labels in order of each set's lowest element; roots are fixed points.
    _, first = np.unique(labels, return_index=True)
    assert np.all(np.diff(first) > 0)
    assert labels[0] == 0
    roots = uf.find(np.arange(n))
    np.testing.assert_array_equal(uf.parent[roots], roots)
    assert uf.rank.max(initial=0) <= np.log2(max(n, 1)) + 1


def test_union_find_star_and_chain_few_rounds() -> None:
    n = 10_000
    uf = UnionFind(n)
    uf.union_pairs(np.arange(n - 1), np.full(n - 1, n - 1))  # all onto one element
    assert len(np.unique(uf.find(np.arange(n)))) == 1
    uf = UnionFind(n)
    uf.union_pairs(np.arange(n - 1), np.arange(1, n))  # a chain
    assert (uf.labels() == 0).all()


def test_union_find_scalar_find_and_errors() -> None:
    uf = UnionFind(3)
    uf.union_pairs([2], [1])
    assert int(uf.find(2)) == int(uf.find(1))
    assert len(uf) == 3
    with pytest.raises(ConfigError, match="'n' parameter of UnionFind"):
        UnionFind(-1)
    with pytest.raises(ConfigError, match="same length"):
        uf.union_pairs([0, 1], [2])


# -- stitch_segments -----------------------------------------------------------------------


def _tiles(
    *tiles: tuple[int, list[int], list[int], list[int]],
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Rows from (tile, original indices, local labels, core original indices) per tile."""
    t, lab, orig, core = [], [], [], []
    for tile, points, labels, cores in tiles:
        t += [tile] * len(points)
        lab += labels
        orig += points
        core += [p in cores for p in points]
    return np.array(t), np.array(lab), np.array(orig), np.array(core)


def test_two_tiles_sharing_buffer_points_join() -> None:
    # Tile 0 core 0-9, buffer 10-13; tile 1 core 10-19, buffer 6-9. Both see 6-13 as one
    # segment (tile 0 calls it 1, tile 1 calls it 4).
    t, lab, orig, core = _tiles(
        (0, list(range(14)), [1] * 14, list(range(10))),
        (1, list(range(6, 20)), [4] * 14, list(range(10, 20))),
    )
    res = stitch_segments(t, lab, orig, is_core=core)
    assert res.labels.tolist() == [1] * 20
    assert res.n_segments == 1
    assert res.mapping() == {(0, 1): 1, (1, 4): 1}


def test_too_few_shared_points_do_not_join() -> None:
    t, lab, orig, core = _tiles(
        (0, [0, 1, 2, 3, 4], [1, 1, 1, 1, 1], [0, 1, 2]),
        (1, [3, 4, 5, 6, 7], [2, 2, 2, 2, 2], [3, 4, 5, 6, 7]),
    )
    res = stitch_segments(t, lab, orig, is_core=core)  # 2 shared < min_shared = 3
    assert res.labels.tolist() == [1, 1, 1, 2, 2, 2, 2, 2]
    res = stitch_segments(t, lab, orig, is_core=core, min_shared=2)
    assert res.labels.tolist() == [1] * 8


def test_incompatible_segments_do_not_join() -> None:
    t, lab, orig, core = _tiles(
        (0, list(range(8)), [1] * 8, list(range(5))),
        (1, list(range(3, 12)), [2] * 9, list(range(5, 12))),
    )
    seen: list[tuple] = []

    def compatible(a: tuple[int, int], b: tuple[int, int]) -> bool:
        seen.append((a, b))
        return False

    res = stitch_segments(t, lab, orig, is_core=core, compatible=compatible)
    assert seen == [((0, 1), (1, 2))]
    assert res.labels.tolist() == [1] * 5 + [2] * 7
    assert res.mapping() == {(0, 1): 1, (1, 2): 2}
    res = stitch_segments(t, lab, orig, is_core=core, compatible=lambda a, b: True)
    assert res.labels.tolist() == [1] * 12


def test_chain_of_three_tiles_joins_transitively() -> None:
    # Tiles 0, 1, 2 in a row; 0 and 2 share nothing, but both share with 1.
    t, lab, orig, core = _tiles(
        (0, list(range(0, 14)), [1] * 14, list(range(0, 10))),
        (1, list(range(6, 24)), [1] * 18, list(range(10, 20))),
        (2, list(range(16, 30)), [7] * 14, list(range(20, 30))),
    )
    res = stitch_segments(t, lab, orig, is_core=core)
    assert res.labels.tolist() == [1] * 30
    assert set(res.mapping().values()) == {1}


def test_only_core_copies_set_the_label() -> None:
    # Tile 1's buffer copy of point 2 says segment 5 (unshared with anything else); the
    # core copy in tile 0 says 0 (unsegmented): the point stays 0. Point 3's core copy
    # (tile 1) says 5, its buffer copy in tile 0 says 0.
    t, lab, orig, core = _tiles(
        (0, [0, 1, 2, 3], [1, 1, 0, 0], [0, 1, 2]),
        (1, [2, 3, 4], [5, 5, -1], [3, 4]),
    )
    res = stitch_segments(t, lab, orig, is_core=core)
    assert res.labels.tolist() == [1, 1, 0, 2, 0]
    assert res.mapping() == {(0, 1): 1, (1, 5): 2}


def test_unsegmented_labels_never_join() -> None:
    t, lab, orig, core = _tiles(
        (0, list(range(10)), [0] * 10, list(range(5))),
        (1, list(range(10)), [-1] * 10, list(range(5, 10))),
    )
    res = stitch_segments(t, lab, orig, is_core=core)
    assert res.labels.tolist() == [0] * 10
    assert res.n_segments == 0
    assert res.mapping() == {}


def test_global_ids_by_lowest_original_index_and_buffer_only_segment() -> None:
    # Tile 5 holds core points 10-14 (segment 2) and buffer points 0-1 (segment 3, seen
    # nowhere else): segment 3 labels no point, so it maps to 0. Tile 9 holds core 0-9
    # in two segments; the one owning point 0 becomes global 1.
    t, lab, orig, core = _tiles(
        (5, [10, 11, 12, 13, 14, 0, 1], [2, 2, 2, 2, 2, 3, 3], [10, 11, 12, 13, 14]),
        (9, list(range(10)), [8, 8, 8, 1, 1, 1, 1, 1, 8, 8], list(range(10))),
    )
    res = stitch_segments(t, lab, orig, is_core=core, n_points=16)
    assert res.labels.tolist() == [1, 1, 1, 2, 2, 2, 2, 2, 1, 1, 3, 3, 3, 3, 3, 0]
    assert res.mapping() == {(5, 2): 3, (5, 3): 0, (9, 1): 2, (9, 8): 1}
    assert res.n_segments == 3
    back = StitchResult.from_dict(res.to_dict())
    np.testing.assert_array_equal(back.labels, res.labels)
    assert back.mapping() == res.mapping()


def test_four_tile_corner() -> None:
    # One point region seen by four tiles (a corner), each labelling it differently.
    shared = list(range(100, 110))
    rows = [(tile, shared + [tile], [tile + 1] * 11, [p for p in shared if p % 4 == tile] + [tile])
            for tile in range(4)]
    t, lab, orig, core = _tiles(*rows)
    res = stitch_segments(t, lab, orig, is_core=core)
    assert res.n_segments == 1
    assert set(res.labels[[0, 1, 2, 3, *shared]]) == {1}


def test_stitch_inputs_not_modified_and_errors() -> None:
    t, lab, orig, core = _tiles(
        (0, [0, 1, 2, 3], [1, 1, 1, 1], [0, 1]),
        (1, [0, 1, 2, 3], [2, 2, 2, 2], [2, 3]),
    )
    copies = [x.copy() for x in (t, lab, orig, core)]
    stitch_segments(t, lab, orig, is_core=core)
    for before, after in zip(copies, (t, lab, orig, core), strict=True):
        np.testing.assert_array_equal(before, after)
    with pytest.raises(ConfigError, match="at most one copy of each point as core"):
        stitch_segments(t, lab, orig, is_core=np.ones(8, dtype=bool))
    with pytest.raises(ConfigError, match="'is_core' parameter"):
        stitch_segments(t, lab, orig, is_core=core[:3])
    with pytest.raises(ConfigError, match="'local_label_of_row' parameter"):
        stitch_segments(t, lab[:3], orig, is_core=core)
    with pytest.raises(ConfigError, match="'min_shared' parameter of stitch_segments"):
        stitch_segments(t, lab, orig, is_core=core, min_shared=0)
    with pytest.raises(ConfigError, match="'n_points' parameter"):
        stitch_segments(t, lab, orig, is_core=core, n_points=2)


def test_stitch_empty() -> None:
    e = np.empty(0, dtype=np.int64)
    res = stitch_segments(e, e, e, is_core=np.empty(0, dtype=bool))
    assert res.labels.shape == (0,)
    assert res.n_segments == 0
    assert res.keys.shape == (0, 2)


# -- csr_by_segment ------------------------------------------------------------------------


@settings(max_examples=100, deadline=None)
@given(st.lists(st.integers(0, 7), max_size=60))
def test_csr_round_trip(ids: list[int]) -> None:
    gid = np.array(ids, dtype=np.int64)
    original = np.arange(len(gid), dtype=np.int64) * 3 + 1000
    indices, offsets = csr_by_segment(gid, original)
    assert offsets[0] == 0
    assert offsets[-1] == len(gid)
    assert len(offsets) == (gid.max() + 2 if len(gid) else 2)
    back = np.empty(len(gid), dtype=np.int64)
    for g in range(len(offsets) - 1):
        members = indices[offsets[g] : offsets[g + 1]]
        assert np.all(np.diff(members) > 0)  # ascending within a segment
        back[(members - 1000) // 3] = g
    np.testing.assert_array_equal(back, gid)


def test_csr_default_original_index_and_errors() -> None:
    indices, offsets = csr_by_segment(np.array([1, 1, 0]))
    assert indices.tolist() == [2, 0, 1]
    assert offsets.tolist() == [0, 1, 3]
    with pytest.raises(ConfigError, match="'global_id_per_point' parameter of csr_by_segment"):
        csr_by_segment(np.array([-1, 0]))
    with pytest.raises(ConfigError, match="'original_index' parameter"):
        csr_by_segment(np.array([0, 1]), np.array([0]))
