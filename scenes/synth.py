"""Write a synthetic labelled scan: the scanner's chunks streamed into LAS 1.4 / LAZ.

This is the edge of ``scenes/``: the only module here that imports laspy and pyarrow.
The file gets point format 7 (XYZ, intensity, return info, gps_time, RGB), a scale of
1 mm, survey-sized offsets (local (0, 0, 0) lies at E 500 000, N 3 500 000, H 200 m, so
any float32 shortcut on the coordinates loses decimetres and fails loudly), the
extra-bytes dimensions ``gt_class`` (uint8, :mod:`hollowtree.classes`) and ``gt_instance``
(uint32, 0 = none), and a ``hollowtree``/1 VLR holding the scan's settings and station
positions as JSON. A Parquet sidecar ``<name>.elements.parquet`` lists the instances.

Both files are written under temporary names in the output folder and renamed into place
only once complete, so a failed or interrupted run never leaves a half file behind and
never damages an existing one.
"""

from __future__ import annotations

import datetime as _dt
import json
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import laspy
import numpy as np
import numpy.typing as npt
import pyarrow as pa
import pyarrow.parquet as pq

from hollowtree.classes import ELEMENT_CLASSES, NUM_CLASSES, ClassId
from hollowtree.errors import ConfigError, InputFileError, OutputExistsError
from hollowtree.scenes.scan_params import DEFAULT_POINTS
from hollowtree.scenes.scanner import (
    RayCaster,
    ScanParams,
    count_rays,
    estimate_step,
    scan,
    station_poses,
)
from hollowtree.scenes.scene import Scene
from hollowtree.scenes.sites import GENERATED, SITES, TEST_SCENES, SiteSpec, build_scene

__all__ = [
    "SURVEY_ORIGIN",
    "SCALE",
    "SynthResult",
    "sidecar_path",
    "check_output_path",
    "write_scan",
    "synth",
    "read_scan_metadata",
]

#: World coordinates of the scene's local origin (a projected frame, metres).
SURVEY_ORIGIN = np.array([500_000.0, 3_500_000.0, 200.0])
#: Coordinate resolution of the written file (1 mm).
SCALE = 0.001
#: Header creation date: fixed, so that the bytes depend only on the arguments.
CREATION_DATE = _dt.date(2026, 1, 1)
VLR_USER_ID = "hollowtree"
VLR_RECORD_ID = 1
_VERSION = "0.1.0"


@dataclass(frozen=True, kw_only=True)
class SynthResult:
    """What one synthetic scan wrote."""

    path: Path
    sidecar: Path
    scene: str
    n_points: int
    n_rays: int
    n_stations: int
    step_deg: float
    seconds: float
    points_per_class: dict[int, int] = field(default_factory=dict)
    instances_per_class: dict[int, int] = field(default_factory=dict)
    expected_counts: dict[int, int] = field(default_factory=dict)

    def summary(self) -> str:
        """A human-readable ground-truth summary (what ``hollowtree synth`` prints)."""
        lines = [
            f"{self.path}: {self.n_points:,} points of {self.scene!r} from "
            f"{self.n_stations} stations at {self.step_deg:.4f} deg "
            f"({self.seconds:.1f} s, {self.n_points / max(self.seconds, 1e-9) / 1e6:.2f} M points/s)",
            f"{'class':<14}{'points':>12}{'instances':>11}{'expected':>10}",
        ]
        for cid in range(1, NUM_CLASSES):
            c = ClassId(cid)
            exp = self.expected_counts.get(cid)
            lines.append(
                f"{c.label:<14}{self.points_per_class.get(cid, 0):>12,}"
                f"{self.instances_per_class.get(cid, 0):>11}"
                f"{'' if exp is None else exp:>10}"
            )
        lines.append(f"elements table: {self.sidecar}")
        return "\n".join(lines)


def sidecar_path(path: Path) -> Path:
    """``site.laz`` -> ``site.elements.parquet`` (same folder)."""
    return path.with_name(path.stem + ".elements.parquet")


