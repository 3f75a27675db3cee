"""HollowNet's training data: labelled segments cut from synthetic scans, as voxel grids.

One call, :func:`build_dataset`, makes a data set from a seed and caches it on disk as
NPZ shards of bit-packed hollow-voxel grids; :func:`load_dataset` reads it back. The
samples come from scans, not from sampled meshes, so they show what the tree will show
the network:

1. a random small scene is drawn (``hollownet/_scenes.py``: domed halls with chattris,
   minarets and bastions, arcades and portals, colonnades and porches, streets with
   clutter), always with the ground and some clutter;
2. it is scanned by the virtual scanner (:func:`scenes.scanner.scan`): first-hit rays
   from 2 to 6 stations (sometimes on a roof or inside), so occlusion, density falling
   with range, range noise and registration error are real;
3. every scanned instance becomes samples of its class: elements (arch, dome, minaret,
   pillar) whole or partial (cut by a random vertical or horizontal plane, as at a scan's
   edge), walls and roofs whole or as pieces, the ground as patches of 3 to 40 m (what the
   coarse stage makes of it), clutter as ``other``; a roof piece must show its top or
   underside (a slab seen only at its rim is a vertical band, a wall to any eye);
4. each sample is augmented (yaw, anisotropic scale, point dropout, jitter) and
   voxelised (:func:`hollownet.voxels.voxelize_batch`, canonical yaw by default).

Scenes are drawn where classes are short, until every class has ``n_per_class``
samples; the result depends only on the parameters (seeded by
``SeedSequence([seed, split, scene])``), never on timing.
"""

from __future__ import annotations

import hashlib
import json
import logging
import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from hollowtree.classes import ELEMENT_CLASSES, ClassId
from hollowtree.errors import ConfigError, CorruptInputError, InputFileError
from hollowtree.hollownet._scenes import RECIPES, random_scene
from hollowtree.hollownet.model import OUTPUT_CLASSES
from hollowtree.hollownet.voxels import GRID_SIZE, OCCUPIED, voxelize_batch
from hollowtree.params import Params, param
from hollowtree.scenes.scanner import ScanParams, scan

__all__ = [
    "DATASET_VERSION",
    "DatasetParams",
    "build_dataset",
    "generate_samples",
    "labelled_samples",
    "load_dataset",
    "pack_grids",
    "unpack_grids",
]

logger = logging.getLogger(__name__)

#: Bump when the generator changes what a seed produces: cached data sets are remade.
DATASET_VERSION = 3
_SPLITS = {"train": 0, "test": 1, "heldout": 2}
_SHARD = 1024
_MIN_POINTS = 150
_MAX_POINTS = 200_000


@dataclass(frozen=True, kw_only=True)
class DatasetParams(Params, owner="DatasetParams"):
    """What a data set is made of; equal parameters give identical data. Each field is
    declared once (``hollowtree.params``): its default, range and meaning."""

    seed: int = param(0, doc="seeds the scenes, the scans and the augmentation")
    split: str = param("train", choices=tuple(_SPLITS),
                       doc="mixed into the seed, so the splits of one seed never share a scene")
    n_per_class: int = param(300, ge=1, doc="samples of every output class")
    variants: int = param(3, ge=1, doc="augmented samples cut from one scanned instance (ground and roof: twice "
                                       "as many)")
    grid_size: int = param(GRID_SIZE, ge=1, doc="edge of the voxel grid, cells")
    canonical_yaw: bool = param(True, doc="voxelise with the footprint's principal axis along x")

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> DatasetParams:
        unknown = set(data) - set(cls.__dataclass_fields__)
        if unknown:
            raise ConfigError(f"unknown data set parameters {sorted(unknown)}; known: {sorted(cls.__dataclass_fields__)}")
        return cls(**data)

    def key(self) -> str:
        """Folder name of the cached data set: readable fields plus a hash of all."""
        h = hashlib.sha256(json.dumps([DATASET_VERSION, self.to_dict()], sort_keys=True).encode()).hexdigest()[:10]
        return f"{self.split}-seed{self.seed}-n{self.n_per_class}-{h}"


# --------------------------------------------------------------------------- cutting
def _crop_plane(p: npt.NDArray[np.float64], rng: np.random.Generator, lo: float, hi: float) -> npt.NDArray[np.bool_]:
    """Keep the points below a random plane: a vertical one (cut from the side) or a horizontal one."""
    if rng.random() < 0.7:
        a = rng.uniform(0, 2 * math.pi)
        s = p[:, 0] * math.cos(a) + p[:, 1] * math.sin(a)
    else:
        s = p[:, 2] * (1.0 if rng.random() < 0.5 else -1.0)
    return s <= np.quantile(s, rng.uniform(lo, hi))


