"""The five-term energy of a proposed split and the fitted energy model.

``../shared/METHOD.md``, "Energy of one proposal": a parent of ``Np`` points split into
``s`` children of ``N1..Ns`` points,

- ``e1 = 1 - std([N1..Ns]) / std([1, Np - 1])`` (balanced populations);
- ``e2 = min(Np, Nmin) / Nmin`` (only large enough parents are worth splitting);
- ``e3 = 1 - exp(-(s - 1)^2 / 2)`` (the Gaussian N(s | 1, 1) scaled so ``e3(1) = 0``);
- ``e4 = W[class(parent), sequence]`` (a K x 3 prior);
- ``e5`` = the mean of the children's classification scores;

and ``xi = w . e``. ``std`` is the population standard deviation (NumPy's default).
The weights ``w``, the prior ``W``, ``Nmin`` and the threshold live in a versioned JSON
file, ``tree/data/energy-v1.json``, written by :func:`tree.fit.fit_energy_from_scenes`.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np
import numpy.typing as npt

from hollowtree.arrays import FloatArray
from hollowtree.classes import NUM_CLASSES

__all__ = [
    "DEFAULT_MODEL_PATH",
    "Classifier",
    "EnergyModel",
    "e1",
    "e2",
    "e3",
    "e4",
    "e5",
    "energy_terms",
    "load_energy_model",
]


#: The energy model shipped with the package (``tree/data/energy-v1.json``).
DEFAULT_MODEL_PATH = Path(__file__).resolve().parent / "data" / "energy-v1.json"


class Classifier(Protocol):
    """What the tree needs from a classifier (HollowNet, or a stand-in).

    ``predict(segments)`` takes a list of ``(n_i, 3)`` float64 point arrays and returns
    ``(class_ids, scores, probabilities)``: int array of shape (n,), float array of shape
    (n,) (the probability of the predicted class), float array of shape (n, K).
    """

    def predict(
        self, segments: Sequence[npt.NDArray[np.float64]]
    ) -> tuple[npt.NDArray[np.integer[Any]], npt.NDArray[np.floating[Any]], npt.NDArray[np.floating[Any]]]: ...


def e1(sizes: npt.ArrayLike, n_parent: int | None = None) -> float:
    """Balanced populations: ``1 - std(sizes) / std([1, Np - 1])``.

    ``Np`` defaults to ``sum(sizes)``. A parent of 2 points or fewer gives 1.

    Examples
    --------
    >>> e1([50, 50]), e1([1, 99]), round(e1([25, 25, 50]), 4)
    (1.0, 0.0, 0.7595)
    """
    n = np.asarray(sizes, dtype=np.float64)
    npar = float(n.sum()) if n_parent is None else float(n_parent)
    ref = float(np.std([1.0, npar - 1.0]))
    if ref <= 0 or len(n) == 0:
        return 1.0
    return float(1.0 - np.std(n) / ref)


def e2(n_parent: int, n_min: int) -> float:
    """Parent population: ``min(Np, Nmin) / Nmin``.

    Examples
    --------
    >>> e2(500, 1000), e2(5000, 1000)
    (0.5, 1.0)
    """
    if n_min <= 0:
        raise ValueError(f"The 'n_min' parameter of e2 must be an int >= 1. Got {n_min} instead.")
    return float(min(n_parent, n_min) / n_min)


def e3(n_children: int) -> float:
    """Number of children: ``1 - exp(-(s - 1)^2 / 2)``; one child gives 0.

    Examples
    --------
    >>> e3(1), round(e3(2), 4), round(e3(8), 4)
    (0.0, 0.3935, 1.0)
    """
    return float(1.0 - math.exp(-0.5 * (n_children - 1) ** 2))


def e4(prior: npt.ArrayLike, parent_class: int, sequence: int) -> float:
    """Class prior of the sequence: ``W[class(parent), sequence - 1]``.

    Examples
    --------
    >>> W = np.full((9, 3), 0.2); W[6, 0] = 0.9
    >>> e4(W, 6, 1), e4(W, 6, 2)
    (0.9, 0.2)
    """
    w = np.asarray(prior, dtype=np.float64)
    if not 1 <= sequence <= w.shape[1]:
        raise ValueError(f"The 'sequence' parameter of e4 must be in 1..{w.shape[1]}. Got {sequence} instead.")
    return float(w[int(parent_class), sequence - 1])


def e5(scores: npt.ArrayLike) -> float:
    """Mean classification score of the children.

    Examples
    --------
    >>> e5([0.5, 1.0])
    0.75
    """
    s = np.asarray(scores, dtype=np.float64)
    return float(s.mean()) if len(s) else 0.0


def energy_terms(
    sizes: npt.ArrayLike,
    *,
    n_min: int,
    prior: npt.ArrayLike,
    parent_class: int,
    sequence: int,
    scores: npt.ArrayLike,
) -> FloatArray:
    """The five terms ``[e1, e2, e3, e4, e5]`` of one proposal.

    Examples
    --------
    >>> W = np.full((9, 3), 0.5)
    >>> energy_terms([40, 60], n_min=200, prior=W, parent_class=2, sequence=2,
    ...              scores=[0.8, 0.6]).round(4).tolist()
    [0.7959, 0.5, 0.3935, 0.5, 0.7]
    """
    n = np.asarray(sizes, dtype=np.int64)
    npar = int(n.sum())
    return np.array([e1(n, npar), e2(npar, n_min), e3(len(n)), e4(prior, parent_class, sequence),
                     e5(scores)])


@dataclass(frozen=True, kw_only=True)
class EnergyModel:
    """Weights ``w``, prior ``W`` and the settings of the energy (a versioned file).

    Attributes
    ----------
    weights : tuple of 5 floats
        ``w`` of ``xi = w . e``.
    prior : tuple of K tuples of 3 floats
        ``W[class, sequence - 1]``, K = :data:`~hollowtree.classes.NUM_CLASSES`.
    n_min : int
        ``Nmin`` of ``e2``.
    threshold : float
        A split is kept when its ``xi`` reaches this value.
    version : int
    r2 : float
        Coefficient of determination of the fit (NaN if unknown).
    seed : int
        Seed of the fit.
    info : dict
        Free-form provenance (samples, classifier, target).
    """

    weights: tuple[float, ...]
    prior: tuple[tuple[float, ...], ...]
    n_min: int = 20_000
    threshold: float = 0.5
    version: int = 1
    r2: float = float("nan")
    seed: int = 0
    info: dict[str, Any] = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        if len(self.weights) != 5:
            raise ValueError(f"an energy model needs 5 weights; got {len(self.weights)}")
        w = np.asarray(self.prior, dtype=np.float64)
        if w.shape != (NUM_CLASSES, 3):
            raise ValueError(f"the prior W must have shape ({NUM_CLASSES}, 3); got {w.shape}")

    @property
    def w(self) -> FloatArray:
        return np.asarray(self.weights, dtype=np.float64)

    @property
    def W(self) -> FloatArray:  # noqa: N802 - the paper's name
        return np.asarray(self.prior, dtype=np.float64)

    def xi(self, terms: npt.ArrayLike) -> float:
        """``xi = w . e``."""
        return float(self.w @ np.asarray(terms, dtype=np.float64))

    def to_dict(self) -> dict[str, Any]:
        return {
            "version": self.version,
            "weights": list(self.weights),
            "prior": [list(r) for r in self.prior],
            "n_min": self.n_min,
            "threshold": self.threshold,
            "r2": None if math.isnan(self.r2) else self.r2,
            "seed": self.seed,
            "info": self.info,
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> EnergyModel:
        unknown = set(d) - {"version", "weights", "prior", "n_min", "threshold", "r2", "seed", "info"}
        if unknown:
            raise ValueError(f"unknown keys in an energy model: {sorted(unknown)}")
        return cls(
            weights=tuple(float(x) for x in d["weights"]),
            prior=tuple(tuple(float(x) for x in row) for row in d["prior"]),
            n_min=int(d.get("n_min", 20_000)),
            threshold=float(d.get("threshold", 0.5)),
            version=int(d.get("version", 1)),
            r2=float("nan") if d.get("r2") is None else float(d["r2"]),
            seed=int(d.get("seed", 0)),
            info=dict(d.get("info", {})),
        )

    def save(self, path: str | Path) -> None:
        Path(path).write_text(json.dumps(self.to_dict(), indent=1) + "\n")


def load_energy_model(path: str | Path | None = None) -> EnergyModel:
    """Read an energy model; the package's ``energy-v1.json`` by default."""
    p = DEFAULT_MODEL_PATH if path is None else Path(path)
    return EnergyModel.from_dict(json.loads(p.read_text()))