def check_output_path(path: Path, *, overwrite: bool) -> Path:
    """Validate an output LAS/LAZ path before anything runs; return it as a Path.

    Raises
    ------
    ConfigError, InputFileError, OutputExistsError
        Wrong suffix, missing folder, or an existing file (or sidecar) without overwrite.
    """
    path = Path(path)
    if path.suffix.lower() not in (".las", ".laz"):
        raise ConfigError(f"output {path}: the name must end in .las or .laz")
    if not path.parent.is_dir():
        raise InputFileError(f"output folder {path.parent} does not exist")
    for p in (path, sidecar_path(path)):
        if p.exists() and not overwrite:
            raise OutputExistsError(f"output {p} already exists (pass --overwrite to replace it)")
        if p.exists() and p.is_dir():
            raise OutputExistsError(f"output {p} is a folder")
    return path


def _header(crs: str | None) -> laspy.LasHeader:
    header = laspy.LasHeader(point_format=7, version="1.4")
    header.add_extra_dims(
        [
            laspy.ExtraBytesParams("gt_class", "u1", description="hollowtree class id"),
            laspy.ExtraBytesParams("gt_instance", "u4", description="element instance, 0=none"),
        ]
    )
    header.scales = np.array([SCALE] * 3)
    header.offsets = SURVEY_ORIGIN.copy()
    header.system_identifier = "hollowtree virtual TLS"
    header.generating_software = f"hollowtree {_VERSION}"
    header.creation_date = CREATION_DATE
    if crs:
        try:
            import pyproj
        except ImportError as exc:  # pragma: no cover - pyproj is a dependency
            raise ConfigError("--crs needs the pyproj package") from exc
        try:
            header.add_crs(pyproj.CRS.from_user_input(crs))
        except pyproj.exceptions.CRSError as exc:
            reason = str(exc).strip().splitlines()[0] if str(exc).strip() else "unknown"
            raise ConfigError(f"crs {crs!r} is not a coordinate reference system: {reason}") from None
    return header


def _instance_bounds(scene: Scene) -> npt.NDArray[np.float64]:
    """World bounding box ``(n_instances + 1, 6)`` of every instance's triangles."""
    n = len(scene.elements) + 1
    tri = scene.vertices[scene.faces]
    lo, hi = tri.min(axis=1), tri.max(axis=1)
    out = np.full((n, 6), np.nan)
    order = np.argsort(scene.face_instance, kind="stable")
    inst = scene.face_instance[order]
    starts = np.flatnonzero(np.r_[True, inst[1:] != inst[:-1]])
    ids = inst[starts]
    out[ids, :3] = np.minimum.reduceat(lo[order], starts, axis=0) + SURVEY_ORIGIN
    out[ids, 3:] = np.maximum.reduceat(hi[order], starts, axis=0) + SURVEY_ORIGIN
    return out


def _elements_table(scene: Scene, counts: npt.NDArray[np.int64], meta: dict) -> pa.Table:
    bounds = _instance_bounds(scene)
    ids = np.array([e.instance for e in scene.elements], dtype=np.uint32)
    cols = {
        "instance": pa.array(ids),
        "class_id": pa.array(np.array([int(e.class_id) for e in scene.elements], dtype=np.uint8)),
        "class_name": pa.array([e.class_id.label for e in scene.elements]),
        "name": pa.array([e.name for e in scene.elements]),
        "site": pa.array([scene.name] * len(ids)),
    }
    for j, key in enumerate(("xmin", "ymin", "zmin", "xmax", "ymax", "zmax")):
        cols[key] = pa.array(bounds[ids, j])
    cols["point_count"] = pa.array(counts[ids].astype(np.uint64))
    table = pa.table(cols)
    return table.replace_schema_metadata({b"hollowtree": json.dumps(meta).encode()})