def _window(p: npt.NDArray[np.float64], rng: np.random.Generator, lo: float, hi: float,
            vertical: float) -> npt.NDArray[np.bool_]:
    """A piece of a planar instance: a window along its principal axis (and maybe in z)."""
    d = p[:, :2] - p[:, :2].mean(axis=0)
    w, v = np.linalg.eigh(d.T @ d)
    u = d @ v[:, -1]
    keep = np.ones(len(p), dtype=bool)
    f = rng.uniform(lo, hi)
    if f < 1:
        a, b = u.min(), u.max()
        start = rng.uniform(a, b - f * (b - a))
        keep &= (u >= start) & (u <= start + f * (b - a))
    if rng.random() < vertical:
        z = p[:, 2]
        g = rng.uniform(0.4, 1.0)
        a, b = z.min(), z.max()
        start = rng.uniform(a, b - g * (b - a))
        keep &= (z >= start) & (z <= start + g * (b - a))
    return keep


def _ground_patch(p: npt.NDArray[np.float64], rng: np.random.Generator) -> npt.NDArray[np.bool_]:
    c = p[rng.integers(len(p)), :2]
    side = math.exp(rng.uniform(math.log(3.0), math.log(40.0)))
    ratio = rng.uniform(0.4, 1.0)
    a = rng.uniform(0, math.pi)
    d = p[:, :2] - c
    u = d[:, 0] * math.cos(a) + d[:, 1] * math.sin(a)
    v = -d[:, 0] * math.sin(a) + d[:, 1] * math.cos(a)
    return (np.abs(u) <= side / 2) & (np.abs(v) <= side * ratio / 2)


def _cut(p: npt.NDArray[np.float64], cls: ClassId, rng: np.random.Generator) -> npt.NDArray[np.bool_]:
    if cls == ClassId.GROUND:
        return _ground_patch(p, rng)
    if cls == ClassId.WALL:
        return _window(p, rng, 0.25, 1.3, vertical=0.3)
    if cls == ClassId.ROOF:
        return _window(p, rng, 0.7, 1.3, vertical=0.0)
    if cls in ELEMENT_CLASSES and rng.random() < 0.35:
        return _crop_plane(p, rng, 0.55, 0.9)
    if cls == ClassId.OTHER and rng.random() < 0.2:
        return _crop_plane(p, rng, 0.6, 0.95)
    return np.ones(len(p), dtype=bool)


def _shows_faces(p: npt.NDArray[np.float64]) -> bool:
    """Whether a roof piece shows its top or underside, not only its rim (a vertical band
    that no one, network or person, tells from a wall): most points near its top or bottom."""
    z = p[:, 2]
    lo, hi = float(z.min()), float(z.max())
    dz = hi - lo
    return dz <= 0 or float(np.mean((z <= lo + 0.15 * dz) | (z >= hi - 0.15 * dz))) >= 0.6


def _augment(p: npt.NDArray[np.float64], rng: np.random.Generator) -> npt.NDArray[np.float64]:
    """Point dropout, yaw, anisotropic scale and jitter of one sample."""
    keep = rng.uniform(0.25, 1.0)
    if keep < 1 and len(p) * keep >= _MIN_POINTS:
        p = p[rng.random(len(p)) < keep]
    q = p - p.mean(axis=0)
    a = rng.uniform(0, 2 * math.pi)
    c, s = math.cos(a), math.sin(a)
    q = q @ np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
    q *= np.exp(rng.uniform(math.log(0.8), math.log(1.25), 3))
    ext = float((q.max(axis=0) - q.min(axis=0)).max())
    q += rng.normal(0.0, rng.uniform(0.0, 0.006) * ext, q.shape)
    return q


def _pick_recipe(need: dict[ClassId, int], rng: np.random.Generator) -> str:
    names = list(RECIPES)
    w = np.array([sum(need[c] for c in RECIPES[n][1]) for n in names], dtype=np.float64)
    if w.sum() == 0:  # only classes every scene has (ground, wall, other) are short
        w = np.ones(len(names))
    return names[int(rng.choice(len(names), p=w / w.sum()))]


