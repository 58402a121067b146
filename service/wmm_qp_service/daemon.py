"""The control daemon: one thread, a fixed-rate loop, all I/O polled inside it.

Each tick: poll the latest state (ring channel, depth 1), the mode changes (FIFO, none
lost), the latest setpoint (ring, depth 1), the ``info`` queries and the sim's liveliness;
validate everything on receipt; run the watchdogs; smooth the setpoint (Ruckig); call the
controller ``ctl.step(state, ref)``; publish the command; publish status and telemetry.
Nothing in the loop raises: failures become a safe stop and a reason in the status.

One controller per robot: the daemon holds the robot's control lease (a liveliness token
``<robot>/lease/<id>``); a second daemon finds the token at start and refuses to start
(:class:`LeaseHeld`) or waits for it. The sim applies commands only from the holder, and
only those addressed to its own instance (the daemon latches the first instance it hears).
"""

from __future__ import annotations

import contextlib
import gc
import math
import sys
import threading
import time
from collections import Counter, deque
from dataclasses import asdict
from pathlib import Path
from typing import Any

import msgspec
import numpy as np
import zenoh

import wmm_qp as w
from wmm_qp.config import ShapeConfig
from wmm_qp.scene import Scene, load_scene
from wmm_qp.tasks import orientation_error as log_rotation_error
from wmm_qp.tasks import quat_to_matrix, rotation_to_quat

from .config import ServiceConfig
from .keys import Keys
from .protocol import (
    CommandMsg,
    InfoMsg,
    ModeMsg,
    ObstaclesMsg,
    SetpointMsg,
    StateMsg,
    StatusMsg,
    TelemetryMsg,
    TruthMsg,
    encode,
)
from .rate_loop import LoopTiming, Mailbox, RateLoop, StateLoop, realtime_priority
from .smoother import OrientationTarget, SetpointSmoother, VelocityEstimator
from .tick_stages import STAGES, TickStages
from .transport import ROLE_DAEMON, open_session
from .validation import Validator

_NAN3 = [math.nan] * 3
ROUND_TRIPS = 50
"""States in the state-age window (each bounded by the time since the command it applied)."""
SEQ_JUMP_MAX = 100_000
"""A state seq further ahead of the last one than this is refused (a sim steps at ~1 kHz)."""
_SENT = 1024  # publication times kept per command seq (a ring)
_POLL, _VALIDATION, _WATCHDOGS, _RUCKIG, _STEP, _PUBLISH, _TELEMETRY, _STATUS, _QUERIES = range(len(STAGES))


def _matching(pub: Any) -> bool:
    """Some subscriber matches the publisher (True when Zenoh cannot tell)."""
    try:
        return bool(pub.matching_status.matching)
    except Exception:
        return True


def _say(line: str) -> None:
    """Write a line to stderr; never raises (a closed pipe, a full terminal)."""
    with contextlib.suppress(Exception):
        print(line, file=sys.stderr, flush=True)


class FaultLog:
    """Fault lines written by a thread of their own, so that a slow or closed stderr can neither
    block nor stop the control thread; at most ``depth`` lines wait, the rest are counted.

    Args:
        depth: lines kept while the writer is behind.
    """

    def __init__(self, depth: int = 256) -> None:
        self._q: deque[str] = deque()
        self._depth = depth
        self.dropped = 0
        self._wake = threading.Event()
        self._stop = False
        self._thread = threading.Thread(target=self._run, name="fault-log", daemon=True)
        self._thread.start()

    def __call__(self, line: str) -> None:
        if len(self._q) >= self._depth:
            self.dropped += 1
            return
        self._q.append(line)
        self._wake.set()

    def _run(self) -> None:
        while True:
            self._wake.wait(0.5)
            self._wake.clear()
            while self._q:
                _say(self._q.popleft())
            if self._stop:
                return

    def close(self) -> None:
        """Write what is left and end the thread."""
        self._stop = True
        self._wake.set()
        self._thread.join(timeout=2.0)
        if self.dropped:
            _say(f"wmm-qp serve: {self.dropped} fault lines dropped (stderr was too slow)")


class LeaseHeld(Exception):
    """Another daemon holds the robot's control lease.

    Attributes:
        robot: ``<prefix>/<robot>``.
        holder: the holder's id.
    """

    def __init__(self, robot: str, holder: str) -> None:
        self.robot = robot
        self.holder = holder
        super().__init__(f"robot {robot} is already controlled by daemon {holder} "
                         f"(its lease token {robot}/lease/{holder} is alive); stop that daemon first, "
                         f"or start this one with --wait-lease to take over when it ends")


def _xd(ref: w.Reference) -> list[float]:
    """The reference's target for messages (NaN when it means "where the EE is")."""
    return list(_NAN3) if ref.x_d is None else ref.x_d.tolist()


