"""The values that cross the controller's one entry point: state, reference, command."""

from __future__ import annotations

import enum
from dataclasses import dataclass, field

import numpy as np

from ._jit import all_finite
from ._typing import FloatArray


class Mode(enum.StrEnum):
    """What the controller does this tick.

    HOLD: keep the EE where it is (brake the robot, then hold x_d = x at the mode change).
    TRACK: follow x_d, ẋ_d (teleop stream or scripted trajectory), eq. (18) without v_n.
    DM_CARTESIAN: move the EE along the Cartesian DM gradient inside the box, eqs. (16)–(17).
    DM_NULLSPACE: follow x_d and raise DM in the null space, eqs. (18)–(19).
    """

    HOLD = "hold"
    TRACK = "track"
    DM_CARTESIAN = "dm_cartesian"
    DM_NULLSPACE = "dm_nullspace"


AT_REST: FloatArray = np.zeros(0)
"""``RobotState.wheel_speeds`` of a state built without wheel speeds: the wheels are at rest (the
controller reads it as zeros of the robot's wheel count). Only this object means that: a field
replaced by None, or by an empty array, after construction is malformed (a safe stop)."""
AT_REST.setflags(write=False)


def _vec(a: object, n: int | None, name: str) -> FloatArray:
    v = np.array(a, dtype=np.float64).reshape(-1)  # an own, writable, contiguous copy
    if n is not None and v.shape != (n,):
        raise ValueError(f"{name} must have {n} entries, got {v.shape[0]}")
    return v


def _is_vec(a: object, n: int) -> bool:
    return isinstance(a, np.ndarray) and a.dtype == np.float64 and a.shape == (n,)


def _is_vec3(a: object) -> bool:
    return _is_vec(a, 3)


@dataclass(slots=True)
class RobotState:
    """What the robot reports (the controller's input).

    The sizes are the robot's (its description's joints and wheels): a controller checks them
    (:meth:`has_shapes`) before it uses a state.

    Attributes:
        q_base: [m, m, rad] base pose (x_b, y_b, ψ) — odometry on a real robot.
        q_arm: [rad or m] joint values q_m, in the robot description's joint order.
        v_arm: [rad/s or m/s] joint rates now (bounds (13) start from them); None = at rest.
        wheel_speeds: [rad/s] wheel speeds now, in the base kind's wheel order; not given (None
            at construction) = at rest, stored as :data:`AT_REST`.
    """

    q_base: FloatArray
    q_arm: FloatArray
    v_arm: FloatArray = None  # type: ignore[assignment]  # None → zeros, in __post_init__
    wheel_speeds: FloatArray = None  # type: ignore[assignment]  # None → AT_REST, in __post_init__

    def __post_init__(self) -> None:
        self.q_base = _vec(self.q_base, 3, "q_base")
        self.q_arm = _vec(self.q_arm, None, "q_arm")
        self.v_arm = np.zeros(self.q_arm.shape[0]) if self.v_arm is None else _vec(self.v_arm, None, "v_arm")
        self.wheel_speeds = AT_REST if self.wheel_speeds is None else _vec(self.wheel_speeds, None, "wheel_speeds")

    def has_shapes(self, n_arm: int, n_wheels: int) -> bool:
        """Every field a float vector of its length (the fields may be replaced after construction)."""
        w = self.wheel_speeds
        return (
            _is_vec(self.q_base, 3)
            and _is_vec(self.q_arm, n_arm)
            and _is_vec(self.v_arm, n_arm)
            and (w is AT_REST or _is_vec(w, n_wheels))
        )

    def is_finite(self) -> bool:
        return (all_finite(self.q_base) and all_finite(self.q_arm) and all_finite(self.v_arm)
                and all_finite(self.wheel_speeds))


