"""The controllers' common entry point ``step(state, reference) → command``.

:meth:`Controller.step` never raises: malformed input, a numerical failure or an exception
anywhere in a controller becomes a safe stop (maximal braking, inside the acceleration
bounds) with the reason in ``Command.reason``.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .._jit import all_finite, jit
from .._typing import FloatArray
from ..config import ControllerConfig, RobotConfig, ShapeConfig
from ..limits import MotionBounds, braking_command, wheel_braking_command
from ..limits.rows import Rows
from ..manipulability import directional_manipulability, dm_cartesian_gradient, dm_gradient
from ..model.wmm import Kinematics, WmmModel
from ..pseudoinverse import damping_factor, sigma_min
from ..scene import Scene
from ..tasks import orientation_error, quat_to_matrix
from ..types import AT_REST, Command, Mode, Reference, RobotState, Status


@dataclass(slots=True)
class TickContext:
    """What every controller computes first in a tick (kinematics, DM, bounds)."""

    kin: Kinematics
    u: FloatArray  # DM direction, base frame, unit
    dm: float
    grad_q: FloatArray | None  # ∇_{q_m} H2, eq. (9), when the mode needs it
    sigma: float
    damping: float
    lo: FloatArray  # bounds on v = [v_b; v_m]: wheel bounds, then eq. (13)
    hi: FloatArray
    n_wheels: int
    v_prev: FloatArray  # [v_b; v_m] the bounds' centre: the rates the robot executes next

    @property
    def wheel_lo(self) -> FloatArray:
        return self.lo[: self.n_wheels]

    @property
    def wheel_hi(self) -> FloatArray:
        return self.hi[: self.n_wheels]

    @property
    def arm_lo(self) -> FloatArray:
        return self.lo[self.n_wheels :]

    @property
    def arm_hi(self) -> FloatArray:
        return self.hi[self.n_wheels :]


@jit
def _task_error(J: FloatArray, v: FloatArray, xdot_ref: FloatArray) -> float:
    """‖J v − ẋ_ref‖ [m/s]."""
    s = 0.0
    for a in range(J.shape[0]):
        e = -xdot_ref[a]
        for i in range(J.shape[1]):
            e += J[a, i] * v[i]
        s += e * e
    return math.sqrt(s)


def _usable_rates(a: object, n: int) -> FloatArray | None:
    """``a`` as a float vector of n entries, non-finite entries as 0; None unless ``a`` is a
    real-valued numpy array of shape (n,)."""
    if not isinstance(a, np.ndarray) or a.shape != (n,) or a.dtype.kind not in "fiu":
        return None
    return np.nan_to_num(a.astype(np.float64), nan=0.0, posinf=0.0, neginf=0.0)


def _describe(a: object) -> str:
    """A short description of a malformed field for a reason string."""
    if isinstance(a, np.ndarray):
        return f"{a.dtype} array of shape {a.shape}"
    return type(a).__name__


class Controller(ABC):
    """A kinematic controller of the WMM (any arm, any base kind, position or pose task).

    Args:
        model: the robot's kinematic model.
        config: gains and settings; ``config.dt`` is the control period.

    Raises:
        ConfigError: the config's per-joint values (``dm.W``) do not fit this robot.
    """

    name = "controller"

    def __init__(self, model: WmmModel, config: ControllerConfig) -> None:
        self.model = model
        self.robot: RobotConfig = model.config
        self.config = config
        self.dt = config.dt
        arm, base = self.robot.arm, self.robot.base
        # the robot's own sizes (from its description; the safe stop must not trust the state's)
        self.n_wheels = int(model.base.M.shape[1])
        self.n_arm = int(arm.acceleration_max.shape[0])
        self.n_v = self.n_wheels + self.n_arm
        free = np.full(self.n_wheels, np.inf)  # wheels: speed and acceleration bounds only
        self.bounds = MotionBounds(
            np.concatenate([-free, arm.position_lower]),
            np.concatenate([free, arm.position_upper]),
            np.concatenate([base.wheel_speed_max, arm.velocity_max]),
            np.concatenate([base.wheel_acceleration_max, arm.acceleration_max]),
            config.dt,
            config.state_latency,
        )  # eq. (13) for the arm; for the wheels (no position limit) it reduces to the wheel bounds
        self._no_wheel_q = np.zeros(self.n_wheels)
        self._rest_wheels = np.zeros(self.n_wheels)
        self.W = config.weights_for(self.robot)  # eq. (8)
        self.pose = config.task.kind == "pose"
        self.r = config.task.r
        self._w_R = config.task.orientation_weight  # the pose task's angular rows are scaled by it
        boxed = np.isfinite(config.ee_box_lower) | np.isfinite(config.ee_box_upper)
        self._boxed_axes = np.flatnonzero(boxed).astype(np.int64)  # the EE box's axes, eq. (17)
        self._u = config.direction / math.sqrt(float(config.direction @ config.direction))  # unit DM direction

    def reset(self) -> None:  # noqa: B027 (optional hook, no-op by default)
        """Forget any state carried between ticks (warm starts, mode latches)."""

    # ------------------------------------------------------------------ entry point
    def step(self, state: RobotState, reference: Reference) -> Command:
        """One control tick. Never raises: failures become a safe stop with a reason."""
        try:
            if not state.has_shapes(self.n_arm, self.n_wheels):  # RobotState is mutable: fields may be replaced
                return self.safe_stop(state, "state arrays have the wrong shapes")
            if not reference.has_shapes():  # so is Reference (the kernels do not bounds-check)
                return self.safe_stop(state, "reference arrays have the wrong shapes or the mode is unknown")
            if not state.is_finite():
                return self.safe_stop(state, "state holds NaN or inf")
            if not reference.is_finite():
                return self.safe_stop(state, "reference holds NaN, inf or a zero direction")
            cmd = self._step(state, reference)
            if not (all_finite(cmd.wheel_speeds) and all_finite(cmd.arm_rates)):
                return self.safe_stop(state, f"{self.name}: non-finite command")
            return cmd
        except Exception as e:  # the control loop must never raise (docs/model.md "The QP")
            return self.safe_stop(state, f"{self.name}: {type(e).__name__}: {e}")

    def warm_up(self, q_arm: FloatArray | None = None) -> None:
        """One tick of every mode, without a target and with one (the EE where it is), then
        :meth:`reset`: compiles, or loads from numba's cache, every kernel of the hot path
        (~0.1–0.5 s once per process, seconds on a machine's first run). Call it before a
        real-time loop starts, so the first real tick does not pay it
        (``test_after_its_warm_up_no_tick_compiles_a_kernel``).

        Args:
            q_arm: [rad] arm configuration to tick at (default: mid-range of every joint).
        """
        state = RobotState(q_base=np.zeros(3), q_arm=self.warm_up_configuration(q_arm))
        x = self.model.ee_position(state.q_base, state.q_arm)
        # every mode, and each with a target where it takes one (a target's kernels are others: the
        # first setpoint of a daemon had compiled the position task's reference velocity, ~0.25 s)
        refs = [Reference(mode) for mode in Mode] + [Reference(mode, x_d=x) for mode in Mode]
        for ref in refs:
            cmd = self.step(state, ref)
            if cmd.status == Status.SAFE_STOP:  # at rest, mid-range: only a broken kernel stops here
                raise RuntimeError(f"{self.name} controller failed its warm-up tick in {ref.mode}: {cmd.reason}")
        self.reset()
        self.clear_statistics()

    def warm_up_configuration(self, q_arm: FloatArray | None = None) -> FloatArray:
        """[rad] where :meth:`warm_up` ticks: q_arm, or mid-range of every joint, off the straight
        (singular) pose."""
        if q_arm is not None:
            return np.asarray(q_arm, dtype=float)
        arm = self.robot.arm
        lo = np.where(np.isfinite(arm.position_lower), arm.position_lower, -1.0)
        hi = np.where(np.isfinite(arm.position_upper), arm.position_upper, 1.0)
        return np.asarray(0.5 * (lo + hi) + 0.3, dtype=float)

    def clear_statistics(self) -> None:  # noqa: B027 (optional hook, no-op by default)
        """Zero the controller's diagnostic counters (after :meth:`warm_up`)."""

    # ------------------------------------------------------------------ declared capabilities
    # What a host (the daemon, the experiments) may ask of any controller. The baselines have no
    # collision rows: the defaults are no-ops, so a host never probes a controller's attributes.
    def set_scene(self, scene: Scene) -> None:  # noqa: B027 (optional hook, no-op by default)
        """The obstacles and the fence the collision rows keep the robot away from / inside."""

    def set_obstacles(self, obstacles: Sequence[ShapeConfig]) -> None:  # noqa: B027 (no-op by default)
        """Replace the obstacle set (live obstacles; the scene's fence stays)."""

    def set_latency(self, latency: float) -> None:
        """[s] the margin of bounds (13) (and of any rows that share it): the state's age when the
        command acts, plus the robot's own command timeout."""
        self.bounds.latency = latency

    @property
    def collision_on(self) -> bool:
        """The controller has collision rows (the status's and the info's ``collision``)."""
        return False

    def collision_summary(self) -> str:
        """One line: whether the controller has collision rows, and what they keep apart."""
        return "no collision rows"

    def last_collision_rows(self) -> Rows | None:
        """The collision rows of the last tick (None: none, or no collision checking)."""
        return None

    @abstractmethod
    def _step(self, state: RobotState, reference: Reference) -> Command:
        """The controller's own computation (may raise; :meth:`step` catches)."""

    # ------------------------------------------------------------------ helpers
    def safe_stop(self, state: object, reason: str) -> Command:
        """Maximal braking inside the acceleration bounds, from the state's rates. Never raises.

        The command always has the robot's own sizes (``n_wheels`` wheels, ``n_arm`` joints, taken
        from the model and the robot config), whatever the state holds. Each rate vector is braked
        from only if it can be trusted: a ``v_arm`` or ``wheel_speeds`` that is not a numeric
        numpy vector of the robot's length (wrong length, 2-D, a scalar, empty, None, an object
        array: the state is malformed) is treated as unknown, and its part of the command is the
        braking step from zero, i.e. zero — the stop command, as the robot's own stale-command
        stop would apply; the reason says so. Non-finite entries of an otherwise usable vector (a
        NaN state) are taken as 0 as well. A state built without wheel speeds (:data:`AT_REST`)
        brakes its wheels from rest.
        """
        try:
            w_raw = getattr(state, "wheel_speeds", None)
            if w_raw is AT_REST:
                w_raw = self._rest_wheels
            w = _usable_rates(w_raw, self.n_wheels)
            v_arm = _usable_rates(getattr(state, "v_arm", None), self.n_arm)
            for name, rates in (("wheel_speeds", w), ("v_arm", v_arm)):
                if rates is None:
                    reason += f"; {name} unusable ({_describe(getattr(state, name, None))}): rates unknown, commanded 0"
            a_max, dt = self.robot.arm.acceleration_max, self.dt
            return Command(
                wheel_speeds=np.zeros(self.n_wheels) if w is None else wheel_braking_command(w, self.robot.base, dt),
                arm_rates=np.zeros(self.n_arm) if v_arm is None else braking_command(v_arm, a_max, dt),
                status=Status.SAFE_STOP,
                reason=reason,
            )
        except Exception as e:  # the last resort: the stop command itself
            return Command(
                wheel_speeds=np.zeros(self.n_wheels),
                arm_rates=np.zeros(self.n_arm),
                status=Status.SAFE_STOP,
                reason=f"{reason}; braking failed ({type(e).__name__}): commanded 0",
            )

    def context(self, state: RobotState, reference: Reference, need_gradient: bool) -> TickContext:
        """Kinematics, DM (and its gradient when needed), σ_min, damping and bounds (13).

        With the pose task the angular rows of ``kin.J`` (and so of ``kin.J_m``) are scaled by
        ``task.orientation_weight`` here, once: every consumer (the QP's task rows, the closed form,
        the pseudoinverses, ``task_error``) then sees the weighted task, and :meth:`task_velocity`
        scales the angular reference alike. σ_min, which switches the singularity damping, is the
        translational rows' for both task kinds (the threshold is the paper's, in m/s per rad/s).
        """
        kin = self.model.kinematics(state.q_base, state.q_arm, hessian=need_gradient, pose=self.pose)
        if self.pose:
            kin.J[3:] *= self._w_R
        d = reference.direction
        u = self._u if d is None else d / math.sqrt(float(d @ d))
        W = self.W
        if need_gradient:
            assert kin.dJ_arm is not None
            dm, grad_q = dm_gradient(kin.J_arm, kin.dJ_arm, u, W)  # eqs. (8), (9)
        else:
            dm, grad_q = directional_manipulability(kin.J_arm, u, W), None  # eq. (8)
        sig = sigma_min(kin.J_m[:3] if self.pose else kin.J_m)  # the arm's translational σ_min: the DLS law's
        wheels = self._rest_wheels if state.wheel_speeds is AT_REST else state.wheel_speeds
        v_prev = np.concatenate((wheels, state.v_arm))
        lo, hi = self.bounds(np.concatenate((self._no_wheel_q, state.q_arm)), v_prev)  # eq. (13), the wheel bounds
        return TickContext(
            kin=kin,
            u=u,
            dm=dm,
            grad_q=grad_q,
            sigma=sig,
            damping=damping_factor(sig, self.config.sigma_threshold, self.config.damping_max),
            lo=lo,
            hi=hi,
            n_wheels=self.n_wheels,
            v_prev=v_prev,
        )

    def task_velocity(self, ctx: TickContext, reference: Reference) -> FloatArray:
        """ẋ_ref of the mode: ẋ_d + K_x (x_d − x) (eq. (18)) or v_c (eq. (17)); with the pose
        task followed by the weighted angular part (:meth:`angular_velocity`)."""
        lin = self.linear_velocity(ctx, reference)
        if not self.pose:
            return lin
        return np.concatenate((lin, self._w_R * self.angular_velocity(ctx, reference)))

    def linear_velocity(self, ctx: TickContext, reference: Reference) -> FloatArray:
        """The position part of ẋ_ref: ẋ_d + K_x (x_d − x) (eq. (18)) or v_c (eq. (17))."""
        if reference.mode == Mode.DM_CARTESIAN:
            assert ctx.grad_q is not None
            return self.cartesian_dm_velocity(ctx)
        if reference.x_d is None:  # hold where the EE is
            return reference.xd_d.copy()
        return reference.xd_d + self.config.K_x * (reference.x_d - ctx.kin.x)  # eq. (18)

    def angular_velocity(self, ctx: TickContext, reference: Reference) -> FloatArray:
        """The pose task's angular part [rad/s], unweighted: ω_d + K_R log(R_d Rᵀ) (docs/model.md "Any robot"),
        ω_d alone without an orientation target."""
        if reference.quat_d is None or ctx.kin.R_ee is None:
            return reference.omega_d.copy()
        e_R = orientation_error(quat_to_matrix(reference.quat_d), ctx.kin.R_ee)
        return reference.omega_d + self.config.task.K_R * e_R

    def cartesian_dm_velocity(self, ctx: TickContext) -> FloatArray:
        """v_c of eq. (17): k_C ∇_x H2 on the axes whose box is active and holds x, else 0."""
        assert ctx.grad_q is not None
        J_m = ctx.kin.J_m[:3] if self.pose else ctx.kin.J_m  # eq. (10) uses the translational rows
        grad_x = dm_cartesian_gradient(ctx.grad_q, J_m, ctx.sigma)  # eq. (10)
        lo, hi, x = self.config.ee_box_lower, self.config.ee_box_upper, ctx.kin.x
        v_c = np.zeros(3)
        for i in self._boxed_axes.tolist():  # eq. (17)
            if lo[i] <= x[i] <= hi[i]:
                v_c[i] = self.config.k_C * grad_x[i]
        return v_c

    @staticmethod
    def needs_gradient(mode: Mode) -> bool:
        return mode in (Mode.DM_CARTESIAN, Mode.DM_NULLSPACE)

    def finish(
        self,
        ctx: TickContext,
        v: FloatArray,
        xdot_ref: FloatArray,
        status: Status = Status.OK,
        reason: str = "",
        alpha: float = 0.0,
    ) -> Command:
        """Wrap v = [v_b; v_m] into a Command with diagnostics."""
        if status == Status.OK and ctx.damping > 0.0:
            status, reason = Status.DAMPED, reason or f"sigma_min {ctx.sigma:.3g} below threshold"
        v = np.array(v, dtype=np.float64)  # the command owns its numbers
        return Command(
            wheel_speeds=v[: self.n_wheels],
            arm_rates=v[self.n_wheels :],
            status=status,
            reason=reason,
            alpha=alpha,
            task_error=_task_error(ctx.kin.J, v, xdot_ref),
            x=ctx.kin.x,  # computed for this tick only
            dm=ctx.dm,
            sigma_min=ctx.sigma,
        )