def generate_samples(
    params: DatasetParams,
    *,
    progress: Callable[[int, int], None] | None = None,
    keep_points: bool = False,
) -> dict[str, Any]:
    """Generate the samples of ``params`` in memory.

    Returns
    -------
    dict
        ``grids`` bool ``(n, s, s, s)`` occupancy, ``labels`` uint8 ``(n,)`` class ids,
        ``n_points`` int32 ``(n,)``, ``scene`` int32 ``(n,)`` (index of the scene the
        sample was cut from), ``recipe`` ``(n,)`` str. Samples are grouped by class.
        With ``keep_points``, also ``points``: the list of each sample's augmented
        points (float64, centred), before voxelisation.
    progress : callable, optional
        ``progress(done, total)`` after each scene, counted in samples.
    """
    classes = list(OUTPUT_CLASSES)
    want = params.n_per_class
    # per class: (occupancy grid, n_points, scene, recipe, points or None)
    got: dict[ClassId, list[tuple[Any, ...]]] = {c: [] for c in classes}
    scene_i = 0
    while any(len(got[c]) < want for c in classes):
        if scene_i > 40 * want:
            short = {c.label: len(got[c]) for c in classes if len(got[c]) < want}
            raise RuntimeError(f"data set generation does not converge; short classes: {short}")
        rng = np.random.default_rng(np.random.SeedSequence([params.seed, _SPLITS[params.split], scene_i]))
        need = {c: max(0, want - len(got[c])) for c in classes}
        recipe = _pick_recipe(need, rng)
        scene = random_scene(recipe, rng)
        sp = ScanParams(step_deg=float(rng.uniform(0.2, 0.4)), noise=float(rng.uniform(0.001, 0.006)),
                        registration_error=float(rng.choice([0.0, rng.uniform(0.0, 0.01)])),
                        seed=int(rng.integers(2**31)))
        chunks = list(scan(scene, sp, workers=2))
        xyz = np.concatenate([ch.xyz for ch in chunks])
        inst = np.concatenate([ch.gt_instance for ch in chunks]).astype(np.int64)
        del chunks
        order = np.argsort(inst, kind="stable")
        xyz, inst = xyz[order], inst[order]
        bounds = np.searchsorted(inst, np.arange(len(scene.elements) + 2))
        inst_class = scene.instance_class
        cut: list[tuple[ClassId, npt.NDArray[np.float64]]] = []
        counted = {c: len(got[c]) for c in classes}
        for i in rng.permutation(np.arange(1, len(scene.elements) + 1)):
            cls = ClassId(int(inst_class[i]))
            p = xyz[bounds[i]:bounds[i + 1]]
            if len(p) < _MIN_POINTS or cls not in got:
                continue
            k = params.variants * (2 if cls in (ClassId.GROUND, ClassId.ROOF) else 1)
            for _ in range(k):
                if counted[cls] >= want:
                    break
                q = p[_cut(p, cls, rng)]
                if len(q) < _MIN_POINTS or (cls == ClassId.ROOF and not _shows_faces(q)):
                    continue
                if len(q) > _MAX_POINTS:  # bounds memory; a 30^3 grid needs far fewer
                    q = q[rng.choice(len(q), _MAX_POINTS, replace=False)]
                cut.append((cls, _augment(q, rng)))
                counted[cls] += 1
        if cut:
            offsets = np.r_[0, np.cumsum([len(q) for _, q in cut])]
            grids, _ = voxelize_batch(np.concatenate([q for _, q in cut]), offsets, size=params.grid_size,
                                      canonical_yaw=params.canonical_yaw)
            for (cls, q), g in zip(cut, grids == OCCUPIED, strict=True):
                got[cls].append((g, len(q), scene_i, recipe, q if keep_points else None))
        scene_i += 1
        if progress is not None:
            progress(sum(min(len(v), want) for v in got.values()), want * len(classes))
    samples = [(c, s) for c in classes for s in got[c]]
    size = params.grid_size
    out: dict[str, Any] = {
        "grids": np.stack([s[0] for _, s in samples]) if samples else np.zeros((0, size, size, size), bool),
        "labels": np.array([int(c) for c, _ in samples], dtype=np.uint8),
        "n_points": np.array([s[1] for _, s in samples], dtype=np.int32),
        "scene": np.array([s[2] for _, s in samples], dtype=np.int32),
        "recipe": np.array([s[3] for _, s in samples]),
    }
    if keep_points:
        out["points"] = [s[4] for _, s in samples]
    return out


