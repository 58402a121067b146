"""Intersection of velocity intervals by priority (the first interval always wins)."""

from __future__ import annotations

import numpy as np

from .._typing import FloatArray


def intersect_by_priority(
    lo: FloatArray, hi: FloatArray, lo2: FloatArray, hi2: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """[lo, hi] ∩ [lo2, hi2] element-wise; where empty, the point of [lo, hi] nearest to [lo2, hi2].

    So the result is never empty and always inside [lo, hi]: the earlier interval has priority.
    """
    # With lo ≤ hi and lo2 ≤ hi2 this is exactly "intersect, or the nearest point of [lo, hi]":
    # clipping each end of the second interval into the first (two ufuncs per end, no masks).
    return np.minimum(np.maximum(lo2, lo), hi), np.minimum(np.maximum(hi2, lo), hi)
