"""Input checks shared by the kernels of ``primitives/`` (one message format)."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from hollowtree.errors import ConfigError


def as_xyz(xyz: object, func: str) -> npt.NDArray[np.float64]:
    """``xyz`` as a finite float64 array of shape (n_points, 3), or a ConfigError naming
    ``func``."""
    arr = np.asarray(xyz, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ConfigError(
            f"The 'xyz' parameter of {func} must be an array of shape (n_points, 3). "
            f"Got shape {arr.shape} instead."
        )
    if not np.isfinite(arr).all():
        raise ConfigError(f"The 'xyz' parameter of {func} must be finite. Got NaN or inf instead.")
    return arr
