"""Streaming readers (tiling/readers.py): small files written here, and the real files in
../shared/data/external (never copied into the repo)."""

from __future__ import annotations

import json
from pathlib import Path

import laspy
import numpy as np
import plyfile
import pytest

from hollowtree.errors import (
    ConfigError,
    CorruptInputError,
    InputFileError,
    PipelineError,
    UnsupportedInputError,
)
from hollowtree.tiling.readers import PointBlock, SourceInfo, probe, read_blocks

EXTERNAL = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "external"
N = 2_500
CHUNK = 700
RANGES = [(0, None), (0, 1), (5, 5), (699, 701), (700, 1400), (1234, 2000), (2400, 10**9), (N, None)]


def external(rel: str) -> Path:
    if not EXTERNAL.is_dir():
        pytest.skip("../shared/data/external is absent: the real sample files live outside the repo")
    path = EXTERNAL / rel
    if not path.is_file():
        pytest.skip(f"../shared/data/external/{rel} is absent")
    return path


def read_all(path, **kwargs) -> PointBlock:
    return PointBlock.concat(read_blocks(path, **kwargs))


def assert_blocks_equal(a: PointBlock, b: PointBlock) -> None:
    assert np.array_equal(a.xyz, b.xyz)
    assert np.array_equal(a.index, b.index)
    if len(a) == 0:  # an empty range yields no blocks, so there are no fields to compare
        return
    for name in ("intensity", "rgb", "return_number", "number_of_returns", "gps_time"):
        x, y = getattr(a, name), getattr(b, name)
        assert (x is None) == (y is None), name
        assert x is None or np.array_equal(x, y), name
    assert a.extra.keys() == b.extra.keys()
    for k in a.extra:
        assert np.array_equal(a.extra[k], b.extra[k]), k


def slice_block(b: PointBlock, lo: int, hi: int | None) -> PointBlock:
    hi = np.iinfo(np.int64).max if hi is None else hi
    m = (b.index >= lo) & (b.index < hi)

    def s(a):
        return None if a is None else a[m]

    return PointBlock(xyz=b.xyz[m], index=b.index[m], intensity=s(b.intensity), rgb=s(b.rgb),
                      return_number=s(b.return_number), number_of_returns=s(b.number_of_returns),
                      gps_time=s(b.gps_time), extra={k: v[m] for k, v in b.extra.items()})


# -- fixtures: small files made here --------------------------------------------------------


@pytest.fixture(scope="module")
def las_pair(tmp_path_factory) -> tuple[Path, Path]:
    """The same seeded point-format-7 scan with gt_class/gt_instance, as .las and .laz."""
    rng = np.random.default_rng(3)
    header = laspy.LasHeader(point_format=7, version="1.4")
    header.add_extra_dims([laspy.ExtraBytesParams("gt_class", "u1"),
                           laspy.ExtraBytesParams("gt_instance", "u4")])
    header.scales = np.array([0.001, 0.001, 0.001])
    header.offsets = np.array([500_000.0, 4_649_000.0, 100.0])
    import pyproj

    header.add_crs(pyproj.CRS.from_epsg(32633))
    las = laspy.LasData(header)
    las.x = 500_000 + rng.uniform(0, 50, N)
    las.y = 4_649_000 + rng.uniform(0, 50, N)
    las.z = 100 + rng.uniform(0, 20, N)
    las.intensity = rng.integers(0, 65535, N)
    las.red, las.green, las.blue = (rng.integers(0, 65535, N) for _ in range(3))
    las.number_of_returns = rng.integers(1, 4, N)
    las.return_number = np.minimum(rng.integers(1, 4, N), las.number_of_returns)
    las.gps_time = np.sort(rng.uniform(0, 1e5, N))
    las.classification = rng.integers(0, 9, N)
    las.gt_class = rng.integers(0, 9, N)
    las.gt_instance = rng.integers(0, 2**31, N)
    root = tmp_path_factory.mktemp("las")
    las.write(root / "scan.las")
    las.write(root / "scan.laz")
    return root / "scan.las", root / "scan.laz"


