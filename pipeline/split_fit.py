"""``hollowtree fit-split``: the training groups of the split model, and the fit.

Each training scene is scanned, run through ingest and the coarse stage of
``workflows/local.yaml`` (in this process, no tree), and its element groups are kept as
one NPZ in the work folder (``groups-<i>.npz``: the coarse segments' points in group
order, each point's ground truth, the groups' first rows), so an interrupted fit goes on
where it stopped and a refit with other settings reuses them. :mod:`tree.fit_split` turns
the groups into proposals and fits the model.

Scenes: ``i`` in ``0..39`` is the HollowNet recipe ``sorted(RECIPES)[i % 5]``, ``i`` in
``100..111`` storeyed arcades; each is drawn from ``default_rng([7, i])`` and scanned at a
step drawn from 0.15-0.3 degrees (scanner seed ``i``, noise 2.5 mm). Procedural sites
(:mod:`scenes.procedural`, training seeds only) and a user's labelled scans can be added
or used instead (:func:`procedural_groups`, :func:`file_groups`).
"""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path

import numpy as np

from hollowtree.pipeline.workflow import shipped_workflows

__all__ = ["TRAINING_SCENES", "file_groups", "fit_split_from_scenes", "procedural_groups", "training_groups"]

#: Scene numbers of the training set (module docstring).
TRAINING_SCENES: tuple[int, ...] = tuple(range(40)) + tuple(range(100, 112))
_WORKFLOW = shipped_workflows() / "local.yaml"


def _scene(i: int):  # type: ignore[no-untyped-def]
    from hollowtree.hollownet._scenes import RECIPES, random_scene, storeyed_arcades

    rng = np.random.default_rng([7, i])
    if i >= 100:
        return "storeyed", storeyed_arcades(rng), rng
    recipe = sorted(RECIPES)[i % len(RECIPES)]
    return recipe, random_scene(recipe, rng), rng


def _groups_of_scan(laz: Path, work: Path, out: Path, name: str, gt: tuple[np.ndarray, np.ndarray]) -> Path:
    """Ingest and coarse-segment ``laz`` in ``work``; keep its element groups with the
    ground truth ``gt`` (class and instance per record) as ``out``."""
    from hollowtree.pipeline.run import run_workflow
    from hollowtree.pipeline.tree_stage import group_starts
    from hollowtree.pipeline.workflow import load_workflow
    from hollowtree.tiling.store import RunStore

    url = work / f"{out.stem}.zarr"
    shutil.rmtree(url, ignore_errors=True)
    wf = load_workflow(_WORKFLOW, [f'input.files=["{laz}"]', "input.synth=null", f"store={url}",
                                   "tree.enabled=false", "outputs.las=null", "outputs.parquet=null",
                                   "outputs.png=null", "cluster.scheduler=sync"])
    run_workflow(wf, progress=False, say=lambda s: None)
    store = RunStore.open(str(url), mode="r")
    starts = group_starts(store)
    off = store.read_unit("coarse/csr", ["offsets"])["offsets"]
    scale = np.asarray(store.attrs["coords"]["scale"])
    n = int(off[-1])
    xyz = store.read_slice("coarse/csr/xyz", 0, n).astype(np.float64) * scale
    rows = store.read_slice("coarse/csr/indices", 0, n).astype(np.int64)
    gc, gi = gt
    tmp = out.with_suffix(".tmp.npz")
    np.savez_compressed(tmp, xyz=xyz.astype(np.float32), gc=gc[rows], gi=gi[rows], gstart=off[starts],
                        recipe=name)
    tmp.replace(out)
    shutil.rmtree(url, ignore_errors=True)
    return out