def write_scan(
    scene: Scene,
    path: Path,
    params: ScanParams,
    *,
    crs: str | None = None,
    expected_counts: dict[int, int] | None = None,
    on_rays: Callable[[int], None] | None = None,
    workers: int = 2,
    caster: RayCaster | None = None,
) -> SynthResult:
    """Scan ``scene`` with ``params`` and stream the points into ``path`` (LAS or LAZ).

    Memory is bounded by the scanner's chunks, whatever the number of points. The file
    and its sidecar appear only when both are complete.

    Parameters
    ----------
    scene : Scene
    path : Path
        ``.laz`` (compressed with lazrs) or ``.las``. Validate it first with
        :func:`check_output_path`.
    params : ScanParams
    crs : str, optional
        Anything pyproj understands ("EPSG:32643"); written as a WKT VLR.
    expected_counts : dict, optional
        Element counts the scene should have, reported in the summary.
    on_rays : callable, optional
        Called with the number of rays of every finished chunk (progress bars).
    """
    t0 = time.perf_counter()
    path = Path(path)
    header = _header(crs)
    caster = caster if caster is not None else RayCaster(scene)
    poses = station_poses(scene, params)
    meta = {
        "generator": f"hollowtree {_VERSION}",
        "scene": scene.name,
        "seed": params.seed,
        "step_deg": params.step_deg,
        "noise_at_10m": params.noise,
        "registration_error": params.registration_error,
        "min_range": params.min_range,
        "max_range": params.max_range,
        "survey_origin": SURVEY_ORIGIN.tolist(),
        # Registered positions: where each station's points put the scanner.
        "stations": [(p.position + p.translation + SURVEY_ORIGIN).tolist() for p in poses],
        "point_source_id": "station index + 1",
    }
    header.vlrs.append(
        laspy.VLR(
            user_id=VLR_USER_ID,
            record_id=VLR_RECORD_ID,
            description="synthetic scan settings",
            record_data=json.dumps(meta).encode(),
        )
    )
    local_shift = SURVEY_ORIGIN - header.offsets  # zero with the default offsets
    counts = np.zeros(len(scene.elements) + 1, dtype=np.int64)
    n_points = n_rays = 0
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    side = sidecar_path(path)
    side_tmp = side.with_name(f".{side.name}.{os.getpid()}.tmp")
    compress = path.suffix.lower() == ".laz"
    try:
        with laspy.open(
            tmp,
            mode="w",
            header=header,
            do_compress=compress,
            laz_backend=laspy.LazBackend.LazrsParallel if compress else None,
        ) as writer:
            for chunk in scan(scene, params, caster=caster, workers=workers):
                n_rays += chunk.n_rays
                if on_rays is not None:
                    on_rays(chunk.n_rays)
                n = len(chunk)
                if n == 0:
                    continue
                rec = laspy.ScaleAwarePointRecord.zeros(n, header=header)
                ints = np.round((chunk.xyz + local_shift) / SCALE).astype(np.int32)
                rec.X, rec.Y, rec.Z = ints[:, 0], ints[:, 1], ints[:, 2]
                rec.intensity = chunk.intensity
                rec.return_number = np.ones(n, dtype=np.uint8)
                rec.number_of_returns = np.ones(n, dtype=np.uint8)
                rec.point_source_id = np.full(n, chunk.station + 1, dtype=np.uint16)
                rec.gps_time = chunk.gps_time
                rec.scan_angle = np.round(chunk.elevation_deg / 0.006).astype(np.int16)
                rec.red, rec.green, rec.blue = chunk.rgb[:, 0], chunk.rgb[:, 1], chunk.rgb[:, 2]
                rec.gt_class = chunk.gt_class
                rec.gt_instance = chunk.gt_instance
                writer.write_points(rec)
                counts += np.bincount(chunk.gt_instance, minlength=len(counts))
                n_points += n
        pq.write_table(_elements_table(scene, counts, meta), side_tmp)
        os.replace(tmp, path)
        os.replace(side_tmp, side)
    finally:
        for p in (tmp, side_tmp):
            if p.exists():
                p.unlink()

    cls = scene.instance_class
    per_class = np.bincount(cls, weights=counts, minlength=NUM_CLASSES).astype(np.int64)
    seen = np.bincount(cls[np.flatnonzero(counts)], minlength=NUM_CLASSES)
    return SynthResult(
        path=path,
        sidecar=side,
        scene=scene.name,
        n_points=n_points,
        n_rays=n_rays,
        n_stations=len(poses),
        step_deg=params.step_deg,
        seconds=time.perf_counter() - t0,
        points_per_class={c: int(per_class[c]) for c in range(1, NUM_CLASSES)},
        instances_per_class={c: int(seen[c]) for c in range(1, NUM_CLASSES)},
        expected_counts=dict(expected_counts or {}),
    )