def _vertex_array(n: int, *, nonfinite: bool) -> np.ndarray:
    rng = np.random.default_rng(5)
    v = np.empty(n, dtype=[("x", "f8"), ("y", "f8"), ("z", "f4"), ("intensity", "u2"),
                           ("red", "u1"), ("green", "u1"), ("blue", "u1"), ("nx", "f4"),
                           ("gt_class", "u1")])
    for name in v.dtype.names:
        kind = v.dtype[name]
        v[name] = rng.uniform(-1e3, 1e3, n) if kind.kind == "f" else rng.integers(0, np.iinfo(kind).max, n)
    if nonfinite:
        v["x"][[3, 10, 701]] = np.nan
        v["z"][[10, 1500]] = np.inf
        v["y"][2499] = -np.inf
    return v


@pytest.fixture(scope="module", params=["ascii", "binary_little_endian", "binary_big_endian"])
def ply_file(request, tmp_path_factory) -> tuple[Path, np.ndarray]:
    """A PLY point cloud with faces after the vertices and some NaN/inf records."""
    v = _vertex_array(N, nonfinite=True)
    faces = np.empty(2, dtype=[("vertex_indices", "i4", (3,))])
    faces["vertex_indices"] = [[0, 1, 2], [2, 3, 4]]
    fmt = request.param
    byte_order = {"binary_big_endian": ">", "binary_little_endian": "<"}.get(fmt, "=")
    ply = plyfile.PlyData([plyfile.PlyElement.describe(v, "vertex"),
                           plyfile.PlyElement.describe(faces, "face")],
                          text=fmt == "ascii", byte_order=byte_order)
    path = tmp_path_factory.mktemp("ply") / f"cloud-{fmt}.ply"
    ply.write(str(path))
    return path, v


def _write_e57(path: Path, scans: list[dict], poses: list) -> None:
    import pye57

    with pye57.E57(str(path), mode="w") as e:
        for data, pose in zip(scans, poses, strict=True):
            if pose is None:
                e.write_scan_raw(data)
            else:
                e.write_scan_raw(data, rotation=pose[0], translation=pose[1])


@pytest.fixture(scope="module")
def e57_file(tmp_path_factory) -> tuple[Path, list[dict]]:
    pytest.importorskip("pye57", reason="pye57 is not installed")
    rng = np.random.default_rng(9)

    def scan(n, invalid=()):
        d = {"cartesianX": rng.uniform(-5, 5, n), "cartesianY": rng.uniform(-5, 5, n),
             "cartesianZ": rng.uniform(0, 3, n), "intensity": rng.uniform(0, 1, n).astype("f4"),
             "colorRed": rng.integers(0, 256, n).astype("u1"),
             "colorGreen": rng.integers(0, 256, n).astype("u1"),
             "colorBlue": rng.integers(0, 256, n).astype("u1"),
             "cartesianInvalidState": np.zeros(n, "i1")}
        d["cartesianInvalidState"][list(invalid)] = 2
        d["cartesianX"][list(invalid)[:1]] = np.nan
        return d

    half = np.sqrt(0.5)
    scans = [scan(1500, invalid=(7, 800)), scan(1000)]
    poses = [(np.array([half, 0.0, 0.0, half]), np.array([10.0, 20.0, 1.5])), None]
    path = tmp_path_factory.mktemp("e57") / "two-scans.e57"
    _write_e57(path, scans, poses)
    return path, scans


# -- LAS / LAZ ------------------------------------------------------------------------------


@pytest.mark.parametrize("which", [0, 1], ids=["las", "laz"])
def test_las_matches_laspy(las_pair, which):
    path = las_pair[which]
    las = laspy.read(path)
    blocks = list(read_blocks(path, chunk_size=CHUNK))
    assert [len(b) for b in blocks] == [700, 700, 700, 400]
    b = PointBlock.concat(blocks)
    assert np.array_equal(b.xyz, np.stack([las.x, las.y, las.z], axis=1))  # exactly laspy's scaling
    assert b.xyz.dtype == np.float64
    assert b.index.dtype == np.uint64
    assert np.array_equal(b.index, np.arange(N))
    assert np.array_equal(b.intensity, las.intensity)
    assert b.intensity.dtype == np.uint16
    assert np.array_equal(b.rgb, np.stack([las.red, las.green, las.blue], axis=1))
    assert np.array_equal(b.return_number, las.return_number)
    assert b.return_number.dtype == np.uint8
    assert np.array_equal(b.number_of_returns, las.number_of_returns)
    assert np.array_equal(b.gps_time, las.gps_time)
    assert set(b.extra) == {"classification", "point_source_id", "gt_class", "gt_instance"}
    assert np.array_equal(b.extra["gt_class"], las.gt_class)
    assert b.extra["gt_class"].dtype == np.uint8
    assert np.array_equal(b.extra["gt_instance"], las.gt_instance)
    assert np.array_equal(b.extra["classification"], las.classification)
    assert b.n_dropped == 0


