"""Efficient RANSAC's result (:class:`RansacResult`); its parameters
(:class:`RansacParams`) are declared in ``primitives/coarse_params.py``;
``primitives/ransac.py`` runs the search."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from hollowtree.primitives.coarse_params import RansacParams
from hollowtree.primitives.shapes import FailedFit, PrimitiveFit

__all__ = ["RansacParams", "RansacResult"]


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