class ControlCore:
    """The daemon's logic without transport: modes, watchdogs, smoothing, the controller.

    The :class:`Daemon` feeds it validated messages and publishes what it returns; tests
    can drive it directly with a fake clock.

    With the pose task (``ctl_cfg.task.kind = "pose"``) the reference carries an orientation
    target too (:class:`~.smoother.OrientationTarget`): latched from the EE's orientation
    wherever the position target is latched (a mode change, hold, after a safe stop), and
    set by the setpoints' ``q`` and ``w`` in the modes that follow setpoints. With the position
    task a setpoint's orientation is ignored and counted (``orientation_ignored``).

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
        # Bounds (13) brake from where the joints can be when the next command (or the robot's
        # own command timeout) takes over: over a transport that is longer than in-process.
        hold = max(ctl_cfg.state_latency, svc.watchdog.command_hold)
        self.cfg = ctl_cfg.with_(rate_hz=svc.loop.rate_hz, state_latency=hold)
        self.robot = robot
        self.model = w.WmmModel(robot)
        self.kind = kind or self.cfg.kind
        self.ctl = w.make_controller(self.kind, self.model, self.cfg)
        # the scene: its obstacles and fence are rows of the QP controller's stages (the baselines
        # have none); every controller's setpoints are clamped into the fence (on_setpoint)
        self.scene = scene if scene is not None else load_scene()
        self.ctl.set_scene(self.scene)
        self.live_obstacles: tuple[ShapeConfig, ...] = ()
        self.obstacles_time = -math.inf  # [s] the last live obstacles message (-inf: none yet)
        self.obstacles_stale = False
        self.z_floor = robot.base.floor_z + self.cfg.collision.floor_margin  # setpoints stay above it
        self.clamped = 0  # setpoints clamped into the fence / above the floor margin
        self.last_clamp = ""
        self.ctl.warm_up()  # the compiled kernels are loaded before the loop, not in its first tick
        self.dt = self.cfg.dt
        if 2.0 * self.dt > svc.watchdog.state_age_max:
            raise w.ConfigError("<service config>", "loop.rate_hz",
                                f"{svc.loop.rate_hz:g} Hz is too slow for watchdog.state_age_max "
                                f"({svc.watchdog.state_age_max * 1e3:g} ms): a state is up to two periods "
                                f"old when it is used; raise the rate or state_age_max (and command_hold)")
        sm = svc.smoothing
        self.smoother = SetpointSmoother(self.dt, sm.v_max, sm.a_max, sm.j_max)
        self.estimator = VelocityEstimator(v_max=sm.v_max)
        self.pose = self.cfg.task.kind == "pose"
        self.orient = OrientationTarget(self.dt)  # the pose task's orientation target
        self.orientation_ignored = 0  # setpoints whose orientation the position task ignored
        self.mode = w.Mode.HOLD
        self.direction: np.ndarray | None = None
        self.state: w.RobotState | None = None
        self.state_msg: StateMsg | None = None
        self.state_time = -math.inf
        self.setpoint_time = -math.inf
        self.need_latch = True
        self.safe = False
        self.last_fault = ""
        self.last_fault_time = -math.inf  # [s] clock value when last_fault was recorded (-inf: none)
        self.sim_alive = False
        self.cmd: w.Command | None = None
        self.ref = w.Reference(mode=w.Mode.HOLD)
        self._ref = w.Reference(mode=w.Mode.HOLD)  # the one tick() refills
        self.ref_valid = False  # self.ref was computed from the current latch
        self.ee_error = math.nan
        self.faults: Counter[str] = Counter()
        self.now = 0.0
        self.t0 = 0.0  # [s] clock value at the loop's start (fault messages say time since)
        self.state_fresh = False
        self.say: Any = _say  # where fault lines go (the Daemon hands them to a FaultLog)
        self.lease = "core"  # this daemon's control lease id (the Daemon sets its Zenoh id)
        self.lease_lost = False  # the sim applies another holder's commands
        self.lease_holder = ""  # the holder the sim reports
        # one robot: the sim instance latched from the first state, and a second source
        self.instance = ""
        self.foreign = ""
        self.foreign_time = -math.inf
        self.twin_seen = False  # a second instance was seen: never latch another one by itself
        self.last_state_seq = -1
        # the last command the robot applied before this daemon drove it (a restarted daemon):
        # not of this daemon's stream, until the robot applies one of this daemon's (-1: none)
        self.inherited_cmd_seq = -1
        # the sim's own referee and firmware
        self.firmware_seen = -1  # protective stops + firmware refusals of the latched instance (-1: no state yet)
        self.truth: TruthMsg | None = None  # the latched instance's last evaluation data (optional)
        self.event_fault = ""  # a fault that happened (not a condition): holds the safe stop
        self.event_until = -math.inf
        self.protective = ""
        # state age without shared clocks: command seq → its publication time
        self.seq = 0
        self._sent_t = np.full(_SENT, -math.inf)
        self._sent_seq = np.full(_SENT, -1, dtype=np.int64)
        self._age = [math.nan] * ROUND_TRIPS  # per-state upper bounds of the age [s]
        self._n_age = 0
        self.round_trip = math.nan
        # bounds (13)'s latency margin: the robot's own command timeout plus the state's age
        # (command_hold = timeout + state_age_max, the worst the watchdog allows); with the state
        # trigger the age is the measured one (follow_state_age, set by the Daemon)
        self.follow_state_age = False
        self.command_timeout = svc.watchdog.command_hold - svc.watchdog.state_age_max
        self.latency = self.cfg.state_latency  # [s] the margin the controller uses now
        self.stages: TickStages | None = None  # the breakdown's stopwatch (None: off)
        self.step_ns = 0  # [ns] the last ctl.step
        # one operator per setpoint stream
        self.operator = ""
        self.operator_time = -math.inf
        self.operator_stamp = -math.inf
        self.operator_conflicts = 0
        self.refused: Counter[str] = Counter()  # setpoints and states refused after validation
        self.resume_needed = False
        self.anchor_on_command = False  # bounds (13) start from the last command (see _anchored)
        self.cmd_state_seq = -1  # seq of the state this tick's command comes from (-1: predicted)
        self._anchor: w.RobotState | None = None  # the anchored state handed to the controller
        # the daemon's own stall: past the robot's command timeout the robot stops by itself
        wd = svc.watchdog
        # [s] a gap in the commands this long counts as a break: inside the robot's command
        # timeout (command_hold − state_age_max). A stop the robot makes on its own (a gap that
        # jitter stretched past its timeout) shows in its state and breaks the stream too.
        self.stream_break = 0.8 * (wd.command_hold - wd.state_age_max)
        self._last_sent_t = -math.inf
        self.stream_broken = False
        self.stream_start = 0  # seq of the first command of the current stream

    # ------------------------------------------------------------------ inputs
    def on_state(self, msg: StateMsg, now: float) -> bool:
        """A validated state arrived at ``now`` [s]; False: refused (another source, old seq).

        The first state latches the sim's instance. A state of another instance while the
        latched one is alive is a second robot on this key: refused, counted and a fault (a
        safe stop while it lasts); once the latched instance has been silent for
        ``state_timeout`` a new instance is a restarted sim and is latched instead. A state
        whose seq does not increase (a replay, or reordering) is refused.
        """
        if msg.instance != self.instance:
            if self.instance and (self.twin_seen or now - self.state_time <= self.svc.watchdog.state_timeout):
                self.refused["instance"] += 1
                self.foreign, self.foreign_time = msg.instance, now
                self.twin_seen = True
                return False
            if self.instance:
                self._fault(f"sim instance changed ({self.instance} -> {msg.instance}: a restarted sim)")
            self.instance = msg.instance
            self.inherited_cmd_seq = msg.cmd_seq  # another daemon's (or none, -1)
            self.anchor_on_command = False  # a new robot: its rates are what it executes
            self.cmd = None  # and the last command was another robot's
            self.last_state_seq = -1
            self.firmware_seen = -1
            self.truth = None
            self._reset_age()
        if msg.seq <= self.last_state_seq or (self.last_state_seq >= 0
                                              and msg.seq > self.last_state_seq + SEQ_JUMP_MAX):
            self.refused["state_seq"] += 1  # old (replayed, reordered), or a forged jump ahead
            return False
        self.last_state_seq = msg.seq
        if msg.cmd_seq != self.inherited_cmd_seq:
            self.inherited_cmd_seq = -1  # the robot applied one of this daemon's commands
        self.state_msg = msg
        self.state = w.RobotState(q_base=msg.q_base, q_arm=msg.q_arm,  # type: ignore[arg-type]
                                  v_arm=msg.v_arm, wheel_speeds=msg.wheel_speeds)  # type: ignore[arg-type]
        self.state_time = now
        self.state_fresh = True
        self.lease_holder = msg.lease
        total = msg.protective_stops + msg.refused.get("firmware", 0)
        if 0 <= self.firmware_seen < total:  # the robot's own reports, not an evaluation's
            self._event(f"robot firmware reported {total - self.firmware_seen} new protective stop(s) or "
                        f"refused command(s) ({msg.protective_reason or 'no reason given'})", "robot firmware", now)
        self.firmware_seen = total
        self.protective = msg.protective_reason if msg.protective_stop else ""
        cs = msg.cmd_seq
        if cs >= max(0, self.stream_start) and self._sent_seq[cs % _SENT] == cs:  # this stream's only
            # this state applied command cs: it is younger than the time since cs was published
            self._age[self._n_age % ROUND_TRIPS] = now - float(self._sent_t[cs % _SENT])
            self._n_age += 1
            if self._n_age >= ROUND_TRIPS and self._n_age % 8 == 0:
                ages = sorted(self._age)  # (np.median of 50 floats: ~15 µs; this: ~2 µs)
                self.round_trip = 0.5 * (ages[(ROUND_TRIPS - 1) // 2] + ages[ROUND_TRIPS // 2])
                if self.follow_state_age:
                    self._set_latency(self.command_timeout + min(ages[-1], self.svc.watchdog.state_age_max))
        return True

    def on_truth(self, msg: TruthMsg) -> None:
        """A validated ``sim/truth`` message: kept for telemetry's ``ee_error`` and the status's
        ``sim_violations`` when it is the latched instance's; the control path never reads it."""
        if msg.instance == self.instance:
            self.truth = msg

    def _set_latency(self, latency: float) -> None:
        """Bounds (13)'s latency margin [s] (and the collision rows', which share it): the
        state's age when the command acts, plus the robot's own command timeout."""
        self.latency = latency
        self.ctl.set_latency(latency)

    def _reset_age(self) -> None:
        """Empty the state-age window (a new robot, or a new stream); bounds (13) go back to the
        worst age the watchdog allows."""
        self._age = [math.nan] * ROUND_TRIPS
        self._n_age = 0
        self.round_trip = math.nan
        if self.latency != self.cfg.state_latency:
            self._set_latency(self.cfg.state_latency)

    @property
    def lease_taken(self) -> bool:
        """The sim applies the commands of another lease holder."""
        return bool(self.lease_holder) and self.lease_holder != self.lease

    def _left_stream(self, msg: StateMsg) -> bool:
        """The state applied a command of the current stream and shows the robot's own stale or
        protective stop: the robot stopped following this stream. A robot that another daemon
        drove before this one (a restarted daemon) reports that daemon's last command, in its
        stale stop, until it applies one of this daemon's: that is no stop of this stream."""
        return ((msg.stale_stop or msg.protective_stop) and 0 < self.stream_start <= msg.cmd_seq
                and msg.cmd_seq != self.inherited_cmd_seq)

    def late(self, now: float) -> bool:
        """More than the robot's command timeout since the last command was published."""
        return math.isfinite(self._last_sent_t) and now - self._last_sent_t > self.stream_break

    def break_stream(self, why: str) -> None:
        """The robot no longer follows this daemon's commands: this daemon stalled past the
        robot's command timeout, the robot stopped itself (its timeout, a protective stop),
        or another daemon holds the lease.

        The robot is braking by itself, at rates the daemon does not know: a command now would
        jump from them. Until a state shows the robot at rest in its own stop, :meth:`tick` sends
        nothing; then the stream starts again from the measured rates, in hold until a mode
        message resumes (``resume = "manual"``).
        """
        self._fault(why)
        self.stream_broken = self.safe = True
        self._reset_age()  # silent meanwhile: the states' ages say nothing about the link
        self.anchor_on_command = False
        self._last_sent_t = -math.inf  # the next stream starts its own clock

    def sent(self, seq: int, now: float) -> None:
        """Command ``seq`` was published at ``now`` [s] (for the round trip and the stream)."""
        self._sent_t[seq % _SENT] = now
        self._sent_seq[seq % _SENT] = seq
        self._last_sent_t = now

    def _event(self, what: str, kind: str, now: float) -> None:
        """A fault that happened once: a safe stop for ``state_timeout``, then (manual) a hold."""
        self._fault(what, kind)
        self.event_fault = what
        self.event_until = now + self.svc.watchdog.state_timeout

    def on_mode(self, msg: ModeMsg) -> None:
        """A validated mode change: switch and re-latch the target from the current EE.

        It is also the explicit act that resumes after a safe stop (``resume = "manual"``):
        one sent during the safe stop itself is overruled by the hold that follows the fault,
        so resuming takes a mode message after the fault has cleared.
        """
        self.mode = w.Mode(msg.mode)
        self.direction = None if msg.direction is None else np.asarray(msg.direction, dtype=float)
        self.need_latch = True
        if not self.safe:
            self.resume_needed = False

    def on_setpoint(self, msg: SetpointMsg, now: float) -> bool:
        """A validated setpoint: feed the smoother (track and null-space DM modes only).

        One operator holds the stream: the first source, for as long as its setpoints keep
        coming (``operator_timeout``); another source's setpoints are refused and counted
        (``operator``), and so is a setpoint whose stamp does not increase (``stamp``: a frozen
        or replayed stream would otherwise look alive and never move the EE). A stamp more than
        ``setpoint_timeout`` behind the last one starts a new stream (a restarted client, or
        one bogus far-future stamp before it), reported as a fault.

        Returns:
            False when the setpoint was refused.
        """
        wd = self.svc.watchdog
        if msg.source != self.operator:
            if self.operator and now - self.operator_time < wd.operator_timeout:
                self.refused["operator"] += 1
                self.operator_conflicts += 1
                self._fault(f"setpoint conflict (from {msg.source!r} refused: {self.operator!r} holds the stream)")
                return False
            self.operator, self.operator_stamp = msg.source, -math.inf
        if not msg.stamp > self.operator_stamp:
            if msg.stamp < self.operator_stamp - wd.setpoint_timeout:  # far behind: a new stream
                self._fault(f"setpoint stamp jumped back (from {msg.source!r}: {msg.stamp!r} after "
                            f"{self.operator_stamp!r}; taken as a restarted stream)")
            else:
                self.refused["stamp"] += 1
                self._fault(f"setpoint stamp not increasing (from {msg.source!r}: {msg.stamp!r} after "
                            f"{self.operator_stamp!r})")
                return False
        self.operator_time, self.operator_stamp = now, msg.stamp
        self.setpoint_time = now
        if not self.pose and (msg.q is not None or msg.w is not None):
            self.orientation_ignored += 1  # the position task (r = 3) has no orientation target
        if self.mode not in (w.Mode.TRACK, w.Mode.DM_NULLSPACE) or self.need_latch:
            return True
        if self.pose:
            self.orient.set_target(msg.q, msg.w)
        x, moved = self.scene.clamp_target(np.asarray(msg.x, dtype=float), self.z_floor)  # never beyond the fence
        if moved:
            self.clamped += 1
            self.last_clamp = f"setpoint clamped to the fence: {moved}"
        if msg.xd is not None:  # a scripted trajectory: its own feed-forward velocity
            xd = np.asarray(msg.xd, dtype=float)
            if moved:
                xd = np.where(x != np.asarray(msg.x, dtype=float), 0.0, xd)  # no feed-forward along a clamped axis
            self.smoother.set_target(x, xd)
        else:
            xf, v = self.estimator.update(x, msg.stamp)
            self.smoother.set_target(xf, v)
        return True

    def on_obstacles(self, shapes: tuple[ShapeConfig, ...], now: float) -> None:
        """A validated live obstacle set arrived: it replaces the previous live set, atomically
        (the controller sees it from the next tick on); the scene's obstacles stay."""
        self.live_obstacles = shapes
        self.obstacles_time = now
        if self.obstacles_stale:
            self.say(f"wmm-qp serve: live obstacles fresh again ({len(shapes)})")
        self.obstacles_stale = False
        self.ctl.set_obstacles(self.scene.obstacles + shapes)

    def check_obstacles(self, now: float) -> None:
        """The live set goes stale after ``watchdog.obstacles_timeout`` without a message: it is
        kept (said once, and shown by the status)."""
        if (not self.obstacles_stale and self.obstacles_time > -math.inf
                and now - self.obstacles_time > self.svc.watchdog.obstacles_timeout):
            self.obstacles_stale = True
            self.say(f"wmm-qp serve: live obstacles stale (none for {now - self.obstacles_time:.2f} s); "
                     f"the last set ({len(self.live_obstacles)}) is kept")

    def collision_on(self) -> bool:
        """The controller has collision rows (the status's and the info's ``collision``)."""
        return self.ctl.collision_on

    def collision_summary(self) -> str:
        """One line: whether the controller has collision rows, and what they keep apart."""
        return self.ctl.collision_summary()

    def on_sim_alive(self, alive: bool) -> None:
        """The sim's liveliness token appeared or vanished."""
        if self.sim_alive and not alive:
            self._fault("sim lost (liveliness)")
            self.state_time = -math.inf
            self.safe = self.state is not None  # the next ticks brake (see _safe_stop)
        self.sim_alive = alive

    def _fault(self, what: str, kind: str | None = None) -> None:
        """Record a fault (and say it once on stderr when it is new).

        Args:
            what: the fault, as the status shows it.
            kind: its key in ``status.faults`` (default: ``what`` up to its first " (").
        """
        if what != self.last_fault:
            st = self.state
            where = (f" [t={self.now - self.t0:.3f} s, mode {self.mode.value}, q_base "
                     f"{np.round(st.q_base, 4).tolist()}, q_arm {np.round(st.q_arm, 4).tolist()}]"
                     if st is not None else "")
            self.say(f"wmm-qp serve: fault: {what}{where}")
        self.last_fault = what
        self.last_fault_time = self.now
        self.faults[kind or what.split(" (")[0]] += 1

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
        self.need_latch = False
        self.ref_valid = False

    def _latch_orientation(self) -> None:
        """The orientation target := the EE's orientation now (``model.ee_pose``), at rest."""
        assert self.state is not None
        _, R = self.model.ee_pose(self.state.q_base, self.state.q_arm)
        self.orient.reset(rotation_to_quat(R))

    # ------------------------------------------------------------------ one tick
    def tick(self, now: float) -> w.Command | None:
        """One control tick at ``now`` [s]; returns the command to publish (None: nothing)."""
        wd = self.svc.watchdog
        self.now = now
        if self.state is None:
            return None
        if not self.stream_broken and self.late(now):
            self.break_stream(f"command stream broken ({(now - self._last_sent_t) * 1e3:.0f} ms without a "
                              f"command: the robot stops itself)")
        msg = self.state_msg
        if not self.stream_broken and self.state_fresh and msg is not None and self._left_stream(msg):
            cause = f"protective stop: {msg.protective_reason}" if msg.protective_stop else "its command timeout"
            self.break_stream(f"the robot stopped following the commands ({cause})")
        if self.lease_taken:
            if not self.lease_lost:
                self.break_stream(f"lease lost (the sim applies the commands of daemon {self.lease_holder})")
                self.lease_lost = True
            return None  # another daemon commands the robot: send nothing
        self.lease_lost = False
        if self.stream_broken:  # wait for a state of the robot at rest in its own stop
            if not (self.state_fresh and msg is not None and (msg.stale_stop or msg.protective_stop)
                    and not any(msg.v_arm) and not any(msg.wheel_speeds)):
                return None
            self.stream_broken = False
            self.anchor_on_command = False
        if not self.anchor_on_command:  # this tick's command starts a stream (the referee's baseline)
            self.stream_start = self.seq + 1  # the seq the daemon gives it
        if (why := self.hazard(now)) is not None:
            cmd = self._safe_stop(why)
            if self.stages is not None:
                self.stages.lap(_WATCHDOGS)
            return cmd
        if self.safe:  # the fault cleared: re-latch from the measured state
            self.safe = False
            self.need_latch = True
            # hold where the robot is until a mode message resumes a task; a daemon that was
            # holding has no task to resume (an idle robot's faults need no operator)
            if wd.resume == "manual" and self.mode != w.Mode.HOLD:
                self.mode, self.direction = w.Mode.HOLD, None
                self.resume_needed = True
        self.cmd_state_seq = self.last_state_seq if self.state_fresh else -1
        if not self.state_fresh and self.cmd is not None:
            self._predict_state()
        self.state_fresh = False
        if self.need_latch:
            self._latch()
        if (not self.smoother.resting and self.mode in (w.Mode.TRACK, w.Mode.DM_NULLSPACE)
                and now - self.setpoint_time > wd.setpoint_timeout):
            self.smoother.bring_to_rest()
        if self.mode == w.Mode.HOLD and not self.smoother.resting:
            self.smoother.bring_to_rest()
        if self.pose and not self.orient.resting and (
                self.mode not in (w.Mode.TRACK, w.Mode.DM_NULLSPACE)
                or now - self.setpoint_time > wd.setpoint_timeout):
            self.orient.bring_to_rest()
        # ground-truth error of the state (the previous tick's command) against its target
        if self.ref_valid and self.truth is not None and self.mode != w.Mode.DM_CARTESIAN:
            x_prev = self.ref.x_d
            self.ee_error = math.dist(self.truth.ee_true, x_prev.tolist()) if x_prev is not None else math.nan
        else:
            self.ee_error = math.nan
        stages = self.stages
        if stages is not None:
            stages.lap(_WATCHDOGS)
        x_d, xd_d = self.smoother.step()
        # one Reference, refilled (a new one re-validates its arrays: ~4 µs); the smoother and the
        # orientation target return fresh float arrays of the right sizes
        ref = self.ref = self._ref
        ref.mode, ref.x_d, ref.xd_d, ref.direction = self.mode, x_d, xd_d, self.direction
        if self.pose:
            ref.quat_d, ref.omega_d = self.orient.step()
        self.ref_valid = True
        state = self._anchored()
        if stages is not None:
            stages.lap(_RUCKIG)
        t = time.perf_counter_ns()
        cmd = self.ctl.step(state, self.ref)
        self.step_ns = time.perf_counter_ns() - t
        if stages is not None:
            stages.lap(_STEP)
        self.anchor_on_command = True
        if cmd.status == w.Status.SAFE_STOP:
            self._fault(f"controller: {cmd.reason}")
            self.smoother.reset(cmd.x if np.isfinite(cmd.x).all() else x_d)
            if self.pose:
                self._latch_orientation()
        self.cmd = cmd
        return cmd

    def hazard(self, now: float) -> str | None:
        """The fault that forces a safe stop now, or None.

        Conditions: no valid state for ``state_timeout`` (or the sim's token vanished); a second
        sim instance on the key within ``state_timeout``; the sim's firmware in a protective
        stop; the state older than ``state_age_max`` (round trip); and, for ``state_timeout``
        after it happened, a rise of the sim's violation counts.
        """
        wd = self.svc.watchdog
        if now - self.state_time > wd.state_timeout:
            return f"state stale (none valid for > {wd.state_timeout * 1e3:.0f} ms)"
        if now - self.foreign_time <= wd.state_timeout:
            return (f"second state source (sim instance {self.foreign} on the key besides the latched "
                    f"{self.instance}: two robots under one id)")
        if self.protective:
            return f"sim protective stop ({self.protective})"
        if self.round_trip > wd.state_age_max:
            return (f"state too old (median age bound {self.round_trip * 1e3:.1f} ms over {ROUND_TRIPS} "
                    f"states; bounds (13) allow {wd.state_age_max * 1e3:.1f} ms)")
        if now < self.event_until:
            return self.event_fault
        return None

    def _anchored(self) -> w.RobotState:
        """The state handed to the controller: its rates replaced by the last command while
        the robot follows the command stream.

        The acceleration bounds of (13) are q̇_prev ± A·Δt around what the robot will execute
        next: the last command (its drives ramp towards it, and the referee judges each
        command against the previous one). The measured rates lag it by the state's age, and
        a late state would pull the bounds back and let two consecutive commands differ by
        more than A·Δt. The measured rates are used for the first command of a stream (to a
        new sim instance, or after this daemon's own stall) and when the robot stopped
        following the stream (a state that applied one of its commands shows a stale or a
        protective stop); a state from before the stream began does not count.
        """
        st, cmd, msg = self.state, self.cmd, self.state_msg
        assert st is not None
        if not self.anchor_on_command or cmd is None or (msg is not None and self._left_stream(msg)):
            return st
        a = self._anchor  # one object, refilled: a new RobotState re-validates its arrays (~10 µs)
        if a is None:
            a = self._anchor = w.RobotState(q_base=st.q_base, q_arm=st.q_arm)
        a.q_base, a.q_arm, a.v_arm, a.wheel_speeds = st.q_base, st.q_arm, cmd.arm_rates, cmd.wheel_speeds
        return a

    def _predict_state(self) -> None:
        """No new state this tick: assume the last command executed for one period.

        The controller's acceleration bounds start from the state's rates; starting them
        again from an old state would let two consecutive commands differ by 2·A·dt.
        """
        assert self.state is not None and self.cmd is not None
        st, cmd = self.state, self.cmd
        twist = self.model.base.P(float(st.q_base[2])) @ cmd.wheel_speeds
        self.state = w.RobotState(q_base=st.q_base + self.dt * twist,
                                  q_arm=st.q_arm + self.dt * cmd.arm_rates,
                                  v_arm=cmd.arm_rates.copy(), wheel_speeds=cmd.wheel_speeds.copy())

    def _safe_stop(self, why: str) -> w.Command:
        """Brake at the acceleration limits from the last command while the robot follows the
        stream (the state is not trusted), else from the measured rates."""
        if not self.safe:
            if why != self.last_fault:  # an event fault is recorded where it happened
                self._fault(why)
            self.safe = True
        assert self.state is not None
        last = self.cmd if self.anchor_on_command else None  # else the robot does not execute it
        base = w.RobotState(
            q_base=self.state.q_base, q_arm=self.state.q_arm,
            v_arm=last.arm_rates if last is not None else self.state.v_arm,
            wheel_speeds=last.wheel_speeds if last is not None else self.state.wheel_speeds)
        cmd = self.ctl.safe_stop(base, why)
        self.cmd = cmd
        self.anchor_on_command = True
        return cmd

    @property
    def fault_active(self) -> bool:
        """A fault holds the robot now (a safe stop, a broken stream, a lost lease), or the
        daemon holds in ``hold`` until a mode message resumes (``resume_needed``)."""
        return self.safe or self.stream_broken or self.lease_lost or self.resume_needed

    def orientation_error(self) -> float:
        """[rad] the angle between the EE's orientation (the last state; model, odometry) and the
        orientation target (``quat_d``); NaN with the position task or before a state."""
        if not self.pose or self.state is None:
            return math.nan
        _, R = self.model.ee_pose(self.state.q_base, self.state.q_arm)
        return float(np.linalg.norm(log_rotation_error(quat_to_matrix(self.orient.quat), R)))  # ‖log(R_d Rᵀ)‖

    def status(self, loop: LoopTiming, rejected: Counter[str], accepted: dict[str, int]) -> StatusMsg:
        """The status message."""
        cmd = self.cmd
        rows = self.ctl.last_collision_rows()
        return StatusMsg(
            robot=self.svc.robot, stamp=time.time(), mode=self.mode.value,
            state_ok=self.state is not None and not self.safe, safe_stop=self.safe,
            controller_status=cmd.status.value if cmd else "", reason=cmd.reason if cmd else "",
            last_fault=self.last_fault, fault_active=self.fault_active,
            last_fault_age=self.now - self.last_fault_time if math.isfinite(self.last_fault_time) else math.nan,
            loop=loop.stats(), rejected=dict(rejected),
            accepted=accepted,
            sim_violations=dict(self.truth.violations) if self.truth is not None else {},
            x=self._ee_now(), x_d=_xd(self.ref),
            dm=float(cmd.dm) if cmd is not None else math.nan, sim_alive=self.sim_alive,
            faults=dict(self.faults), lease=self.lease, lease_holder=self.lease_holder,
            sim_instance=self.instance, operator=self.operator,
            operator_conflicts=self.operator_conflicts, resume_needed=self.resume_needed,
            round_trip_ms=self.round_trip * 1e3, protective_stop=bool(self.protective),
            quat_d=self.orient.quat.tolist() if self.pose else [],
            orientation_error=self.orientation_error(),
            orientation_ignored=self.orientation_ignored, clamped=self.clamped, last_clamp=self.last_clamp,
            obstacles=len(self.scene.obstacles) + len(self.live_obstacles),
            obstacles_live=len(self.live_obstacles), obstacles_stale=self.obstacles_stale,
            collision_distance=rows.min_distance if rows is not None and math.isfinite(rows.min_distance) else math.nan,
            collision_pair=rows.closest if rows is not None else "",
            collision=self.collision_on(), collision_summary=self.collision_summary())

    def _ee_now(self) -> list[float]:
        """[m] the EE position of the last command, or — when it has none (a safe stop's) — of
        the last state (model, odometry); [] before any state. Never NaN: clients start
        streams from it."""
        cmd = self.cmd
        if cmd is not None and np.isfinite(cmd.x).all():
            return cmd.x.tolist()
        st = self.state
        if st is None:
            return []
        x = self.model.ee_position(st.q_base, st.q_arm)
        return x.tolist() if np.isfinite(x).all() else []

    def config_dict(self) -> dict[str, Any]:
        """The running configuration as plain data (for the ``info`` queryable)."""
        c, r = self.cfg, self.robot
        t = c.task
        return {
            "service": _plain(asdict(self.svc)),
            "controller": {"kind": self.kind, "rate_hz": c.rate_hz, "K_x": c.K_x, "alpha": c.alpha,
                           "k_C": c.k_C, "k_N": c.k_N, "W": c.weights_for(r).tolist(),
                           "direction": c.direction.tolist(), "solver": c.qp.solver,
                           "task": {"kind": t.kind, "r": t.r, "K_R": t.K_R,
                                    "orientation_weight": t.orientation_weight,
                                    "angular_speed_max": t.angular_speed_max,
                                    "angular_recovery_speed": t.angular_recovery_speed}},
            "robot": {"name": r.name, "file": str(r.path) if r.path is not None else "",
                      "ee_frame": r.arm.ee_frame, "joint_types": list(r.arm.joint_types),
                      "start": r.arm.start.tolist()},
        }

    def info(self, loop: LoopTiming, rejected: Counter[str], accepted: dict[str, int]) -> InfoMsg:
        """The ``info`` reply: status, the robot description's names and sizes, the configuration."""
        return InfoMsg(robot=self.svc.robot, stamp=time.time(), status=self.status(loop, rejected, accepted),
                       config=self.config_dict(), joints=list(self.robot.arm.joints),
                       wheels=list(self.model.base.wheel_names), base_kind=self.model.base.kind,
                       task=self.cfg.task.kind, n_arm=self.model.n_arm, n_wheels=self.model.n_wheels,
                       collision=self.collision_on(), collision_summary=self.collision_summary())


