"""Training HollowNet: data set, loop, per-epoch checkpoints, resume, confusion matrix.

:func:`train` is what ``hollowtree train`` runs. The shipped weights
(``hollownet/weights/hollownet-v1.pt``) are ``hollowtree train --out
hollownet/weights/hollownet-v1.pt`` with the default :class:`TrainConfig` (seed 0).

- Data: :func:`hollownet.dataset.build_dataset` with split "train" (``n_train`` per
  class) and split "test" (``n_test`` per class, other scenes) of ``seed``, cached
  under ``data_dir``.
- Optimiser: Adam, learning rate 0.001 (the paper's), cosine decay to 0 over the epochs,
  cross-entropy, batches of ``batch_size``; each grid is flipped at random along x and y
  (the sign of the canonical axis is arbitrary).
- Precision: on a CPU with AMX (``torch.cpu._is_amx_tile_supported()``) or on CUDA the
  forward pass runs under bfloat16 autocast (``amp``), weights stay float32.
- After every epoch the test accuracy is measured and a checkpoint (model, optimiser,
  epoch, history) is written next to ``out`` (``<out>.ckpt``, kept at the end); ``resume=True``
  continues from it, also to train more epochs than first asked (the learning-rate schedule
  is a closed-form function of the epoch, so a resumed run equals an uninterrupted one). The end writes ``out`` (weights and metadata), ``<out stem>.json``, the
  confusion matrix as text (``.confusion.txt``) and PNG (``.confusion.png``).
"""

from __future__ import annotations

import hashlib
import json
import logging
import math
import os
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import torch
import torch.nn.functional as F
from tqdm import tqdm

from hollowtree.classes import CLASS_NAMES
from hollowtree.errors import ConfigError, OutputExistsError
from hollowtree.hollownet._png import confusion_png
from hollowtree.hollownet.dataset import DatasetParams, build_dataset, load_dataset
from hollowtree.hollownet.model import (
    OUTPUT_CLASSES,
    get_model,
    list_models,
    load_checkpoint,
    save_checkpoint,
)
from hollowtree.params import Params, like, param

__all__ = ["TrainConfig", "TrainReport", "confusion_matrix", "format_confusion", "grids_to_input",
           "default_data_dir", "resolve_device", "train", "evaluate"]

logger = logging.getLogger(__name__)


def default_data_dir() -> Path:
    """Where data sets are cached: ``$HOLLOWTREE_CACHE`` or ``~/.cache/hollowtree``, plus ``hollownet``."""
    base = os.environ.get("HOLLOWTREE_CACHE") or os.path.join(os.path.expanduser("~"), ".cache", "hollowtree")
    return Path(base) / "hollownet"


@dataclass(frozen=True, kw_only=True)
class TrainConfig(Params, owner="TrainConfig"):
    """Settings of one training run (``hollowtree train --config FILE`` reads these keys).

    The defaults made the shipped weights. Each field is declared once
    (``hollowtree.params``); ``seed`` and ``variants`` are the data sets'
    (:class:`~hollownet.dataset.DatasetParams`).
    """

    arch: str = param("hollownet_v1", check=lambda v: None if v in list_models() else
                      f"must be one of {list_models()}", doc="the network (hollownet.model registry)")
    seed: int = like(DatasetParams, "seed")
    n_train: int = param(400, ge=1, doc="training samples of every output class")
    n_test: int = param(60, ge=1, doc="test samples of every output class (other scenes)")
    variants: int = like(DatasetParams, "variants")
    epochs: int = param(16, ge=1, doc="passes over the training set")
    batch_size: int = param(32, ge=1, doc="samples per optimiser step")
    lr: float = param(0.001, gt=0, lt=10, doc="Adam's learning rate (cosine decay to 0 over the epochs)")
    weight_decay: float = param(0.0, ge=0, lt=10, doc="Adam's weight decay")
    amp: bool = param(True, doc="bfloat16 autocast of the forward pass on CUDA or a CPU with AMX")
    threads: int = param(2, ge=1, doc="torch's CPU threads")
    data_dir: str | None = field(default=None, compare=False)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: object) -> TrainConfig:
        """Build from a mapping (a parsed YAML/JSON file); unknown keys are errors."""
        if not isinstance(data, dict):
            raise ConfigError(f"a training config must be a mapping of keys to values; got {type(data).__name__}")
        known = set(cls.__dataclass_fields__)
        unknown = sorted(set(data) - known)
        if unknown:
            raise ConfigError(f"unknown training config keys {unknown}; known keys: {sorted(known)}")
        return cls(**data)

    def fingerprint(self) -> str:
        """Hash of everything that changes the result (``data_dir`` and ``threads`` do not)."""
        d = {k: v for k, v in self.to_dict().items() if k not in ("data_dir", "threads", "epochs")}
        return hashlib.sha256(json.dumps(d, sort_keys=True).encode()).hexdigest()[:16]

    def datasets(self) -> tuple[DatasetParams, DatasetParams]:
        return (DatasetParams(seed=self.seed, split="train", n_per_class=self.n_train, variants=self.variants),
                DatasetParams(seed=self.seed, split="test", n_per_class=self.n_test, variants=self.variants))


