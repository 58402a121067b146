"""The null-space DM preference v_n: eq. (19) as printed, or a normalised ascent (the QP's).

Eq. (19) asks the arm for v_n = k_N ∇_{q_m}H2ᵀ. By eq. (9) the gradient scales with H2³, so the
ascent's rate depends on how flat the start is: from the Gen3's start ‖∇H2‖ is 4.20 along x
(H2 = 3.82) but 0.26 along z (H2 = 1.12), and along z the ascent of eq. (19) needs ~64 s of null
space to reach the paper's 4.031 (docs/results.md §2).

The normalised preference keeps eq. (19)'s direction and floors its speed:

    v_n = s(‖g‖)·g,   s(‖g‖) = max(k_N, ρ / sqrt(‖g‖² + g₀²)),   g = ∇_{q_m}H2ᵀ.

Where eq. (19) is fast (‖g‖ ≥ ρ/k_N) it is unchanged (clipped, as eq. (19) is in the QP, to 10×
the velocity limits: a preference, which bounds (13) cut to what the joints may do); where the
gradient is flat the arm is asked for a joint speed ‖v_n‖ < ρ [rad/s] along the gradient's
direction instead of k_N‖g‖, and ρ is at most the slowest joint's velocity limit (the QP caps
it), so the floor itself never asks for more than a joint can do. (Clipping each entry of the
whole preference at 1× the limits instead turns its direction where eq. (19) is fast: along x
the ascent then settles at DM 5.01 instead of 5.79.) Near an unconstrained optimum (‖g‖ → 0) the
gain is ρ/g₀, finite, so v_n → 0 linearly and the ascent settles without the chatter of a
plain unit vector g/‖g‖; at a constrained optimum (a joint at its limit, where bounds (13) hold
it) the gradient's blocked part keeps ‖g‖ away from 0 and the free joints' preference still
vanishes linearly with their own gradient entries. With ρ = 0 it is eq. (19) exactly.
"""

from __future__ import annotations

import math

import numpy as np

from .._jit import jit
from .._typing import FloatArray


@jit
def dm_preference_gain(grad_q: FloatArray, k_N: float, speed: float, g0: float) -> float:
    """s(‖∇H2‖) of the normalised preference: max(k_N, ρ / sqrt(‖∇H2‖² + g₀²)); k_N if ρ = 0.

    Args:
        grad_q: ∇_{q_m}H2 (n,), eq. (9).
        k_N: eq. (19)'s gain.
        speed: ρ [rad/s], the joint speed asked for along a flat gradient (0: eq. (19)).
        g0: g₀ [1/rad], the gradient norm below which the preference fades out linearly.
    """
    if not speed > 0.0:
        return k_N
    n2 = 0.0
    for i in range(grad_q.shape[0]):
        n2 += grad_q[i] * grad_q[i]
    s = speed / math.sqrt(n2 + g0 * g0)
    return s if s > k_N else k_N  # NaN in the gradient: k_N, and the clip downstream sees NaN


def dm_preference(grad_q: FloatArray, k_N: float, speed: float, g0: float, v_max: FloatArray) -> FloatArray:
    """v_n's arm part (n,): s(‖∇H2‖)·∇H2 clipped to ±v_max (the QP: 10× the velocity limits)."""
    s = dm_preference_gain(grad_q, k_N, speed, g0)
    return np.clip(s * grad_q, -v_max, v_max)
