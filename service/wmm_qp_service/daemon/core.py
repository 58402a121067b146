"""The control core: the daemon's logic without transport — one robot's cycle.

:meth:`ControlCore.on_state` takes a validated state in, :meth:`ControlCore.tick` computes the
command to send; between them the host (:mod:`.host`) hands it the operator's inputs (:mod:`.inputs`:
modes, setpoints, obstacles, the robot's truth and liveliness). Its concerns live beside it:
the instance latch and seq (:mod:`.state_gate`), the command stream (:mod:`.command_stream`),
the setpoint stream (:mod:`.setpoints`), live obstacles (:mod:`.obstacles`), the watchdogs and
faults (:mod:`.watchdog`), the reports (:mod:`.reports`). Nothing here raises in the loop:
failures become a safe stop and a reason in the status. Tests drive it with a fake clock.
"""

from __future__ import annotations

import math
import time
from collections import Counter
from collections.abc import Callable

import numpy as np

import wmm_qp as w
from wmm_qp.fault_codes import FaultCode
from wmm_qp.scene import Scene, load_scene
from wmm_qp.tasks import rotation_to_quat

from ..config import ServiceConfig
from ..protocol import StateMsg, TruthMsg
from ..smoother import OrientationTarget, SetpointSmoother, VelocityEstimator
from ..tick_stages import CALL_NONE, CALL_REPEAT, CALL_SAFE_STOP, CALL_STEP, RUCKIG, STEP, WATCHDOGS, TickStages
from .command_stream import CommandStream, predicted
from .inputs import CoreInputs
from .obstacles import LiveObstacles
from .setpoints import Setpoints
from .state_gate import Latch, StateGate
from .watchdog import Fault, FaultRecord, hazard, say, second_source

UNCONFIRMED = 1.0
"""[s] a stream whose first command no state has named applied for this long, while states come,
is said as a fault once (a driver that does not report ``cmd_seq``; the robot does not move)."""


