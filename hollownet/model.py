"""The HollowNet 3D CNN, its registry of builders, and versioned checkpoints.

The paper's network: Conv3d with 32 filters of 5^3, Conv3d with 64 filters of 5^3 and
stride 2 (the stride replaces pooling), a Leaky ReLU after each, then two fully connected
layers, the last with ``K`` outputs. ``K`` comes from the class vocabulary
(:mod:`hollowtree.classes`): every class except ``unclassified`` (the element classes, the
planar classes and ``other``), in id order: see :data:`OUTPUT_CLASSES`.

Sizes the paper leaves open, chosen to keep the model small and fast (``docs/method.md``, "HollowNet"):

- no padding ("valid" convolutions): 30^3 -> 26^3 -> 11^3; padding would cost 2.4x the
  multiply-adds for voxels that are mostly empty border;
- a 4^3 adaptive max pooling before the first fully connected layer: without it the
  first FC layer alone would hold 64 * 11^3 * width weights (43 MB at width 128); with it,
  64 * 4^3 = 4096 inputs;
- first FC width 128, Leaky ReLU slope 0.1 (Brock et al.'s voxel networks use 0.1).

Like torchvision's ``register_model`` / ``get_model``, builders are registered by name
and a checkpoint records the name of the builder that made it.
"""

from __future__ import annotations

import io
import os
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import torch
from torch import nn

from hollowtree.classes import CLASS_NAMES, ELEMENT_CLASSES, PLANAR_CLASSES, ClassId
from hollowtree.errors import InputFileError, PipelineError
from hollowtree.hollownet import DEFAULT_WEIGHTS

__all__ = [
    "CHECKPOINT_VERSION",
    "DEFAULT_WEIGHTS",
    "NUM_OUTPUTS",
    "OUTPUT_CLASSES",
    "HollowNet",
    "WeightsError",
    "get_model",
    "hollownet_v1",
    "list_models",
    "load_checkpoint",
    "load_model",
    "register_model",
    "save_checkpoint",
]

#: The classes HollowNet predicts, output ``i`` is ``OUTPUT_CLASSES[i]`` (id order).
OUTPUT_CLASSES: tuple[ClassId, ...] = tuple(
    c for c in ClassId if c in ELEMENT_CLASSES or c in PLANAR_CLASSES or c == ClassId.OTHER
)
#: ``K`` of the paper for our vocabulary.
NUM_OUTPUTS: int = len(OUTPUT_CLASSES)
#: Layout version of checkpoint files; a file of another version is refused.
CHECKPOINT_VERSION = 1
_FORMAT = "hollowtree.hollownet"


class WeightsError(PipelineError, ValueError):
    """A checkpoint is not a HollowNet checkpoint, or is of another version or class set."""


