"""The σ_min floor of the DM modes: a row that keeps the arm out of its singularities while DM rises.

Raising the directional manipulability H2 (eq. (8)) along u lowers uᵀJ A Jᵀu: the ascent (9) drives
the arm towards configurations whose Jacobian barely moves the EE along some other direction, and
nothing in eqs. (16)–(19) stops it at a singularity. On an arm whose DM along u has no interior
optimum it stops only at a joint limit with σ_min(J_m) near zero, where the singularity damping
then holds the arm for every task that follows.

The floor is a velocity damper on σ_min, of the form of the collision dampers (docs/model.md,
"Collisions"), a hard row of the DM modes' QP stage:

    ∇_{q_m}σ_min · v_m ≥ −γ (σ' − σ_f),   σ' = σ_min − τ·max(0, −∇σ_min·v_prev)

σ_f = ``dm.sigma_min_floor``, γ = :data:`FLOOR_RATE`, τ the state's latency (``state_latency``; the
joints keep moving at v_prev meanwhile). Above the floor σ_min may fall at most at a rate that
decays with its distance to the floor, so to first order it reaches the floor only asymptotically;
below it (a mode entered there) the row asks σ_min back up at the same rate. The row is added only
within :data:`INFLUENCE` × σ_f, so a DM ascent that stays clear of the floor solves the very same
QP as without it. Like the collision rows it yields to the acceleration bounds (13): a rate they
cannot reach is relaxed to the most σ-raising rate they admit.

The gradient: σ_min² = λ_min(J Jᵀ) with unit eigenvector w, so ∂σ_min/∂q_k = wᵀ(∂J/∂q_k)Jᵀw / σ_min
(first-order perturbation of a simple eigenvalue), ∂J/∂q_k the kinematic Hessian of eq. (9).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .._jit import jit
from .._typing import FloatArray
from ..linalg3 import gram3
from ..pseudoinverse import _sigma_min3
from ..types import Mode
from .rows import Retry, Rows, RowSource, Tick

FLOOR_RATE = 2.0  # γ [1/s]: σ_min − σ_f may shrink by at most this fraction per second
INFLUENCE = 2.0  # the row acts while σ_min < INFLUENCE·σ_f
SIGMA_EPS = 1e-9  # [m/rad] below this σ_min its gradient is undefined (a double singular value at 0)


@dataclass(frozen=True, slots=True)
class FloorRow:
    """The σ_min floor's row of one tick: l ≤ C v (no upper bound), v = [v_b; v_m].

    Attributes:
        C: (n_v,) [m/rad] ∇σ_min on the arm's columns, 0 on the wheels'.
        l: [m/rad/s] the damper, relaxed to the most σ-raising rate the bounds admit.
        l_brake: [m/rad/s] l relaxed further to admit the braking command v₀ = clip(0, lb, ub).
        sigma: [m/rad] σ_min(J_m) this tick.
        floor: [m/rad] σ_f.
        damper: [m/rad/s] the damper's own bound −γ(σ' − σ_f).
    """

    C: FloatArray
    l: float
    l_brake: float
    sigma: float
    floor: float
    damper: float = 0.0


def sigma_min_gradient(J_arm: FloatArray, dJ_arm: FloatArray) -> tuple[float, FloatArray]:
    """σ_min of the 3×n translational arm Jacobian and its joint gradient ∇_{q_m}σ_min (n,).

    Args:
        J_arm: 3×n translational arm Jacobian [m/rad].
        dJ_arm: (n, 3, n), dJ_arm[k] = ∂J_arm/∂q_k (the kinematic Hessian, as for eq. (9)).

    Returns:
        (σ_min [m/rad], ∇σ_min [m/rad²]); the gradient is 0 where σ_min < ``SIGMA_EPS``.
    """
    grad = np.empty(J_arm.shape[1])
    s = _sigma_min_gradient(np.asarray(J_arm, dtype=np.float64), np.asarray(dJ_arm, dtype=np.float64), grad)
    return s, grad


@jit
def _smallest_eigvec3(a: float, b: float, c: float, d: float, e: float, f: float, lam: float) -> FloatArray:
    """A unit eigenvector of [[a, b, c], [b, d, e], [c, e, f]] for its eigenvalue lam: the longest
    cross product of two rows of (G − lam I) (they span the orthogonal complement of a simple one)."""
    r0 = np.array((a - lam, b, c))
    r1 = np.array((b, d - lam, e))
    r2 = np.array((c, e, f - lam))
    best = np.zeros(3)
    nb = 0.0
    for p, q in ((r0, r1), (r0, r2), (r1, r2)):
        x = np.array((p[1] * q[2] - p[2] * q[1], p[2] * q[0] - p[0] * q[2], p[0] * q[1] - p[1] * q[0]))
        n = x[0] * x[0] + x[1] * x[1] + x[2] * x[2]
        if n > nb:
            best, nb = x, n
    if not nb > 0.0:  # G − lam I of rank < 2: a multiple eigenvalue, any of its vectors will do
        return np.array((1.0, 0.0, 0.0)) if abs(a - lam) <= abs(d - lam) else np.array((0.0, 1.0, 0.0))
    return best / math.sqrt(nb)


@jit
def _sigma_min_gradient(J: FloatArray, dJ: FloatArray, grad: FloatArray) -> float:
    s = _sigma_min3(J)  # the controller's own σ_min (closed form), λ_min(J Jᵀ) = s²
    a, b, c, d, e, f = gram3(J)
    n = J.shape[1]
    for k in range(n):
        grad[k] = 0.0
    if not s >= SIGMA_EPS:
        return s
    w = _smallest_eigvec3(a, b, c, d, e, f, s * s)
    jw = np.empty(n)  # Jᵀw
    for i in range(n):
        jw[i] = J[0, i] * w[0] + J[1, i] * w[1] + J[2, i] * w[2]
    for k in range(n):
        g = 0.0  # wᵀ (∂J/∂q_k) Jᵀ w
        for r_ in range(3):
            row = 0.0
            for i in range(n):
                row += dJ[k, r_, i] * jw[i]
            g += w[r_] * row
        grad[k] = g / s
    return s


def floor_row(
    J_arm: FloatArray,
    dJ_arm: FloatArray,
    floor: float,
    v_prev: FloatArray,
    lb: FloatArray,
    ub: FloatArray,
    latency: float,
) -> FloorRow | None:
    """The σ_min floor's row this tick, or None (no floor, or σ_min ≥ INFLUENCE·σ_f).

    Args:
        J_arm: 3×n translational arm Jacobian [m/rad].
        dJ_arm: (n, 3, n) its derivatives, dJ_arm[k] = ∂J_arm/∂q_k.
        floor: σ_f [m/rad] (0: no floor).
        v_prev: [v_b; v_m] the bounds' centre, the last command (rad/s).
        lb, ub: the stage's bounds on v (eq. (13) and the wheel bounds).
        latency: τ [s], the state's age when the command acts.
    """
    if not floor > 0.0:
        return None
    sigma, grad = sigma_min_gradient(J_arm, dJ_arm)
    if sigma >= INFLUENCE * floor or not sigma >= SIGMA_EPS:
        return None
    n_w = lb.shape[0] - grad.shape[0]
    C = np.zeros(lb.shape[0])
    C[n_w:] = grad
    rate_prev = float(C @ v_prev)
    s_eff = sigma - latency * max(0.0, -rate_prev)  # where σ_min is by the time the command acts
    damper = -FLOOR_RATE * (s_eff - floor)
    best = float(np.sum(np.maximum(C * lb, C * ub)))  # the most σ-raising rate the bounds admit
    l = min(damper, best)
    v0 = np.clip(0.0, lb, ub)
    return FloorRow(C=C, l=l, l_brake=min(l, float(C @ v0)), sigma=sigma, floor=floor, damper=damper)


class SigmaMinFloor(RowSource):
    """The σ_min floor as a row source: its row in the DM modes, while σ_min is near σ_f.

    Priority: task, then the floor, then DM. In DM_NULLSPACE the task outranks the row (a stage
    whose task it cuts is solved again without it); in DM_CARTESIAN the task is the DM ascent
    itself (v_c of eq. (17)), which the row cuts. It steers the ascent, so a solver meets it to its
    tolerance (not re-checked), and in the stage solved again when rows exclude each other it is
    relaxed to admit the braking command and the dampers' joint command.

    Args:
        floor: σ_f [m/rad] (``dm.sigma_min_floor``; 0: no floor).
        latency: τ [s], the state's age when the command acts (``state_latency``).
    """

    name = "sigma_min floor"
    retry = Retry.ADMIT
    rechecked = False

    def __init__(self, floor: float, latency: float) -> None:
        self.floor, self.latency = floor, latency
        self.last: FloorRow | None = None  # the row of the last tick

    def compute_rows(self, tick: Tick) -> Rows | None:
        kin = tick.kin
        self.last = None
        if tick.mode not in (Mode.DM_CARTESIAN, Mode.DM_NULLSPACE) or kin.dJ_arm is None:
            return None
        row = self.last = floor_row(kin.J_arm, kin.dJ_arm, self.floor, tick.v_prev, tick.lb, tick.ub, self.latency)
        if row is None:
            return None
        return Rows(row.C[None, :], np.array([row.l]), l_brake=np.array([row.l_brake]), damper=np.array([row.damper]),
                    names=[self.name], distances=np.array([row.sigma - row.floor]))

    def yields_to_task(self, mode: Mode) -> bool:
        return mode == Mode.DM_NULLSPACE

    def cut_reason(self, rows: Rows, v: FloatArray) -> str:
        """The command on the row, to a solver's tolerance (1e-6 m/rad/s)."""
        row = self.last
        if row is None or not float(rows.C[0] @ v) - float(rows.l[0]) <= 1e-6:
            return ""
        return f"sigma_min floor: sigma_min {row.sigma:.3g} near {row.floor:.3g} (task cut)"