def _synthetic_gt(laz: Path) -> tuple[np.ndarray, np.ndarray]:
    """``gt_class`` and ``gt_instance`` of a synthetic scan by record number (the CSR's
    ``coarse/csr/indices``)."""
    from hollowtree.tiling.readers import probe, read_blocks

    n_rec = probe(laz).point_count
    gc, gi = np.zeros(n_rec, dtype=np.uint8), np.zeros(n_rec, dtype=np.int32)
    for blk in read_blocks(laz):
        gc[blk.index] = blk.extra["gt_class"]
        gi[blk.index] = blk.extra["gt_instance"]
    return gc, gi


def training_groups(i: int, work: Path) -> Path:
    """The element groups of training scene ``i`` (made once, then read from ``work``)."""
    from hollowtree.scenes.scanner import ScanParams
    from hollowtree.scenes.synth import sidecar_path, write_scan

    out = work / f"groups-{i}.npz"
    if out.exists():
        return out
    recipe, scene, rng = _scene(i)
    laz = work / f"scene-{i}.laz"
    write_scan(scene, laz, ScanParams(step_deg=float(rng.uniform(0.15, 0.3)), seed=i), workers=2)
    _groups_of_scan(laz, work, out, recipe, _synthetic_gt(laz))
    laz.unlink()
    sidecar_path(laz).unlink(missing_ok=True)
    return out


def check_training_seed(seed: int, what: str) -> None:
    """Raise a ConfigError unless ``seed`` is a training seed of ``scenes.procedural``
    (``what``: the learned part, e.g. "HollowNet is trained")."""
    from hollowtree.errors import ConfigError
    from hollowtree.scenes.procedural import SPLITS

    lo, hi = SPLITS["train"]
    if not lo <= seed < hi:
        raise ConfigError(f"procedural seed {seed} is not a training seed ({lo}-{hi - 1}): {what} on training "
                          "seeds only")


def scan_training_site(seed: int, out: Path, n_points: int) -> None:
    """Scan procedural training site ``seed`` to ``out`` at about ``n_points`` points,
    with the seed's own noise and registration error."""
    from hollowtree.scenes.procedural import scan_draw
    from hollowtree.scenes.synth import synth

    check_training_seed(seed, "learned parts are fitted")
    d = scan_draw(seed)
    synth("gen", out, n_points=n_points, seed=seed, noise=d.noise, registration_error=d.registration_error,
          overwrite=True, workers=2)


def procedural_groups(seed: int, work: Path, *, n_points: int = 600_000) -> Path:
    """The element groups of the procedural site of training seed ``seed``, scanned at
    about ``n_points`` points with the seed's own noise and registration error.

    Raises
    ------
    ConfigError
        If ``seed`` is not a training seed (``scenes.procedural.SPLITS["train"]``).
    """
    from hollowtree.scenes.procedural import GENERATOR
    from hollowtree.scenes.synth import sidecar_path

    check_training_seed(seed, "the split model is fitted")
    out = work / f"groups-{GENERATOR}-{seed}-{n_points}.npz"
    if out.exists():
        return out
    laz = work / f"gen-{seed}.laz"
    scan_training_site(seed, laz, n_points)
    _groups_of_scan(laz, work, out, f"gen-{seed}", _synthetic_gt(laz))
    laz.unlink()
    sidecar_path(laz).unlink(missing_ok=True)
    return out


def file_groups(path: Path, work: Path, *, class_dim: str = "gt_class", instance_dim: str = "gt_instance",
                class_map: dict[int, int] | None = None) -> Path:
    """The element groups of a user's labelled scan ``path`` (made once per file, its
    dimensions and map, then read from ``work``)."""
    import hashlib
    import json

    from hollowtree.pipeline.hollownet_cmd import read_labelled

    key = hashlib.sha256(json.dumps([str(Path(path).resolve()), Path(path).stat().st_size, class_dim, instance_dim,
                                     sorted((class_map or {}).items())]).encode()).hexdigest()[:12]
    out = work / f"groups-file-{Path(path).stem}-{key}.npz"
    if out.exists():
        return out
    _, index, cls, inst = read_labelled(Path(path), class_dim, instance_dim, class_map)
    index = index.astype(np.int64)
    n_rec = int(index.max(initial=-1)) + 1
    gc, gi = np.zeros(n_rec, dtype=np.uint8), np.zeros(n_rec, dtype=np.int32)
    gc[index], gi[index] = cls, inst
    return _groups_of_scan(Path(path), work, out, Path(path).stem, (gc, gi))


