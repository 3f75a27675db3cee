"""Classifying segments with trained HollowNet weights, in batches, once per process.

:class:`Classifier` is what the tree (and ``hollowtree classify``) calls for every
segment. :meth:`Classifier.get` caches one instance per weights file and process, so a
Dask worker loads the weights once however many tasks it runs.

Bad segments never reach torch: an empty segment, fewer than ``min_points`` points, a
non-finite coordinate, or all points at one spot (zero extent) gets the explicit answer
``other`` with score 0 and all-zero probabilities.
"""

from __future__ import annotations

import threading
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import torch

from hollowtree.classes import ClassId
from hollowtree.columns import column_span
from hollowtree.errors import ConfigError
from hollowtree.hollownet.model import DEFAULT_WEIGHTS, OUTPUT_CLASSES, load_model
from hollowtree.hollownet.voxels import GRID_SIZE, voxelize_batch
from hollowtree.threads import task_threads

__all__ = ["Classifier", "Prediction", "default_threads"]

_CLASS_IDS = np.array([int(c) for c in OUTPUT_CLASSES], dtype=np.uint8)
_CACHE: dict[tuple[str, str, int], Classifier] = {}
_LOCK = threading.Lock()


def default_threads() -> int:
    """Torch threads for inference: ``OMP_NUM_THREADS`` if set (1 in a Dask worker), else
    min(4, CPUs of this process) (:func:`hollowtree.threads.task_threads`)."""
    return task_threads(cap=4)


@dataclass(frozen=True, kw_only=True, eq=False)
class Prediction:
    """Classes of a batch of segments.

    Attributes
    ----------
    class_id : ndarray of shape (n_segments,), uint8
        :class:`~hollowtree.classes.ClassId` values.
    score : ndarray of shape (n_segments,), float32
        Probability of the predicted class (0 for a segment that could not be classified).
    probabilities : ndarray of shape (n_segments, K), float32
        Softmax over :data:`~hollownet.model.OUTPUT_CLASSES` (all zero for a segment that
        could not be classified).
    valid : ndarray of shape (n_segments,), bool
        False where the segment was degenerate and got ``other`` with score 0.
    """

    class_id: npt.NDArray[np.uint8]
    score: npt.NDArray[np.float32]
    probabilities: npt.NDArray[np.float32]
    valid: npt.NDArray[np.bool_]

    def __iter__(self) -> Any:  # ``class_ids, scores, probabilities = clf.predict(...)``
        return iter((self.class_id, self.score, self.probabilities))

    def __len__(self) -> int:
        return len(self.class_id)


