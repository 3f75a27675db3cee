"""The procedural site generator (scenes/procedural.py): every family builds, a seed is a
site, compound elements are split into their parts, the splits never overlap."""

from __future__ import annotations

import re
import subprocess
import sys

import laspy
import numpy as np
import pytest

from hollowtree.classes import ClassId
from hollowtree.errors import ConfigError
from hollowtree.scenes.mesh import TriMesh
from hollowtree.scenes.procedural import (
    FAMILIES,
    FOOT_HEIGHT,
    SPLITS,
    _footprint,
    family_of,
    procedural_site,
    scan_draw,
    split_seeds,
)
from hollowtree.scenes.sites import GENERATED, build_scene


@pytest.mark.parametrize("family", FAMILIES)
def test_every_family_builds_for_seeds_of_every_split(family):
    for split in SPLITS:
        for seed in split_seeds(split, 4, family=family):
            s = procedural_site(seed, family)
            assert s.name == f"gen-{family}-{seed}"
            assert len(s.stations) >= 3
            assert sum(e.class_id == ClassId.GROUND for e in s.elements) == 1


def test_a_seed_is_one_site_and_seeds_differ():
    a, b = procedural_site(200_010), procedural_site(200_010)
    np.testing.assert_array_equal(a.vertices, b.vertices)
    np.testing.assert_array_equal(a.face_instance, b.face_instance)
    c = procedural_site(200_017)  # the same family (seeds 7 apart), another site
    assert family_of(200_010) == family_of(200_017)
    assert a.vertices.shape != c.vertices.shape or not np.array_equal(a.vertices, c.vertices)


def test_the_family_cycles_with_the_seed_and_can_be_named():
    assert [family_of(s) for s in range(7)] == list(FAMILIES)
    assert procedural_site(3, "fort").name == "gen-fort-3"
    with pytest.raises(ConfigError, match="family 'castle'"):
        procedural_site(3, "castle")


def test_splits_are_disjoint_and_hold_every_family():
    ranges = sorted(SPLITS.values())
    assert all(a[1] <= b[0] for a, b in zip(ranges, ranges[1:], strict=False))
    for split in SPLITS:
        assert {family_of(s) for s in split_seeds(split, 7)} == set(FAMILIES)
    with pytest.raises(ConfigError, match="split 'dev'"):
        split_seeds("dev", 3)


def test_a_pavilion_is_its_dome_columns_and_slab():
    """Compound elements are labelled by part, as the tree is meant to split them."""
    names: dict[ClassId, list[str]] = {}
    for seed in split_seeds("train", 6, family="pavilion_garden"):
        for e in procedural_site(seed).elements:
            names.setdefault(e.class_id, []).append(e.name)
    assert any(n.endswith(" dome") and n.startswith("pavilion") for n in names[ClassId.DOME])
    assert any(" column " in n for n in names[ClassId.PILLAR])
    assert any(n.endswith(" slab") for n in names[ClassId.ROOF])


def test_a_gateway_is_its_arch_and_piers():
    names = [(e.class_id, e.name) for seed in split_seeds("train", 8, family="fort")
             for e in procedural_site(seed).elements if e.name.startswith("gateway")]
    assert (ClassId.ARCH, "gateway arch") in names
    assert (ClassId.PILLAR, "gateway pier 1") in names


def test_ruins_miss_parts_of_their_layout():
    """A ruin is its layout with elements missing or broken off: fewer triangles and no
    more elements than the same layout built intact."""
    for seed in split_seeds("train", 8, family="ruins"):
        ruin, intact = procedural_site(seed), procedural_site(seed, ruin=0.0)
        assert len(ruin.faces) < len(intact.faces)
        assert len(ruin.elements) <= len(intact.elements)
    with pytest.raises(ConfigError, match="ruin must be between 0 and 1"):
        procedural_site(3, "ruins", ruin=1.5)


def test_a_site_is_its_layout_turned_by_its_own_heading():
    """The heading is its own draw: the same site at heading 0 is the layout along the axes,
    turned rigidly about the vertical axis (stations too); seeds draw different headings."""
    angles = []
    for seed in split_seeds("val", 3, family="fort"):
        turned, along = procedural_site(seed), procedural_site(seed, heading=0.0)
        np.testing.assert_array_equal(turned.faces, along.faces)
        np.testing.assert_array_equal(turned.face_instance, along.face_instance)
        np.testing.assert_allclose(turned.vertices[:, 2], along.vertices[:, 2])
        for p, q in ((turned.vertices, along.vertices), (turned.stations, along.stations)):
            np.testing.assert_allclose(np.hypot(p[:, 0], p[:, 1]), np.hypot(q[:, 0], q[:, 1]), atol=1e-9)
        far = int(np.argmax(np.hypot(*along.vertices[:, :2].T)))
        angles.append(np.arctan2(*turned.vertices[far, 1::-1]) - np.arctan2(*along.vertices[far, 1::-1]))
    assert len({round(float(np.mod(a, 2 * np.pi)), 3) for a in angles}) == 3
    with pytest.raises(ConfigError, match="heading must be a finite angle"):
        procedural_site(3, "fort", heading=float("nan"))