@dataclass(slots=True)
class Reference:
    """What the controller should do (the controller's other input).

    Attributes:
        mode: see :class:`Mode`.
        x_d: [m] desired EE position (world), used by TRACK, DM_NULLSPACE and HOLD; None = where
            the EE is now (so ``Reference("hold")`` holds still, never drives to the origin).
        xd_d: [m/s] its feed-forward velocity.
        direction: DM direction u in the base (yaw-compensated) frame; None = the config's.
        quat_d: desired EE orientation (world), a quaternion [x, y, z, w] (pose task only; the
            controller normalises it); None = no orientation target (the EE turns at ω_d only).
        omega_d: [rad/s] its feed-forward angular velocity (world, pose task only).
    """

    mode: Mode
    x_d: FloatArray | None = None
    xd_d: FloatArray = field(default_factory=lambda: np.zeros(3))
    direction: FloatArray | None = None
    quat_d: FloatArray | None = None
    omega_d: FloatArray = field(default_factory=lambda: np.zeros(3))

    def __post_init__(self) -> None:
        self.mode = Mode(self.mode)
        if self.x_d is not None:
            self.x_d = _vec(self.x_d, 3, "x_d")
        self.xd_d = _vec(self.xd_d, 3, "xd_d")
        if self.direction is not None:
            self.direction = _vec(self.direction, 3, "direction")
        if self.quat_d is not None:
            self.quat_d = _vec(self.quat_d, 4, "quat_d")
        self.omega_d = _vec(self.omega_d, 3, "omega_d")

    def has_shapes(self) -> bool:
        """The mode a :class:`Mode` and every array a float vector of its size (or None where
        allowed): the fields may be replaced after construction, and the kernels do not bounds-check."""
        return (
            isinstance(self.mode, Mode)
            and _is_vec3(self.xd_d)
            and (self.x_d is None or _is_vec3(self.x_d))
            and (self.direction is None or _is_vec3(self.direction))
            and (self.quat_d is None or _is_vec(self.quat_d, 4))
            and _is_vec3(self.omega_d)
        )

    def is_finite(self) -> bool:
        d, qd = self.direction, self.quat_d
        return (
            (self.x_d is None or all_finite(self.x_d))
            and all_finite(self.xd_d)
            and (d is None or (all_finite(d) and float(np.linalg.norm(d)) > 1e-9))
            and (qd is None or (all_finite(qd) and float(np.linalg.norm(qd)) > 1e-9))
            and all_finite(self.omega_d)
        )


class Status(enum.StrEnum):
    """Outcome of one controller step."""

    OK = "ok"  # the task is met within the bounds
    SATURATED = "saturated"  # the bounds cut the task: best effort (slack > 0)
    DAMPED = "damped"  # near a singularity: damped least squares
    SAFE_STOP = "safe_stop"  # something failed: braking at the acceleration limits


@dataclass(slots=True)
class Command:
    """The controller's output for one tick.

    Attributes:
        wheel_speeds: [rad/s] wheel speed command v_b (the base kind's wheel order).
        arm_rates: [rad/s or m/s] joint rate command v_m.
        status: see :class:`Status`.
        reason: why, when status is not OK ("" otherwise).
        alpha: the α actually used (paper controller) or configured (QP).
        task_error: [m/s] ‖J v − ẋ_ref‖ of this command (0 when the task is met; the pose task's
            angular rows enter scaled by ``task.orientation_weight``).
        x: [m] EE position the command was computed at (model, world frame).
        dm: directional manipulability H2 at this state along the active direction.
        sigma_min: σ_min(J_m) at this state.
    """

    wheel_speeds: FloatArray
    arm_rates: FloatArray
    status: Status = Status.OK
    reason: str = ""
    alpha: float = 0.0
    task_error: float = 0.0
    x: FloatArray = field(default_factory=lambda: np.full(3, np.nan))
    dm: float = float("nan")
    sigma_min: float = float("nan")

    @property
    def v(self) -> FloatArray:
        """[v_b; v_m] ∈ R^(n_wheels + n_arm)."""
        return np.concatenate([self.wheel_speeds, self.arm_rates])