@dataclass(frozen=True, kw_only=True)
class TrainReport:
    """What a training run produced."""

    weights: str
    epochs: int
    accuracy: float
    confusion: list[list[int]]
    seconds: float
    resumed_from: int

    def summary(self) -> str:
        names = [CLASS_NAMES[c] for c in OUTPUT_CLASSES]
        return (f"trained {self.epochs} epochs ({self.seconds:.0f} s"
                f"{f', resumed after epoch {self.resumed_from}' if self.resumed_from else ''}); "
                f"test accuracy {100 * self.accuracy:.2f} %\n"
                f"{format_confusion(np.asarray(self.confusion), names)}\nweights: {self.weights}")


def resolve_device(device: str) -> torch.device:
    """``auto`` -> CUDA when available, else CPU; ``cuda`` without a GPU is an error."""
    if device not in ("auto", "cpu", "cuda"):
        raise ConfigError(f"device must be auto, cpu or cuda; got {device!r}")
    if device == "cuda" and not torch.cuda.is_available():
        raise ConfigError("device cuda was asked for but torch sees no CUDA device; use --device cpu")
    if device == "auto":
        device = "cuda" if torch.cuda.is_available() else "cpu"
    return torch.device(device)


def grids_to_input(grids: npt.NDArray[Any] | torch.Tensor) -> torch.Tensor:
    """Occupancy (bool) or hollow-voxel (int8, -1/5) grids ``(n, s, s, s)`` -> float input ``(n, 1, s, s, s)``.

    Examples
    --------
    >>> g = np.zeros((1, 2, 2, 2), dtype=bool); g[0, 0, 0, 0] = True
    >>> grids_to_input(g)[0, 0, 0, 0].tolist()
    [5.0, -1.0]
    """
    t = torch.as_tensor(np.asarray(grids)) if not isinstance(grids, torch.Tensor) else grids
    if t.dtype == torch.bool:
        x = t.to(torch.float32) * 6.0 - 1.0
    else:
        x = t.to(torch.float32)
    return x.unsqueeze(1)


def confusion_matrix(y_true: npt.ArrayLike, y_pred: npt.ArrayLike, n: int) -> npt.NDArray[np.int64]:
    """Counts ``m[i, j]`` of samples of true class index ``i`` predicted as ``j``.

    Examples
    --------
    >>> confusion_matrix([0, 1, 1], [0, 1, 0], 2).tolist()
    [[1, 0], [1, 1]]
    """
    t, p = np.asarray(y_true, dtype=np.int64), np.asarray(y_pred, dtype=np.int64)
    return np.bincount(t * n + p, minlength=n * n).reshape(n, n)


def format_confusion(m: npt.NDArray[np.integer], names: list[str]) -> str:
    """A text table: rows true class, columns predicted, per-class recall at the end.

    Examples
    --------
    >>> print(format_confusion(np.array([[3, 1], [0, 4]]), ["dome", "wall"]))
    true \\ pred   dome  wall  recall
    dome             3     1   75.0%
    wall             0     4  100.0%
    """
    w = max(6, max(len(n) for n in names) + 1)
    head = "true \\ pred".ljust(max(w, 12)) + "".join(n.rjust(w) for n in names) + "  recall"
    rows = [head]
    for i, name in enumerate(names):
        tot = int(m[i].sum())
        rec = f"{100 * m[i, i] / tot:.1f}%" if tot else "-"
        rows.append(name.ljust(max(w, 12)) + "".join(str(int(v)).rjust(w) for v in m[i]) + rec.rjust(8))
    return "\n".join(rows)


def _autocast(device: torch.device, amp: bool) -> Any:
    use = amp and (device.type == "cuda" or (hasattr(torch.cpu, "_is_amx_tile_supported")
                                             and torch.cpu._is_amx_tile_supported()))
    return torch.autocast(device.type, dtype=torch.bfloat16, enabled=use)


