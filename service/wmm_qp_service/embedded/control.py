"""The control core in a robot's own cycle: read → update → write in one thread, no transport.

:class:`EmbeddedControl` hosts the daemon's :class:`~..daemon.ControlCore` and its
:class:`~..daemon.Cycle` inside a robot side's loop (the sim's step loop, libfranka's control
callback). Each robot cycle the robot side calls:

1. :meth:`EmbeddedControl.update` with the state it just measured — the command's path: the
   state is checked (:meth:`~..validation.Validator.checked`), handed to the core, the tick runs
   (watchdogs, Ruckig, the controller) and the command goes straight to the robot side's input
   (:class:`~.link.InProcessLink`); on the cycles between two ticks (a control rate below the
   robot's, ``decimation``) it is not called;
2. :meth:`EmbeddedControl.after`, after the command is written — the slack: the operator's
   inputs (modes, setpoints, obstacles, validated here, on the cycle's thread, since the core is
   not thread-safe) take effect for the next tick; the state, the evaluation data, telemetry,
   status and ``info`` replies are handed to the service thread (:mod:`.service`) as they are
   (no copies: each is a fresh object the cycle does not touch again), which encodes and
   publishes them off this thread; Python's garbage collector runs here, not in a tick
   (:class:`SlackCollector`).

Nothing here imports Zenoh: tests drive it with a fake clock.
"""

from __future__ import annotations

import math
import sys
import time
from collections import Counter, deque
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

import wmm_qp as w
from wmm_qp.scene import Scene

from ..config import ServiceConfig
from ..daemon import ControlCore, Cycle, FaultLog, Sent, reports
from ..daemon.host import HostInputs
from ..daemon.reports import NAN3
from ..daemon.watchdog import say
from ..protocol import StateMsg, TelemetryMsg, TruthMsg
from .collector import SlackCollector
from .link import InProcessLink
from .timing import CycleTiming, decimation

if TYPE_CHECKING:
    from ..recording.journal import TickJournal

OUTBOX = 4096
"""Messages waiting for the service thread at most (the oldest dropped beyond: a stalled
service thread costs clients messages, never the cycle time)."""

# The interpreter's thread switch interval stays its default (5 ms): a short one makes the cycle
# hand the GIL to the service thread in the middle of its ticks (docs/benchmarks.md §5.5).


class Telemetry(NamedTuple):
    """One tick's telemetry as the cycle hands it over: references to objects the cycle does not
    touch again (the command, the reference's fresh arrays, the truth's lists); the service thread
    builds the message (:func:`telemetry_msg`).

    Attributes:
        sent: the command as sent.
        t: [s] since the loop's start.
        mode: the mode's name.
        x_d, xd_d: [m], [m/s] the reference's target and its velocity (x_d None: the EE).
        ee_true: [m] the ground truth EE position (NaN: unknown).
        ee_error: [m] its error to the previous target.
        tick_us: [µs] the previous tick's work.
        step_us: [µs] ``ctl.step`` of this tick.
        state_seq: the state the command comes from (-1: predicted).
        state_rx: [s] that state's hand-over (wall clock; NaN: predicted).
    """

    sent: Sent
    t: float
    mode: str
    x_d: np.ndarray | None
    xd_d: np.ndarray
    ee_true: list[float]
    ee_error: float
    tick_us: float
    step_us: float
    state_seq: int
    state_rx: float


def telemetry_msg(robot: str, p: Telemetry) -> TelemetryMsg:
    """The telemetry message of one tick's hand-over (the same fields as the daemon's)."""
    cmd = p.sent.cmd
    return TelemetryMsg(
        robot=robot, seq=p.sent.seq, stamp=p.sent.stamp, t=p.t, mode=p.mode, x=cmd.x.tolist(),
        x_d=list(NAN3) if p.x_d is None else p.x_d.tolist(), xd_d=p.xd_d.tolist(), ee_true=p.ee_true,
        ee_error=p.ee_error, wheel_speeds=cmd.wheel_speeds.tolist(), arm_rates=cmd.arm_rates.tolist(),
        status=cmd.status.value, dm=float(cmd.dm), task_error=float(cmd.task_error), tick_us=p.tick_us,
        step_us=p.step_us, state_seq=p.state_seq, state_rx=p.state_rx, cmd_stamp=p.sent.stamp)