def _spec(name: str) -> SiteSpec:
    if name in SITES:
        return SITES[name]
    if name in TEST_SCENES:
        return TEST_SCENES[name]
    if name in GENERATED:
        return GENERATED[name]
    raise ConfigError(
        f"unknown site {name!r}; known sites: {', '.join(SITES)}; "
        f"test scenes: {', '.join(TEST_SCENES)}; procedural: {', '.join(GENERATED)}"
    )


def synth(
    site: str,
    out: Path,
    *,
    n_points: int | None = None,
    step_deg: float | None = None,
    n_stations: int | None = None,
    seed: int = ScanParams.seed,
    noise: float = ScanParams.noise,
    registration_error: float = ScanParams.registration_error,
    crs: str | None = None,
    overwrite: bool = False,
    on_rays: Callable[[int], None] | None = None,
    on_total: Callable[[int], None] | None = None,
    workers: int = 2,
) -> SynthResult:
    """Generate the labelled scan of ``site`` into ``out`` (the ``hollowtree synth`` job).

    Everything is validated before anything is written. With neither ``n_points`` nor
    ``step_deg`` the scan aims at ``DEFAULT_POINTS`` (one million).

    Raises
    ------
    ConfigError, InputFileError, OutputExistsError
        On bad arguments; nothing is written then.
    """
    spec = _spec(site)
    out = check_output_path(Path(out), overwrite=overwrite)
    if n_points is not None and step_deg is not None:
        raise ConfigError("give either points or step, not both")
    if n_points is not None and n_points <= 0:
        raise ConfigError(f"points must be a positive count; got {n_points}")
    if n_stations is None:
        n_stations = spec.default_stations
    # Validate the numbers before the (slower) scene build.
    ScanParams(
        step_deg=1.0 if step_deg is None else step_deg,
        n_stations=n_stations,
        noise=noise,
        registration_error=registration_error,
        seed=seed,
    )
    _header(crs)
    scene = build_scene(site, rng=seed)
    caster = RayCaster(scene)
    if step_deg is None:
        step_deg = estimate_step(
            scene, DEFAULT_POINTS if n_points is None else n_points, n_stations=n_stations, caster=caster
        )
    params = ScanParams(
        step_deg=step_deg,
        n_stations=n_stations,
        noise=noise,
        registration_error=registration_error,
        seed=seed,
    )
    if on_total is not None:
        on_total(count_rays(scene, params))
    built = spec.expected_counts or scene.element_counts()  # a generated site: as built
    expected = {int(c): int(built.get(c, 0)) for c in ELEMENT_CLASSES}
    return write_scan(
        scene,
        out,
        params,
        crs=crs,
        expected_counts=expected,
        on_rays=on_rays,
        workers=workers,
        caster=caster,
    )



def read_scan_metadata(path: Path) -> dict:
    """The settings and station positions that :func:`write_scan` stored in a LAS/LAZ file.

    Raises
    ------
    InputFileError
        If the file is missing or carries no hollowtree VLR.
    """
    path = Path(path)
    if not path.is_file():
        raise InputFileError(f"{path} does not exist")
    with laspy.open(path) as reader:
        for vlr in reader.header.vlrs:
            if vlr.user_id == VLR_USER_ID and vlr.record_id == VLR_RECORD_ID:
                return json.loads(bytes(vlr.record_data).decode())
    raise InputFileError(f"{path} has no hollowtree scan metadata (not made by hollowtree synth)")
