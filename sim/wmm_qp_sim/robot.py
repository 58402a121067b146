"""The simulated wheeled mobile manipulator's firmware and referees, driving a plant.

:class:`SimRobot` is the robot as its controller meets it: it receives commands, runs the
robot's firmware (command refusal, stale and protective stops), writes the rates the drives
follow to a :class:`~.plant.Plant` (the hardware: :class:`~.kinematic_plant.KinematicPlant` by
default, a kinematic robot that executes the rates as they are), advances it, reads it back,
integrates the odometry (the base kind's nominal model, eq. (3), from the measured wheel speeds)
and counts every limit violation (:mod:`.referee`, :mod:`.collision`): the referee, not the
plant, judges whether the commands were legal. It never raises from ``step``: a malformed command
is ignored (counted in ``SimState.rejected_commands``) and the held command goes on. Its state
reports the measured joint positions and the **executed** rates, the ones it wrote to the drives
(exactly 0 at rest), as a real robot's state does: a controller starts a new stream from them and,
after a stop, waits for them to be 0; a physics plant's measured rates never are.

Stale commands: when no new command has arrived for ``config.stale_timeout`` seconds, the
firmware brakes every joint and wheel to rest by itself at its acceleration limit
(``SimState.stale_stop`` is True until the next command it accepts).

A stop ends the stream it stopped: after a stale or protective stop the firmware refuses every
further command of that stream (``SimCommand.stream`` of its ``sender``; counted in
``ended_commands``, apart from the firmware's refusals in ``refused_commands``: the stop itself
is what the robot reports) and resumes only on a new stream. A command of the old stream that
reaches the robot late (it sat in a frozen sender's transmit queue, or in a congested link)
would otherwise restart the robot at rates its sender computed before the stop, while the
sender, having seen the stop, starts a new stream from the robot at rest: the two would meet as
a jump.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from wmm_qp_robot.collision import CollisionReferee
from wmm_qp_robot.referee import Referee
from wmm_qp_robot.stream_rules import StreamRules, Verdict

import wmm_qp
from wmm_qp.config import FloatArray
from wmm_qp.fault_codes import FaultCode

from .command import SimCommand
from .config import BoxConfig, SimConfig
from .contact import Box
from .gripper import Gripper
from .plant import Plant, PlantState
from .plants import make_plant
from .slip import integrate_pose
from .state import SimState

__all__ = ["SimCommand", "SimRobot", "SimState"]


class SimRobot(StreamRules):
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
        plant: the hardware driven; None: the config's ``physics.plant`` (:mod:`.plants`; the
            default a :class:`~.kinematic_plant.KinematicPlant` with the config's slip, seeded
            with ``seed``).

    Raises:
        PlantNotAvailable: the config names a plant whose package is not installed.

    Attributes:
        v_arm: [rad/s] the joint rates the drives were last told (written to the plant).
        wheels: [rad/s] the wheel speeds the drives were last told.
    """

    def __init__(self, model: wmm_qp.WmmModel, config: SimConfig, seed: int | None = None,
                 ramp: bool = False, scene: wmm_qp.scene.Scene | None = None,
                 collisions: bool | None = None, plant: Plant | None = None) -> None:
        self.model = model
        self.config = config
        self.seed = config.seed if seed is None else seed
        self.plant: Plant = plant if plant is not None else make_plant(config.physics.plant, model, config,
                                                                       self.seed, scene)
        self._ps: PlantState = self.plant.read()
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
        self.reset()

    # ------------------------------------------------------------------ the plant's measurements
    @property
    def q_arm(self) -> FloatArray:
        """[rad] the measured joint positions."""
        return self._ps.q_arm

    @property
    def base_true(self) -> FloatArray:
        """[m, m, rad] the true base pose; setting it carries the base there."""
        return self._ps.base_true

    @base_true.setter
    def base_true(self, pose: FloatArray) -> None:
        self.plant.set_base_pose(pose)
        self._ps = self.plant.read()

    @property
    def box(self) -> Box | None:
        """The push box, or None."""
        return self.plant.box

    def set_obstacles(self, obstacles: Sequence[wmm_qp.config.ShapeConfig]) -> None:
        """The live obstacles the referee checks against (they replace the previous live set; the
        scene's and the pushed box stay)."""
        self.live_obstacles = tuple(obstacles)
        self._update_obstacles()

    def box_obstacle(self) -> wmm_qp.config.ShapeConfig | None:
        """The pushed box as an obstacle for every body but the EE's (``exempt = ["ee"]``): from
        the floor to its height, its depth along x its width (the contact model knows only the
        face), in the pose the plant measured (a physics box may slide and tip), None without a
        box."""
        if self.box is None:
            return None
        c = self.box.config
        z0 = self.model.config.base.floor_z
        centre = self.box.center  # a physics box: where it is, tipped or not
        return wmm_qp.config.ShapeConfig(
            name="box", link="", kind="box", size=np.array([c.width, c.width, c.height - z0]),
            xyz=np.array([self.box.face_x + 0.5 * c.width, c.center_y, 0.5 * (c.height + z0)])
            if centre is None else np.array(centre, dtype=float),
            rpy=self.box.rpy.copy(), exempt=("ee",))

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
        self.referee.reset()
        if self.collision is not None:
            self.collision.reset()
        self.t = 0.0
        start = self.model.config.arm.start if q_arm is None else q_arm
        self.v_arm = np.zeros(self.n_arm)
        self.wheels = np.zeros(self.n_wheels)
        self.base_odom = np.array(q_base, dtype=float).reshape(3)
        box_cfg = box if box is not None else self.config.box
        self.plant.reset(self.base_odom.copy(), np.array(start, dtype=float).reshape(self.n_arm), box_cfg)
        self._ps = self.plant.read()
        self._box_x = self.box.face_x if self.box is not None else math.nan
        self._box_tilt = self.box.tilt if self.box is not None else 0.0
        self._update_obstacles()
        self.t_last_command = 0.0
        self.rejected = 0
        self.n_commands = 0
        self.target_arm = np.zeros(self.n_arm)  # the command the drives follow
        self.target_wheels = np.zeros(self.n_wheels)
        self.reset_rules()  # the firmware's stream rules (streams keyed (sender, stream))
        self.drives = {"torque_limit": [0] * self.n_arm, "tracking": [0] * self.n_arm}
        g = self.model.config.gripper
        self.gripper = Gripper(g) if g is not None else None
        return self.state()

    def command_gripper(self, action: str, width: float = 0.0, speed: float = 0.05, force: float = 0.0) -> bool:
        """Start a gripper command (see :mod:`.gripper`); False: no gripper, or an unknown action."""
        return self.gripper is not None and self.gripper.command(action, width, speed, force)

    def place_box(self, box: BoxConfig | None) -> None:
        """Put a box in the scene now (or remove it with None), keeping the robot's state."""
        self.plant.place_box(box)
        self._box_x = self.box.face_x if self.box is not None else math.nan
        self._box_tilt = self.box.tilt if self.box is not None else 0.0
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
        elif self.t - self.t_last_command >= self.config.stale_timeout - 1e-12 and self.go_stale():
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
            self.protect(FaultCode.CANNOT_STOP_BEFORE_LIMIT, f"joint {j + 1} at {self.q_arm[j]:.4f} rad "
                         f"moving {v[j]:.3f} rad/s could not stop before its {side} limit")
            v, w = self._braked(dt)
        self.v_arm, self.wheels = np.array(v, dtype=float), np.array(w, dtype=float)
        self.plant.write(self.wheels, self.v_arm)
        self.plant.advance(dt)
        self._ps = self.plant.read()
        if self._ps.stalled_joint is not None:
            self.drives["torque_limit"][self._ps.stalled_joint] += 1
        if self._ps.lagging_joint is not None:
            self.drives["tracking"][self._ps.lagging_joint] += 1
        self.base_odom = integrate_pose(self.base_odom, self.model.base.body_twist(self._ps.wheel_speeds), dt)
        self.t += dt
        self.referee.check_positions(self.q_arm)
        if self.collision is not None:
            if self.box is not None and (abs(self.box.face_x - self._box_x) > 1e-4
                                         or abs(self.box.tilt - self._box_tilt) > 1e-4):  # the box moved
                self._box_x, self._box_tilt = self.box.face_x, self.box.tilt
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

    def receive_superseded(self, command: SimCommand, dt: float) -> None:
        """A command that another one superseded within the same step of dt [s]: received (the
        referee judges it, the firmware checks it, it may start or end a stop) but not executed.
        A malformed one is ignored (as :meth:`step` ignores it)."""
        if command.is_valid(self.n_wheels, self.n_arm):
            self._receive(command, dt)

    def _receive(self, command: SimCommand, dt: float) -> None:
        """A valid command arrived: the referee judges it as received, then the firmware."""
        arm, wheels = command.arm_rates, command.wheel_speeds
        self.referee.on_command(self.t, arm, wheels, self.v_arm, self.wheels, period=command.period,
                                seq=command.seq, received=command.received, step=dt,
                                stream=command.stream, sent=command.sent)
        self.n_commands += 1
        self.t_last_command = self.t
        key = command.stream_key
        if not self.config.firmware:  # a plain integrator: every valid command is followed
            self.stale, self.stream = False, key
        else:
            verdict = self.receive(key, self._illegal(arm, wheels), at_rest=not (self.v_arm.any() or self.wheels.any()))
            if verdict is Verdict.RESUME:
                self.referee.break_stream(hard=False)
            if not verdict.followed:
                return
        self.target_arm, self.target_wheels = arm.copy(), wheels.copy()

    def _illegal(self, arm: FloatArray, wheels: FloatArray) -> str | None:
        """Why a command is illegal whatever the state (a rate past its limit), or None."""
        bad_v = np.flatnonzero(np.abs(arm) > self._v_tol)
        if bad_v.size:
            return f"joint {bad_v[0] + 1} rate {arm[bad_v[0]]:.3g} rad/s beyond {self.v_max[bad_v[0]]:.3g}"
        bad_w = np.flatnonzero(np.abs(wheels) > self._w_tol)
        if bad_w.size:
            return f"wheel {bad_w[0] + 1} speed {wheels[bad_w[0]]:.3g} rad/s beyond {self.w_max[bad_w[0]]:.3g}"
        return None

    def protect(self, code: FaultCode, why: str) -> None:
        """A protective stop (:meth:`StreamRules.protect`): the referee's stream breaks too."""
        super().protect(code, why)
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
            tau=self._ps.tau.copy(),
            contact_force=self._ps.contact_force.copy(),
            box_position=self.box.face_x if self.box is not None else float("nan"),
            box_displacement=self.box.displacement if self.box is not None else float("nan"),
            stalled_joint=self._ps.stalled_joint,
            violations=dict(self.referee.counts),
            stale_stop=self.stale,
            rejected_commands=self.rejected,
            commands=self.n_commands,
            protective_stop=self.protective,
            protective_stops=self.protective_stops,
            protective_reason=self.protective_reason,
            protective_code=self.protective_code,
            refused_commands=self.refused,
            ended_commands=self.ended,
            drives={k: list(v) for k, v in self.drives.items()},
            gripper_width=self.gripper.width if self.gripper is not None else float("nan"),
        )

    def robot_state(self) -> wmm_qp.RobotState:
        """What a controller sees: odometry base pose, measured joint angles, executed rates
        (the state a real robot reports, docs/drivers.md)."""
        return wmm_qp.RobotState(
            q_base=self.base_odom.copy(),
            q_arm=self.q_arm.copy(),
            v_arm=self.v_arm.copy(),
            wheel_speeds=self.wheels.copy(),
        )
