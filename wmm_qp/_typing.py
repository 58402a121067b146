"""The array types every module of the package annotates with, and the read-only array of a frozen config.

A leaf module: it imports nothing of the package, so any module may import it.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]


def readonly(a: Any) -> FloatArray:
    """``a`` as a new float array that cannot be written (the vectors of the frozen configs)."""
    out = np.array(a, dtype=float)
    out.setflags(write=False)
    return out