def test_las_and_laz_read_the_same(las_pair):
    assert_blocks_equal(read_all(las_pair[0]), read_all(las_pair[1], chunk_size=333))


@pytest.mark.parametrize(("start", "stop"), RANGES)
@pytest.mark.parametrize("which", [0, 1], ids=["las", "laz"])
def test_las_start_stop_is_a_slice(las_pair, which, start, stop):
    path = las_pair[which]
    full = read_all(path)
    part = read_all(path, chunk_size=CHUNK, start=start, stop=stop)
    assert_blocks_equal(part, slice_block(full, start, stop))


def test_las_probe(las_pair):
    for path, fmt in zip(las_pair, ("las", "laz"), strict=True):
        info = probe(path)
        las = laspy.read(path)
        assert info.format == fmt
        assert info.format_version == "1.4 pf7"
        assert info.point_count == N
        assert info.size_bytes == path.stat().st_size
        assert info.scale == (0.001, 0.001, 0.001)
        assert info.offset == (500_000.0, 4_649_000.0, 100.0)
        assert info.has_intensity
        assert info.has_rgb
        assert info.has_returns
        assert info.has_gps_time
        assert info.extra_dims == ("classification", "point_source_id", "gt_class", "gt_instance")
        assert np.allclose(info.mins, [las.x.min(), las.y.min(), las.z.min()])
        assert "32633" in info.crs_wkt
        d = json.loads(json.dumps(info.to_dict()))
        assert SourceInfo.from_dict(d) == info


def test_synthetic_scan_keeps_ground_truth(scan_of):
    s = scan_of("plane_wall", step_deg=0.2, noise=0.0, n_stations=1)
    b = read_all(s.path, chunk_size=10_000)
    assert np.array_equal(b.extra["gt_class"], s.gt_class)
    assert np.array_equal(b.extra["gt_instance"], s.gt_instance)
    assert np.array_equal(b.extra["point_source_id"].astype(np.int64) - 1, s.station)
    assert {"gt_class", "gt_instance"} <= set(probe(s.path).extra_dims)


# -- PLY ------------------------------------------------------------------------------------


def test_ply_reads_fields_and_drops_nonfinite(ply_file):
    path, v = ply_file
    b = read_all(path, chunk_size=CHUNK)
    xyz = np.stack([v["x"], v["y"], v["z"]], axis=1).astype(np.float64)
    keep = np.isfinite(xyz).all(axis=1)
    assert b.n_dropped == 5 == (~keep).sum()
    assert np.array_equal(b.index, np.flatnonzero(keep))
    assert np.array_equal(b.xyz, xyz[keep])
    assert np.array_equal(b.intensity, v["intensity"][keep])
    assert np.array_equal(b.rgb[:, 0], v["red"][keep].astype(np.uint16) * 257)
    assert set(b.extra) == {"nx", "gt_class"}
    assert np.array_equal(b.extra["gt_class"], v["gt_class"][keep])
    assert np.array_equal(b.extra["nx"], v["nx"][keep])
    assert b.extra["nx"].dtype.isnative
    per_block = [blk.n_dropped for blk in read_blocks(path, chunk_size=CHUNK)]
    assert per_block == [2, 1, 1, 1]  # rows 3 and 10 | 701 | 1500 | 2499
    info = probe(path)
    assert info.format == "ply"
    assert info.point_count == N
    assert info.scale is None
    assert info.has_intensity
    assert info.has_rgb
    assert not info.has_gps_time
    assert info.extra_dims == ("nx", "gt_class")
    assert info.mins is None


@pytest.mark.parametrize(("start", "stop"), RANGES)
def test_ply_start_stop_is_a_slice(ply_file, start, stop):
    path, _ = ply_file
    full = read_all(path)
    part = PointBlock.concat(read_blocks(path, chunk_size=CHUNK, start=start, stop=stop))
    assert_blocks_equal(part, slice_block(full, start, stop))


