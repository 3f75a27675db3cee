"""The parameters of Efficient RANSAC (:class:`RansacParams`, their rules) and its result
(:class:`RansacResult`); ``primitives/ransac.py`` runs the search."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from hollowtree.errors import ConfigError
from hollowtree.primitives.shapes import (
    DEFAULT_KINDS,
    KINDS,
    FailedFit,
    PrimitiveFit,
)

__all__ = ["RansacParams", "RansacResult"]


# ------------------------------------------------------------------ parameter rules
@dataclass(frozen=True)
class _Interval:
    kind: type
    low: float
    high: float
    closed: str  # "neither", "left", "right", "both"
    none_ok: bool = False

    def check(self, name: str, value: object, caller: str) -> None:
        if value is None and self.none_ok:
            return
        is_int = isinstance(value, (int, np.integer)) and not isinstance(value, bool)
        is_num = is_int or isinstance(value, (float, np.floating))
        ok = is_int if self.kind is int else is_num
        if ok:
            v = float(value)  # type: ignore[arg-type]
            lo_ok = v >= self.low if self.closed in ("left", "both") else v > self.low
            hi_ok = v <= self.high if self.closed in ("right", "both") else v < self.high
            ok = math.isfinite(v) and lo_ok and hi_ok or (v == math.inf and hi_ok and lo_ok)
        if not ok:
            left = "[" if self.closed in ("left", "both") else "("
            right = "]" if self.closed in ("right", "both") else ")"
            tname = "an int" if self.kind is int else "a float"
            tail = " or None" if self.none_ok else ""
            raise ConfigError(
                f"The '{name}' parameter of {caller} must be {tname} in the range "
                f"{left}{float(self.low) if self.kind is float else int(self.low)}, "
                f"{self.high if self.high == math.inf else (float(self.high) if self.kind is float else int(self.high))}"
                f"{right}{tail}. Got {value!r} instead."
            )


_PARAMETER_CONSTRAINTS: dict[str, _Interval | str] = {
    "epsilon": _Interval(float, 0.0, math.inf, "neither"),
    "alpha_deg": _Interval(float, 0.0, 90.0, "right"),
    "cluster_epsilon": _Interval(float, 0.0, math.inf, "neither"),
    "min_support": _Interval(int, 3, math.inf, "left"),
    "probability": _Interval(float, 0.0, 1.0, "neither"),
    "max_iterations": _Interval(int, 1, math.inf, "left", none_ok=True),
    "shapes": "kinds",
}


def _validate(values: Mapping[str, object], caller: str) -> None:
    for name, rule in _PARAMETER_CONSTRAINTS.items():
        value = values[name]
        if isinstance(rule, _Interval):
            rule.check(name, value, caller)
            continue
        bad = (isinstance(value, str) or not isinstance(value, Sequence) or len(value) == 0
               or any(v not in KINDS for v in value))
        if bad:
            raise ConfigError(
                f"The '{name}' parameter of {caller} must be a non-empty sequence of "
                f"{', '.join(repr(k) for k in KINDS)}. Got {value!r} instead."
            )


@dataclass(frozen=True, kw_only=True)
class RansacParams:
    """Defaults of :func:`efficient_ransac` for survey-density scans (mm to cm spacing).

    ``efficient_ransac(xyz, normals, **RansacParams().to_dict())`` runs with them.

    Examples
    --------
    >>> p = RansacParams(min_support=500)
    >>> RansacParams.from_dict(p.to_dict()) == p, p.epsilon
    (True, 0.03)
    """

    epsilon: float = 0.03
    alpha_deg: float = 20.0
    cluster_epsilon: float = 0.15
    min_support: int = 200
    probability: float = 0.01
    shapes: tuple[str, ...] = DEFAULT_KINDS
    max_iterations: int | None = None

    def __post_init__(self) -> None:
        _validate(asdict(self), "RansacParams")

    def to_dict(self) -> dict[str, Any]:
        """Plain-Python form whose keys are :func:`efficient_ransac`'s keywords."""
        d = asdict(self)
        d["shapes"] = list(self.shapes)
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> RansacParams:
        """Inverse of :meth:`to_dict`; unknown keys are errors."""
        unknown = set(d) - set(cls.__dataclass_fields__)
        if unknown:
            raise ConfigError(f"Unknown RansacParams keys {sorted(unknown)}; valid keys are "
                              f"{sorted(cls.__dataclass_fields__)}.")
        kw = dict(d)
        if "shapes" in kw:
            kw["shapes"] = tuple(kw["shapes"])
        return cls(**kw)


@dataclass(frozen=True, kw_only=True, eq=False)
class RansacResult:
    """What :func:`efficient_ransac` found.

    Parameters
    ----------
    labels : ndarray of int64, shape (n_points,)
        Index into ``primitives`` of each point's primitive, ``-1`` for none.
    primitives : tuple of PrimitiveFit
        In extraction order (largest first, roughly).
    n_candidates : int
        Minimal sets drawn (``T`` of the stopping rule).
    stop_reason : str
        Why the search ended.
    failure : FailedFit or None
        Set (falsy) when the input could not be searched at all (too few points,
        degenerate geometry); ``labels`` are then all ``-1``.

    Examples
    --------
    >>> r = RansacResult(labels=np.array([-1, 0]), primitives=(), n_candidates=0, stop_reason="x")
    >>> r.n_unassigned, RansacResult.from_dict(r.to_dict()).labels.tolist()
    (1, [-1, 0])
    """

    labels: npt.NDArray[np.int64]
    primitives: tuple[PrimitiveFit, ...]
    n_candidates: int
    stop_reason: str
    failure: FailedFit | None = None

    @property
    def n_primitives(self) -> int:
        """Number of primitives found."""
        return len(self.primitives)

    @property
    def n_unassigned(self) -> int:
        """Points in no primitive."""
        return int(np.count_nonzero(self.labels < 0))

    def to_dict(self) -> dict[str, Any]:
        """Plain-Python form (labels as a list)."""
        return {"labels": self.labels.tolist(), "primitives": [p.to_dict() for p in self.primitives],
                "n_candidates": self.n_candidates, "stop_reason": self.stop_reason,
                "failure": None if self.failure is None else self.failure.reason}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> RansacResult:
        """Inverse of :meth:`to_dict`."""
        return cls(labels=np.asarray(d["labels"], dtype=np.int64),
                   primitives=tuple(PrimitiveFit.from_dict(p) for p in d["primitives"]),
                   n_candidates=int(d["n_candidates"]), stop_reason=str(d["stop_reason"]),
                   failure=None if d.get("failure") is None else FailedFit(reason=str(d["failure"])))
