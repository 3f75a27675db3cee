"""The NumPy array type aliases of the kernels' signatures.

On the ground floor (``hollowtree/`` itself): every package may import it.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

__all__ = ["FloatArray", "IntArray"]

#: A float64 array (coordinates, normals, scores).
FloatArray = npt.NDArray[np.float64]
#: An int64 array (indices, labels, counts).
IntArray = npt.NDArray[np.int64]
