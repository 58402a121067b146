"""The referee of ``wmm-qp verify``: every hard bound re-derived from the raw robot config,
independently of :mod:`wmm_qp.limits` (which the controllers use), checked on one command.

It asks of a command only what is physically possible from the state:

* acceleration: |v − v_prev| ≤ A·dt;
* velocity: |v| ≤ V, or — if the joint is already faster than V — it slows down at A;
* position: the next position q + v·dt stays inside the limits (or, beyond a limit, does not
  go further out), unless even full braking at A cannot achieve it, in which case the
  command must be that full braking; and the robot must still be able to stop: holding the
  command for dt and then braking at A tick by tick must end inside the limits, or no further
  out than braking right now would;
* wheel: wheel speed and acceleration, the same way;
* ee_box (DM_CARTESIAN only, on the axes with a finite bound of eq. (17)'s EE box): the EE
  position predicted after one tick, p = x + Δt·J v (eqs. (2), (5), the model's kinematics), stays
  inside the box, or — if the EE is already outside — no further out than it is, or — if even
  full braking at A cannot keep it in — no further out than full braking takes it. The box comes
  from the controller's config (like the limits from the robot's), the rule is re-derived here;
* collision: :class:`~wmm_qp.verify.collision.CollisionJudge`.

Tolerance: 1e-9 (absolute, in rad/s; for ee_box in m/s, i.e. 1e-9·Δt on the position); for
collision 1e-5 m (the second-order term of one tick's motion the linear rows do not see).
"""

from __future__ import annotations

import numpy as np

from .._typing import FloatArray
from ..config import RobotConfig
from ..model.wmm import WmmModel
from ..types import AT_REST, Command, RobotState
from .collision import CollisionJudge

KINDS = ("position", "velocity", "acceleration", "wheel", "ee_box", "collision")
TOL = 1e-9


def check_command(
    robot: RobotConfig,
    dt: float,
    state: RobotState,
    cmd: Command,
    tol: float = TOL,
    *,
    model: WmmModel | None = None,
    ee_box: tuple[FloatArray, FloatArray] | None = None,
    collision: CollisionJudge | None = None,
) -> dict[str, int]:
    """Number of joints (or wheels, or EE axes) whose command violates each kind of hard bound.

    ``ee_box`` = (lower, upper) [m], given with ``model``, also checks the EE box of eq. (17) (pass
    it for a DM_CARTESIAN command only); otherwise the "ee_box" count is 0.
    """
    arm, base = robot.arm, robot.base
    v, v0, q = np.asarray(cmd.arm_rates), state.v_arm, state.q_arm
    a = arm.acceleration_max * dt
    out = dict.fromkeys(KINDS, 0)
    finite = np.isfinite(v)
    out["acceleration"] = int(np.sum(~finite | (np.abs(v - v0) > a + tol)))
    out["velocity"] = int(np.sum(~finite | (np.abs(v) > np.maximum(arm.velocity_max, np.abs(v0) - a) + tol)))
    with np.errstate(invalid="ignore"):
        up = np.maximum(arm.position_upper - q, 0.0) / dt  # never further out
        lo = np.minimum(arm.position_lower - q, 0.0) / dt
        too_high = v > np.maximum(up, v0 - a) + tol
        too_low = v < np.minimum(lo, v0 + a) - tol
        # braking distance: where the joint stops if it brakes at A after this command
        stop_cmd = _stop_position(q, v, a, dt)
        stop_now = _stop_position(q, v0 - np.clip(v0, -a, a), a, dt)
        overrun_hi = stop_cmd > np.maximum(arm.position_upper, stop_now) + tol * dt
        overrun_lo = stop_cmd < np.minimum(arm.position_lower, stop_now) - tol * dt
    out["position"] = int(np.sum(~finite | too_high | too_low | overrun_hi | overrun_lo))
    w = np.asarray(cmd.wheel_speeds)
    w0 = np.zeros(base.n_wheels) if state.wheel_speeds is AT_REST else state.wheel_speeds
    aw = base.wheel_acceleration_max * dt
    bad_w = (
        ~np.isfinite(w)
        | (np.abs(w - w0) > aw + tol)
        | (np.abs(w) > np.maximum(base.wheel_speed_max, np.abs(w0) - aw) + tol)
    )
    out["wheel"] = int(np.sum(bad_w))
    if model is not None and ee_box is not None:
        out["ee_box"] = check_ee_box(model, dt, state, cmd, ee_box[0], ee_box[1], tol)
    if collision is not None:
        out["collision"] = collision.check(dt, state, cmd)
    return out


def check_ee_box(
    model: WmmModel,
    dt: float,
    state: RobotState,
    cmd: Command,
    lower: FloatArray,
    upper: FloatArray,
    tol: float = TOL,
) -> int:
    """Number of EE axes on which the command leaves the box [lower, upper] of eq. (17) (see the
    module docstring): p = x + Δt·J v against the box widened to x and to full braking's p."""
    arm, base = model.config.arm, model.config.base
    lower, upper = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
    kin = model.kinematics(state.q_base, state.q_arm)  # eqs. (2), (5)
    a, aw = arm.acceleration_max * dt, base.wheel_acceleration_max * dt
    v0 = state.v_arm
    w0 = np.zeros(base.n_wheels) if state.wheel_speeds is AT_REST else state.wheel_speeds
    brake = np.concatenate([w0 - np.clip(w0, -aw, aw), v0 - np.clip(v0, -a, a)])  # full braking at A
    v = np.concatenate([np.asarray(cmd.wheel_speeds, dtype=float), np.asarray(cmd.arm_rates, dtype=float)])
    p, p_brake = kin.x + dt * (kin.J @ v), kin.x + dt * (kin.J @ brake)
    hi = np.maximum(np.maximum(upper, kin.x), p_brake)
    lo = np.minimum(np.minimum(lower, kin.x), p_brake)
    boxed = np.isfinite(lower) | np.isfinite(upper)
    with np.errstate(invalid="ignore"):
        bad = ~np.isfinite(p) | (p > hi + tol * dt) | (p < lo - tol * dt)
    return int(np.sum(boxed & bad))


def _stop_position(q: np.ndarray, v: np.ndarray, a_dt: np.ndarray, dt: float) -> np.ndarray:
    """Where a joint ends if it holds v for dt, then brakes by a_dt per tick (held dt each) to 0."""
    speed = np.abs(v)
    n = np.floor(speed / a_dt)
    braking = n * speed - a_dt * n * (n + 1.0) / 2.0  # Σ_{j=1..n} (|v| − j·a_dt)
    return q + np.sign(v) * dt * (speed + braking)


