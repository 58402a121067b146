"""Directional manipulability (DM) of the arm along u, eqs. (8)–(10).

H2(q) = (uᵀ J A Jᵀ u)^(−1/2), A = WᵀW, W = diag(τ_ref/τ_lim,i)           eq. (8)

For a force f·u at the EE the weighted joint torque norm is ‖W Jᵀ u‖·f = f / H2: larger
H2 means more force along u for the same (weighted) torque.

u is given in the base (yaw-compensated) frame and J is the arm Jacobian in the arm base
frame, so uᵀ J_m = uᵀ Rz(ψ)ᵀ Rz(ψ) J_arm: H2 depends on q_m only.
"""

from __future__ import annotations

import math

import numpy as np

from .._jit import jit
from .._typing import FloatArray
from ..linalg3 import gram3, solve_sym3

S_MIN = 1e-12  # uᵀ J A Jᵀ u is floored here: H2 ≤ 1e6 where Jᵀu = 0 (a singular direction)


def directional_manipulability(J_arm: FloatArray, u: FloatArray, W: FloatArray) -> float:
    """H2 of eq. (8) (capped at 1e6 along a singular direction, where it is infinite).

    Args:
        J_arm: 3×7 translational arm Jacobian (arm base frame).
        u: unit direction (arm base frame).
        W: diagonal of the torque scaling W.
    """
    return _dm(np.asarray(J_arm, dtype=np.float64), np.asarray(u, dtype=np.float64), np.asarray(W, dtype=np.float64))


@jit
def _dm(J_arm: FloatArray, u: FloatArray, W: FloatArray) -> float:
    s = 0.0
    for i in range(J_arm.shape[1]):
        t = W[i] * (J_arm[0, i] * u[0] + J_arm[1, i] * u[1] + J_arm[2, i] * u[2])  # W Jᵀ u
        s += t * t
    return 1.0 / math.sqrt(max(s, S_MIN))


def torque_norm_per_newton(J_arm: FloatArray, u: FloatArray, W: FloatArray) -> float:
    """‖W Jᵀ u‖ [N·m/N]: weighted joint torque per newton of EE force along u (= 1/H2)."""
    return float(np.linalg.norm(W * (J_arm.T @ u)))


def dm_gradient(J_arm: FloatArray, dJ_arm: FloatArray, u: FloatArray, W: FloatArray) -> tuple[float, FloatArray]:
    """H2 and its joint gradient ∇_{q_m} H2 (7,), eq. (9).

    ∂H2/∂q_k = −½ H2³ ∂(uᵀ J A Jᵀ u)/∂q_k = −H2³ · uᵀ (∂J/∂q_k) A Jᵀ u.

    Args:
        J_arm: 3×7 arm Jacobian.
        dJ_arm: (7, 3, 7) with dJ_arm[k] = ∂J_arm/∂q_k (analytic, from the kinematic Hessian).
        u: unit direction.
        W: diagonal of W.
    """
    grad = np.empty(J_arm.shape[1])
    h2 = _dm_gradient(J_arm, dJ_arm, np.asarray(u, dtype=np.float64), np.asarray(W, dtype=np.float64), grad)
    return h2, grad


@jit
def _dm_gradient(J_arm: FloatArray, dJ_arm: FloatArray, u: FloatArray, W: FloatArray, grad: FloatArray) -> float:
    n = J_arm.shape[1]
    a = np.empty(n)  # A Jᵀ u
    s = 0.0  # uᵀ J A Jᵀ u
    for i in range(n):
        jtu = J_arm[0, i] * u[0] + J_arm[1, i] * u[1] + J_arm[2, i] * u[2]
        a[i] = W[i] * W[i] * jtu
        s += jtu * a[i]
    h2 = 1.0 / math.sqrt(max(s, S_MIN))
    for k in range(n):
        g = 0.0  # g_k = uᵀ ∂J/∂q_k A Jᵀ u
        for r in range(3):
            row = 0.0
            for i in range(n):
                row += dJ_arm[k, r, i] * a[i]
            g += u[r] * row
        grad[k] = -(h2**3) * g  # eq. (9)
    return h2


def dm_cartesian_gradient(grad_q: FloatArray, J_m: FloatArray, sigma_min: float | None = None) -> FloatArray:
    """∇_x H2 = ∇_{q_m} H2 · J_m⁺ (3,), eq. (10), with J_m world-aligned.

    J_m⁺ = J_mᵀ (J_m J_mᵀ)⁻¹ is the plain right pseudoinverse. Given σ_min(J_m) ≥ 1e-4 (the
    controller knows it), the 3×3 normal equations are solved in a compiled kernel; otherwise,
    or without σ_min, by lstsq (Moore–Penrose, finite next to singularities).
    """
    if sigma_min is not None and sigma_min >= 1e-4 and J_m.shape[0] == 3:
        y = np.empty(3)
        _solve_normal3(np.asarray(J_m, dtype=np.float64), np.asarray(grad_q, dtype=np.float64), y)
        return y
    out: FloatArray = np.asarray(np.linalg.lstsq(J_m.T, grad_q, rcond=1e-10)[0], dtype=np.float64)
    return out  # solves J_mᵀ y = gᵀ: y = (J_m⁺)ᵀ gᵀ


@jit
def _solve_normal3(J: FloatArray, g: FloatArray, y: FloatArray) -> None:
    """y = (J Jᵀ)⁻¹ J g for a 3×n J of full row rank (adjugate of the symmetric 3×3)."""
    r0 = r1 = r2 = 0.0  # J g
    for i in range(J.shape[1]):
        r0 += J[0, i] * g[i]
        r1 += J[1, i] * g[i]
        r2 += J[2, i] * g[i]
    a, b, c, d, e, f = gram3(J)
    _, y[0], y[1], y[2] = solve_sym3(a, b, c, d, e, f, r0, r1, r2)
