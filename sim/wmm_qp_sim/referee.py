"""The sim's own limit referee: counts every limit violation, independently of the controller.

It deliberately does not use :mod:`wmm_qp.limits`: the limits come straight from the robot
config and the checks are written out here. A value is legal when
``|v| <= limit·(1 + rtol) + atol`` (``configs/sim.toml`` [referee], default 1e-9 and 1e-9).

Kinds and what one count means:

- ``position``: a (sim step, joint) pair whose angle is outside [lower − tol, upper + tol]
  after integration; continuous joints (±inf limits) are never counted.
- ``velocity``: a (new executed rate, joint) pair with |q̇| above velocity_max.
- ``acceleration``: a (rate change, joint) pair with |q̇_new − q̇_old| / Δt above
  acceleration_max, where Δt is the time the new rate was held, i.e. the time between this
  command and the next one (the period over which the controller's bound
  q̇_prev ± A·Δt allows the change). It is judged when the next command (or stale-stop braking
  step) arrives, so the count lags one command.
- ``wheel_speed`` / ``wheel_acceleration``: the same for the four wheels.
"""

from __future__ import annotations

import numpy as np

from wmm_qp.config import FloatArray, RobotConfig

from .config import RefereeConfig

VIOLATION_KINDS = ("position", "velocity", "acceleration", "wheel_speed", "wheel_acceleration")


class Referee:
    """Counts limit violations by kind.

    Args:
        robot: the robot config (its limits are the referee's rules).
        config: tolerances.
    """

    def __init__(self, robot: RobotConfig, config: RefereeConfig) -> None:
        a, b = robot.arm, robot.base
        self.q_lo = np.array(a.position_lower, dtype=float)
        self.q_hi = np.array(a.position_upper, dtype=float)
        self.v_max = np.array(a.velocity_max, dtype=float)
        self.a_max = np.array(a.acceleration_max, dtype=float)
        self.w_max = float(b.wheel_speed_max)
        self.wa_max = float(b.wheel_acceleration_max)
        self.rtol, self.atol = config.rtol, config.atol
        self.counts: dict[str, int] = dict.fromkeys(VIOLATION_KINDS, 0)
        self._pending: tuple[FloatArray, FloatArray, float] | None = None

    def reset(self) -> None:
        """Zero every count and forget the pending rate change."""
        self.counts = dict.fromkeys(VIOLATION_KINDS, 0)
        self._pending = None

    def _exceeds(self, value: FloatArray, limit: FloatArray | float) -> int:
        return int(
            np.count_nonzero(np.abs(value) > np.asarray(limit) * (1.0 + self.rtol) + self.atol)
        )

    def check_positions(self, q_arm: FloatArray) -> None:
        """Count joints outside their position limits (continuous joints have none)."""
        tol_lo = np.abs(self.q_lo) * self.rtol + self.atol
        tol_hi = np.abs(self.q_hi) * self.rtol + self.atol
        with np.errstate(invalid="ignore"):
            bad = (q_arm < self.q_lo - tol_lo) | (q_arm > self.q_hi + tol_hi)
        self.counts["position"] += int(np.count_nonzero(bad))

    def on_new_rates(
        self, t: float, v_old: FloatArray, w_old: FloatArray, v_new: FloatArray, w_new: FloatArray
    ) -> None:
        """A new executed rate starts at time t [s] (a command, or a braking step).

        Judges the previous change over the time its rate was held, checks the new rates'
        magnitudes, and keeps this change pending until the next one.
        """
        self._judge_pending(t)
        self.counts["velocity"] += self._exceeds(v_new, self.v_max)
        self.counts["wheel_speed"] += self._exceeds(w_new, self.w_max)
        self._pending = (v_new - v_old, w_new - w_old, t)

    def _judge_pending(self, t: float) -> None:
        if self._pending is None:
            return
        dv, dw, t0 = self._pending
        held = t - t0
        self.counts["acceleration"] += self._exceeds(dv, self.a_max * held)
        self.counts["wheel_acceleration"] += self._exceeds(dw, self.wa_max * held)
        self._pending = None
