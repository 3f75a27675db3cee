"""LAS codes of the exported classes and the class styles written beside the LAS/LAZ."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import laspy
import numpy as np
import pytest

from hollowtree.classes import CLASS_NAMES, ClassId
from hollowtree.pipeline.export import (
    CLASS_COLOURS,
    LAS_CLASSIFICATION,
    LAS_LEGEND,
    cloudcompare_scale,
    qgis_style,
    style_paths,
)

SHARED = {ClassId.UNCLASSIFIED, ClassId.OTHER}  # both are ASPRS 1


def _rgb(c: ClassId) -> tuple[int, int, int]:
    return tuple(int(round(255 * v)) for v in CLASS_COLOURS[c])


def test_each_class_has_its_own_code_but_unclassified_and_other():
    assert set(LAS_CLASSIFICATION) == set(ClassId)
    own = [LAS_CLASSIFICATION[c] for c in ClassId if c not in SHARED]
    assert len(own) == len(set(own))
    assert {LAS_CLASSIFICATION[c] for c in SHARED} == {1}
    assert 1 not in own
    assert LAS_CLASSIFICATION[ClassId.GROUND] == 2
    # the element codes stay where they were; wall and roof follow them in the user range
    assert [LAS_CLASSIFICATION[c] for c in (ClassId.ARCH, ClassId.DOME, ClassId.MINARET, ClassId.PILLAR,
                                            ClassId.WALL, ClassId.ROOF)] == [64, 65, 66, 67, 68, 69]
    assert 6 not in LAS_CLASSIFICATION.values()


def test_legend_names_and_colours_every_code():
    codes = [code for code, _, _ in LAS_LEGEND]
    assert codes == sorted(set(LAS_CLASSIFICATION.values()))
    legend = {code: (name, rgb) for code, name, rgb in LAS_LEGEND}
    assert legend[1] == ("unclassified", _rgb(ClassId.UNCLASSIFIED))
    for c in ClassId:
        if c not in SHARED:
            assert legend[LAS_CLASSIFICATION[c]] == (CLASS_NAMES[c], _rgb(c)), c


def test_qgis_style_has_one_category_per_code():
    text = qgis_style()
    assert text.startswith(b"<!DOCTYPE qgis ")
    root = ET.fromstring(text)
    assert root.tag == "qgis"
    renderer = root.find("renderer")
    assert renderer.get("type") == "classified"
    assert renderer.get("attribute") == "Classification"
    cats = renderer.findall("categories/category")
    assert [int(c.get("value")) for c in cats] == [code for code, _, _ in LAS_LEGEND]
    for cat, (_, name, (r, g, b)) in zip(cats, LAS_LEGEND, strict=True):
        assert cat.get("label") == name
        assert cat.get("color") == f"{r},{g},{b},255"
        assert cat.get("render") == "true"


def _cc_colour(root: ET.Element, value: float) -> tuple[int, int, int]:
    """The colour CloudCompare gives ``value``: linear between the steps of the absolute scale."""
    lo = float(root.findtext("ColorScale/Properties/minValue"))
    rng = float(root.findtext("ColorScale/Properties/range"))
    steps = [(float(s.get("pos")), np.array([int(s.get(k)) for k in "rgb"], float))
             for s in root.findall("ColorScale/Data/step")]
    x = (value - lo) / rng
    for (p0, c0), (p1, c1) in zip(steps, steps[1:], strict=False):
        if p0 <= x <= p1:
            return tuple(int(v) for v in np.round(c0 + (c1 - c0) * (x - p0) / max(p1 - p0, 1e-12)))
    raise AssertionError(f"{value} outside the scale")


def test_cloudcompare_scale_labels_and_colours_every_code():
    text = cloudcompare_scale()
    root = ET.fromstring(text)
    assert root.tag == "CloudCompare"
    scale = root.find("ColorScale")
    assert list(scale.attrib) == ["version"]
    assert scale.get("version") == "1"
    props = scale.find("Properties")
    assert [e.tag for e in props] == ["name", "uuid", "absolute", "minValue", "range"]
    assert props.findtext("absolute") == "1"
    pos = [float(s.get("pos")) for s in scale.findall("Data/step")]
    assert pos[0] == 0.0
    assert pos[-1] == 1.0
    assert pos == sorted(pos)
    assert len(set(pos)) == len(pos)  # CloudCompare's sort of equal positions is not stable
    labels = {int(float(e.get("val"))): e.get("text") for e in scale.findall("Data/label")}
    assert labels == {code: name for code, name, _ in LAS_LEGEND}
    for code, _, rgb in LAS_LEGEND:  # flat around each code
        for dv in (-0.4, 0.0, 0.4):
            assert _cc_colour(root, code + dv) == rgb, (code, dv)
    assert cloudcompare_scale() == text  # the same UUID every time


def test_style_paths_share_the_stem(tmp_path):
    assert style_paths(tmp_path / "site.a.laz") == (tmp_path / "site.a.qml", tmp_path / "site.a.cc-classes.xml")


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    from hollowtree.pipeline.run import run_workflow
    from hollowtree.pipeline.workflow import load_workflow
    from hollowtree.scenes.synth import synth

    d = tmp_path_factory.mktemp("styles")
    scan = d / "scan.laz"
    synth("wazir_khan", scan, n_points=30_000, seed=5)
    out = d / "o.laz"
    wf = d / "wf.yaml"
    wf.write_text(f"""\
input: {{files: [{scan}]}}
store: {d / 's.zarr'}
ingest: {{tile_size: 50.0}}
coarse: {{min_support: 300}}
tree: {{enabled: false}}
cluster: {{scheduler: sync}}
outputs: {{las: {out}}}
""")
    said: list[str] = []
    run_workflow(load_workflow(wf), progress=False, say=said.append)
    return out, said


def test_styles_are_written_beside_the_export(exported):
    out, said = exported
    qml, cc = style_paths(out)
    assert qml.read_bytes() == qgis_style()
    assert cc.read_bytes() == cloudcompare_scale()
    assert sorted(p.name for p in out.parent.iterdir() if p.name.startswith(".")) == []  # no partial files
    assert any(str(qml) in line and str(cc) in line for line in said), said
    las = laspy.read(out)
    lookup = next(v for v in las.header.vlrs if isinstance(v, laspy.vlrs.known.ClassificationLookupVlr))
    assert lookup.lookups == {code: name for code, name, _ in LAS_LEGEND}
    codes = set(np.unique(np.asarray(las.classification)).tolist())
    assert codes <= {code for code, _, _ in LAS_LEGEND}
    np.testing.assert_array_equal(
        np.asarray(las.classification),
        np.array([LAS_CLASSIFICATION[ClassId(c)] for c in ClassId])[np.asarray(las["class_id"])])


def test_export_command_writes_and_names_the_styles(exported, tmp_path, capsys):
    from hollowtree.pipeline.cli import main

    out = tmp_path / "again.las"
    assert main(["export", str(exported[0].parent / "s.zarr"), "--las", str(out), "--no-progress"]) == 0
    printed = capsys.readouterr().out
    for path in style_paths(out):
        assert path.is_file()
        assert str(path) in printed
    assert style_paths(out)[0].read_bytes() == qgis_style()