class ControlCore(CoreInputs):
    """The daemon's logic without transport: modes, watchdogs, smoothing, the controller.

    With the pose task (``ctl_cfg.task.kind = "pose"``) the reference carries an orientation
    target too (:class:`~wmm_qp_service.smoother.OrientationTarget`): latched from the EE's
    orientation wherever the position target is latched (a mode change, hold, after a safe
    stop), and set by the setpoints' ``q`` and ``w`` in the modes that follow setpoints. With
    the position task a setpoint's orientation is ignored and counted (``orientation_ignored``).

    Args:
        svc: service config (an open robot id is the robot's name).
        ctl_cfg: controller config (its rate is replaced by ``svc.loop.rate_hz``).
        robot: robot config.
        kind: controller kind (qp, paper, traditional); None = ``ctl_cfg.kind``.
        scene: obstacles and the workspace fence (None: ``configs/scenes/default.toml``).
    """

    def __init__(self, svc: ServiceConfig, ctl_cfg: w.ControllerConfig, robot: w.RobotConfig,
                 kind: str | None = None, scene: Scene | None = None) -> None:
        svc = svc.with_robot(robot)
        self.svc = svc
        wd = svc.watchdog
        # Bounds (13) brake from where the joints can be when the next command (or the robot's
        # own command timeout) takes over: over a transport that is longer than in-process.
        hold = max(ctl_cfg.state_latency, wd.command_hold)
        self.cfg = ctl_cfg.with_(rate_hz=svc.loop.rate_hz, state_latency=hold)
        self.robot = robot
        self.model = w.WmmModel(robot)
        self.kind = kind or self.cfg.kind
        self.ctl = w.make_controller(self.kind, self.model, self.cfg)
        # the scene: its obstacles and fence are rows of the QP controller's stages (the baselines
        # have none); every controller's setpoints are clamped into the fence (on_setpoint)
        self.scene = scene if scene is not None else load_scene()
        self.ctl.set_scene(self.scene)
        self.obstacles = LiveObstacles(wd.obstacles_timeout)
        self.ctl.warm_up()  # the compiled kernels are loaded before the loop, not in its first tick
        self.dt = self.cfg.dt
        if 2.0 * self.dt > wd.state_age_max:
            raise w.ConfigError("<service config>", "loop.rate_hz", f"{svc.loop.rate_hz:g} Hz is too slow for "
                                f"watchdog.state_age_max ({wd.state_age_max * 1e3:g} ms): a state is up to two "
                                f"periods old when it is used; raise the rate or state_age_max (and command_hold)")
        sm = svc.smoothing
        self.smoother = SetpointSmoother(self.dt, sm.v_max, sm.a_max, sm.j_max)
        self.estimator = VelocityEstimator(v_max=sm.v_max)
        self.pose = self.cfg.task.kind == "pose"
        self.orient = OrientationTarget(self.dt)  # the pose task's orientation target
        self.mode = w.Mode.HOLD
        self.direction: np.ndarray | None = None
        self.state: w.RobotState | None = None
        self.state_msg: StateMsg | None = None
        self.state_time = -math.inf
        self.state_fresh = False
        self.need_latch, self.safe = True, False
        self.resume_needed = self.robot_alive = False
        self.cmd: w.Command | None = None
        self.ref = w.Reference(mode=w.Mode.HOLD)
        self._ref = w.Reference(mode=w.Mode.HOLD)  # the one tick() refills
        self.ref_valid = False  # self.ref was computed from the current latch
        self.ee_error = math.nan
        self.now = 0.0
        self.t0 = 0.0  # [s] clock value at the loop's start (fault messages say time since)
        self.say: Callable[[str], None] = say  # where fault lines go (the Daemon hands them to a FaultLog)
        self.refused: Counter[str] = Counter()  # setpoints and states refused after validation
        self.fault_record = FaultRecord()
        self.gate = StateGate(wd.state_timeout, self.refused)  # one robot, its states in order
        self.stream = CommandStream(wd, self.cfg.state_latency, self.ctl.set_latency)
        self.setpoints = Setpoints(wd, self.scene, robot.base.floor_z + self.cfg.collision.floor_margin,
                                   self.pose, self.refused, self._fault)
        self.lease = "core"  # this daemon's control lease id (the Daemon sets its Zenoh id)
        self.lease_lost = False  # the robot applies another holder's commands
        self.lease_holder = ""  # the holder the robot reports
        # the robot's own firmware and its referee
        self.firmware_seen = -1  # protective stops + firmware refusals of the latched instance (-1: no state yet)
        self.protective = ""
        self.truth: TruthMsg | None = None  # the latched instance's last evaluation data (optional)
        self.stages: TickStages | None = None  # the breakdown's stopwatch (None: off)
        self.step_ns = 0  # [ns] the last ctl.step
        # what this tick asked of the controller (CALL_*), the state handed to it and bounds (13)'s
        # latency margin [s]: for a recording's replay (wmm_qp_service.recording)
        self.ctl_call, self.ctl_latency = CALL_NONE, math.nan
        self.ctl_state: w.RobotState | None = None
        self.latches = 0  # re-latches so far (each resets the controller's warm starts)
        self._sent: tuple[w.Command | None, bool] = (None, False)  # the last command sent, and anchored

    # ------------------------------------------------------------------ the state
    def on_state(self, msg: StateMsg, now: float) -> bool:
        """A validated state arrived at ``now`` [s]; False: refused (another source, old seq).

        The first state latches the robot's instance (:class:`~.state_gate.StateGate`); a
        restarted robot is latched as a new one (a fault), with its rates and ages anew.
        """
        seen = self.gate.foreign_time
        latch = self.gate.latch(msg.instance, now, self.state_time)
        if latch is Latch.REFUSED:
            # recorded as it appears, whatever the daemon is doing (already in a safe stop, its
            # stream broken): the status names the second robot; the tick's hazard holds the stop
            if now - seen > self.svc.watchdog.state_timeout:
                self._fault(*second_source(self.gate))
            return False
        if latch is Latch.NEW:
            if self.gate.previous:
                self._fault(FaultCode.ROBOT_INSTANCE_CHANGED,
                            f"robot instance changed ({self.gate.previous} -> {msg.instance}: a restarted robot)")
            self.stream.new_robot(msg.cmd_seq)  # its last command is another daemon's (or none, -1)
            self.cmd = None  # and the last command was another robot's
            self.firmware_seen = -1
            self.truth = None
            if any(msg.v_arm) or any(msg.wheel_speeds):
                # it holds another daemon's last command until its timeout, then brakes: what it
                # executes when a first command of this one's arrives is unknown until it rests
                self.break_stream(FaultCode.FOREIGN_COMMANDS, f"the robot moves under commands that are not this "
                                  f"daemon's (cmd_seq {msg.cmd_seq}): waiting for it to rest in its own stop")
        if not self.gate.next_seq(msg.seq):
            return False
        self.stream.applied(msg)
        self.state_msg = msg
        self.state = w.RobotState(q_base=msg.q_base, q_arm=msg.q_arm,  # type: ignore[arg-type]
                                  v_arm=msg.v_arm, wheel_speeds=msg.wheel_speeds)  # type: ignore[arg-type]
        self.state_time = now
        self.state_fresh = True
        self.lease_holder = msg.lease
        total = msg.protective_stops + msg.refused.get("firmware", 0)
        if 0 <= self.firmware_seen < total:  # the robot's own reports, not an evaluation's
            code = f"{msg.protective_code}: " if msg.protective_code else ""
            self._event(Fault(FaultCode.ROBOT_FIRMWARE, f"robot firmware reported {total - self.firmware_seen} new "
                              f"protective stop(s) or refused command(s) ({code}"
                              f"{msg.protective_reason or 'no reason given'})"), now)
        self.firmware_seen = total
        self.protective = msg.protective_reason if msg.protective_stop else ""
        self.stream.observe(msg, now)
        return True

    # ------------------------------------------------------------------ faults
    def _fault(self, code: FaultCode, what: str) -> None:
        """Record a fault (and say it once on stderr when it is new).

        Args:
            code: its stable code, the key in ``status.faults``.
            what: its message, as the status's ``last_fault`` shows it.
        """
        if what != self.fault_record.last:
            st = self.state
            where = (f" [t={self.now - self.t0:.3f} s, mode {self.mode.value}, q_base "
                     f"{np.round(st.q_base, 4).tolist()}, q_arm {np.round(st.q_arm, 4).tolist()}]"
                     if st is not None else "")
            self.say(f"{self.who}: fault: {code}: {what}{where}")
        self.fault_record.record(code, what, self.now)

    def _event(self, fault: Fault, now: float) -> None:
        """A fault that happened once: a safe stop for ``state_timeout``, then (manual) a hold."""
        self._fault(*fault)
        self.fault_record.hold(fault, now + self.svc.watchdog.state_timeout)

    def hazard(self, now: float) -> Fault | None:
        """The fault that forces a safe stop now, or None (:func:`~.watchdog.hazard`)."""
        return hazard(self.svc.watchdog, now, self.state_time, self.gate, self.protective,
                      self.stream.round_trip, self.fault_record)

    def break_stream(self, code: FaultCode, why: str) -> None:
        """The robot no longer follows this daemon's commands (its own stop, another lease holder):
        nothing is sent until a state shows it at rest in its stop; then a new stream starts from
        the measured rates, in hold until a mode message (:meth:`.CommandStream.break_off`)."""
        self._fault(code, why)
        self.safe = True
        self.stream.break_off()

    def brake_stream(self, why: str) -> None:
        """This daemon stalled past the robot's command timeout: :meth:`tick` brakes the stream to
        rest with the controller's safe stop, in the same stream (:meth:`.CommandStream.stall`)."""
        self._fault(FaultCode.STALL_BRAKING, why)
        self.safe = True
        self.stream.stall(why)

    def withdraw(self, why: str) -> None:
        """The command :meth:`tick` returned was not sent (the tick itself took past the robot's
        command timeout): the last command sent anchors again, and the stream is braked from it
        (:meth:`brake_stream`)."""
        self.cmd, anchored = self._sent
        self.stream.withdraw(anchored)
        self.brake_stream(why)

    @property
    def lease_taken(self) -> bool:
        """The sim applies the commands of another lease holder."""
        return bool(self.lease_holder) and self.lease_holder != self.lease

    @property
    def fault_active(self) -> bool:
        """A fault holds the robot now (a safe stop, a broken stream, a lost lease, a stream whose
        commands the robot's states have not named applied for a second), or the daemon holds in
        ``hold`` until a mode message resumes (``resume_needed``)."""
        st = self.stream
        return (self.safe or st.broken or self.lease_lost or self.resume_needed
                or (st.unconfirmed_said and not st.confirmed))

    # ------------------------------------------------------------------ one tick
    def tick(self, now: float) -> w.Command | None:
        """One control tick at ``now`` [s]; returns the command to send (None: nothing)."""
        self.now = now
        self.ctl_call = CALL_NONE
        stream = self.stream
        self._sent = (self.cmd, stream.anchor_on_command)  # the last command sent (withdraw)
        if self.state is None or not self._may_send(now):
            return None
        if not stream.anchor_on_command:  # this tick's command starts a stream (the referee's baseline)
            stream.begin(now)
        fault = self.hazard(now) or (Fault(FaultCode.STALL_BRAKING, stream.stalled) if stream.stalled else None)
        if fault is not None:
            cmd = self._safe_stop(fault)
            stream.safe_stop_sent(now, at_rest=not cmd.arm_rates.any() and not cmd.wheel_speeds.any())
            if self.stages is not None:
                self.stages.lap(WATCHDOGS)
            return cmd
        self._after_fault()
        if not stream.confirmed and stream.anchor_on_command and self.cmd is not None:
            # the robot applied none of this stream's commands yet: the last one again (its first,
            # or the last of a safe stop since, braked from it)
            if stream.unconfirmed_too_long(now, UNCONFIRMED, self.state_fresh):
                seq = self.state_msg.cmd_seq if self.state_msg is not None else -1
                self._fault(FaultCode.COMMANDS_NOT_APPLIED, f"the robot's states name none of this stream's commands "
                            f"as applied (cmd_seq {seq}, the stream began at seq {stream.start}): the daemon "
                            f"repeats its first command; a driver reports the last command it applied")
            stream.computed_from(-1)
            self.ctl_call = CALL_REPEAT
            self.state_fresh = False
            self.ee_error = math.nan
            if self.stages is not None:
                self.stages.lap(WATCHDOGS)
            return self.cmd
        stream.computed_from(self.gate.last_seq if self.state_fresh else -1)
        if not self.state_fresh and self.cmd is not None:
            self.state = predicted(self.model, self.dt, self.state, self.cmd)
        self.state_fresh = False
        if self.need_latch:
            self._latch()
        self._settle(now)
        # ground-truth error of the state (the previous tick's command) against its target
        if self.ref_valid and self.truth is not None and self.mode != w.Mode.DM_CARTESIAN:
            x_prev = self.ref.x_d
            self.ee_error = math.dist(self.truth.ee_true, x_prev.tolist()) if x_prev is not None else math.nan
        else:
            self.ee_error = math.nan
        stages = self.stages
        if stages is not None:
            stages.lap(WATCHDOGS)
        x_d, xd_d = self.smoother.step()
        # one Reference, refilled (a new one re-validates its arrays: ~4 µs); the smoother and the
        # orientation target return fresh float arrays of the right sizes
        ref = self.ref = self._ref
        ref.mode, ref.x_d, ref.xd_d, ref.direction = self.mode, x_d, xd_d, self.direction
        if self.pose:
            ref.quat_d, ref.omega_d = self.orient.step()
        self.ref_valid = True
        state = stream.anchored(self.state, self.cmd, self.state_msg)
        if stages is not None:
            stages.lap(RUCKIG)
        self.ctl_call, self.ctl_state, self.ctl_latency = CALL_STEP, state, self.stream.latency
        t = time.perf_counter_ns()
        cmd = self.ctl.step(state, self.ref)
        self.step_ns = time.perf_counter_ns() - t
        if stages is not None:
            stages.lap(STEP)
        stream.follow()
        if cmd.status == w.Status.SAFE_STOP:
            self._fault(FaultCode.CONTROLLER_FAILED, f"controller: {cmd.reason}")
            self.smoother.reset(cmd.x if np.isfinite(cmd.x).all() else x_d)
            if self.pose:
                self._latch_orientation()
        self.cmd = cmd
        return cmd

    def _may_send(self, now: float) -> bool:
        """Whether this tick may send at all: not while the robot stopped following the stream
        (until a state shows it at rest in its own stop), nor while another daemon holds the lease.
        A stall of this daemon's own starts braking the stream (:meth:`brake_stream`)."""
        stream, msg = self.stream, self.state_msg
        if not stream.broken and stream.late(now):
            self.brake_stream(f"braking stream after a stall ({(now - stream.last_sent_t) * 1e3:.0f} ms without "
                              f"a command: its commands may still reach the robot)")
        if not stream.broken and self.state_fresh and msg is not None and stream.left(msg):
            cause = f"protective stop: {msg.protective_reason}" if msg.protective_stop else "its command timeout"
            self.break_stream(FaultCode.STREAM_BROKEN, f"the robot stopped following the commands ({cause})")
        if self.lease_taken:
            if not self.lease_lost:
                self.break_stream(FaultCode.LEASE_LOST,
                                  f"lease lost (the robot applies the commands of daemon {self.lease_holder})")
                self.lease_lost = True
            return False  # another daemon commands the robot: send nothing
        self.lease_lost = False
        if stream.broken:  # wait for a state of the robot at rest in its own stop
            if not (self.state_fresh and msg is not None and (msg.stale_stop or msg.protective_stop)
                    and not any(msg.v_arm) and not any(msg.wheel_speeds)):
                return False
            stream.rejoin()
        if stream.stalled and self.state_fresh and msg is not None and stream.braked(msg):
            stream.braked_to_rest()
        return True

    def _after_fault(self) -> None:
        """The fault cleared: re-latch from the measured state, and hold where the robot is until a
        mode message resumes a task (a daemon that was holding has none: an idle robot's faults
        need no operator)."""
        if self.safe:
            self.safe = False
            self.need_latch = True
            if self.svc.watchdog.resume == "manual" and self.mode != w.Mode.HOLD:
                self.mode, self.direction = w.Mode.HOLD, None
                self.resume_needed = True

    def _settle(self, now: float) -> None:
        """Bring the targets to rest in hold, and when the setpoints stopped for ``setpoint_timeout``."""
        following = self.mode in (w.Mode.TRACK, w.Mode.DM_NULLSPACE)
        quiet = now - self.setpoints.time > self.svc.watchdog.setpoint_timeout
        if not self.smoother.resting and ((following and quiet) or self.mode == w.Mode.HOLD):
            self.smoother.bring_to_rest()
        if self.pose and not self.orient.resting and (not following or quiet):
            self.orient.bring_to_rest()

    def _latch(self) -> None:
        """Re-latch: the smoother restarts from the current EE position and velocity (and,
        with the pose task, the orientation target from the EE's orientation)."""
        assert self.state is not None
        st = self.state
        kin = self.model.kinematics(st.q_base, st.q_arm)
        xdot = kin.J @ np.concatenate([st.wheel_speeds, st.v_arm])
        self.smoother.reset(kin.x, xdot)
        if self.pose:
            self._latch_orientation()
        self.estimator.reset()
        self.ctl.reset()
        self.latches += 1
        self.need_latch = False
        self.ref_valid = False

    def _latch_orientation(self) -> None:
        """The orientation target := the EE's orientation now (``model.ee_pose``), at rest."""
        assert self.state is not None
        _, R = self.model.ee_pose(self.state.q_base, self.state.q_arm)
        self.orient.reset(rotation_to_quat(R))

    def _safe_stop(self, fault: Fault) -> w.Command:
        """Brake at the acceleration limits from the last command while the robot follows the
        stream (the state is not trusted), else from the measured rates."""
        if not self.safe:
            if fault.message != self.fault_record.last:  # an event fault is recorded where it happened
                self._fault(*fault)
            self.safe = True
        assert self.state is not None
        last = self.cmd if self.stream.anchor_on_command else None  # else the robot does not execute it
        base = w.RobotState(
            q_base=self.state.q_base, q_arm=self.state.q_arm,
            v_arm=last.arm_rates if last is not None else self.state.v_arm,
            wheel_speeds=last.wheel_speeds if last is not None else self.state.wheel_speeds)
        self.ctl_call, self.ctl_state, self.ctl_latency = CALL_SAFE_STOP, base, self.stream.latency
        cmd = self.ctl.safe_stop(base, fault.message)
        self.cmd = cmd
        self.stream.follow()
        return cmd