class Classifier:
    """Trained HollowNet weights ready to classify point segments.

    Parameters
    ----------
    weights : str or Path, optional
        A checkpoint written by ``hollowtree train``; default: the shipped weights.
    device : {"cpu", "cuda"}
    batch_size : int
        Segments per forward pass.
    num_threads : int, optional
        Torch intra-op threads (process-wide); default :func:`default_threads`.
    min_points : int
        Segments with fewer points are ``other`` with score 0.
    precision : {"float32", "bfloat16"}
        ``bfloat16`` runs the network under bfloat16 autocast: fast on CPUs with AMX (2.5 ms
        per segment against 4.4 ms), but emulated and about 60x slower on CPUs without
        bfloat16 instructions (AVX2 only); keep ``float32`` there.

    Examples
    --------
    >>> clf = Classifier.get()
    >>> t = np.linspace(0, 2 * np.pi, 400, endpoint=False)
    >>> z = np.repeat(np.linspace(0, 6, 40), 10)
    >>> shaft = np.c_[0.3 * np.cos(t), 0.3 * np.sin(t), z]
    >>> p = clf.predict([shaft, np.zeros((0, 3))])
    >>> p.valid.tolist(), ClassId(int(p.class_id[1])).label, float(p.score[1])
    ([True, False], 'other', 0.0)
    """

    def __init__(self, weights: str | Path | None = None, *, device: str = "cpu", batch_size: int = 64,
                 num_threads: int | None = None, min_points: int = 10, precision: str = "float32") -> None:
        if precision not in ("float32", "bfloat16"):
            raise ConfigError(f"precision must be float32 or bfloat16; got {precision!r}")
        if batch_size < 1 or min_points < 1:
            raise ConfigError(f"batch_size and min_points must be positive; got {batch_size}, {min_points}")
        if device == "cuda" and not torch.cuda.is_available():
            raise ConfigError("device cuda was asked for but torch sees no CUDA device")
        self.weights = Path(weights) if weights is not None else DEFAULT_WEIGHTS
        torch.set_num_threads(num_threads if num_threads is not None else default_threads())
        model, self.meta = load_model(self.weights)
        self.device = torch.device(device)
        self.model = model.to(self.device)
        if self.device.type == "cpu":
            self.model = self.model.to(memory_format=torch.channels_last_3d)
        self.grid_size = int(self.meta.get("grid_size", GRID_SIZE))
        self.canonical_yaw = bool(self.meta.get("canonical_yaw", True))
        self.batch_size = int(batch_size)
        self.min_points = int(min_points)
        self.precision = precision

    @classmethod
    def get(cls, weights: str | Path | None = None, *, device: str = "cpu", **kwargs: Any) -> Classifier:
        """The process-wide classifier for ``weights`` (built on first use, then reused)."""
        path = Path(weights) if weights is not None else DEFAULT_WEIGHTS
        stat = path.stat() if path.is_file() else None
        key = (str(path.resolve()), device, stat.st_mtime_ns if stat else 0)
        with _LOCK:
            if key not in _CACHE:
                _CACHE[key] = cls(path, device=device, **kwargs)
            return _CACHE[key]

    @property
    def classes(self) -> tuple[ClassId, ...]:
        """Output order of :attr:`Prediction.probabilities`."""
        return OUTPUT_CLASSES

    def _valid(self, xyz: npt.NDArray[np.float64]) -> bool:
        if xyz.ndim != 2 or xyz.shape[1] != 3 or len(xyz) < self.min_points:
            return False
        if not np.isfinite(xyz).all():
            return False
        return bool(column_span(xyz).max() > 0)

    def predict(self, segments: Sequence[npt.ArrayLike]) -> Prediction:
        """Classify each segment (an ``(n_points, 3)`` array of coordinates).

        Returns a :class:`Prediction`; unpacks as ``class_ids, scores, probabilities``.
        """
        arrays = [np.asarray(s, dtype=np.float64) for s in segments]
        valid = np.array([self._valid(a) for a in arrays], dtype=bool)
        n, k = len(arrays), len(OUTPUT_CLASSES)
        probs = np.zeros((n, k), dtype=np.float32)
        good = np.flatnonzero(valid)
        for a in range(0, len(good), self.batch_size):
            sel = good[a:a + self.batch_size]
            parts = [arrays[i] for i in sel]
            offsets = np.r_[0, np.cumsum([len(p) for p in parts])]
            grids, _ = voxelize_batch(np.concatenate(parts), offsets, size=self.grid_size,
                                      canonical_yaw=self.canonical_yaw)
            probs[sel] = self.predict_grids(grids)
        class_id = np.full(n, int(ClassId.OTHER), dtype=np.uint8)
        score = np.zeros(n, dtype=np.float32)
        if len(good):
            best = probs[good].argmax(axis=1)
            class_id[good] = _CLASS_IDS[best]
            score[good] = probs[good, best]
        return Prediction(class_id=class_id, score=score, probabilities=probs, valid=valid)

    def predict_grids(self, grids: npt.NDArray[Any]) -> npt.NDArray[np.float32]:
        """Softmax probabilities ``(n, K)`` for hollow-voxel grids ``(n, s, s, s)`` (int8 -1/5 or bool)."""
        g = torch.as_tensor(np.asarray(grids))
        x = (g.to(torch.float32) * 6.0 - 1.0) if g.dtype == torch.bool else g.to(torch.float32)
        x = x.unsqueeze(1).to(self.device)
        if self.device.type == "cpu":
            x = x.contiguous(memory_format=torch.channels_last_3d)
        with torch.inference_mode(), torch.autocast(self.device.type, dtype=torch.bfloat16,
                                                    enabled=self.precision == "bfloat16"):
            logits = self.model(x).float()
        return torch.softmax(logits, dim=1).cpu().numpy().astype(np.float32)