def test_ply_whole_file_fallback(tmp_path):
    """A binary vertex element behind a list element cannot be mapped; it is read whole."""
    v = _vertex_array(50, nonfinite=False)
    lists = np.empty(2, dtype=[("ids", "O")])
    lists["ids"] = [np.array([1, 2], "i4"), np.array([3], "i4")]
    ply = plyfile.PlyData([plyfile.PlyElement.describe(lists, "group"),
                           plyfile.PlyElement.describe(v, "vertex")], byte_order="<")
    ply.write(str(tmp_path / "odd.ply"))
    b = read_all(tmp_path / "odd.ply", chunk_size=16, start=3, stop=40)
    assert np.array_equal(b.index, np.arange(3, 40))
    assert np.array_equal(b.xyz[:, 0], v["x"][3:40])


def test_ply_float_intensity_stays_in_extra(tmp_path):
    v = np.zeros(4, dtype=[("x", "f4"), ("y", "f4"), ("z", "f4"), ("intensity", "f4")])
    v["intensity"] = [0.1, 0.5, 1.0, 7.0]
    plyfile.PlyData([plyfile.PlyElement.describe(v, "vertex")], text=True).write(str(tmp_path / "f.ply"))
    b = read_all(tmp_path / "f.ply")
    assert b.intensity is None
    assert np.allclose(b.extra["intensity"], v["intensity"])
    assert not probe(tmp_path / "f.ply").has_intensity


def test_real_ascii_mesh_ply():
    path = external("kenney-castle-kit-1.0/gate.ply")
    ref = plyfile.PlyData.read(str(path))["vertex"].data
    b = read_all(path, chunk_size=100)
    assert len(b) == len(ref) == probe(path).point_count == 720
    assert np.array_equal(b.xyz[:, 1], ref["y"].astype(np.float64))
    assert np.array_equal(b.extra["nz"], ref["nz"])
    assert probe(path).format_version == "ascii"


# -- E57 ------------------------------------------------------------------------------------


def test_e57_matches_pye57(e57_file):
    import pye57

    path, scans = e57_file
    with pye57.E57(str(path)) as e:
        ref = [e.read_scan(i, intensity=True, colors=True) for i in range(e.scan_count)]
    b = read_all(path, chunk_size=CHUNK)
    want = np.concatenate([np.stack([r["cartesianX"], r["cartesianY"], r["cartesianZ"]], 1) for r in ref])
    assert np.allclose(b.xyz, want, rtol=0, atol=1e-9)
    assert b.n_dropped == 2
    assert len(b) == 2500 - 2
    assert np.array_equal(b.index, np.delete(np.arange(2500), [7, 800]))
    assert np.array_equal(b.extra["scan_index"], np.repeat([0, 1], [1498, 1000]))
    red = np.concatenate([r["colorRed"] for r in ref]).astype(np.uint16) * 257
    assert np.array_equal(b.rgb[:, 0], red)
    # intensity is rescaled from the scan's limits to 0..65535
    assert b.intensity.dtype == np.uint16
    assert b.intensity.max() == 65535
    assert b.intensity.min() == 0
    # the pose was applied: scan 0 is rotated 90 degrees about z and shifted
    raw = scans[0]
    i = 0  # first valid record of scan 0
    assert np.allclose(b.xyz[i], [-raw["cartesianY"][i] + 10, raw["cartesianX"][i] + 20,
                                  raw["cartesianZ"][i] + 1.5], atol=1e-5)


@pytest.mark.parametrize(("start", "stop"), [*RANGES, (1499, 1501), (1500, 1700)])
def test_e57_start_stop_is_a_slice(e57_file, start, stop):
    path, _ = e57_file
    full = read_all(path)
    assert_blocks_equal(read_all(path, chunk_size=CHUNK, start=start, stop=stop),
                        slice_block(full, start, stop))


def test_e57_probe(e57_file):
    path, _ = e57_file
    info = probe(path)
    assert info.format == "e57"
    assert info.point_count == 2500
    assert info.has_intensity
    assert info.has_rgb
    assert info.extra_dims == ("scan_index",)
    assert SourceInfo.from_dict(info.to_dict()) == info


def test_e57_nonfinite_after_reading_is_dropped():
    """pye57 cannot write NaN into a valid record, so feed one to the block builder."""
    pytest.importorskip("pye57", reason="pye57 is not installed")
    from hollowtree.tiling import read_e57 as readers

    scan = readers._Scan(header=None, count=3, coords=("cartesianX", "cartesianY", "cartesianZ"),
                         invalid=None, intensity=None, rgb_top=None, pose=None)
    d = {"cartesianX": np.array([0.0, np.nan, 2.0]), "cartesianY": np.zeros(3),
         "cartesianZ": np.array([0.0, 1.0, np.inf])}
    b = readers._e57_block(d, scan, 0, 10, False, False)
    assert b.index.tolist() == [10]
    assert b.n_dropped == 2


