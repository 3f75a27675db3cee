"""The virtual terrestrial laser scanner: first-hit ray casting from scanner stations.

Each station sends a spherical grid of rays (azimuth x elevation at one angular step, the
way a real phase or pulse scanner sweeps vertical profiles while it turns). The first
triangle a ray meets is the point, so occlusion and the fall of density with range are
real, not faked by sampling surfaces. The range gets Gaussian noise, every point gets an
intensity and a colour from its material and incidence angle, and each station can carry
a small registration error (rotation + translation) as real registered scans do.

Ray engine: Intel Embree through ``embreex`` (a PyPI wheel of a few MB, no system
libraries). Measured on our 2-core machine it casts 1.2 M incoherent rays/s per core and
releases the GIL, so the chunks of one scan are cast on a small thread pool.

Everything here works in local metres (the scene's frame) as float64; the survey offset is
added only when the points are written (``scenes/synth.py``). Nothing here imports laspy.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from embreex import mesh_construction, rtcore_scene

from hollowtree.classes import NUM_CLASSES
from hollowtree.errors import ConfigError
from hollowtree.scenes.scan_params import ScanParams
from hollowtree.scenes.scene import Scene

__all__ = [
    "ScanParams",
    "PointChunk",
    "RayCaster",
    "range_sigma",
    "station_poses",
    "count_rays",
    "estimate_step",
    "scan",
]

#: Elevation window of a station, degrees above the horizon (a tripod scanner's 300 deg).
ELEVATION_MIN_DEG = -60.0
ELEVATION_MAX_DEG = 90.0
#: Reference range of the noise setting: ``noise`` is the standard deviation at 10 m.
NOISE_REFERENCE_RANGE = 10.0
#: Rays per cast (bounds memory: about 200 bytes per ray in flight).
CHUNK_RAYS = 262_144
#: Pulse rate of the simulated scanner (gps_time advances by 1 / rate per ray).
PULSE_RATE_HZ = 1_000_000.0
#: Profiles per noise seed: chunks are whole multiples, so chunking never changes a draw.
NOISE_BLOCK = 16
#: Coarse step of the pilot scan that sets the step for a requested point count.
PILOT_STEP_DEG = 0.5

# Diffuse reflectance and base colour (8-bit RGB) per class id: sandstone, brick, marble.
_REFLECTANCE = np.array([0.5, 0.30, 0.55, 0.45, 0.60, 0.75, 0.65, 0.65, 0.25])
_COLOUR = np.array(
    [
        [128, 128, 128],  # unclassified
        [150, 135, 110],  # ground: dust and paving
        [176, 96, 64],  # wall: fired brick
        [160, 150, 140],  # roof: lime plaster
        [196, 120, 80],  # arch: brick with sandstone frame
        [236, 232, 224],  # dome: white marble / plaster
        [200, 110, 70],  # minaret: glazed brick
        [214, 190, 150],  # pillar: sandstone
        [70, 110, 60],  # other: vegetation, vehicles
    ],
    dtype=np.float64,
)
assert len(_REFLECTANCE) == NUM_CLASSES
assert len(_COLOUR) == NUM_CLASSES


@dataclass(frozen=True, kw_only=True, eq=False)
class PointChunk:
    """Points of one chunk of rays, in scan order (local metres).

    Attributes
    ----------
    xyz : ndarray of shape (n_points, 3), float64
    intensity : ndarray of shape (n_points,), uint16
    rgb : ndarray of shape (n_points, 3), uint16 (16-bit colour, as LAS stores it)
    gt_class : ndarray of shape (n_points,), uint8
    gt_instance : ndarray of shape (n_points,), uint32
    station : int
        Index of the station (0-based).
    gps_time : ndarray of shape (n_points,), float64
    elevation_deg : ndarray of shape (n_points,), float32
        Elevation of the ray above the horizon.
    n_rays : int
        Rays cast for this chunk (hits and misses).
    """

    xyz: npt.NDArray[np.float64]
    intensity: npt.NDArray[np.uint16]
    rgb: npt.NDArray[np.uint16]
    gt_class: npt.NDArray[np.uint8]
    gt_instance: npt.NDArray[np.uint32]
    station: int
    gps_time: npt.NDArray[np.float64]
    elevation_deg: npt.NDArray[np.float32]
    n_rays: int

    def __len__(self) -> int:
        return int(len(self.xyz))


class RayCaster:
    """First-hit ray casting against a scene's triangles (Embree).

    Build once per scene (the BVH build takes about 1 s per million triangles) and call
    :meth:`cast` from several threads: Embree releases the GIL.
    """

    def __init__(self, scene: Scene) -> None:
        self._scene = rtcore_scene.EmbreeScene()
        # Embree takes float32 vertices: scenes are in local metres (|x| < a few hundred),
        # where float32 resolves a few micrometres. Keep the mesh object alive with the scene.
        self._mesh = mesh_construction.TriangleMesh(
            self._scene,
            np.ascontiguousarray(scene.vertices, dtype=np.float32),
            np.ascontiguousarray(scene.faces, dtype=np.int32),
        )

    def cast(
        self,
        origin: npt.NDArray[np.float64],
        directions: npt.NDArray[np.float64],
        *,
        max_range: float,
    ) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """Cast rays from one origin.

        Returns
        -------
        face : ndarray of shape (n_rays,), int64
            Triangle hit first, -1 for a miss.
        t : ndarray of shape (n_rays,), float64
            Distance to the hit along the (unit) direction.
        normal : ndarray of shape (n_rays, 3), float64
            Unit geometric normal of the triangle hit (sign arbitrary).
        """
        n = len(directions)
        o = np.broadcast_to(np.asarray(origin, dtype=np.float32), (n, 3)).copy()
        d = np.ascontiguousarray(directions, dtype=np.float32)
        dists = np.full(n, max_range, dtype=np.float32)
        res = self._scene.run(o, d, dists=dists, output=1)
        face = res["primID"].astype(np.int64)
        face[res["geomID"] < 0] = -1
        ng = res["Ng"].astype(np.float64)
        norm = np.linalg.norm(ng, axis=1, keepdims=True)
        np.divide(ng, norm, out=ng, where=norm > 0)
        return face, res["tfar"].astype(np.float64), ng


def range_sigma(r: npt.NDArray[np.float64], noise: float) -> npt.NDArray[np.float64]:
    """Standard deviation of the range noise at range ``r`` (metres).

    ``noise`` is the value at 10 m; half of it is range-independent, half grows linearly.

    Examples
    --------
    >>> range_sigma(np.array([0.0, 10.0, 30.0]), 0.002).round(4).tolist()
    [0.001, 0.002, 0.004]
    """
    return noise * (0.5 + 0.5 * np.asarray(r, dtype=np.float64) / NOISE_REFERENCE_RANGE)


@dataclass(frozen=True)
class _StationPose:
    position: npt.NDArray[np.float64]  # true optical centre, local metres
    heading: float  # azimuth of the first profile, radians
    rotation: npt.NDArray[np.float64]  # registration error rotation (3, 3)
    translation: npt.NDArray[np.float64]  # registration error translation (3,)


def _rotation_matrix(rotvec: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    theta = float(np.linalg.norm(rotvec))
    if theta == 0.0:
        return np.eye(3)
    k = rotvec / theta
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(theta) * kx + (1 - math.cos(theta)) * kx @ kx


def station_poses(scene: Scene, params: ScanParams) -> list[_StationPose]:
    """Positions, headings and registration errors of the stations a scan uses (seeded)."""
    k = len(scene.stations) if params.n_stations is None else params.n_stations
    if k > len(scene.stations):
        raise ConfigError(
            f"scene {scene.name!r} has {len(scene.stations)} scanner stations; asked for {k}"
        )
    poses = []
    for i in range(k):
        rng = np.random.default_rng(np.random.SeedSequence([params.seed, 1, i]))
        heading = float(rng.uniform(0, 2 * math.pi))
        err = params.registration_error
        rot = _rotation_matrix(rng.normal(0.0, err / 20.0, 3)) if err > 0 else np.eye(3)
        trans = rng.normal(0.0, err, 3) if err > 0 else np.zeros(3)
        poses.append(_StationPose(scene.stations[i].copy(), heading, rot, trans))
    return poses


def _grid_shape(step_deg: float) -> tuple[int, npt.NDArray[np.float64]]:
    n_az = int(round(360.0 / step_deg))
    n_el = int(math.floor((ELEVATION_MAX_DEG - ELEVATION_MIN_DEG) / step_deg)) + 1
    elevations = np.radians(ELEVATION_MIN_DEG + step_deg * np.arange(n_el))
    return n_az, elevations


def _ray_normals(
    seed: int, station: int, global_ray: npt.NDArray[np.int64], n_el: int
) -> npt.NDArray[np.float64]:
    """Three standard normal draws per hit, seeded per block of NOISE_BLOCK profiles.

    The draws depend on the station and the ray's place in the grid only, never on how
    the profiles were grouped into chunks.
    """
    out = np.empty((len(global_ray), 3))
    block = global_ray // (NOISE_BLOCK * n_el)
    starts = np.flatnonzero(np.r_[True, block[1:] != block[:-1]]) if len(block) else []
    bounds = list(starts) + [len(block)]
    for a, b in zip(bounds[:-1], bounds[1:], strict=True):
        rng = np.random.default_rng(np.random.SeedSequence([seed, 2, station, int(block[a])]))
        out[a:b] = rng.normal(0.0, 1.0, (b - a, 3))
    return out


def _scan_block(
    caster: RayCaster,
    scene_class: npt.NDArray[np.uint8],
    face_instance: npt.NDArray[np.uint32],
    pose: _StationPose,
    station: int,
    columns: range,
    params: ScanParams,
) -> PointChunk:
    """Cast the profiles ``columns`` of one station and turn hits into points."""
    n_az, elev = _grid_shape(params.step_deg)
    step = math.radians(params.step_deg)
    az = pose.heading + step * np.arange(columns.start, columns.stop)
    ce, se = np.cos(elev), np.sin(elev)
    d = np.empty((len(az), len(elev), 3))
    d[..., 0] = np.cos(az)[:, None] * ce[None, :]
    d[..., 1] = np.sin(az)[:, None] * ce[None, :]
    d[..., 2] = se[None, :]
    d = d.reshape(-1, 3)
    face, t, normal = caster.cast(pose.position, d, max_range=params.max_range)
    hit = (face >= 0) & (t >= params.min_range) & (t <= params.max_range)
    ray_index = np.flatnonzero(hit)
    face, t, normal, d = face[hit], t[hit], normal[hit], d[hit]

    n_el = len(elev)
    global_ray = columns.start * n_el + ray_index
    noise = _ray_normals(params.seed, station, global_ray, n_el)
    r = t + noise[:, 0] * range_sigma(t, params.noise)
    xyz = pose.position + d * r[:, None]
    if params.registration_error > 0:
        xyz = pose.position + (xyz - pose.position) @ pose.rotation.T + pose.translation

    inst = face_instance[face]
    cls = scene_class[inst]
    cos_inc = np.abs(np.einsum("ij,ij->i", normal, d))
    shade = 0.3 + 0.7 * cos_inc
    refl = _REFLECTANCE[cls] * shade * np.exp(-t / 400.0)
    refl *= 1.0 + 0.03 * noise[:, 1]
    intensity = np.clip(refl * 65535.0, 0, 65535).astype(np.uint16)
    colour = _COLOUR[cls] * (0.55 + 0.45 * cos_inc)[:, None]
    colour *= 1.0 + 0.04 * noise[:, 2:3]
    rgb = (np.clip(colour, 0, 255) * 257.0).astype(np.uint16)

    gps_time = 1.0e9 + 3600.0 * station + global_ray / PULSE_RATE_HZ
    elevation = np.degrees(elev)[ray_index % n_el].astype(np.float32)
    return PointChunk(
        xyz=xyz,
        intensity=intensity,
        rgb=rgb,
        gt_class=cls.astype(np.uint8),
        gt_instance=inst.astype(np.uint32),
        station=station,
        gps_time=gps_time,
        elevation_deg=elevation,
        n_rays=len(az) * n_el,
    )


def count_rays(scene: Scene, params: ScanParams) -> int:
    """Rays a scan with ``params`` casts (for progress bars)."""
    n_az, elev = _grid_shape(params.step_deg)
    k = len(scene.stations) if params.n_stations is None else params.n_stations
    return k * n_az * len(elev)


def scan(
    scene: Scene,
    params: ScanParams,
    *,
    caster: RayCaster | None = None,
    workers: int = 2,
    chunk_rays: int = CHUNK_RAYS,
) -> Iterator[PointChunk]:
    """Scan ``scene`` from its stations; yield the points chunk by chunk, in scan order.

    Station by station, profile block by profile block; at most ``2 * workers`` chunks
    are in flight, so memory does not grow with the number of points. The result depends
    only on ``scene`` and ``params`` (never on ``workers`` or timing).

    Parameters
    ----------
    scene : Scene
    params : ScanParams
    caster : RayCaster, optional
        Reuse a caster already built for ``scene``.
    workers : int
        Threads casting rays.
    chunk_rays : int
        Approximate rays per chunk.

    Yields
    ------
    PointChunk
    """
    poses = station_poses(scene, params)
    caster = caster if caster is not None else RayCaster(scene)
    scene_class = scene.instance_class
    n_az, elev = _grid_shape(params.step_deg)
    cols = max(1, chunk_rays // (len(elev) * NOISE_BLOCK)) * NOISE_BLOCK
    jobs = [
        (pose, i, range(c, min(c + cols, n_az)))
        for i, pose in enumerate(poses)
        for c in range(0, n_az, cols)
    ]
    with ThreadPoolExecutor(max_workers=max(1, workers)) as pool:
        pending = []
        for job in jobs:
            pending.append(
                pool.submit(
                    _scan_block, caster, scene_class, scene.face_instance, *job, params
                )
            )
            while len(pending) > 2 * max(1, workers):
                yield pending.pop(0).result()
        for fut in pending:
            yield fut.result()


def estimate_step(
    scene: Scene,
    n_points: int,
    *,
    n_stations: int | None = None,
    min_range: float = ScanParams.min_range,
    max_range: float = ScanParams.max_range,
    caster: RayCaster | None = None,
) -> float:
    """Angular step (degrees) at which a scan of ``scene`` yields about ``n_points``.

    A pilot scan at 0.5 degrees counts the hits; hits grow as the inverse square of the
    step, so the step follows. The count of the real scan lands within a few percent.

    Raises
    ------
    ConfigError
        If ``n_points`` is not positive, or needs a step finer than 0.001 degrees.
    """
    if n_points <= 0:
        raise ConfigError(f"points must be a positive count; got {n_points}")
    pilot = ScanParams(
        step_deg=PILOT_STEP_DEG,
        n_stations=n_stations,
        noise=0.0,
        min_range=min_range,
        max_range=max_range,
    )
    hits = sum(len(c) for c in scan(scene, pilot, caster=caster))
    if hits == 0:
        raise ConfigError(f"scene {scene.name!r}: the stations see nothing")
    step = PILOT_STEP_DEG * math.sqrt(hits / n_points)
    if step < 0.001:
        raise ConfigError(
            f"{n_points} points would need an angular step of {step:.2g} degrees; "
            "use more stations or fewer points"
        )
    return min(step, 10.0)

