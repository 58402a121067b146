"""Pseudoinverses of the whole-robot Jacobian: weighted, eq. (11), and damped.

J# = W_x Jᵀ (J W_x Jᵀ)⁻¹,  W_x = diag(α·I_wheels, (1−α)·I_joints)        eqs. (11), (12)

The print shows I_b in the base block; the text (α = 0: arm only, α = 1: base only)
needs α·I_b. Near singularities (σ_min(J_m) below a threshold) the inverse is damped:
J#_λ = W_x Jᵀ (J W_x Jᵀ + λ² I)⁻¹ with λ² = λ_max² (1 − (σ/σ_th)²) (variable damping).
"""

from __future__ import annotations

import math

import numpy as np

from ._jit import jit
from ._typing import FloatArray
from .linalg3 import gram3


def weight_matrix_diag(alpha: float, n_wheels: int, n_arm: int) -> FloatArray:
    """Diagonal of W_x, eq. (12): α for each wheel, 1 − α for each joint."""
    return np.concatenate([np.full(n_wheels, alpha), np.full(n_arm, 1.0 - alpha)])


def weighted_pinv(J: FloatArray, w: FloatArray, damping: float = 0.0) -> FloatArray:
    """W Jᵀ (J W Jᵀ + λ² I)⁻¹ for a diagonal weight w (eq. (11); damped when λ > 0).

    Args:
        J: r×n Jacobian.
        w: diagonal of W_x (n,), entries ≥ 0.
        damping: λ ≥ 0.
    """
    WJt = w[:, None] * J.T
    G = J @ WJt
    if damping > 0.0:
        G = G + (damping**2) * np.eye(J.shape[0])
    return WJt @ np.linalg.pinv(G, rcond=1e-12, hermitian=True)


def damping_factor(sigma_min: float, threshold: float, damping_max: float) -> float:
    """λ of the damped least squares: 0 above the threshold, λ_max at σ_min = 0."""
    if sigma_min >= threshold or threshold <= 0.0:
        return 0.0
    return float(damping_max * np.sqrt(1.0 - (sigma_min / threshold) ** 2))


def sigma_min(J: FloatArray) -> float:
    """Smallest singular value of J (r×n, r ≤ n).

    For r = 3 (every Jacobian here) it is the square root of the smallest eigenvalue of the
    3×3 Gram matrix J Jᵀ, in closed form (the trigonometric solution of the characteristic
    cubic; an SVD costs ~10× more per tick). Accurate to ~1e-8 absolute where σ_min ≥ 1e-3;
    next to the arm's straight pose the trigonometric form loses digits (errors up to ~4e-6 for
    σ_min in [1e-4, 1e-3) and ~7e-5 below, against the SVD on configurations near that pose:
    tests/core/test_controllers.py) — all far below the 0.08 threshold it is compared with.
    """
    if J.shape[0] != 3:
        return float(np.linalg.svd(J, compute_uv=False)[-1])
    return _sigma_min3(np.asarray(J, dtype=np.float64))


@jit
def _sigma_min3(J: FloatArray) -> float:
    a, b, c, d, e, f = gram3(J)  # J Jᵀ = [[a, b, c], [b, d, e], [c, e, f]]
    p1 = b * b + c * c + e * e
    q = (a + d + f) / 3.0
    aq, dq, fq = a - q, d - q, f - q
    p = math.sqrt((aq * aq + dq * dq + fq * fq + 2.0 * p1) / 6.0)
    if p < 1e-300:
        return math.sqrt(max(q, 0.0))
    det = aq * (dq * fq - e * e) - b * (b * fq - e * c) + c * (b * e - dq * c)
    r = max(-1.0, min(1.0, det / (2.0 * p**3)))
    lam = q + 2.0 * p * math.cos(math.acos(r) / 3.0 + 2.0 * math.pi / 3.0)
    return math.sqrt(max(lam, 0.0))