def _plain(d: Any) -> Any:
    if isinstance(d, dict):
        return {k: _plain(v) for k, v in d.items()}
    if isinstance(d, float) and not math.isfinite(d):
        return str(d)
    if isinstance(d, int | float | str | bool) or d is None:
        return d
    return str(d)


class Daemon:
    """The control daemon over Zenoh (``wmm-qp serve``).

    Args:
        svc: service config (an open robot id is the robot's name).
        ctl_cfg: controller config.
        robot: robot config.
        kind: controller kind; None = the controller config's.
        wait_lease: when another daemon holds the robot's lease, wait until it is free
            instead of refusing to start (:class:`LeaseHeld`).
        scene: obstacles and the workspace fence (None: ``configs/scenes/default.toml``).
        breakdown: time each stage of every tick that publishes a command
            (:class:`~.tick_stages.TickStages`) and write the summary to this JSON file at exit
            (``wmm-qp serve --breakdown``; ``wmm-qp bench --only daemon``). None: off.
    """

    LEASE_GRACE = 1.0
    """[s] the sim may name another holder this long (tokens propagate) before this daemon
    concludes that it lost a start-up race for the lease."""

    def __init__(self, svc: ServiceConfig, ctl_cfg: w.ControllerConfig, robot: w.RobotConfig,
                 kind: str | None = None, wait_lease: bool = False, scene: Scene | None = None,
                 breakdown: str | Path | None = None) -> None:
        self.wait_lease = wait_lease
        self.breakdown = breakdown
        self.stages = TickStages() if breakdown is not None else None
        svc = svc.with_robot(robot)
        self.svc = svc
        self.core = ControlCore(svc, ctl_cfg, robot, kind, scene)
        self.keys = Keys.of(svc.prefix, svc.robot)
        lim = svc.validation
        self.v_state = Validator(StateMsg, svc.robot, lim, n_arm=robot.n_arm, n_wheels=robot.n_wheels)
        self.v_truth = Validator(TruthMsg, svc.robot, lim)
        self.v_mode = Validator(ModeMsg, svc.robot, lim)
        self.v_setpoint = Validator(SetpointMsg, svc.robot, lim)
        self.v_obstacles = Validator(ObstaclesMsg, svc.robot, lim)
        self.loop: LoopTiming = RateLoop(svc.loop.rate_hz, svc.loop.spin_us * 1e-6)  # run() sets the trigger's
        self.scheduling = "not started"  # set by run(): the control thread's scheduling policy

    def rejected(self) -> Counter[str]:
        """Rejected and refused messages by reason, all keys together."""
        return (self.v_state.rejected + self.v_mode.rejected + self.v_setpoint.rejected
                + self.v_obstacles.rejected + self.v_truth.rejected + self.core.refused)

    def accepted(self) -> dict[str, int]:
        """Accepted messages by key."""
        return {"state": self.v_state.accepted, "mode": self.v_mode.accepted,
                "setpoint": self.v_setpoint.accepted, "obstacles": self.v_obstacles.accepted}

    def run(self, stop: threading.Event, max_ticks: int | None = None) -> StatusMsg:
        """Run until ``stop`` is set (or ``max_ticks``); returns the final status.

        Raises:
            LeaseHeld: another daemon holds the robot's lease (and ``wait_lease`` is off), at
                start or — after a start-up race the other one won — within ``LEASE_GRACE``.
        """
        with open_session(self.svc, ROLE_DAEMON) as session:
            self.core.lease = str(session.info.zid())
            if not self._acquire_lease(session, stop):
                return self.core.status(self.loop, self.rejected(), self.accepted())
            return self._run(session, stop, max_ticks)

    def answer_queries(self, queryable: Any, limit: int) -> int:
        """Answer at most ``limit`` pending ``info`` queries (the rest wait in the queryable's
        FIFO for the next ticks: a burst costs the loop ``limit`` replies a tick, not a stall).

        Returns:
            the number answered.
        """
        core, k = self.core, self.keys
        n = 0
        while n < limit and (q := queryable.try_recv()) is not None:
            n += 1
            try:
                q.reply(k.info, encode(core.info(self.loop, self.rejected(), self.accepted())))
            except Exception as e:  # a vanished querier must not stop the loop
                core.last_fault = f"info reply failed: {e}"
        return n

    def _holders(self, session: zenoh.Session) -> list[str]:
        """The lease holders alive now (liveliness query)."""
        out = []
        for reply in session.liveliness().get(self.keys.lease_all, timeout=0.5):
            if reply.ok is not None:
                out.append(str(reply.ok.key_expr).rsplit("/", 1)[-1])
        return [h for h in out if h != self.core.lease]

    def _acquire_lease(self, session: zenoh.Session, stop: threading.Event) -> bool:
        """Refuse (or wait) while another daemon holds the lease; False: stopped while waiting."""
        robot = self.keys.root
        said = False
        while (held := self._holders(session)):
            if not self.wait_lease:
                raise LeaseHeld(robot, held[0])
            if not said:
                print(f"wmm-qp serve: waiting: robot {robot} is controlled by daemon {held[0]}",
                      file=sys.stderr, flush=True)
                said = True
            if stop.wait(0.2):
                return False
        return True

    def _run(self, session: zenoh.Session, stop: threading.Event, max_ticks: int | None) -> StatusMsg:
        k, core, svc = self.keys, self.core, self.svc
        # After the session opened: Zenoh's own threads keep normal priority, only this one is raised.
        self.scheduling = realtime_priority(svc.loop.rt_priority)
        print(f"wmm-qp serve: control thread: {self.scheduling}; trigger {svc.loop.trigger}",
              file=sys.stderr, flush=True)
        ring = zenoh.handlers.RingChannel
        fifo = zenoh.handlers.FifoChannel
        clock, clock_ns, wall = time.perf_counter, time.perf_counter_ns, time.time
        state_trigger = svc.loop.trigger == "state"
        # The state trigger's states: a callback on Zenoh's own thread stamps each one and hands
        # it over (the newest wins), the control thread sleeps until then (no polling, no spin)
        inbox: Mailbox[tuple[float, zenoh.Sample]] = Mailbox()

        def on_state_sample(sample: zenoh.Sample) -> None:
            inbox.put((wall(), sample))

        sub_state = (session.declare_subscriber(k.state, zenoh.handlers.Callback(on_state_sample, indirect=False))
                     if state_trigger else None)
        ring_state = None if state_trigger else session.declare_subscriber(k.state, ring(1))
        sub_setpoint = session.declare_subscriber(k.setpoint, ring(1))
        sub_mode = session.declare_subscriber(k.mode, fifo(256))
        sub_obstacles = session.declare_subscriber(k.obstacles, ring(1))  # the latest set wins
        sub_truth = session.declare_subscriber(k.sim_truth, ring(1))  # optional: telemetry only
        queryable = session.declare_queryable(k.info, fifo(64))
        alive_sub = session.liveliness().declare_subscriber(k.alive("sim"), fifo(64), history=True)
        token = session.liveliness().declare_token(k.alive("daemon"))
        lease_token = session.liveliness().declare_token(k.lease(core.lease))
        lost_since = math.inf  # [s] since when the sim names another lease holder
        lost = ""
        pub_cmd = session.declare_publisher(k.cmd, express=True,
                                            congestion_control=zenoh.CongestionControl.DROP,
                                            priority=zenoh.Priority.REAL_TIME)
        pub_status = session.declare_publisher(k.status)
        pub_tel = session.declare_publisher(k.telemetry, congestion_control=zenoh.CongestionControl.DROP)
        status_every = max(1, round(svc.loop.rate_hz / svc.loop.status_hz))
        tel_every = svc.loop.telemetry_every
        tel_listened = bool(tel_every)  # re-read with every status: no telemetry built for nobody
        queries_per_tick = svc.loop.queries_per_tick
        period = 1.0 / svc.loop.rate_hz
        stages = self.stages
        core.stages = stages
        v_state = self.v_state
        rx = [0, 0, 0]  # [ns] a state's poll start, decoded, accepted (the breakdown's stages)
        rx_wall = [math.nan]  # [s] the daemon's receipt time of the last accepted state

        def poll_state() -> StateMsg | None:
            """The newest state if one arrived, validated and accepted (``core.on_state``)."""
            t0 = clock_ns() if stages is not None else 0
            if state_trigger:
                got = inbox.take()
                if got is None:
                    return None
                t_rx, s = got  # its receipt on Zenoh's thread (the telemetry's state_rx)
            else:
                assert ring_state is not None
                if (r := ring_state.try_recv()) is None:
                    return None
                t_rx, s = wall(), r  # its receipt (the telemetry's state_rx)
            data = s.payload.to_bytes()
            if stages is not None:
                rx[0], rx[1] = t0, clock_ns()
            m = v_state(data)
            if m is None or not core.on_state(m, clock()):
                return None
            rx_wall[0] = t_rx
            if stages is not None:
                rx[2] = clock_ns()
            return m

        state_loop: StateLoop[StateMsg] | None = None
        if state_trigger:
            state_loop = StateLoop(svc.loop.rate_hz, poll_state, block=inbox.wait)
        loop: LoopTiming = state_loop or RateLoop(svc.loop.rate_hz, svc.loop.spin_us * 1e-6)
        self.loop = loop
        core.follow_state_age = state_loop is not None
        core.say = fault_log = FaultLog()
        gc.collect()
        gc.freeze()
        t0 = loop.start()
        core.t0 = now = t0
        try:
            while not stop.is_set() and (max_ticks is None or loop.ticks < max_ticks):
                # ---- the state: the state loop's wait() polled it, the fixed-rate loop polls now
                if stages is not None:
                    stages.begin(clock_ns())
                m = state_loop.item if state_loop is not None else poll_state()
                if m is not None:
                    if stages is not None:
                        stages.begin(rx[0])
                        stages.lap_at(_POLL, rx[1])
                        stages.lap_at(_VALIDATION, rx[2])
                    if core.lease_taken:
                        lost_since = min(lost_since, now)
                        if now - lost_since > self.LEASE_GRACE and not self.wait_lease:
                            lost = core.lease_holder  # a start-up race, lost: leave the loop
                            break
                    else:
                        lost_since = math.inf
                # ---- the other inputs (FIFO of modes, the latest setpoint and obstacles)
                while (s := sub_mode.try_recv()) is not None:
                    if (mm := self.v_mode(s.payload.to_bytes())) is not None:
                        core.on_mode(mm)
                s = sub_setpoint.try_recv()
                if s is not None and (sp := self.v_setpoint(s.payload.to_bytes())) is not None:
                    core.on_setpoint(sp, now)
                s = sub_obstacles.try_recv()
                if s is not None and self.v_obstacles(s.payload.to_bytes()) is not None:
                    core.on_obstacles(self.v_obstacles.shapes, now)
                s = sub_truth.try_recv()
                if s is not None and (tr := self.v_truth(s.payload.to_bytes())) is not None:
                    core.on_truth(tr)
                if stages is not None:
                    stages.lap(_POLL)
                core.check_obstacles(now)
                # ---- control (stages: watchdogs, ruckig, step)
                cmd = core.tick(now)
                if cmd is not None and core.late(t_pub := clock()):  # this tick itself stalled
                    core.break_stream(f"command stream broken (the tick took "
                                      f"{(t_pub - now) * 1e3:.0f} ms: its command is too late)")
                    cmd = None
                if cmd is not None:
                    core.seq += 1
                    seq = core.seq
                    pub_cmd.put(encode(CommandMsg(
                        robot=svc.robot, seq=seq, stamp=wall(),
                        wheel_speeds=cmd.wheel_speeds.tolist(), arm_rates=cmd.arm_rates.tolist(),
                        status=cmd.status.value, lease=core.lease, instance=core.instance,
                        period=period, state_seq=core.cmd_state_seq, stream=core.stream_start)))
                    cmd_stamp = wall()
                    core.sent(seq, t_pub)
                    if stages is not None:
                        stages.lap(_PUBLISH)
                    # ---- after the command: telemetry (when someone listens), status, queries
                    if tel_listened and loop.ticks % tel_every == 0:
                        fresh = core.cmd_state_seq >= 0
                        ee = core.truth.ee_true if core.truth is not None else _NAN3
                        pub_tel.put(encode(TelemetryMsg(
                            robot=svc.robot, seq=seq, stamp=cmd_stamp, t=now - t0,
                            mode=core.mode.value, x=cmd.x.tolist(), x_d=_xd(core.ref),
                            xd_d=core.ref.xd_d.tolist(), ee_true=ee, ee_error=core.ee_error,
                            wheel_speeds=cmd.wheel_speeds.tolist(), arm_rates=cmd.arm_rates.tolist(),
                            status=cmd.status.value, dm=float(cmd.dm), task_error=float(cmd.task_error),
                            tick_us=loop.last_work * 1e6, step_us=core.step_ns * 1e-3,
                            state_seq=core.cmd_state_seq, state_rx=rx_wall[0] if fresh else math.nan,
                            cmd_stamp=cmd_stamp)))
                    if stages is not None:
                        stages.lap(_TELEMETRY)
                while (a := alive_sub.try_recv()) is not None:
                    core.on_sim_alive(a.kind == zenoh.SampleKind.PUT)
                if loop.ticks % status_every == 0:
                    pub_status.put(encode(core.status(loop, self.rejected(), self.accepted())))
                    tel_listened = bool(tel_every) and _matching(pub_tel)
                if stages is not None:
                    stages.lap(_STATUS)
                self.answer_queries(queryable, queries_per_tick)
                if stages is not None:
                    stages.lap(_QUERIES)
                    if cmd is not None:
                        stages.end()
                    else:
                        stages.discard()
                now = loop.wait()
        finally:
            fault_log.close()
            core.say = _say
            gc.unfreeze()
            final = core.status(loop, self.rejected(), self.accepted())
            for ent in (token, lease_token, sub_state, ring_state, sub_setpoint, sub_mode, sub_obstacles, sub_truth,
                        queryable, alive_sub, pub_cmd, pub_status, pub_tel):
                with contextlib.suppress(Exception):
                    if ent is not None:
                        ent.undeclare()
            if stages is not None and self.breakdown is not None:
                with contextlib.suppress(Exception):
                    stages.write(self.breakdown, {"trigger": svc.loop.trigger, "rate_hz": svc.loop.rate_hz,
                                                  "loop": msgspec.to_builtins(final.loop)})
        if lost:
            raise LeaseHeld(k.root, lost)
        return final
