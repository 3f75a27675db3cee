"""``hollowtree synth``: the files it writes, determinism, and bad input."""

from __future__ import annotations

import subprocess
import sys

import laspy
import numpy as np
import pyarrow.parquet as pq
import pytest

from hollowtree.classes import ELEMENT_CLASSES, ClassId
from hollowtree.pipeline.cli import main
from hollowtree.scenes.sites import SITES
from hollowtree.scenes.synth import SCALE, read_scan_metadata, sidecar_path


def test_version(capsys):
    assert main(["--version"]) == 0
    assert capsys.readouterr().out.startswith("hollowtree ")


def test_console_script_runs():
    out = subprocess.run(
        [sys.executable, "-m", "hollowtree", "--version"], capture_output=True, text=True
    )
    assert out.returncode == 0
    assert "hollowtree" in out.stdout


def test_same_seed_same_file(tmp_path):
    a, b, c = tmp_path / "a.laz", tmp_path / "b.laz", tmp_path / "c.laz"
    for path, seed in [(a, 7), (b, 7), (c, 8)]:
        assert main(["synth", "minaret", "--points", "60000", "--seed", str(seed),
                     "--out", str(path), "--no-progress"]) == 0
    assert a.read_bytes() == b.read_bytes()
    assert sidecar_path(a).read_bytes() == sidecar_path(b).read_bytes()
    assert a.read_bytes() != c.read_bytes()


def test_file_is_valid_las_with_ground_truth(tmp_path, capsys):
    out = tmp_path / "m.laz"
    assert main(["synth", "minaret", "--points", "80000", "--out", str(out),
                 "--crs", "EPSG:32643", "--no-progress"]) == 0
    summary = capsys.readouterr().out
    assert "minaret" in summary
    assert "points" in summary
    las = laspy.read(out)
    h = las.header
    assert (h.version.major, h.version.minor) == (1, 4)
    assert h.point_format.id == 7
    assert {"gt_class", "gt_instance"} <= set(h.point_format.extra_dimension_names)
    assert las.gt_class.dtype == np.uint8
    assert las.gt_instance.dtype == np.uint32
    assert h.point_count == len(las.points) == pytest.approx(80_000, rel=0.05)
    assert np.allclose(h.scales, SCALE)
    # Survey-sized coordinates: float32 cannot hold them to the millimetre.
    assert h.mins[0] > 400_000
    assert h.mins[1] > 3_000_000
    assert np.abs(np.float32(las.y) - las.y).max() > 0.01
    assert np.allclose(h.mins, [las.x.min(), las.y.min(), las.z.min()])
    assert np.allclose(h.maxs, [las.x.max(), las.y.max(), las.z.max()])
    assert h.parse_crs().to_epsg() == 32643
    # Labels agree with the elements table.
    table = pq.read_table(sidecar_path(out))
    inst = table.column("instance").to_numpy()
    cls = table.column("class_id").to_numpy()
    lookup = np.zeros(inst.max() + 1, dtype=np.uint8)
    lookup[inst] = cls
    assert np.array_equal(lookup[las.gt_instance], las.gt_class)
    counts = np.bincount(las.gt_instance, minlength=inst.max() + 1)
    assert np.array_equal(counts[inst], table.column("point_count").to_numpy())
    assert ClassId.MINARET in set(cls.tolist())
    meta = read_scan_metadata(out)
    assert meta["scene"] == "minaret"
    assert len(meta["stations"]) >= 1
    assert set(np.unique(las.point_source_id)) <= set(range(1, len(meta["stations"]) + 1))


@pytest.mark.parametrize("site", list(SITES))
def test_site_scans_contain_every_element(site, scan_of):
    s = scan_of(site, n_points=600_000)
    expected = SITES[site].expected_counts
    for c in ELEMENT_CLASSES:
        found = np.unique(s.gt_instance[s.gt_class == c]).size
        assert found == expected.get(c, 0), (site, c.label)


def _fails(capsys, argv, needle):
    code = main(argv)
    err = capsys.readouterr().err
    assert code == 2, err
    assert needle in err
    assert len(err.strip().splitlines()) == 1
    return err


def test_unknown_site_lists_known(tmp_path, capsys):
    err = _fails(capsys, ["synth", "taj_mahal", "--out", str(tmp_path / "x.laz")], "taj_mahal")
    for name in SITES:
        assert name in err
    assert not any(tmp_path.iterdir())


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--points", "0"], "positive"),
        (["--points", "-5"], "positive"),
        (["--noise", "-0.1"], "The 'noise' parameter of scan must be a float in the range [0.0, inf)"),
        (["--registration-error", "-1"], "'registration_error' parameter"),
        (["--step", "0"], "step"),
        (["--stations", "999"], "stations"),
        (["--crs", "EPSG:999999999"], "crs"),
    ],
)
def test_bad_numbers(tmp_path, capsys, args, needle):
    out = tmp_path / "x.laz"
    _fails(capsys, ["synth", "minaret", "--out", str(out), "--no-progress", *args], needle)
    assert not any(tmp_path.iterdir())


def test_missing_output_folder(tmp_path, capsys):
    _fails(capsys, ["synth", "minaret", "--out", str(tmp_path / "no" / "x.laz")], "does not exist")
    assert not any(tmp_path.iterdir())


def test_bad_suffix(tmp_path, capsys):
    _fails(capsys, ["synth", "minaret", "--out", str(tmp_path / "x.txt")], ".laz")


def test_existing_output_is_kept(tmp_path, capsys):
    out = tmp_path / "x.laz"
    out.write_bytes(b"precious")
    _fails(capsys, ["synth", "minaret", "--out", str(out), "--no-progress"], "--overwrite")
    assert out.read_bytes() == b"precious"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.laz"]
    assert main(["synth", "minaret", "--points", "20000", "--out", str(out),
                 "--overwrite", "--no-progress"]) == 0
    assert laspy.read(out).header.point_count > 0