def fit_split_from_scenes(work: Path, *, scenes: tuple[int, ...] = TRAINING_SCENES, seed: int = 0,
                          threshold: float = 0.5, on_scene: Callable[[int], None] | None = None,
                          files: tuple[Path, ...] = (), class_dim: str = "gt_class",
                          instance_dim: str = "gt_instance", class_map: dict[int, int] | None = None,
                          procedural: tuple[int, ...] = (),
                          procedural_points: int | tuple[int, int] = 600_000):  # type: ignore[no-untyped-def]
    """Make (or reuse) the groups of every scene, procedural training site and labelled
    file in ``work``, collect the proposals, fit. ``scenes=()`` leaves the random scenes out.
    ``procedural_points``: points per procedural site, or a range ``(lo, hi)`` each site's
    count is drawn from by its seed (:func:`scenes.procedural.site_points`)."""
    from hollowtree.errors import ConfigError
    from hollowtree.hollownet.predict import Classifier
    from hollowtree.pipeline.workflow import load_workflow
    from hollowtree.scenes.procedural import site_points
    from hollowtree.tree.fit_split import (
        GOOD_TARGET,
        SplitSamples,
        fit_split_model,
        proposal_samples,
    )

    work.mkdir(parents=True, exist_ok=True)
    clf = Classifier.get(None)
    mgp = load_workflow(_WORKFLOW, []).tree.max_group_points  # groups met as the tree stage meets them
    parts = []
    for i in scenes:
        d = np.load(training_groups(i, work))
        parts.append(proposal_samples(d["xyz"], d["gc"], d["gi"], d["gstart"], clf, scene=f"s{i}",
                                      max_group_points=mgp))
        if on_scene is not None:
            on_scene(i)
    for seed in procedural:
        n = procedural_points if isinstance(procedural_points, int) else site_points(seed, *procedural_points)
        d = np.load(procedural_groups(seed, work, n_points=n))
        parts.append(proposal_samples(d["xyz"], d["gc"], d["gi"], d["gstart"], clf, scene=f"g{seed}",
                                      max_group_points=mgp))
        if on_scene is not None:
            on_scene(seed)
    for k, f in enumerate(files):
        d = np.load(file_groups(f, work, class_dim=class_dim, instance_dim=instance_dim, class_map=class_map))
        parts.append(proposal_samples(d["xyz"], d["gc"], d["gi"], d["gstart"], clf, scene=f"f{k}",
                                      max_group_points=mgp))
        if on_scene is not None:
            on_scene(-1 - k)
    if not any(len(p) for p in parts):
        raise ConfigError("no split proposals to fit: the scans hold no element group the tree could split")
    samples = SplitSamples.concat(parts)
    good = samples.target >= GOOD_TARGET
    per_site = (f"{procedural_points:,} points" if isinstance(procedural_points, int)
                else "{:,}-{:,} points, log-uniform by seed".format(*procedural_points))
    data = "element groups of workflows/local.yaml on " + " and ".join(
        ([f"{len(scenes)} random scenes"] if scenes else [])
        + ([f"{len(procedural)} procedural training sites ({per_site})"] if procedural else [])
        + ([f"{len(files)} labelled scans"] if files else []))
    if good.all() or not good.any():
        raise ConfigError(f"the scans give {len(samples)} split proposals, {int(good.sum())} of them right: the "
                          "split model needs right and wrong ones; add labelled scans or keep the synthetic scenes")
    return fit_split_model(samples, seed=seed, threshold=threshold,
                           info={"classifier": "HollowNet (shipped weights)", "scenes": len(scenes),
                                 "procedural": list(procedural), "files": [str(f) for f in files], "data": data})