# -- real files -----------------------------------------------------------------------------


def test_real_simple_las_equals_laz():
    a = read_all(external("laspy/simple.las"), chunk_size=100)
    b = read_all(external("laspy/simple.laz"), chunk_size=1000)
    assert len(a) == 1065
    assert_blocks_equal(a, b)


def test_real_autzen_start_stop_and_laspy_values():
    path = external("pdal/autzen_trim.laz")
    las = laspy.read(path)
    full = read_all(path, chunk_size=25_000)
    assert np.array_equal(full.xyz, np.stack([las.x, las.y, las.z], axis=1))
    assert np.array_equal(full.index, np.arange(110_000))
    for start, stop in [(0, 30_000), (49_999, 50_001), (77_777, None)]:
        assert_blocks_equal(read_all(path, chunk_size=10_000, start=start, stop=stop),
                            slice_block(full, start, stop))
    info = probe(path)
    assert info.point_count == 110_000
    assert "Lambert" in info.crs_wkt


@pytest.mark.parametrize(("rel", "dims"), [
    ("pdal/las_with_several_extra_byte_bloc.laz", ("Deviation", "ExtraBytes")),
    ("lidR/MixedConifer.laz", ("treeID",)),
    ("lidR/dbh.laz", ("Range", "Ring", "hag", "cluster")),
])
def test_real_extra_dims_come_through(rel, dims):
    path = external(rel)
    las = laspy.read(path)
    b = read_all(path, chunk_size=200_000)
    for d in dims:
        assert np.array_equal(b.extra[d], np.asarray(las[d])), d
    assert probe(path).extra_dims[2:] == dims


@pytest.mark.parametrize("start", [1_000, 100_000, 500_000])
def test_real_copc_start_reads_the_right_records(start):
    """COPC has variable-size LAZ chunks, where laspy/lazrs' seek lands on wrong records."""
    path = external("pdal/lone-star.copc.laz")
    las = laspy.read(path)
    b = read_all(path, start=start, stop=start + 12_345, chunk_size=5_000)
    assert np.array_equal(b.index, np.arange(start, start + 12_345))
    assert np.array_equal(b.xyz[:, 0], las.x[start : start + 12_345])
    assert np.array_equal(b.gps_time, las.gps_time[start : start + 12_345])


# -- bad inputs -----------------------------------------------------------------------------


def one_line(err: pytest.ExceptionInfo, path: Path) -> str:
    msg = str(err.value)
    assert "\n" not in msg, msg
    assert str(path) in msg, msg
    assert isinstance(err.value, PipelineError)
    return msg


def test_missing_and_not_a_file(tmp_path):
    with pytest.raises(InputFileError, match="no such file") as err:
        probe(tmp_path / "nope.laz")
    one_line(err, tmp_path / "nope.laz")
    with pytest.raises(FileNotFoundError):
        read_blocks(tmp_path / "nope.ply")
    (tmp_path / "dir.las").mkdir()
    with pytest.raises(InputFileError, match="not a regular file"):
        probe(tmp_path / "dir.las")


@pytest.mark.parametrize("suffix", [".las", ".laz", ".ply", ".e57", ".json"])
def test_empty_file(tmp_path, suffix):
    path = tmp_path / f"empty{suffix}"
    path.touch()
    for call in (lambda: probe(path), lambda: next(read_blocks(path))):
        with pytest.raises(CorruptInputError, match="empty file") as err:
            call()
        one_line(err, path)


def test_unknown_suffix_and_not_a_point_cloud(tmp_path):
    (tmp_path / "cloud.xyz").write_text("1 2 3\n")
    with pytest.raises(UnsupportedInputError, match="unknown point cloud suffix '.xyz'") as err:
        probe(tmp_path / "cloud.xyz")
    one_line(err, tmp_path / "cloud.xyz")
    for name in ("notes.las", "notes.ply", "notes.e57"):
        (tmp_path / name).write_text("hello, I am text\n" * 20)
        with pytest.raises(CorruptInputError, match="not a .* point cloud") as err:
            probe(tmp_path / name)
        one_line(err, tmp_path / name)