def evaluate(model: torch.nn.Module, grids: npt.NDArray[np.bool_], labels: npt.NDArray[np.integer], *,
             device: torch.device, batch_size: int = 64, amp: bool = False) -> npt.NDArray[np.int64]:
    """Confusion matrix of ``model`` on occupancy ``grids`` with class-id ``labels``."""
    index = {int(c): i for i, c in enumerate(OUTPUT_CLASSES)}
    y = np.array([index[int(v)] for v in labels], dtype=np.int64)
    preds = []
    model.eval()
    with torch.inference_mode(), _autocast(device, amp):
        for a in range(0, len(grids), batch_size):
            x = grids_to_input(grids[a:a + batch_size]).to(device)
            preds.append(model(x).argmax(dim=1).cpu().numpy())
    return confusion_matrix(y, np.concatenate(preds) if preds else np.zeros(0, np.int64), len(OUTPUT_CLASSES))


def _ckpt_path(out: Path) -> Path:
    return out.with_name(out.name + ".ckpt")


def train(config: TrainConfig, *, out: str | Path, device: str = "auto", resume: bool = False,
          overwrite: bool = False, progress: bool = True,
          labelled: Sequence[tuple[str, dict[str, Any], dict[str, Any]]] = (),
          synthetic: bool = True) -> TrainReport:
    """Train ``config.arch`` on the data sets of ``config`` and write the weights to ``out``.

    ``labelled`` adds samples cut from a user's labelled scans: ``(name, train, test)``
    per scan, as :func:`hollownet.dataset.labelled_samples` returns them. With
    ``synthetic=False`` they are the only data (the synthetic data sets are not made).

    Raises
    ------
    OutputExistsError
        If ``out`` exists and neither ``overwrite`` nor ``resume`` is set.
    ConfigError
        If ``resume`` is set and the checkpoint was made with other settings, or the
        device is unavailable.
    """
    t0 = time.perf_counter()
    out = Path(out)
    if not out.parent.is_dir():
        raise ConfigError(f"output folder {out.parent} does not exist")
    if out.exists() and not (overwrite or resume):
        raise OutputExistsError(f"{out} exists; pass --overwrite to replace it or --resume to continue")
    dev = resolve_device(device)
    torch.set_num_threads(config.threads)
    torch.manual_seed(config.seed)
    data_dir = Path(config.data_dir) if config.data_dir else default_data_dir()
    train_p, test_p = config.datasets()
    if not synthetic and not labelled:
        raise ConfigError("nothing to train on: no labelled scan and the synthetic data sets are off")
    sets = []
    for p in (train_p, test_p) if synthetic else ():
        bar = tqdm(total=p.n_per_class * len(OUTPUT_CLASSES), desc=f"data set {p.split}", unit="sample",
                   disable=None if progress else True, leave=False)

        def step(done: int, total: int, bar: tqdm = bar) -> None:
            bar.update(done - bar.n)

        folder = build_dataset(data_dir, p, progress=step)
        bar.close()
        sets.append(load_dataset(folder))
    for _name, ltr, lte in labelled:
        sets = [ltr, lte] if not sets else [
            {k: np.concatenate([a[k], b[k]]) for k in ("grids", "labels", "n_points", "scene", "recipe")}
            for a, b in zip(sets, (ltr, lte), strict=True)]
    tr, te = sets
    if not len(tr["labels"]) or not len(te["labels"]):
        raise ConfigError(f"too few labelled instances: {len(tr['labels'])} training and {len(te['labels'])} test "
                          "samples; add labelled scans or keep the synthetic data sets")
    data_key = hashlib.sha256(json.dumps([synthetic, [n for n, _, _ in labelled],
                                          [int(len(a["labels"])) for _, a, _ in labelled]]).encode()).hexdigest()[:16]
    index = np.zeros(256, dtype=np.int64)
    for i, c in enumerate(OUTPUT_CLASSES):
        index[int(c)] = i
    y_train = torch.as_tensor(index[tr["labels"]])
    g_train = torch.as_tensor(tr["grids"])

    model = get_model(config.arch).to(dev)
    if dev.type == "cpu":
        model = model.to(memory_format=torch.channels_last_3d)
    opt = torch.optim.Adam(model.parameters(), lr=config.lr, weight_decay=config.weight_decay)
    start, history = 0, []
    ckpt = _ckpt_path(out)
    if resume:
        if not ckpt.is_file():
            raise ConfigError(f"nothing to resume: no checkpoint {ckpt}")
        ck = load_checkpoint(ckpt)
        meta = ck["meta"]
        if meta.get("fingerprint") != config.fingerprint() or meta.get("data_key", data_key) != data_key:
            raise ConfigError(f"{ckpt} was made with other training settings ({meta.get('config')}); "
                              "rerun without --resume or with the same config")
        model.load_state_dict(ck["state_dict"])
        opt.load_state_dict(ck["optimizer"])
        start, history = int(meta["epoch"]), list(meta["history"])
        logger.info("resuming after epoch %d", start)
    n = len(y_train)
    for epoch in range(start, config.epochs):
        model.train()
        for group in opt.param_groups:  # cosine decay, closed form: resuming gives the same rates
            group["lr"] = float(config.lr * 0.5 * (1.0 + math.cos(math.pi * epoch / config.epochs)))
        rng = np.random.default_rng(np.random.SeedSequence([config.seed, 7, epoch]))
        order = torch.as_tensor(rng.permutation(n))
        flips = torch.as_tensor(rng.random((n, 2)) < 0.5)
        tot_loss, tot_ok, seen = 0.0, 0, 0
        bar = tqdm(range(0, n, config.batch_size), desc=f"epoch {epoch + 1}/{config.epochs}", unit="batch",
                   disable=None if progress else True, leave=False)
        for a in bar:
            idx = order[a:a + config.batch_size]
            g = g_train[idx]
            for axis in (0, 1):
                f = flips[idx, axis]
                if f.any():
                    g[f] = torch.flip(g[f], dims=(axis + 1,))
            x = grids_to_input(g).to(dev)
            if dev.type == "cpu":
                x = x.contiguous(memory_format=torch.channels_last_3d)
            y = y_train[idx].to(dev)
            opt.zero_grad(set_to_none=True)
            with _autocast(dev, config.amp):
                logits = model(x)
            loss = F.cross_entropy(logits.float(), y)
            loss.backward()
            opt.step()
            tot_loss += float(loss.detach()) * len(idx)
            tot_ok += int((logits.argmax(1) == y).sum())
            seen += len(idx)
            bar.set_postfix(loss=f"{tot_loss / seen:.3f}", acc=f"{100 * tot_ok / seen:.1f}%")
        bar.close()
        cm = evaluate(model, te["grids"], te["labels"], device=dev, amp=config.amp)
        acc = float(np.trace(cm) / max(cm.sum(), 1))
        history.append({"epoch": epoch + 1, "loss": tot_loss / max(seen, 1), "train_accuracy": tot_ok / max(seen, 1),
                        "test_accuracy": acc})
        msg = (f"epoch {epoch + 1}/{config.epochs}: loss {tot_loss / max(seen, 1):.4f}, "
               f"train {100 * tot_ok / max(seen, 1):.2f} %, test {100 * acc:.2f} %")
        logger.info(msg)
        if progress:
            tqdm.write(msg)
        save_checkpoint(ckpt, model, arch=config.arch, optimizer=opt, meta={
            "epoch": epoch + 1, "history": history, "config": config.to_dict(),
            "fingerprint": config.fingerprint(), "data_key": data_key})
    cm = evaluate(model, te["grids"], te["labels"], device=dev, amp=config.amp)
    acc = float(np.trace(cm) / max(cm.sum(), 1))
    names = [CLASS_NAMES[c] for c in OUTPUT_CLASSES]
    meta = {
        "config": config.to_dict(), "fingerprint": config.fingerprint(), "seed": config.seed,
        "epochs": config.epochs, "history": history, "test_accuracy": acc, "confusion": cm.tolist(),
        "grid_size": train_p.grid_size, "canonical_yaw": train_p.canonical_yaw,
        "datasets": {"train": train_p.key(), "test": test_p.key()} if synthetic else {},
        "labelled": [{"source": n, "train_samples": int(len(a["labels"])), "test_samples": int(len(b["labels"]))}
                     for n, a, b in labelled],
        "n_train": int(len(y_train)), "n_test": int(len(te["labels"])), "torch": str(torch.__version__),
    }
    model = model.to("cpu").to(memory_format=torch.contiguous_format)
    save_checkpoint(out, model, arch=config.arch, meta=meta)
    stem = out.with_suffix("")
    Path(f"{stem}.json").write_text(json.dumps({"classes": names, "weights": out.name, **meta}, indent=2))
    Path(f"{stem}.confusion.txt").write_text(format_confusion(cm, names) + "\n")
    confusion_png(f"{stem}.confusion.png", cm, names)
    return TrainReport(weights=str(out), epochs=config.epochs, accuracy=acc, confusion=cm.tolist(),
                       seconds=time.perf_counter() - t0, resumed_from=start)

