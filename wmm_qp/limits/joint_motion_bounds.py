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


class MotionBounds:
    """Q_min(q), Q_max(q) of eq. (13) for a fixed set of joints: constants computed once.

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

    Calling it costs ~30 small vector operations: the upper limits and the mirrored lower
    limits (−q_min against −q) go through the braking formula together as one 2n-vector.
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
        a_max = np.asarray(a_max, dtype=float)
        n = a_max.shape[0]
        self.n = n
        self._step = a_max * dt
        self._v_max = np.asarray(v_max, dtype=float)
        self._neg_v_max = -self._v_max
        self._limit = np.concatenate([q_max, np.negative(q_min)])  # upper; lower mirrored
        sign = np.concatenate([np.ones(n), -np.ones(n)])
        self._scale = np.concatenate([sign, latency * sign])  # [q; q; v; v] → [q; −q; vτ; −vτ]
        self._slack = np.concatenate([0.5 * a_max * latency * latency] * 2)  # ½Aτ²
        a2 = np.concatenate([a_max, a_max])
        self._c8 = 8.0 / (a2 * dt * dt)  # distance → 8 d̂ (see braking_velocity)
        self._adt8 = a2 * dt / 8.0

    def __call__(self, q: FloatArray, v_prev: FloatArray) -> tuple[FloatArray, FloatArray]:
        """(lo, hi) for positions q [rad] and current rates v_prev [rad/s]; lo ≤ hi, finite."""
        n = self.n
        lo, hi = v_prev - self._step, v_prev + self._step  # acceleration
        lo_v = np.minimum(np.maximum(self._neg_v_max, lo), hi)  # velocity, by priority
        hi_v = np.minimum(np.maximum(self._v_max, lo), hi)
        x = np.concatenate((q, q, v_prev, v_prev))
        x *= self._scale  # [q; −q; v·τ; −v·τ]
        # distance to each limit once the latency has passed (upper, then mirrored lower)
        d = self._limit - x[: 2 * n]
        d -= np.maximum(x[2 * n :] + self._slack, 0.0)
        # braking_velocity's exact discrete-time bound with e = 8 d̂ and m = n + 1:
        # v = a·dt·(d̂/m + (m − 1)/2) = (a·dt/8)·(e/m + 4m − 4), m = ⌊(√(e + 1) + 1)/2⌋
        e = np.minimum(np.maximum(d, 0.0) * self._c8, 8.0 * _D_HAT_CAP)
        m = np.floor(np.sqrt(e + 1.0) * 0.5 + 0.5)
        brake = (e / m + 4.0 * m - 4.0) * self._adt8
        lo_f = np.minimum(np.maximum(np.negative(brake[n:]), lo_v), hi_v)  # eq. (13)
        hi_f = np.minimum(np.maximum(brake[:n], lo_v), hi_v)
        return lo_f, hi_f


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