def test_corrupt_las_header(tmp_path, las_pair):
    data = bytearray(las_pair[0].read_bytes())
    (tmp_path / "short.las").write_bytes(bytes(data[:120]))
    data[104] = 42  # point format id 42 does not exist
    (tmp_path / "badformat.las").write_bytes(bytes(data))
    for name in ("short.las", "badformat.las"):
        path = tmp_path / name
        for call in (lambda p=path: probe(p), lambda p=path: list(read_blocks(p))):
            with pytest.raises(CorruptInputError, match="corrupt LAS/LAZ header") as err:
                call()
            one_line(err, path)


@pytest.mark.parametrize("frac", [0.3, 0.75, 0.999])
@pytest.mark.parametrize("source", ["made", "autzen"])
def test_truncated_laz_fails_clearly(tmp_path, las_pair, source, frac):
    src = las_pair[1] if source == "made" else external("pdal/autzen_trim.laz")
    data = src.read_bytes()
    path = tmp_path / "cut.laz"
    path.write_bytes(data[: int(len(data) * frac)])
    with pytest.raises(CorruptInputError, match="truncated or corrupt LAS/LAZ data") as err:
        for _ in read_blocks(path, chunk_size=1000):
            pass
    one_line(err, path)
    with pytest.raises(CorruptInputError):
        list(read_blocks(path, start=1_000, chunk_size=1000))


def test_truncated_las(tmp_path, las_pair):
    data = las_pair[0].read_bytes()
    header = laspy.open(las_pair[0]).header
    for cut in (header.offset_to_point_data + 100 * header.point_format.size,  # on a record edge
                len(data) - 7):
        path = tmp_path / f"cut{cut}.las"
        path.write_bytes(data[:cut])
        for call in (lambda p=path: probe(p), lambda p=path: list(read_blocks(p))):
            with pytest.raises(CorruptInputError, match="truncated LAS: the header promises 2500") as err:
                call()
            one_line(err, path)


