"""The simulated wheeled mobile manipulator: a kinematic robot stepped by commanded rates.

:meth:`SimRobot.step` executes the commanded wheel speeds and joint rates as they are (a
kinematic robot: the referee, not the sim, judges whether they were legal), integrates the
arm, the odometry (the base kind's nominal model, eq. (3)) and the true base (with slip and drift, see
:mod:`.slip`), pushes the box if there is one (:mod:`.contact`), and counts every limit
violation (:mod:`.referee`). It never raises from ``step``: a malformed command is ignored
(counted in ``SimState.rejected_commands``) and the held command goes on.

Stale commands: when no new command has arrived for ``config.stale_timeout`` seconds, the
sim brakes every joint and wheel to rest by itself at its acceleration limit
(``SimState.stale_stop`` is True until the next command it accepts).

A stop ends the stream it stopped: after a stale or protective stop the firmware refuses every
further command of that stream (``SimCommand.stream``; counted in ``refused_commands``) and
resumes only on a new stream. A command of the old stream that reaches the robot late (it sat
in a frozen sender's transmit queue, or in a congested link) would otherwise restart the robot
at rates its sender computed before the stop, while the sender, having seen the stop, starts a
new stream from the robot at rest: the two would meet as a jump.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

import wmm_qp
from wmm_qp.config import FloatArray

from .collision import CollisionReferee
from .config import BoxConfig, SimConfig
from .contact import Box
from .gripper import Gripper
from .referee import Referee
from .slip import SlipModel, integrate_pose


@dataclass(slots=True)
class SimCommand:
    """A command to the robot, held until the next one.

    Attributes:
        wheel_speeds: [rad/s] wheel speeds (the base kind's wheel order).
        arm_rates: [rad/s or m/s] joint rates (the robot description's joint order).
        period: [s] the command's own period (the Δt of its sender's bounds (13)); the referee
            judges the change from the previous command over it. None: over the time since the
            previous command.
        seq: the sender's sequence number (a gap widens the referee's window), or None.
        received: [s] monotonic time the command was received (caps the referee's window at
            the time that really passed), or None.
        stream: the sender's stream id (a new one is judged against the executed rates), or
            None (then a stale or protective stop starts a new stream).
        sent: [s] the sender's stamp (its own clock), or None.
    """

    wheel_speeds: FloatArray
    arm_rates: FloatArray
    period: float | None = None
    seq: int | None = None
    received: float | None = None
    stream: int | None = None
    sent: float | None = None

    def __post_init__(self) -> None:
        self.wheel_speeds = np.asarray(self.wheel_speeds, dtype=float).reshape(-1)
        self.arm_rates = np.asarray(self.arm_rates, dtype=float).reshape(-1)

    def is_valid(self, n_wheels: int, n_arm: int) -> bool:
        """The robot's sizes and finite values."""
        return bool(
            self.wheel_speeds.shape == (n_wheels,)
            and self.arm_rates.shape == (n_arm,)
            and np.isfinite(self.wheel_speeds).all()
            and np.isfinite(self.arm_rates).all()
        )


@dataclass(slots=True)
class SimState:
    """Everything the sim reports (ground truth included).

    Attributes:
        t: [s] sim time since reset.
        q_arm: [rad] joint angles.
        v_arm: [rad/s] executed joint rates.
        wheel_speeds: [rad/s] executed wheel speeds.
        base_odom: [m, m, rad] base pose integrated from the wheel speeds with the nominal model.
        base_true: [m, m, rad] true base pose (with slip and drift).
        ee_true: [m] true EE position (world), the "motion capture".
        tau: [N·m] joint torques J_mᵀ F from the box contact (zeros without contact).
        contact_force: [N] force the EE applies to the box (world).
        box_position: [m] world x of the box face, nan without a box.
        box_displacement: [m] how far the box has been pushed, nan without a box.
        stalled_joint: the joint (0-based) that stalled the push this step, or None.
        violations: counts by kind (see :mod:`.referee`).
        stale_stop: the sim is braking because commands went stale.
        rejected_commands: malformed commands ignored since reset.
        commands: valid commands received since reset.
        protective_stop: the firmware is braking the robot (or holds it at rest) after a
            command it refused.
        protective_stops: protective stops since reset.
        protective_reason: why the last protective stop started ("" = none yet).
        refused_commands: commands the firmware refused since reset.
        gripper_width: [m] the gripper's opening (nan: the robot file declares no gripper).
    """

    t: float
    q_arm: FloatArray
    v_arm: FloatArray
    wheel_speeds: FloatArray
    base_odom: FloatArray
    base_true: FloatArray
    ee_true: FloatArray
    tau: FloatArray
    contact_force: FloatArray
    box_position: float
    box_displacement: float
    stalled_joint: int | None
    violations: dict[str, int]
    stale_stop: bool
    rejected_commands: int = 0
    commands: int = 0
    protective_stop: bool = False
    protective_stops: int = 0
    protective_reason: str = ""
    refused_commands: int = 0
    gripper_width: float = float("nan")


