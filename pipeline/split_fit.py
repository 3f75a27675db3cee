"""``hollowtree fit-split``: the training groups of the split model, and the fit.

Each training scene is scanned, run through ingest and the coarse stage of
``workflows/local.yaml`` (in this process, no tree), and its element groups are kept as
one NPZ in the work folder (``groups-<i>.npz``: the coarse segments' points in group
order, each point's ground truth, the groups' first rows), so an interrupted fit goes on
where it stopped and a refit with other settings reuses them. :mod:`tree.fit_split` turns
the groups into proposals and fits the model.

Scenes: ``i`` in ``0..39`` is the HollowNet recipe ``sorted(RECIPES)[i % 5]``, ``i`` in
``100..111`` storeyed arcades; each is drawn from ``default_rng([7, i])`` and scanned at a
step drawn from 0.15-0.3 degrees (scanner seed ``i``, noise 2.5 mm).
"""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path

import numpy as np

__all__ = ["TRAINING_SCENES", "fit_split_from_scenes", "training_groups"]

#: Scene numbers of the training set (module docstring).
TRAINING_SCENES: tuple[int, ...] = tuple(range(40)) + tuple(range(100, 112))
_WORKFLOW = Path(__file__).resolve().parent.parent / "workflows" / "local.yaml"


def _scene(i: int):  # type: ignore[no-untyped-def]
    from hollownet._scenes import RECIPES, random_scene, storeyed_arcades

    rng = np.random.default_rng([7, i])
    if i >= 100:
        return "storeyed", storeyed_arcades(rng), rng
    recipe = sorted(RECIPES)[i % len(RECIPES)]
    return recipe, random_scene(recipe, rng), rng


def training_groups(i: int, work: Path) -> Path:
    """The element groups of training scene ``i`` (made once, then read from ``work``)."""
    from pipeline.run import run_workflow
    from pipeline.tree_stage import group_starts
    from pipeline.workflow import load_workflow
    from scenes.scanner import ScanParams
    from scenes.synth import sidecar_path, write_scan
    from tiling.readers import probe, read_blocks
    from tiling.store import RunStore

    out = work / f"groups-{i}.npz"
    if out.exists():
        return out
    recipe, scene, rng = _scene(i)
    laz, url = work / f"scene-{i}.laz", work / f"scene-{i}.zarr"
    shutil.rmtree(url, ignore_errors=True)
    write_scan(scene, laz, ScanParams(step_deg=float(rng.uniform(0.15, 0.3)), seed=i, noise=0.0025), workers=2)
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
    n_rec = probe(laz).point_count
    gc, gi = np.zeros(n_rec, dtype=np.uint8), np.zeros(n_rec, dtype=np.int32)
    for blk in read_blocks(laz):  # ground truth by record number (coarse/csr/indices)
        gc[blk.index] = blk.extra["gt_class"]
        gi[blk.index] = blk.extra["gt_instance"]
    tmp = work / f"groups-{i}.tmp.npz"
    np.savez_compressed(tmp, xyz=xyz.astype(np.float32), gc=gc[rows], gi=gi[rows], gstart=off[starts],
                        recipe=recipe)
    tmp.replace(out)
    laz.unlink()
    sidecar_path(laz).unlink(missing_ok=True)
    shutil.rmtree(url, ignore_errors=True)
    return out


def fit_split_from_scenes(work: Path, *, scenes: tuple[int, ...] = TRAINING_SCENES, seed: int = 0,
                          threshold: float = 0.5, on_scene: Callable[[int], None] | None = None):  # type: ignore[no-untyped-def]
    """Make (or reuse) every scene's groups in ``work``, collect the proposals, fit."""
    from hollownet.predict import Classifier
    from tree.fit_split import SplitSamples, fit_split_model, proposal_samples

    work.mkdir(parents=True, exist_ok=True)
    clf = Classifier.get(None)
    parts = []
    for i in scenes:
        d = np.load(training_groups(i, work))
        parts.append(proposal_samples(d["xyz"], d["gc"], d["gi"], d["gstart"], clf, scene=f"s{i}"))
        if on_scene is not None:
            on_scene(i)
    return fit_split_model(SplitSamples.concat(parts), seed=seed, threshold=threshold,
                           info={"classifier": "HollowNet (shipped weights)", "scenes": len(scenes),
                                 "data": "element groups of workflows/local.yaml on random scenes"})
