"""Joint motion bounds Q_min(q) ≤ q̇_m ≤ Q_max(q), eq. (13).

The saturation-in-null-space bounds of Flacco et al., per joint, for a command held for
one control period dt:

* acceleration: q̇_prev − A·dt ≤ q̇ ≤ q̇_prev + A·dt;
* velocity:     |q̇| ≤ V;
* position and braking distance: a command that the robot can still brake from, at A,
  without passing the limit. In continuous time that is q̇ ≤ sqrt(2 A (q_max − q)); we
  use its exact discrete-time form (the robot holds each command for dt), which also
  implies the one-step position bound q̇ ≤ (q_max − q)/dt. At or beyond a limit the bound
  is 0: never further out. Continuous joints have no position bound.

Priority acceleration > velocity > position: where two bounds conflict, the result is the
point of the higher-priority interval nearest to the lower-priority one. So the set is never
empty and always contains the braking command q̇_prev − clip(q̇_prev, −A·dt, A·dt): the robot
can always brake. From a state that satisfied these bounds one tick earlier, braking never
overshoots a position limit.
"""

from __future__ import annotations

import numpy as np

from ..config import FloatArray
from .interval import intersect_by_priority


def braking_velocity(distance: FloatArray, a_max: FloatArray, dt: float) -> FloatArray:
    """Largest speed v ≥ 0 that can be held for dt and then braked at a_max within ``distance``.

    Exact for a command sequence v, v − a·dt, v − 2a·dt, … each held for dt: the distance
    covered is dt·Σ_j max(v − j·a·dt, 0). With d̂ = d/(a dt²), n = ⌊(√(8 d̂ + 1) − 1)/2⌋ and
    v̂ = (d̂ + n(n+1)/2)/(n+1), v = v̂·a·dt. Tends to sqrt(2 a d) as dt → 0.

    Args:
        distance: [rad] distance to the limit (negative is treated as 0).
        a_max: [rad/s²] braking acceleration.
        dt: [s] control period.
    """
    # An infinite distance (continuous joint) is capped at a finite d̂ whose speed exceeds any
    # velocity limit by far (~1e6·a·dt): the same bound after intersection, and no inf − inf,
    # so no np.errstate (a context manager costs microseconds per call) and no mask.
    d_hat = np.minimum(np.maximum(distance, 0.0) / (a_max * dt * dt), _D_HAT_CAP)
    n = np.floor((np.sqrt(8.0 * d_hat + 1.0) - 1.0) / 2.0)
    return (d_hat + 0.5 * n * (n + 1.0)) / (n + 1.0) * (a_max * dt)


_D_HAT_CAP = 1e12


def braking_command(v_prev: FloatArray, a_max: FloatArray, dt: float) -> FloatArray:
    """The command one tick of maximal braking yields: q̇_prev moved towards 0 by at most A·dt."""
    step = a_max * dt
    return v_prev - np.clip(v_prev, -step, step)


def joint_motion_bounds(
    q: FloatArray,
    v_prev: FloatArray,
    q_min: FloatArray,
    q_max: FloatArray,
    v_max: FloatArray,
    a_max: FloatArray,
    dt: float,
    latency: float = 0.0,
) -> tuple[FloatArray, FloatArray]:
    """Q_min(q), Q_max(q) of eq. (13).

    Args:
        q: [rad] joint positions.
        v_prev: [rad/s] current joint rates (the measured rate, or the last command).
        q_min, q_max: [rad] position limits (±inf for continuous joints).
        v_max: [rad/s] velocity limits.
        a_max: [rad/s²] acceleration limits.
        dt: [s] control period.
        latency: [s] how old the state is when the command starts to act (transport, compute).
            The joint moves meanwhile (at a rate within A·latency of v_prev), so the braking
            distance to each limit is shortened by the most it can travel towards it,
            max(0, ±v_prev·latency + ½A·latency²). 0 for an in-process robot.

    Returns:
        (lo, hi), lo ≤ hi element-wise, both finite.
    """
    step = a_max * dt
    lo, hi = v_prev - step, v_prev + step  # acceleration
    lo, hi = intersect_by_priority(lo, hi, -v_max, v_max)  # velocity
    n = q.shape[0]
    # Travel towards each limit before the command acts: the rate was within A·τ of v_prev over
    # those τ seconds (it may have been braking), so at most v_prev·τ + ½A·τ² towards q_max.
    ahead, slack = v_prev * latency, 0.5 * a_max * latency * latency
    distance = np.concatenate([q_max - q - np.maximum(ahead + slack, 0.0), q - q_min - np.maximum(slack - ahead, 0.0)])
    brake = braking_velocity(distance, np.concatenate([a_max, a_max]), dt)
    return intersect_by_priority(lo, hi, -brake[n:], brake[:n])  # eq. (13), position + braking distance
