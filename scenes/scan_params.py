"""The settings of one synthetic scan, declared once (``hollowtree.params``):
:class:`ScanParams`, run by ``scenes/scanner.py``. A light module (no NumPy): the flags of
``hollowtree synth`` and the workflow's ``input.synth`` are derived from these fields.
"""

from __future__ import annotations

from dataclasses import dataclass

from hollowtree.errors import ConfigError
from hollowtree.params import Params, param

__all__ = ["DEFAULT_POINTS", "ScanParams"]

#: Points a scan aims at when neither a count nor a step is given (``scenes.synth.synth``).
DEFAULT_POINTS = 1_000_000


@dataclass(frozen=True, kw_only=True)
class ScanParams(Params, owner="scan"):
    """Settings of one synthetic scan.

    Parameters
    ----------
    step_deg : float
        Angular step of the spherical ray grid, degrees (both azimuth and elevation).
    n_stations : int or None
        Use the first ``n_stations`` stations of the scene; None = all of them.
    noise : float
        Standard deviation of the range noise at 10 m, metres (default 2.5 mm, like a
        survey-grade scanner). At range r it is ``noise * (0.5 + 0.5 * r / 10)``.
    registration_error : float
        Standard deviation of each station's registration translation, metres; the
        rotation has standard deviation ``registration_error / 20`` radians per axis
        (so about the same displacement 20 m from the station). 0 = perfect registration.
    min_range, max_range : float
        The scanner's blind zone and its reach, metres.
    seed : int
        Seeds the station headings, the noise and the registration error.
    """

    step_deg: float = param(ge=0.001, le=10.0, doc="angular step of the scanner, degrees")
    n_stations: int | None = param(None, ge=1, doc="use the first K stations of the site; null = all")
    noise: float = param(0.0025, ge=0, doc="range noise standard deviation at 10 m, metres")
    registration_error: float = param(0.0, ge=0, doc="per-station registration error, metres")
    min_range: float = param(0.6, ge=0, doc="the scanner's blind zone, metres")
    max_range: float = param(300.0, gt=0, doc="the scanner's reach, metres")
    seed: int = param(0, doc="random seed")

    def __post_init__(self) -> None:
        super().__post_init__()
        if not self.min_range < self.max_range:
            raise ConfigError(f"need 0 <= min_range < max_range; got {self.min_range}, {self.max_range}")
