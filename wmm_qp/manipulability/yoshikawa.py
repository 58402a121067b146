"""Yoshikawa's velocity manipulability index, for completeness (Sec. III-A).

w(q) = sqrt(det(J Jᵀ)) for the 3×7 translational arm Jacobian; zero at singularities.
(The paper prints 1/det[J_m J_mᵀ]; Yoshikawa's index is the square root of the determinant.)
"""

from __future__ import annotations

import numpy as np

from .._typing import FloatArray


def yoshikawa_manipulability(J: FloatArray) -> float:
    """sqrt(det(J Jᵀ)) of a translational Jacobian J (3×n)."""
    return float(np.sqrt(max(np.linalg.det(J @ J.T), 0.0)))