def test_scan_draw_is_seeded_and_in_range():
    assert scan_draw(5) == scan_draw(5)
    assert scan_draw(5) != scan_draw(6)


def test_generated_names_build_through_the_registry():
    assert set(GENERATED) == {"gen", *(f"gen-{f}" for f in FAMILIES)}
    assert build_scene("gen", rng=200_003).name == procedural_site(200_003).name
    assert build_scene("gen-monument", rng=4).name == "gen-monument-4"


def test_synth_writes_a_procedural_site_with_its_own_counts(tmp_path):
    out = tmp_path / "g.laz"
    proc = subprocess.run([sys.executable, "-m", "hollowtree", "synth", "gen-pavilion_garden", "--seed", "200003",
                           "--points", "40000", "--out", str(out), "--no-progress"], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    las = laspy.read(out)
    assert 30_000 < len(las.points) < 50_000
    scene = procedural_site(200_003, "pavilion_garden")
    seen = set(np.unique(np.asarray(las.gt_instance)).tolist()) - {0}
    assert seen <= {e.instance for e in scene.elements}
    expected = scene.element_counts()[ClassId.PILLAR]
    assert f"{expected:>10}" in next(line for line in proc.stdout.splitlines() if line.startswith("pillar"))


def _unsupported_columns(site) -> list[str]:
    """Columns whose foot stands on nothing: a ray cast down from the centre of a raised
    column's foot (columns left out of the scene) meets the next surface more than 2 cm below."""
    from types import SimpleNamespace

    from hollowtree.scenes.scanner import RayCaster

    pillar = site.instance_class[site.face_instance] == int(ClassId.PILLAR)
    rays = RayCaster(SimpleNamespace(vertices=site.vertices, faces=site.faces[~pillar]))
    bad = []
    for e in site.elements:
        if e.class_id != ClassId.PILLAR:
            continue
        v = site.vertices[np.unique(site.faces[site.face_instance == e.instance])]
        z0 = v[:, 2].min()
        if z0 < 0.02:
            continue
        foot = v[v[:, 2] < z0 + 0.01, :2].mean(axis=0)
        face, t, _ = rays.cast(np.r_[foot, z0 + 0.005], np.array([[0.0, 0.0, -1.0]]), max_range=1e4)
        if face[0] < 0 or t[0] > 0.025:
            bad.append(f"{e.name} at {z0:.2f} m")
    return bad


@pytest.mark.parametrize("family", FAMILIES)
def test_every_raised_column_stands_on_something(family):
    """A pavilion's columns on its platform (square to them), a facade's roof pavilions on a
    platform on the wall, a monument's inside its roof; in a ruin what stood on a fallen
    part is gone with it (``gen-v3``)."""
    raised = 0
    for seed in split_seeds("train", 4, family=family):
        site = procedural_site(seed, family)
        assert _unsupported_columns(site) == [], site.name
        raised += sum(e.class_id == ClassId.PILLAR for e in site.elements)
    assert family == "curved_facade" or raised > 0


def _cells(site, name: str, below: float = FOOT_HEIGHT) -> set[int]:
    inst = next(e.instance for e in site.elements if e.name == name)
    return set(_footprint(TriMesh(site.vertices, site.faces[site.face_instance == inst]), below).tolist())


@pytest.mark.parametrize("family", FAMILIES)
def test_nothing_stands_inside_anything_else(family):
    """``gen-v4``: no clutter shares a raster cell of what stands on the ground (below 2 m)
    with anything else; a garden's pavilions, colonnades and pillars share none at any height."""
    clutter = re.compile(r"(tree|person|car|bench|bicycle|scaffold) \d+")
    for seed in split_seeds("train", 3, family=family):
        site = procedural_site(seed, family, heading=0.0)
        names = [e.name for e in site.elements if e.class_id != ClassId.GROUND]
        low = {n: _cells(site, n) for n in names}
        for a in filter(clutter.fullmatch, names):
            assert not any(low[a] & low[b] for b in names if b != a), (site.name, a)
        groups: dict[str, set[int]] = {}
        for n in names:
            m = re.match(r"(pavilion|colonnade|pillar) \d+", n)
            if m and family == "pavilion_garden":
                groups.setdefault(m.group(0), set()).update(_cells(site, n, below=np.inf))
        g = list(groups.values())
        assert all(not (g[i] & g[j]) for i in range(len(g)) for j in range(i + 1, len(g))), site.name