def test_truncated_and_broken_ply(tmp_path, ply_file):
    path, _ = ply_file
    data = path.read_bytes()
    cut = tmp_path / "cut.ply"
    body = data.index(b"end_header") + 11
    cut.write_bytes(data[: body + (len(data) - body) // 2])
    with pytest.raises(CorruptInputError, match="truncated PLY") as err:
        list(read_blocks(cut, chunk_size=CHUNK))
    one_line(err, cut)
    (tmp_path / "header.ply").write_bytes(b"ply\nformat ascii 1.0\nelement vertex 3\nproperty flot x\n")
    with pytest.raises(CorruptInputError, match="corrupt PLY header"):
        probe(tmp_path / "header.ply")
    (tmp_path / "mesh.ply").write_bytes(
        b"ply\nformat ascii 1.0\nelement face 1\nproperty list uchar int vertex_index\nend_header\n3 0 1 2\n")
    with pytest.raises(CorruptInputError, match="no 'vertex' element"):
        probe(tmp_path / "mesh.ply")
    (tmp_path / "noz.ply").write_bytes(
        b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n1 2\n")
    with pytest.raises(CorruptInputError, match=r"lacks \['z'\]"):
        probe(tmp_path / "noz.ply")
    (tmp_path / "junk.ply").write_bytes(
        b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
        b"property float z\nend_header\n1 2 3\n1 two 3\n")
    with pytest.raises(CorruptInputError, match="truncated or corrupt PLY data"):
        list(read_blocks(tmp_path / "junk.ply"))


def test_truncated_e57(tmp_path, e57_file):
    path, _ = e57_file
    data = path.read_bytes()
    for frac in (0.1, 0.5, 0.95):
        cut = tmp_path / f"cut{frac}.e57"
        cut.write_bytes(data[: int(len(data) * frac)])
        with pytest.raises(CorruptInputError, match="corrupt E57 file") as err:
            list(read_blocks(cut))
        one_line(err, cut)


def test_bad_parameters(las_pair):
    path = las_pair[0]
    for kwargs, match in [({"chunk_size": 0}, "'chunk_size'"), ({"chunk_size": 2.5}, "'chunk_size'"),
                          ({"start": -1}, "'start'"), ({"start": 10, "stop": 5}, "'stop'"),
                          ({"stop": True}, "'stop'")]:
        with pytest.raises(ConfigError, match=match):
            read_blocks(path, **kwargs)
    with pytest.raises(ConfigError, match="unknown keys \\['colour'\\]"):
        SourceInfo.from_dict(probe(path).to_dict() | {"colour": True})
    with pytest.raises(ConfigError, match="rows like xyz"):
        PointBlock(xyz=np.zeros((2, 3)), index=np.zeros(2, np.uint64), intensity=np.zeros(3, np.uint16))


def test_pdal_pipeline(tmp_path, las_pair):
    """Optional: libpdal has no Debian bookworm or PyPI build our machines can install."""
    try:
        import pdal  # noqa: F401
    except ImportError:
        pytest.skip("pdal is not importable (libpdal has no bookworm/PyPI build for our machines)")
    pipe = tmp_path / "pipe.json"
    pipe.write_text(json.dumps({"pipeline": [str(las_pair[0])]}))
    b = read_all(pipe, chunk_size=CHUNK)
    ref = read_all(las_pair[0])
    assert np.allclose(b.xyz, ref.xyz)
    assert np.array_equal(b.index, ref.index)
    assert probe(pipe).point_count == N


def test_pdal_missing_is_a_clear_error(tmp_path):
    try:
        import pdal  # noqa: F401
    except ImportError:
        pass
    else:
        pytest.skip("pdal is installed")
    pipe = tmp_path / "pipe.json"
    pipe.write_text("{}")
    with pytest.raises(UnsupportedInputError, match="optional package 'pdal'") as err:
        list(read_blocks(pipe))
    one_line(err, pipe)


def _las_with_empty_wkt(path: Path) -> Path:
    """A LAS whose WKT VLR holds two quote marks, as ../shared's warsaw_small.las does."""
    header = laspy.LasHeader(point_format=3, version="1.2")
    header.vlrs.append(laspy.vlrs.known.WktCoordinateSystemVlr("''"))
    las = laspy.LasData(header)
    rng = np.random.default_rng(0)
    las.x, las.y, las.z = (rng.uniform(0, 10, 50) for _ in range(3))
    las.write(path)
    return path


@pytest.mark.parametrize("source", ["made", "warsaw"])
def test_an_empty_crs_vlr_is_no_crs_in_ingest_and_export(tmp_path, source, caplog):
    from hollowtree.pipeline.export import _out_header

    path = _las_with_empty_wkt(tmp_path / "empty-wkt.las") if source == "made" else external("pdal/warsaw_small.las")
    info = probe(path)
    assert info.crs_wkt is None
    with caplog.at_level("WARNING"):
        header = _out_header([info.to_dict()])
    assert header.parse_crs() is None
    assert any("CRS VLR could not be parsed" in r.getMessage() and str(path) in r.getMessage()
               and "the labelled copy has no CRS" in r.getMessage() for r in caplog.records)


def test_a_broken_crs_vlr_is_reported_once_per_file_while_reading(tmp_path, caplog):
    """A run reads a header more than once (probe, ingest): one warning per file."""
    a, b = _las_with_empty_wkt(tmp_path / "a.las"), _las_with_empty_wkt(tmp_path / "b.las")
    with caplog.at_level("WARNING"):
        for p in (a, b, a, b):
            assert probe(p).crs_wkt is None
        assert sum(1 for _ in read_blocks(a)) >= 1
    said = [r.getMessage() for r in caplog.records if "CRS VLR could not be parsed" in r.getMessage()]
    assert [str(a) in m for m in said] == [True, False]
    assert all("taken as no CRS" in m for m in said)


def test_autzen_in_feet_runs_in_metres_and_is_called_sparse(tmp_path):
    """A real scan in feet (its CRS says so): the run converts to metres, says so, and
    warns that an airborne scan this sparse is outside what the method is made for."""
    import subprocess
    import sys

    path = external("pdal/autzen_trim.laz")
    wf = tmp_path / "wf.yaml"
    wf.write_text(f"input: {{files: [{path}]}}\nstore: {tmp_path / 's.zarr'}\ntree: {{enabled: false}}\n"
                  "cluster: {scheduler: sync}\n")
    r = subprocess.run([sys.executable, "-m", "hollowtree", "run", str(wf), "--no-progress"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert "input coordinates in foot (0.3048 m, from the CRS)" in r.stdout
    assert "m apart" in r.stderr
    assert "made for terrestrial scans" in r.stderr
