"""Intersection of velocity intervals by priority (the first interval always wins)."""

from __future__ import annotations

import numpy as np

from ..config import FloatArray


def intersect_by_priority(
    lo: FloatArray, hi: FloatArray, lo2: FloatArray, hi2: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """[lo, hi] ∩ [lo2, hi2] element-wise; where empty, the point of [lo, hi] nearest to [lo2, hi2].

    So the result is never empty and always inside [lo, hi]: the earlier interval has priority.
    """
    new_lo = np.maximum(lo, lo2)
    new_hi = np.minimum(hi, hi2)
    below = hi2 < lo  # the second interval lies entirely below the first: take lo
    above = lo2 > hi  # entirely above: take hi
    new_lo = np.where(below, lo, np.where(above, hi, new_lo))
    new_hi = np.where(below, lo, np.where(above, hi, new_hi))
    return new_lo, new_hi