class SimRobot:
    """The simulated WMM.

    Args:
        model: the robot's kinematic model (its config gives the limits the referee enforces).
        config: the sim's config.
        seed: seed of the slip/drift noise; None = ``config.seed``.
        ramp: the drives ramp the executed rates towards the command at the acceleration
            limits (see the module docstring); False: each command is executed at once.
        scene: the obstacles the referee checks the robot against (None: none; self and floor
            collisions are checked anyway).
        collisions: check collisions (``collision`` violations, :mod:`.collision`); None: the
            config's ``referee.collisions``.
    """

    def __init__(self, model: wmm_qp.WmmModel, config: SimConfig, seed: int | None = None,
                 ramp: bool = False, scene: wmm_qp.scene.Scene | None = None,
                 collisions: bool | None = None) -> None:
        self.model = model
        self.config = config
        self.seed = config.seed if seed is None else seed
        self.rng = np.random.default_rng(self.seed)
        self.slip = SlipModel(config.slip, model.base.M, self.rng)
        self.referee = Referee(model.config, config.referee, period_max=config.stale_timeout)
        self.torque_limit = np.array(model.config.arm.torque_limit, dtype=float)
        self.a_max = np.array(model.config.arm.acceleration_max, dtype=float)
        self.wa_max = np.array(model.config.base.wheel_acceleration_max, dtype=float)
        self.n_arm, self.n_wheels = model.n_arm, model.n_wheels
        arm = model.config.arm
        self.q_lo = np.array(arm.position_lower, dtype=float)
        self.q_hi = np.array(arm.position_upper, dtype=float)
        self.v_max = np.array(arm.velocity_max, dtype=float)
        self.w_max = np.array(model.config.base.wheel_speed_max, dtype=float)
        tol = config.referee
        self._v_tol = self.v_max * (1.0 + tol.rtol) + tol.atol
        self._w_tol = self.w_max * (1.0 + tol.rtol) + tol.atol
        self.ramp = ramp
        self.collision: CollisionReferee | None = None
        if config.referee.collisions if collisions is None else collisions:
            self.collision = CollisionReferee(model, config.referee.collision_distance)
        self.scene_obstacles = scene.obstacles if scene is not None else ()
        self.live_obstacles: tuple[wmm_qp.config.ShapeConfig, ...] = ()
        self.box: Box | None = None
        self.reset()

    def set_obstacles(self, obstacles: Sequence[wmm_qp.config.ShapeConfig]) -> None:
        """The live obstacles the referee checks against (they replace the previous live set; the
        scene's and the pushed box stay)."""
        self.live_obstacles = tuple(obstacles)
        self._update_obstacles()

    def box_obstacle(self) -> wmm_qp.config.ShapeConfig | None:
        """The pushed box as an obstacle for every body but the EE's (``exempt = ["ee"]``): from
        the floor to its height, its depth along x its width (the contact model knows only the
        face), None without a box."""
        if self.box is None:
            return None
        c = self.box.config
        z0 = self.model.config.base.floor_z
        return wmm_qp.config.ShapeConfig(
            name="box", link="", kind="box", size=np.array([c.width, c.width, c.height - z0]),
            xyz=np.array([self.box.face_x + 0.5 * c.width, c.center_y, 0.5 * (c.height + z0)]),
            rpy=np.zeros(3), exempt=("ee",))

    def _update_obstacles(self) -> None:
        if self.collision is not None:
            box = self.box_obstacle()
            self.collision.set_obstacles(self.scene_obstacles + self.live_obstacles + ((box,) if box else ()))

    def reset(
        self,
        q_base: Sequence[float] | FloatArray = (0.0, 0.0, 0.0),
        q_arm: Sequence[float] | FloatArray | None = None,
        box: BoxConfig | None = None,
    ) -> SimState:
        """Put the robot at rest at (q_base, q_arm); odometry = truth; counts zeroed.

        Args:
            q_base: [m, m, rad] base pose (x, y, ψ).
            q_arm: [rad] joint values; None = the robot description's ``arm.start``.
            box: the box to push; None = ``config.box`` (which may itself be None).
        """
        self.rng = np.random.default_rng(self.seed)
        self.slip.rng = self.rng
        self.slip.reset()
        self.referee.reset()
        if self.collision is not None:
            self.collision.reset()
        self.t = 0.0
        start = self.model.config.arm.start if q_arm is None else q_arm
        self.q_arm = np.array(start, dtype=float).reshape(self.n_arm)
        self.v_arm = np.zeros(self.n_arm)
        self.wheels = np.zeros(self.n_wheels)
        self.base_odom = np.array(q_base, dtype=float).reshape(3)
        self.base_true = self.base_odom.copy()
        box_cfg = box if box is not None else self.config.box
        self.box = Box(box_cfg) if box_cfg is not None else None
        self._box_x = self.box.face_x if self.box is not None else math.nan
        self._update_obstacles()
        self.t_last_command = 0.0
        self.stale = False
        self.rejected = 0
        self.n_commands = 0
        self.target_arm = np.zeros(self.n_arm)  # the command the drives follow
        self.target_wheels = np.zeros(self.n_wheels)
        self.protective = False
        self.protective_stops = 0
        self.protective_reason = ""
        self.refused = 0
        self.stream: int | None = None  # the stream of the last command received (and not refused for it)
        self.stopped_stream: int | None = None  # the stream a stale or protective stop ended
        self.tau = np.zeros(self.n_arm)
        self.force = np.zeros(3)
        self.stalled_joint: int | None = None
        g = self.model.config.gripper
        self.gripper = Gripper(g) if g is not None else None
        return self.state()

    def command_gripper(self, action: str, width: float = 0.0, speed: float = 0.05, force: float = 0.0) -> bool:
        """Start a gripper command (see :mod:`.gripper`); False: no gripper, or an unknown action."""
        return self.gripper is not None and self.gripper.command(action, width, speed, force)

    def place_box(self, box: BoxConfig | None) -> None:
        """Put a box in the scene now (or remove it with None), keeping the robot's state."""
        self.box = Box(box) if box is not None else None
        self._box_x = self.box.face_x if self.box is not None else math.nan
        self._update_obstacles()

    # ------------------------------------------------------------------ stepping
    def step(self, command: SimCommand | None, dt: float) -> SimState:
        """Advance by dt [s]: take the new command (None = keep the held one), integrate.

        Never raises; a malformed command is ignored and counted.
        """
        if self.gripper is not None:
            self.gripper.step(dt)
        if command is not None and not command.is_valid(self.n_wheels, self.n_arm):
            self.rejected += 1
            command = None
        if command is not None:
            self._receive(command, dt)
        elif self.t - self.t_last_command >= self.config.stale_timeout - 1e-12 and not self.stale:
            self.stale = True
            self.stopped_stream = self.stream
            self.referee.break_stream(hard=False)
        if self.stale or self.protective:
            v, w = self._braked(dt)
        elif self.ramp:
            v = self.v_arm + np.clip(self.target_arm - self.v_arm, -self.a_max * dt, self.a_max * dt)
            w = self.wheels + np.clip(self.target_wheels - self.wheels, -self.wa_max * dt, self.wa_max * dt)
        else:
            v, w = self.target_arm, self.target_wheels
        if self.config.firmware and not self.protective and (j := self._cannot_stop(v, dt)) >= 0:
            side = "upper" if v[j] > 0 else "lower"
            self._protective_stop(f"joint {j + 1} at {self.q_arm[j]:.4f} rad moving {v[j]:.3f} rad/s "
                                  f"could not stop before its {side} limit")
            v, w = self._braked(dt)
        self.v_arm, self.wheels = np.array(v, dtype=float), np.array(w, dtype=float)
        self._integrate(dt)
        self.t += dt
        self.referee.check_positions(self.q_arm)
        if self.collision is not None:
            if self.box is not None and abs(self.box.face_x - self._box_x) > 1e-4:  # the box moved
                self._box_x = self.box.face_x
                self._update_obstacles()
            hits = self.collision.check(self.base_true, self.q_arm)
            if hits:
                self.referee.counts["collision"] += hits
                self.referee.last_event = f"collision: {self.collision.closest} at {self.collision.min_distance:.4f} m"
        return self.state()

    def coast(self, steps: int, dt: float) -> bool:
        """Advance ``steps`` steps of dt [s] in one go when they cannot change anything: the
        robot rests in its own (stale or protective) stop and receives no command meanwhile.

        Returns:
            False (nothing done) unless the robot is at rest in its own stop.
        """
        if not (self.stale or self.protective) or self.v_arm.any() or self.wheels.any():
            return False
        self.t += steps * dt
        return True

    def _receive(self, command: SimCommand, dt: float) -> None:
        """A valid command arrived: the referee judges it as received, then the firmware."""
        arm, wheels = command.arm_rates, command.wheel_speeds
        self.referee.on_command(self.t, arm, wheels, self.v_arm, self.wheels, period=command.period,
                                seq=command.seq, received=command.received, step=dt,
                                stream=command.stream, sent=command.sent)
        self.n_commands += 1
        self.t_last_command = self.t
        if (self.config.firmware and command.stream is not None and (self.stale or self.protective)
                and command.stream == self.stopped_stream):
            self.refused += 1  # the stop ended this stream: only a new one resumes
            return
        self.stale = False
        self.stream = command.stream
        if self.config.firmware:
            bad_v = np.flatnonzero(np.abs(arm) > self._v_tol)
            bad_w = np.flatnonzero(np.abs(wheels) > self._w_tol)
            if bad_v.size or bad_w.size:
                self.refused += 1
                what = (f"joint {bad_v[0] + 1} rate {arm[bad_v[0]]:.3g} rad/s beyond {self.v_max[bad_v[0]]:.3g}"
                        if bad_v.size else
                        f"wheel {bad_w[0] + 1} speed {wheels[bad_w[0]]:.3g} rad/s beyond {self.w_max[bad_w[0]]:.3g}")
                self._protective_stop(f"refused command: {what}")
                return
            if self.protective:
                if self.v_arm.any() or self.wheels.any():
                    self.refused += 1  # still braking: commands wait until the robot is at rest
                    return
                self.protective = False  # at rest, and a legal command: resume
                self.referee.break_stream(hard=False)
        self.target_arm, self.target_wheels = arm.copy(), wheels.copy()

    def _protective_stop(self, why: str) -> None:
        if not self.protective:
            self.protective_stops += 1
            self.stopped_stream = self.stream
        self.protective = True
        self.protective_reason = why
        self.referee.break_stream(hard=False)

    def _braked(self, dt: float) -> tuple[FloatArray, FloatArray]:
        """One braking step toward rest at the acceleration limits; the targets become rest."""
        self.target_arm = np.zeros(self.n_arm)
        self.target_wheels = np.zeros(self.n_wheels)
        dv = np.clip(-self.v_arm, -self.a_max * dt, self.a_max * dt)
        dw = np.clip(-self.wheels, -self.wa_max * dt, self.wa_max * dt)
        return self.v_arm + dv, self.wheels + dw

    def _cannot_stop(self, v: FloatArray, dt: float) -> int:
        """The first joint that, after one step at rate v, could not brake to rest at its
        acceleration limit before its position limit (-1: none). Braking distance v²/(2A)."""
        q = self.q_arm + v * dt
        stop = v * np.abs(v) / (2.0 * self.a_max)
        with np.errstate(invalid="ignore"):
            bad = ((v > 0) & (q + stop > self.q_hi)) | ((v < 0) & (q + stop < self.q_lo))
        idx = np.flatnonzero(bad)
        return int(idx[0]) if idx.size else -1

    def _integrate(self, dt: float) -> None:
        q_new = self.q_arm + self.v_arm * dt
        self.base_odom = integrate_pose(self.base_odom, self.model.base.body_twist(self.wheels), dt)
        base_new = integrate_pose(self.base_true, self.slip.true_body_twist(self.wheels, dt), dt)
        self.tau = np.zeros(self.n_arm)
        self.force = np.zeros(3)
        self.stalled_joint = None
        if self.box is not None:
            kin = self.model.kinematics(base_new, q_new)
            contact = self.box.check(kin.x, kin.J_m, self.torque_limit)
            self.tau, self.force, self.stalled_joint = (
                contact.tau,
                contact.force,
                contact.stalled_joint,
            )
            if contact.stalled:
                return  # the robot is blocked by the box: neither the arm nor the base moves
            if contact.in_contact:
                self.box.slide_to(float(kin.x[0]))
        self.q_arm, self.base_true = q_new, base_new

    # ------------------------------------------------------------------ reporting
    def state(self) -> SimState:
        """The full state, ground truth included."""
        return SimState(
            t=self.t,
            q_arm=self.q_arm.copy(),
            v_arm=self.v_arm.copy(),
            wheel_speeds=self.wheels.copy(),
            base_odom=self.base_odom.copy(),
            base_true=self.base_true.copy(),
            ee_true=self.model.ee_position(self.base_true, self.q_arm),
            tau=self.tau.copy(),
            contact_force=self.force.copy(),
            box_position=self.box.face_x if self.box is not None else float("nan"),
            box_displacement=self.box.displacement if self.box is not None else float("nan"),
            stalled_joint=self.stalled_joint,
            violations=dict(self.referee.counts),
            stale_stop=self.stale,
            rejected_commands=self.rejected,
            commands=self.n_commands,
            protective_stop=self.protective,
            protective_stops=self.protective_stops,
            protective_reason=self.protective_reason,
            refused_commands=self.refused,
            gripper_width=self.gripper.width if self.gripper is not None else float("nan"),
        )

    def robot_state(self) -> wmm_qp.RobotState:
        """What a controller sees: odometry base pose, joint angles, executed rates."""
        return wmm_qp.RobotState(
            q_base=self.base_odom.copy(),
            q_arm=self.q_arm.copy(),
            v_arm=self.v_arm.copy(),
            wheel_speeds=self.wheels.copy(),
        )
