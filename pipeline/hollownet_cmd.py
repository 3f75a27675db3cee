"""The ``hollowtree train`` and ``hollowtree classify`` subcommands (HollowNet).

``pipeline/cli.py`` adds them with :func:`add_parsers`; until it does, ``python -m
pipeline.hollownet_cmd train ...`` runs the same commands with the same error handling
(a :class:`~hollowtree.errors.PipelineError` becomes one line on stderr and exit code 2).

- ``train [--config FILE] [--epochs N] [--device auto|cpu|cuda] [--out FILE] [--resume]``:
  builds (or reuses) the cached data set, trains with a progress bar (loss, accuracy), a
  checkpoint each epoch (``FILE.ckpt``), and prints the confusion matrix (also written
  as ``.confusion.txt`` and ``.confusion.png`` beside the weights).
- ``classify INPUT``: INPUT is a LAS/LAZ/PLY file holding one segment, or a run store
  after ``hollowtree coarse``, whose coarse segments (``coarse/csr``) are classified.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from hollowtree.errors import ConfigError, InputFileError, PipelineError
from hollowtree.pipeline.cli_args import _positive_int, _procedural_points, _procedural_points_flag

__all__ = ["add_labelled_args", "add_parsers", "class_map_of", "cmd_classify", "cmd_train", "procedural_samples",
           "read_labelled"]


def add_parsers(sub: Any) -> None:
    """Add ``train`` and ``classify`` to ``sub`` (the subparsers of ``hollowtree``)."""
    t = sub.add_parser(
        "train",
        help="train HollowNet on scanned synthetic elements (progress, checkpoints, confusion matrix)",
        description=(
            "Generate (or reuse) the seeded HollowNet data set of segments cut from synthetic "
            "scans, train the network with a checkpoint per epoch, and write the weights, a "
            "JSON report and the confusion matrix (text and PNG). The default config made "
            "the shipped weights."
        ),
    )
    t.add_argument("--config", type=Path, help="YAML or JSON file of TrainConfig keys (hollownet/train.py)")
    t.add_argument("--epochs", type=_positive_int, help="epochs (overrides the config)")
    t.add_argument("--device", choices=["auto", "cpu", "cuda"], default="auto", help="default: auto")
    t.add_argument("--out", type=Path, default=Path("hollownet.pt"), help="weights file (default hollownet.pt)")
    t.add_argument("--resume", action="store_true", help="continue from the checkpoint OUT.ckpt")
    t.add_argument("--data-dir", help="data set cache (default $HOLLOWTREE_CACHE or ~/.cache/hollowtree)")
    t.add_argument("--overwrite", action="store_true", help="replace an existing weights file")
    t.add_argument("--no-progress", action="store_true", help="no progress bars")
    add_labelled_args(t, "training samples")
    t.add_argument("--procedural", type=int, default=0, metavar="N",
                   help="add samples cut from the first N procedural training sites (scenes/procedural.py; "
                        "training seeds only), each scanned with its seed's noise and registration error")
    _procedural_points_flag(t, 2_000_000)
    t.set_defaults(func=cmd_train)

    c = sub.add_parser(
        "classify",
        help="classify a segment file (LAS/LAZ/PLY) or the coarse segments of a run store",
        description=(
            "Print the HollowNet class and score of a segment: a LAS/LAZ/PLY file holding one "
            "segment, or every coarse segment of a run store made by `hollowtree coarse`."
        ),
    )
    c.add_argument("input", type=Path, help="segment file or run store")
    c.add_argument("--weights", type=Path, help="weights file (default: the shipped weights)")
    c.add_argument("--batch-size", type=_positive_int, default=64, help="segments per batch (default 64)")
    c.add_argument("--json", action="store_true", help="print JSON instead of a table")
    c.set_defaults(func=cmd_classify)


def _read_config(path: Path) -> dict[str, Any]:
    if not path.is_file():
        raise InputFileError(f"{path}: no such config file")
    try:
        data = yaml.safe_load(path.read_text())
    except (yaml.YAMLError, UnicodeDecodeError) as exc:
        first = str(exc).strip().splitlines()[0]
        raise ConfigError(f"{path}: not valid YAML or JSON ({first})") from None
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: a training config must be a mapping of keys to values")
    return data


def cmd_train(args: argparse.Namespace) -> int:
    """``hollowtree train``."""
    from hollowtree.hollownet.dataset import labelled_samples
    from hollowtree.hollownet.train import TrainConfig, train

    data = _read_config(args.config) if args.config else {}
    if args.epochs is not None:
        data["epochs"] = args.epochs
    if args.data_dir:
        data["data_dir"] = args.data_dir
    try:
        config = TrainConfig.from_dict(data)
    except TypeError as exc:
        raise ConfigError(f"invalid training config: {exc}") from None
    if args.procedural < 0:
        raise ConfigError(f"--procedural must be a count >= 0; got {args.procedural}")
    if args.no_synthetic and not args.labelled and not args.procedural:
        raise ConfigError("--no-synthetic needs at least one --from FILE or --procedural N")
    pts = _procedural_points(args)
    class_map = class_map_of(args.class_map)
    labelled = []
    if args.procedural:
        from hollowtree.hollownet.train import default_data_dir
        from hollowtree.scenes.procedural import site_points, split_seeds

        cache = Path(config.data_dir) if config.data_dir else default_data_dir()
        for seed in split_seeds("train", args.procedural):
            n = pts if isinstance(pts, int) else site_points(seed, *pts)
            name, tr, te = procedural_samples(seed, n, cache, seed=config.seed,
                                              variants=config.variants)
            print(f"procedural site {seed}: {len(tr['labels'])} training and {len(te['labels'])} test samples")
            labelled.append((name, tr, te))
    for path in args.labelled:
        xyz, _, cls, inst = read_labelled(path, args.class_dim, args.instance_dim, class_map)
        tr, te = labelled_samples(xyz, cls, inst, seed=config.seed, variants=config.variants, source=path.name)
        print(f"{path}: {len(tr['labels'])} training and {len(te['labels'])} test samples "
              f"from {len(np.unique(inst[inst > 0]))} instances")
        labelled.append((str(path), tr, te))
    report = train(config, out=args.out, device=args.device, resume=args.resume,
                   overwrite=args.overwrite, progress=not args.no_progress, labelled=labelled,
                   synthetic=not args.no_synthetic)
    print(report.summary())
    return 0


def procedural_samples(site_seed: int, n_points: int, cache: Path, *, seed: int, variants: int
                       ) -> tuple[str, dict[str, Any], dict[str, Any]]:
    """HollowNet samples cut from procedural training site ``site_seed``, scanned at about
    ``n_points`` points with its seed's noise and registration error: the samples
    ``hollowtree train --from`` takes from that scan (made once, then read from
    ``cache/procedural``).

    Raises
    ------
    ConfigError
        If ``site_seed`` is not a training seed (``scenes.procedural.SPLITS["train"]``).
    """
    import tempfile

    from hollowtree.hollownet.dataset import labelled_samples
    from hollowtree.pipeline.split_fit import check_training_seed, scan_training_site
    from hollowtree.scenes.procedural import GENERATOR

    check_training_seed(site_seed, "HollowNet is trained")
    name = f"gen-{site_seed}-{n_points}.laz"
    out = cache / "procedural" / f"samples-{GENERATOR}-{site_seed}-{n_points}-s{seed}-v{variants}.npz"
    if not out.is_file():
        out.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory(dir=out.parent) as tmp:
            laz = Path(tmp) / name
            scan_training_site(site_seed, laz, n_points)
            xyz, _, cls, inst = read_labelled(laz, "gt_class", "gt_instance")
        tr, te = labelled_samples(xyz, cls, inst, seed=seed, variants=variants, source=name)
        tmp_out = out.with_suffix(".tmp.npz")
        np.savez_compressed(tmp_out, **{f"train_{k}": v for k, v in tr.items()},
                            **{f"test_{k}": v for k, v in te.items()})
        tmp_out.replace(out)
    with np.load(out) as z:
        tr = {k[6:]: z[k] for k in z.files if k.startswith("train_")}
        te = {k[5:]: z[k] for k in z.files if k.startswith("test_")}
    return name, tr, te


def add_labelled_args(p: argparse.ArgumentParser, what: str) -> None:
    """The options that name a user's labelled scans (``train`` and ``fit-split``)."""
    p.add_argument("--from", dest="labelled", action="append", type=Path, default=[], metavar="FILE",
                   help=f"a labelled LAS/LAZ scan to take {what} from (repeatable): every instance of "
                        "--instance-dim, its class from --class-dim")
    p.add_argument("--class-dim", default="gt_class",
                   help="the per-point class of --from files: an extra dimension holding hollowtree class "
                        "ids, or any dimension (e.g. 'classification') with --class-map (default gt_class)")
    p.add_argument("--instance-dim", default="gt_instance",
                   help="the per-point instance id of --from files (default gt_instance; 0 = none)")
    p.add_argument("--class-map", default=None, metavar="CODE=CLASS,...",
                   help="translate --class-dim values to classes, e.g. '2=ground,6=wall,64=arch,65=dome'; "
                        "values not named are left out")
    p.add_argument("--no-synthetic", action="store_true",
                   help="use the --from scans alone (no synthetic scenes)")


