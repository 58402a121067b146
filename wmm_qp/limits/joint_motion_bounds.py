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

That guarantee needs q̇_prev to be what the robot executes next — the previous *command*, while
the robot follows the command stream — not a measured rate. A measured rate lags the command
by the state's age (transport, the robot's own step, a drive that ramps towards the command):
it is the command of r ticks ago (r ≥ 2 over a transport). Where the braking bound is active,
the acceleration bound wins, so each command could then drop only A·dt below the command of r
ticks ago: the joint brakes at A/r, not A, and overshoots by far more than any latency margin
covers (``tests/core/test_limits.py`` drives a joint into its limit both ways). The latency margin
covers the lag of the *position*.
"""

from __future__ import annotations

import math

import numpy as np

from .._jit import jit
from .._typing import FloatArray


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


@jit
def _braking_speed(distance: float, a: float, dt: float) -> float:
    """:func:`braking_velocity` of one joint (the same formula, compiled)."""
    d_hat = min(max(distance, 0.0) / (a * dt * dt), _D_HAT_CAP)
    n = math.floor((math.sqrt(8.0 * d_hat + 1.0) - 1.0) / 2.0)
    return (d_hat + 0.5 * n * (n + 1.0)) / (n + 1.0) * (a * dt)


@jit
def _motion_bounds(
    q: FloatArray,
    v: FloatArray,
    q_min: FloatArray,
    q_max: FloatArray,
    v_max: FloatArray,
    a_max: FloatArray,
    dt: float,
    latency: float,
    lo: FloatArray,
    hi: FloatArray,
) -> None:
    """Eq. (13) joint by joint into lo, hi (see :class:`MotionBounds`)."""
    for i in range(q.shape[0]):
        step = a_max[i] * dt
        lo_a, hi_a = v[i] - step, v[i] + step  # acceleration
        lo_v = min(max(-v_max[i], lo_a), hi_a)  # velocity: the acceleration interval's point
        hi_v = min(max(v_max[i], lo_a), hi_a)  # nearest [−V, V] where they do not meet
        # distance to each limit once the latency has passed: the joint may travel up to
        # v·τ + ½Aτ² towards it meanwhile (its rate stays within A·τ of v)
        ahead, slack = v[i] * latency, 0.5 * a_max[i] * latency * latency
        up = _braking_speed(q_max[i] - q[i] - max(ahead + slack, 0.0), a_max[i], dt)
        down = _braking_speed(q[i] - q_min[i] - max(slack - ahead, 0.0), a_max[i], dt)
        lo[i] = min(max(-down, lo_v), hi_v)  # position and braking distance, lowest priority
        hi[i] = min(max(up, lo_v), hi_v)


class MotionBounds:
    """Q_min(q), Q_max(q) of eq. (13) for a fixed set of joints.

    Args:
        q_min, q_max: [rad] position limits (±inf: no position bound, e.g. a continuous joint
            or a wheel).
        v_max: [rad/s] velocity limits.
        a_max: [rad/s²] acceleration limits.
        dt: [s] control period.
        latency: [s] how old the state is when the command starts to act (transport, compute).
            The joint moves meanwhile (at a rate within A·latency of v_prev), so the braking
            distance to each limit is shortened by the most it can travel towards it,
            max(0, ±v_prev·latency + ½A·latency²). 0 for an in-process robot.

    A call is one compiled kernel (``_motion_bounds``) over the joints.
    """

    def __init__(
        self,
        q_min: FloatArray,
        q_max: FloatArray,
        v_max: FloatArray,
        a_max: FloatArray,
        dt: float,
        latency: float = 0.0,
    ) -> None:
        self.q_min, self.q_max, self.v_max, self.a_max = (
            np.array(a, dtype=np.float64) for a in (q_min, q_max, v_max, a_max)
        )
        self.n = self.a_max.shape[0]
        if any(a.shape != (self.n,) for a in (self.q_min, self.q_max, self.v_max)):
            raise ValueError("q_min, q_max, v_max and a_max must be vectors of one length")
        self.dt, self.latency = float(dt), float(latency)

    def __call__(self, q: FloatArray, v_prev: FloatArray) -> tuple[FloatArray, FloatArray]:
        """(lo, hi) of eq. (13); lo ≤ hi, finite.

        Args:
            q: [rad] positions (the state's: up to ``latency`` old).
            v_prev: [rad/s] the rates the robot executes next: the last command while the robot
                follows the command stream (not a measured rate that lags it; see the module
                docstring), the measured rate otherwise (a first command, a robot braking by
                itself).
        """
        q, v_prev = np.asarray(q, dtype=np.float64), np.asarray(v_prev, dtype=np.float64)
        if q.shape != (self.n,) or v_prev.shape != (self.n,):  # the kernel does not bounds-check
            raise ValueError(f"q and v_prev must have {self.n} entries, got {q.shape} and {v_prev.shape}")
        lo, hi = np.empty(self.n), np.empty(self.n)
        _motion_bounds(q, v_prev, self.q_min, self.q_max, self.v_max, self.a_max, self.dt, self.latency, lo, hi)
        return lo, hi


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
    """Q_min(q), Q_max(q) of eq. (13), in one call (a controller keeps a :class:`MotionBounds`).

    Args: as :class:`MotionBounds` and its call.

    Returns:
        (lo, hi), lo ≤ hi element-wise, both finite.
    """
    return MotionBounds(q_min, q_max, v_max, a_max, dt, latency)(q, v_prev)