def labelled_samples(
    xyz: npt.ArrayLike,
    gt_class: npt.ArrayLike,
    gt_instance: npt.ArrayLike,
    *,
    seed: int = DatasetParams.seed,
    variants: int = DatasetParams.variants,
    holdout: float = 0.2,
    grid_size: int = DatasetParams.grid_size,
    canonical_yaw: bool = DatasetParams.canonical_yaw,
    source: str = "labelled",
) -> tuple[dict[str, Any], dict[str, Any]]:
    """Training and test samples cut from a user's labelled scan (``hollowtree train --from``).

    Every instance (``gt_instance`` > 0; the points of one class with instance 0 count as
    one instance of that class) takes the majority of its points' ``gt_class`` and gives
    ``variants`` samples (ground and roof twice as many), cut and augmented as the
    synthetic ones are. Whole instances are held out for the test set, a share
    ``holdout`` of them (seeded; at least one where there are two or more), so no test
    sample shares points with a training one.

    Returns
    -------
    train, test : dict
        The keys of :func:`generate_samples` (``scene`` is the instance id, ``recipe`` is
        ``source``).

    Raises
    ------
    ConfigError
        If the arrays do not match, ``holdout`` is not in [0, 1), or no instance of an
        output class has enough points (``_MIN_POINTS``).

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> pts = np.r_[rng.uniform(0, 20, (4000, 3)) * [1, 1, 0], rng.normal([5, 5, 3], 0.5, (1000, 3))]
    >>> cls = np.r_[np.full(4000, 1), np.full(1000, 5)]
    >>> tr, te = labelled_samples(pts, cls, np.r_[np.zeros(4000), np.ones(1000)], holdout=0.0)
    >>> sorted(set(tr["labels"].tolist())), len(te["labels"])
    ([1, 5], 0)
    """
    p = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
    c = np.asarray(gt_class).astype(np.int64).reshape(-1)
    inst = np.asarray(gt_instance).astype(np.int64).reshape(-1)
    if not (len(p) == len(c) == len(inst)):
        raise ConfigError(f"labelled_samples: {len(p)} points, {len(c)} classes and {len(inst)} instances differ")
    if not 0.0 <= holdout < 1.0:
        raise ConfigError(f"The 'holdout' parameter must be in [0, 1). Got {holdout!r} instead.")
    rng = np.random.default_rng(np.random.SeedSequence([seed, 77]))
    # instance 0 of class k becomes the key -1 - k: one pseudo-instance per class
    key = np.where(inst > 0, inst, -1 - c)
    order = np.argsort(key, kind="stable")
    key_s = key[order]
    starts = np.flatnonzero(np.r_[True, key_s[1:] != key_s[:-1]])
    ends = np.r_[starts[1:], len(key_s)]
    usable = []  # (first sorted row, end, class) of instances of an output class, big enough
    for a, b in zip(starts.tolist(), ends.tolist(), strict=True):
        cls_id = int(np.bincount(c[order[a:b]]).argmax())
        if cls_id in [int(k) for k in OUTPUT_CLASSES] and b - a >= _MIN_POINTS:
            usable.append((a, b, ClassId(cls_id)))
    n_test = 0 if holdout == 0 or len(usable) < 2 else max(1, round(holdout * len(usable)))
    held = set(rng.choice(len(usable), n_test, replace=False).tolist()) if n_test else set()
    out: dict[str, list[tuple[ClassId, npt.NDArray[np.float64], int]]] = {"train": [], "test": []}
    for j, (a, b, cls) in enumerate(usable):
        part = "test" if j in held else "train"
        pts = p[order[a:b]]
        for _ in range(variants * (2 if cls in (ClassId.GROUND, ClassId.ROOF) else 1)):
            q = pts[_cut(pts, cls, rng)]
            if len(q) < _MIN_POINTS or (cls == ClassId.ROOF and not _shows_faces(q)):
                continue
            if len(q) > _MAX_POINTS:
                q = q[rng.choice(len(q), _MAX_POINTS, replace=False)]
            out[part].append((cls, _augment(q, rng), int(key_s[a])))
    if not out["train"] and not out["test"]:
        raise ConfigError(f"{source}: no labelled instance of a HollowNet class with at least {_MIN_POINTS} points")
    result = []
    for part in ("train", "test"):
        cut = out[part]
        if cut:
            offsets = np.r_[0, np.cumsum([len(q) for _, q, _ in cut])]
            grids, _ = voxelize_batch(np.concatenate([q for _, q, _ in cut]), offsets, size=grid_size,
                                      canonical_yaw=canonical_yaw)
            grids = grids == OCCUPIED
        else:
            grids = np.zeros((0, grid_size, grid_size, grid_size), dtype=bool)
        result.append({
            "grids": grids, "labels": np.array([int(k) for k, _, _ in cut], dtype=np.uint8),
            "n_points": np.array([len(q) for _, q, _ in cut], dtype=np.int32),
            "scene": np.array([i for _, _, i in cut], dtype=np.int32),
            "recipe": np.array([source] * len(cut), dtype="U16"),
        })
    return result[0], result[1]