def class_map_of(text: str | None) -> dict[int, int] | None:
    """``"2=ground,64=arch"`` -> ``{2: 1, 64: 4}``; None stays None."""
    from hollowtree.classes import class_id

    if text is None:
        return None
    out: dict[int, int] = {}
    for item in filter(None, (t.strip() for t in text.split(","))):
        code, _, name = item.partition("=")
        try:
            out[int(code)] = int(class_id(name))
        except ValueError:  # not a whole number, or not a class name (also: no '=')
            raise ConfigError(f"--class-map: {item!r} is not CODE=CLASS (a whole number and a class name)") from None
    return out


def read_labelled(path: Path, class_dim: str, instance_dim: str, class_map: dict[int, int] | None = None
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Points (metres, minus the file's lowest corner), record numbers, classes and
    instances of a labelled scan.

    Raises
    ------
    ConfigError
        If the file lacks either dimension (the message lists the ones it has) or a
        class is not a hollowtree class id (without ``class_map``).
    """
    from hollowtree.classes import NUM_CLASSES
    from hollowtree.tiling.readers import PointBlock, read_blocks

    blocks = PointBlock.concat(read_blocks(path))
    for dim in (class_dim, instance_dim):
        if dim not in blocks.extra:
            raise ConfigError(f"{path}: no dimension {dim!r} (it has {', '.join(sorted(blocks.extra)) or 'none'})")
    cls = np.asarray(blocks.extra[class_dim]).astype(np.int64)
    if class_map is not None:
        lut = np.zeros(int(max(cls.max(initial=0), max(class_map, default=0))) + 1, dtype=np.int64)
        for code, c in class_map.items():
            if code >= 0:
                lut[code] = c
        cls = np.where(cls >= 0, lut[np.clip(cls, 0, None)], 0)
    elif len(cls) and (cls.min() < 0 or cls.max() >= NUM_CLASSES):
        raise ConfigError(f"{path}: {class_dim} holds {int(cls.max())}, not a hollowtree class id (0-{NUM_CLASSES - 1}); "
                          "pass --class-map CODE=CLASS,...")
    xyz = blocks.xyz - blocks.xyz.min(axis=0) if len(blocks.xyz) else blocks.xyz
    return xyz, blocks.index, cls, np.asarray(blocks.extra[instance_dim]).astype(np.int64)


def _segment_file(path: Path) -> np.ndarray:
    from hollowtree.tiling.readers import PointBlock, read_blocks

    return PointBlock.concat(read_blocks(path)).xyz


def _store_segments(path: Path) -> tuple[np.ndarray, list[np.ndarray]]:
    """Coarse segment ids and their points (store-local metres) from ``coarse/csr``."""
    from hollowtree.tiling.store import RunStore

    store = RunStore.open(str(path))
    attrs = store.attrs
    try:
        names = set(store.unit_arrays("coarse/csr")) if "coarse" in attrs.get("stages", {}) else set()
    except (KeyError, FileNotFoundError):  # zarr: no such group
        names = set()
    if "offsets" not in names or not names & {"xyz", "indices"}:
        raise PipelineError(f"store {path} has no coarse segments; run `hollowtree coarse {path}` first")
    offsets = store.read_unit("coarse/csr", ["offsets"])["offsets"].astype(np.int64)
    scale = np.asarray(attrs["coords"]["scale"], dtype=np.float64)
    if "xyz" in names:  # the coarse stage stores each segment's coordinates with the CSR
        pts = store.read_slice("coarse/csr/xyz").astype(np.float64) * scale
    else:
        pts = _csr_points_from_tiles(store, path, scale)
    segs = [pts[offsets[s]:offsets[s + 1]] for s in range(len(offsets) - 1)]
    return np.arange(1, len(segs) + 1), segs


def _csr_points_from_tiles(store: Any, path: Path, scale: np.ndarray) -> np.ndarray:
    """Points of ``coarse/csr/indices`` looked up in the tiles (every one is a core row of one tile)."""
    wanted = store.read_unit("coarse/csr", ["indices"])["indices"].astype(np.uint64)
    index_parts, xyz_parts = [], []
    for t in store.attrs.get("ingest", {}).get("tiles", []):
        d = store.read_unit(f"tiles/{int(t)}", ["xyz", "index", "core"])
        index_parts.append(d["index"][d["core"]])
        xyz_parts.append(d["xyz"][d["core"]])
    if not index_parts:
        return np.zeros((0, 3))
    index = np.concatenate(index_parts)
    xyz = np.concatenate(xyz_parts)
    order = np.argsort(index)
    index, xyz = index[order], xyz[order]
    pos = np.searchsorted(index, wanted)
    if len(wanted) and (pos.max() >= len(index) or not np.array_equal(index[pos], wanted)):
        raise PipelineError(f"store {path}: coarse/csr names points that no tile holds; rerun `hollowtree coarse`")
    out: np.ndarray = np.asarray(xyz[pos], dtype=np.float64) * scale
    return out


def cmd_classify(args: argparse.Namespace) -> int:
    """``hollowtree classify``."""
    from hollowtree.classes import ClassId
    from hollowtree.hollownet.predict import Classifier

    path: Path = args.input
    if not path.exists():
        raise InputFileError(f"{path}: no such file or run store")
    clf = Classifier.get(args.weights, batch_size=args.batch_size)
    if path.is_dir():
        ids, segs = _store_segments(path)
        names = [f"segment {int(i)}" for i in ids]
    else:
        segs = [_segment_file(path)]
        names = [str(path)]
    pred = clf.predict(segs)
    rows: list[dict[str, Any]] = [{"segment": name, "n_points": len(s), "class": ClassId(int(c)).label, "score": round(float(sc), 4),
             **({} if ok else {"note": "degenerate segment"})}
            for name, s, c, sc, ok in zip(names, segs, pred.class_id, pred.score, pred.valid, strict=True)]
    if args.json:
        print(json.dumps(rows, indent=1))
        return 0
    width = max([len(r["segment"]) for r in rows] + [7])
    print(f"{'segment'.ljust(width)}  {'points':>9}  {'class':<8} score")
    for r in rows:
        note = f"  ({r['note']})" if "note" in r else ""
        print(f"{r['segment'].ljust(width)}  {r['n_points']:>9}  {r['class']:<8} {r['score']:.3f}{note}")
    return 0