class HollowNet(nn.Module):
    """Two 3D convolutions and two fully connected layers over a hollow-voxel grid.

    Parameters
    ----------
    widths : tuple of int
        Filters of each convolution (the paper: 32, then doubled).
    strides : tuple of int
        Stride of each convolution (the paper: 1, 2).
    kernel_size : int
        Side of the cubic filters (the paper: 5).
    padding : int
        Zero padding of each convolution.
    pool : int
        Side of the adaptive max pooling before the fully connected layers (0: none).
    hidden : int
        Width of the first fully connected layer.
    num_classes : int
        ``K``, outputs of the last layer.
    grid_size : int
        Side of the input grid (the paper: 30).
    negative_slope : float
        Slope of the Leaky ReLUs.

    Examples
    --------
    >>> net = HollowNet(widths=(4, 8), hidden=16, num_classes=3, grid_size=16)
    >>> net(torch.zeros(2, 1, 16, 16, 16)).shape
    torch.Size([2, 3])
    """

    def __init__(
        self,
        *,
        widths: tuple[int, ...] = (32, 64),
        strides: tuple[int, ...] = (1, 2),
        kernel_size: int = 5,
        padding: int = 0,
        pool: int = 4,
        hidden: int = 128,
        num_classes: int = NUM_OUTPUTS,
        grid_size: int = 30,
        negative_slope: float = 0.1,
    ) -> None:
        super().__init__()
        if len(widths) != len(strides):
            raise ValueError(f"widths {widths} and strides {strides} must have the same length")
        layers: list[nn.Module] = []
        c_in, side = 1, grid_size
        for w, s in zip(widths, strides, strict=True):
            layers += [nn.Conv3d(c_in, w, kernel_size, stride=s, padding=padding),
                       nn.LeakyReLU(negative_slope, inplace=True)]
            c_in, side = w, (side + 2 * padding - kernel_size) // s + 1
        if side < 1:
            raise ValueError(f"grid_size {grid_size} is too small for these convolutions")
        if pool:
            layers.append(nn.AdaptiveMaxPool3d(pool))
            side = pool
        self.features = nn.Sequential(*layers)
        self.classifier = nn.Sequential(
            nn.Flatten(),
            nn.Linear(c_in * side**3, hidden),
            nn.LeakyReLU(negative_slope, inplace=True),
            nn.Linear(hidden, num_classes),
        )
        self.num_classes = num_classes
        self.grid_size = grid_size

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Logits of shape ``(batch, num_classes)`` for grids of shape ``(batch, 1, s, s, s)``."""
        return self.classifier(self.features(x))


_MODELS: dict[str, Callable[..., HollowNet]] = {}


def register_model(name: str) -> Callable[[Callable[..., HollowNet]], Callable[..., HollowNet]]:
    """Decorator registering a builder under ``name`` (torchvision's ``register_model``)."""

    def wrap(fn: Callable[..., HollowNet]) -> Callable[..., HollowNet]:
        if name in _MODELS:
            raise ValueError(f"a model is already registered as {name!r}")
        _MODELS[name] = fn
        return fn

    return wrap


def list_models() -> list[str]:
    """Names of the registered builders.

    Examples
    --------
    >>> "hollownet_v1" in list_models()
    True
    """
    return sorted(_MODELS)


def get_model(name: str, **kwargs: Any) -> HollowNet:
    """Build the model registered as ``name``.

    Raises
    ------
    WeightsError
        If no builder has that name; the message lists the known ones.
    """
    if name not in _MODELS:
        raise WeightsError(f"unknown HollowNet architecture {name!r}; known: {', '.join(list_models())}")
    return _MODELS[name](**kwargs)


@register_model("hollownet_v1")
def hollownet_v1(*, num_classes: int = NUM_OUTPUTS) -> HollowNet:
    """The paper's layers with the open sizes of this module's notes (785 544 weights, 3.1 MB).

    Examples
    --------
    >>> net = hollownet_v1()
    >>> sum(p.numel() for p in net.parameters())
    785544
    """
    return HollowNet(widths=(32, 64), strides=(1, 2), kernel_size=5, padding=0, pool=4,
                     hidden=128, num_classes=num_classes, grid_size=30)


# --------------------------------------------------------------------------- checkpoints
def save_checkpoint(path: str | Path, model: nn.Module, *, arch: str, meta: Mapping[str, Any],
                    optimizer: torch.optim.Optimizer | None = None) -> None:
    """Write ``model`` (and optionally the optimizer state) to ``path`` atomically.

    ``meta`` must hold only JSON-like values (it is loaded with ``weights_only=True``).
    The file records the format version, the builder name and the output classes.
    """
    path = Path(path)
    payload: dict[str, Any] = {
        "format": _FORMAT,
        "version": CHECKPOINT_VERSION,
        "arch": arch,
        "classes": [CLASS_NAMES[c] for c in OUTPUT_CLASSES],
        "meta": dict(meta),
        "state_dict": {k: v.detach().cpu().contiguous() for k, v in model.state_dict().items()},
    }
    if optimizer is not None:
        payload["optimizer"] = optimizer.state_dict()
    buf = io.BytesIO()
    torch.save(payload, buf)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_bytes(buf.getvalue())
    os.replace(tmp, path)


def load_checkpoint(path: str | Path) -> dict[str, Any]:
    """Read and check a checkpoint written by :func:`save_checkpoint`.

    Raises
    ------
    InputFileError
        If the file does not exist.
    WeightsError
        If it is not a HollowNet checkpoint, is of another format version, was trained
        for another set of classes (another ``K``), or names an unknown architecture.
    """
    path = Path(path)
    if not path.is_file():
        raise InputFileError(f"{path}: no such weights file")
    try:
        ck = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # torch raises many types for a file that is not a checkpoint
        raise WeightsError(f"{path} is not a HollowNet checkpoint ({type(exc).__name__})") from None
    if not isinstance(ck, dict) or ck.get("format") != _FORMAT:
        raise WeightsError(f"{path} is not a HollowNet checkpoint (no {_FORMAT!r} format tag)")
    if ck.get("version") != CHECKPOINT_VERSION:
        raise WeightsError(
            f"{path} is a HollowNet checkpoint of version {ck.get('version')!r}; this hollowtree "
            f"reads version {CHECKPOINT_VERSION} only: retrain with `hollowtree train`"
        )
    ours = [CLASS_NAMES[c] for c in OUTPUT_CLASSES]
    theirs = list(ck.get("classes", []))
    if theirs != ours:
        raise WeightsError(
            f"{path} was trained for K={len(theirs)} classes ({', '.join(map(str, theirs))}); this "
            f"hollowtree needs K={len(ours)} ({', '.join(ours)}): retrain with `hollowtree train`"
        )
    if ck.get("arch") not in _MODELS:
        raise WeightsError(
            f"{path} needs architecture {ck.get('arch')!r}; known: {', '.join(list_models())}"
        )
    return ck


def load_model(path: str | Path = DEFAULT_WEIGHTS) -> tuple[HollowNet, dict[str, Any]]:
    """Build the checkpoint's architecture and load its weights (eval mode, CPU).

    Returns the model and the checkpoint's ``meta`` dictionary.
    """
    ck = load_checkpoint(path)
    model = get_model(ck["arch"], num_classes=len(ck["classes"]))
    try:
        model.load_state_dict(ck["state_dict"])
    except RuntimeError as exc:
        first = str(exc).strip().splitlines()[0]
        raise WeightsError(f"{path}: weights do not fit architecture {ck['arch']!r}: {first}") from None
    model.eval()
    return model, dict(ck.get("meta", {}))