# --------------------------------------------------------------------------- storage
def pack_grids(grids: npt.NDArray[np.bool_]) -> npt.NDArray[np.uint8]:
    """Bit-pack occupancy grids ``(n, s, s, s)`` to ``(n, ceil(s**3 / 8))`` bytes.

    Examples
    --------
    >>> g = np.zeros((2, 4, 4, 4), dtype=bool); g[1, 0, 0, 1] = True
    >>> p = pack_grids(g); p.shape
    (2, 8)
    >>> bool((unpack_grids(p, 4) == g).all())
    True
    """
    n = len(grids)
    return np.packbits(grids.reshape(n, -1), axis=1)


def unpack_grids(packed: npt.NDArray[np.uint8], size: int) -> npt.NDArray[np.bool_]:
    """Inverse of :func:`pack_grids`."""
    n = len(packed)
    return np.unpackbits(packed, axis=1, count=size**3).astype(bool).reshape(n, size, size, size)


def build_dataset(
    root: str | Path,
    params: DatasetParams,
    *,
    progress: Callable[[int, int], None] | None = None,
) -> Path:
    """Generate the data set of ``params`` under ``root`` unless it is cached there.

    The folder ``root / params.key()`` holds ``shard-000.npz``, ... and ``manifest.json``,
    written last (its presence marks a complete data set). Returns the folder.
    """
    folder = Path(root) / params.key()
    manifest = folder / "manifest.json"
    if manifest.is_file():
        logger.info("data set %s is cached", folder)
        return folder
    t0 = time.perf_counter()
    data = generate_samples(params, progress=progress)
    folder.mkdir(parents=True, exist_ok=True)
    n = len(data["labels"])
    shards = []
    for k, a in enumerate(range(0, n, _SHARD)):
        name = f"shard-{k:03d}.npz"
        sl = slice(a, a + _SHARD)
        np.savez_compressed(folder / name, grids=pack_grids(data["grids"][sl]), labels=data["labels"][sl],
                            n_points=data["n_points"][sl], scene=data["scene"][sl],
                            recipe=data["recipe"][sl].astype("U16"))
        shards.append(name)
    counts = np.bincount(data["labels"], minlength=max(OUTPUT_CLASSES) + 1)
    info = {
        "version": DATASET_VERSION, "params": params.to_dict(), "n_samples": n, "shards": shards,
        "n_scenes": int(data["scene"].max()) + 1 if n else 0,
        "counts": {c.label: int(counts[c]) for c in OUTPUT_CLASSES},
        "seconds": round(time.perf_counter() - t0, 1),
    }
    tmp = manifest.with_suffix(".tmp")
    tmp.write_text(json.dumps(info, indent=2))
    tmp.replace(manifest)
    return folder


def load_dataset(folder: str | Path) -> dict[str, npt.NDArray[Any]]:
    """Read a data set written by :func:`build_dataset` (grids unpacked to bool).

    Raises
    ------
    InputFileError
        If the folder has no ``manifest.json`` (not made, or not finished).
    CorruptInputError
        If a shard is missing or unreadable, or the data set is of another version.
    """
    folder = Path(folder)
    manifest = folder / "manifest.json"
    if not manifest.is_file():
        raise InputFileError(f"{folder}: no complete HollowNet data set (manifest.json missing)")
    info = json.loads(manifest.read_text())
    if info.get("version") != DATASET_VERSION:
        raise CorruptInputError(f"{folder}: data set version {info.get('version')!r}, expected {DATASET_VERSION}")
    size = int(info["params"]["grid_size"])
    parts: dict[str, list[npt.NDArray[Any]]] = {"grids": [], "labels": [], "n_points": [], "scene": [], "recipe": []}
    for name in info["shards"]:
        try:
            with np.load(folder / name) as z:
                parts["grids"].append(unpack_grids(z["grids"], size))
                for k in ("labels", "n_points", "scene", "recipe"):
                    parts[k].append(z[k])
        except (OSError, ValueError, KeyError) as exc:
            raise CorruptInputError(f"{folder / name}: unreadable shard ({exc})") from None
    return {k: np.concatenate(v) for k, v in parts.items()}