class EmbeddedControl:
    """The daemon's control core hosted in a robot side's cycle (see the module docstring).

    Args:
        svc: service config; ``loop.rate_hz`` is the control rate (it divides ``robot_rate_hz``).
        ctl_cfg: controller config.
        robot: robot config.
        deliver: the robot side's command input, called with each command as it is sent.
        robot_rate_hz: [Hz] the robot's cycle rate.
        kind: controller kind (None: the controller config's).
        scene: obstacles and the fence (None: ``configs/scenes/default.toml``).
        on_input: the robot side's own inputs from the service thread, as payloads: ``box``,
            ``gripper`` and ``obstacles`` (its referee's; the core gets the obstacles too).
        clock: [s] monotonic clock (the robot side's).
        wall: [s] wall clock (stamps).
        cuts: the cycle's cost cuts: Python's garbage collector in the slack only
            (:class:`SlackCollector`); False: the interpreter's own collection (``--plain-cycle``:
            to measure what the cuts buy).

    Attributes:
        inbox: (kind, payload) from the service thread: ``mode``, ``setpoint``, ``obstacles``,
            and the robot side's kinds.
        queries: ``info`` queries from the service thread, answered in the slack.
        outbox: what the service thread publishes: ``("state", StateMsg)``, ``("truth",
            TruthMsg)``, ``("tel", Telemetry)``, ``("status", StatusMsg)``, ``("reply", query,
            InfoMsg)``.
        notes: lines from the service thread for the status's ``last_fault`` (a failed reply).
        tel_listened: someone subscribes to the telemetry (the service thread says).
        kick: wakes the service thread (set by it; a no-op without one).
    """

    def __init__(self, svc: ServiceConfig, ctl_cfg: w.ControllerConfig, robot: w.RobotConfig,
                 deliver: Callable[[Any], None], robot_rate_hz: float, *, kind: str | None = None,
                 scene: Scene | None = None, on_input: Callable[[str, bytes], object] | None = None,
                 clock: Callable[[], float] = time.monotonic, wall: Callable[[], float] = time.time,
                 cuts: bool = True) -> None:
        svc = svc.with_robot(robot)
        self.svc = svc
        rate = svc.loop.rate_hz
        self.decimation = decimation(robot_rate_hz, rate)
        self.robot_rate_hz = robot_rate_hz
        self.core = core = ControlCore(svc, ctl_cfg, robot, kind, scene)
        core.stream.follow_state_age = True  # the robot's cycle is the clock: bounds (13) follow the measured age
        core.robot_alive = True  # the robot is this process
        core.who = "wmm-qp embedded"  # its fault lines name the embedded controller, not a daemon
        self.inputs = HostInputs(svc, robot.n_arm, robot.n_wheels)
        self.v_state = self.inputs.v_state
        self.clock, self.wall = clock, wall
        self.link = InProcessLink(self.v_state, deliver)
        self.cycle = Cycle(core, self.link, svc.robot, 1.0 / rate, clock=clock, wall=wall)
        self.timing = CycleTiming(rate, clock, 2048)
        self.on_input = on_input
        self.inbox: deque[tuple[str, bytes]] = deque(maxlen=1024)
        self.queries: deque[Any] = deque(maxlen=64)
        self.outbox: deque[tuple[Any, ...]] = deque(maxlen=OUTBOX)
        self.notes: deque[str] = deque(maxlen=16)
        lp = svc.loop
        self.status_every = max(1, round(rate / lp.status_hz))
        self.tel_every = lp.telemetry_every
        self.tel_listened = bool(self.tel_every)
        self.queries_per_tick = lp.queries_per_tick
        self.kick: Callable[[], object] = lambda: None
        self.wake_every = 1  # the service thread, every cycle: one state per publication burst
        self.cuts = cuts
        self.gc = SlackCollector(cuts)
        self.sent: Sent | None = None
        self._t_update = 0.0
        self._cycles = 0
        self._fault_log: FaultLog | None = None
        self.journal: TickJournal | None = None  # the recording's hook (``sim --embedded --record``)

    # ------------------------------------------------------------------ life
    def start(self) -> float:
        """Before the first cycle: fault lines to their own thread, the collector frozen; returns
        the loop's start [s]."""
        self._fault_log = FaultLog()
        self.core.say = self._fault_log
        self.gc.start()
        self.core.t0 = t0 = self.timing.start()
        return t0

    def stop(self) -> None:
        """After the last cycle (never raises)."""
        self.gc.stop()
        if self._fault_log is not None:
            self._fault_log.close()
            self._fault_log = None
        self.core.say = say

    # ------------------------------------------------------------------ the cycle
    def ticks_now(self, cycle: int) -> bool:
        """Whether robot cycle ``cycle`` (0, 1, …) is one the core ticks in."""
        return cycle % self.decimation == 0

    def update(self, state: StateMsg, now: float) -> Sent | None:
        """Read → update → write: the robot's state of this cycle in, the command out to the
        robot side (``deliver``) at once. Never raises.

        Args:
            state: the state the robot side measured this cycle.
            now: [s] the cycle's start (the robot side's clock).

        Returns:
            the command as sent, or None (nothing sent: a fault holds, or the tick was late).
        """
        self._t_update = self.clock()
        self.link.hand(state, self.wall())
        self.cycle.poll_state()  # refused (counted): the tick runs on the prediction path
        self.inputs.apply(self.core, now)  # validated in the last slack: applied where the daemon applies them
        self.core.check_obstacles(now)
        self.sent = sent = self.cycle.command(now)
        if self.journal is not None:  # copies into shared memory; a writer process serialises
            self.journal.tick(self.core, sent, self.timing.ticks, now - self.core.t0, self.timing.last_work * 1e6)
        return sent

    def after(self, now: float, state: StateMsg | None, truth: TruthMsg | None, ticked: bool) -> None:
        """The slack of a robot cycle, after the command is written (never raises).

        Args:
            now: [s] the cycle's start.
            state: the state to publish (None: none this cycle).
            truth: the evaluation data of that state, for the core (telemetry's EE error) and to
                publish (None: none).
            ticked: :meth:`update` ran this cycle.
        """
        out = self.outbox
        if state is not None:
            out.append(("state", state))
        if truth is not None:
            self.core.on_truth(truth)
            out.append(("truth", truth))
        if ticked:
            try:
                self._after_tick(now)
            except Exception as e:  # a client's bad luck is never the loop's end
                self.core.fault_record.last = f"embedded: {type(e).__name__}: {e}"
        self.gc.slack()
        self._cycles += 1
        if self._cycles % self.wake_every == 0:
            self.kick()

    def _after_tick(self, now: float) -> None:
        core, timing, out = self.core, self.timing, self.outbox
        sent = self.sent
        if sent is not None and self.tel_listened and self.tel_every and timing.ticks % self.tel_every == 0:
            fresh = core.stream.cmd_state_seq >= 0
            ref = core.ref
            out.append(("tel", Telemetry(
                sent, now - core.t0, core.mode.value, ref.x_d, ref.xd_d,
                core.truth.ee_true if core.truth is not None else NAN3, core.ee_error,
                timing.last_work * 1e6, core.step_ns * 1e-3, core.stream.cmd_state_seq,
                self.cycle.state_rx if fresh else math.nan)))
        self._apply_inputs(now)
        if timing.ticks % self.status_every == 0:
            status = reports.status(core, timing, self.rejected(), self.accepted())
            out.append(("status", status))
            if self.journal is not None:
                self.journal.status(timing.ticks, status)
        for _ in range(self.queries_per_tick):
            try:
                q = self.queries.popleft()
            except IndexError:
                break
            out.append(("reply", q, reports.info(core, timing, self.rejected(), self.accepted())))
        while self.notes:
            core.fault_record.last = self.notes.popleft()  # shown by the status; not a fault of the robot
        timing.record(self.clock() - self._t_update)

    def _apply_inputs(self, now: float) -> None:
        """What the service thread received since the last tick, validated here in the slack
        (:meth:`.HostInputs.take`; the next :meth:`update` applies it before its command, as the
        daemon does), and the robot side's own inputs (``box``, ``gripper``, the obstacles)."""
        inputs, inbox = self.inputs, self.inbox
        latest: dict[str, bytes] = {}  # the latest setpoint and obstacle set (as the daemon's rings keep)
        while inbox:
            kind, data = inbox.popleft()
            if kind == "mode":
                inputs.take(kind, data)
            elif kind in ("setpoint", "obstacles"):
                latest[kind] = data
            elif self.on_input is not None:
                self.on_input(kind, data)
        for kind, data in latest.items():
            inputs.take(kind, data)
            if kind == "obstacles" and self.on_input is not None:
                self.on_input(kind, data)

    # ------------------------------------------------------------------ reports
    def rejected(self) -> Counter[str]:
        """Rejected and refused messages by reason (the status's ``rejected``)."""
        return self.inputs.rejected(self.core)

    def accepted(self) -> dict[str, int]:
        """Accepted messages by key (the status's ``accepted``)."""
        return self.inputs.accepted()

    def report(self) -> dict[str, Any]:
        """The run's cycle figures (``--cycle-report``): ticks, misses, the tick's work, the
        collector."""
        t = self.timing
        p50, p99 = t.percentiles_us(50.0, 99.0)
        return {"rate_hz": t.rate_hz, "robot_rate_hz": self.robot_rate_hz, "decimation": self.decimation,
                "cuts": self.cuts, "switch_interval_s": sys.getswitchinterval(),
                "ticks": t.ticks, "deadline_misses": t.deadline_misses,
                "tick_us": {"p50": round(p50, 1), "p99": round(p99, 1), "max": round(t.tick_max * 1e6, 1)},
                "gc": self.gc.report()}
