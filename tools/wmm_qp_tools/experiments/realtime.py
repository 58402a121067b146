"""The real-time driver of a scenario: through the daemon and the sim over Zenoh.

``wmm-qp experiment circle|dm|push --realtime`` runs the experiment's scenario (the same one the
in-process driver runs, :mod:`.scenario`) on sim and daemon processes (:func:`.stack.on_stack`;
the push: each of its runs on a fresh pair). For each phase the client places its box
(``sim/box``, :meth:`~..client.Client.place_box`, waiting until the sim's truth shows it), sends
the phase's mode, takes the phase's anchor from the daemon's first tick in that mode (its
telemetry's ``x``: the EE the daemon estimates, odometry-based) and streams the phase's target at
``SETPOINT_HZ`` for the phase's duration of wall-clock time, or until its ``done``.

The client records (:class:`~.recorder.Recorder`) every state the sim publishes, its evaluation
data (``sim/truth``: ground truth, box, referee, one per state, naming the state's seq) and
every tick's telemetry of the daemon. A log row is one daemon tick of a phase — from the
phase's first tick in its mode, for its duration, up to the tick the daemon made when it
ended (the client waits for that tick to arrive, :func:`caught_up`): the command and the
reference come from the tick's telemetry, the state (joint angles, odometry, torques) is *the
state the daemon used* (:func:`~.recorder.match_states`), and the
truth of that seq gives its ground truth, the box and the stalled joint. The per-tick
:class:`~.trace.Trace` is the in-process one, so the same metrics and the same CSV columns
apply. Time ``t`` is the daemon's tick time since the scenario's first tick.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import msgspec
import numpy as np
from wmm_qp_service.client import Client
from wmm_qp_service.protocol import StateMsg, TelemetryMsg
from wmm_qp_sim import BoxConfig

from wmm_qp.config import FloatArray
from wmm_qp.manipulability import directional_manipulability
from wmm_qp_tools.experiments.progress_bar import Progress
from wmm_qp_tools.experiments.recorder import Recorder, match_states
from wmm_qp_tools.experiments.scenario import Anchor, Phase, Scenario
from wmm_qp_tools.experiments.setup import Setup
from wmm_qp_tools.experiments.stack import RealtimeError, StackOptions, on_stack
from wmm_qp_tools.experiments.trace import Trace

SETPOINT_HZ = 100.0  # [Hz] rate of the scripted setpoint stream (feed-forward velocity included)
SWITCH_TIMEOUT = 5.0  # [s] for the daemon's first tick in a phase's mode, for the sim to show a box
CATCH_UP_SLACK = 0.01  # [s] a phase's window may end this much of daemon time before its wall-clock end


@dataclass
class RealtimeResult:
    """A real-time run: the per-tick trace and the service-side figures.

    Attributes:
        trace: per-tick trace (in-process layout).
        service: loop figures, state age, rejections, faults, exit codes (JSON-able).
    """

    trace: Trace
    service: dict[str, Any]


class ClientProbe:
    """A phase's questions answered over Zenoh (:class:`~.scenario.Probe`): the sim's truth.

    Attributes:
        face_x: [m] the placed box face's initial world x (nan: no box yet).
    """

    def __init__(self, c: Client) -> None:
        self.c = c
        self.face_x = math.nan

    def ee_true(self) -> FloatArray:
        tr = self.c.wait_truth(SWITCH_TIMEOUT)
        if tr is None:
            raise RealtimeError("no ground truth from the sim")
        return np.array(tr.ee_true)

    def place_box(self, box: BoxConfig) -> None:
        self.c.place_box(box.mass, box.mu, box.face_x, box.center_y, box.width, box.height)
        end = time.monotonic() + SWITCH_TIMEOUT
        while not ((s := self.c.wait_truth(0.5)) is not None and math.isfinite(s.box_position)):
            if time.monotonic() > end:
                raise RealtimeError("the sim did not place the box")
        self.face_x = box.face_x

    def box_moved(self) -> float:
        s = self.c.latest_truth()
        return s.box_position - self.face_x if s is not None else math.nan


@dataclass(frozen=True)
class Window:
    """The daemon ticks of one phase.

    Attributes:
        phase: the phase's name.
        mode: its mode.
        start: [s] daemon time of its first tick in that mode.
        duration: [s] the phase's duration.
        last: [s] daemon time of the newest tick received when the phase ended.
    """

    phase: str
    mode: str
    start: float
    duration: float
    last: float

    def holds(self, m: TelemetryMsg) -> bool:
        """Whether the tick ``m`` belongs to the phase."""
        return m.mode == self.mode and self.start <= m.t <= self.last and m.t - self.start < self.duration - 1e-9


def first_tick(rec: Recorder, n: int, mode: str) -> TelemetryMsg:
    """The first telemetry in ``mode`` recorded after the first ``n`` (waits ``SWITCH_TIMEOUT``)."""
    end = time.monotonic() + SWITCH_TIMEOUT
    while True:
        rec.drain()
        m = next((m for m in rec.telemetry[n:] if m.mode == mode), None)
        if m is not None:
            return m
        n = len(rec.telemetry)
        if time.monotonic() > end:
            raise RealtimeError(f"the daemon did not switch to {mode} within {SWITCH_TIMEOUT:g} s "
                                "(no telemetry in that mode: is loop.telemetry_every 0?)")
        time.sleep(0.002)


def run_phase(c: Client, rec: Recorder, phase: Phase, probe: ClientProbe,
              progress: Callable[[float], None]) -> Window:
    """Run one phase (box, mode, anchor, the target streamed at ``SETPOINT_HZ``); ``progress``
    is called with the time [s] since the phase's first tick."""
    if phase.box is not None:
        probe.place_box(phase.box(probe.ee_true()))
    rec.drain()
    n = len(rec.telemetry)
    mode, direction = phase.mode_message()
    c.set_mode(mode, direction)
    first = first_tick(rec, n, mode)
    anchor = Anchor(np.array(first.x))
    t0 = time.monotonic()
    k = 0
    while (t := time.monotonic() - t0) < phase.duration and not (phase.done is not None and phase.done(t, probe)):
        if phase.target is not None:
            g = phase.target(t, anchor)
            c.send_setpoint(g.x_d, g.xd_d, q=g.quat_d)
        rec.drain()
        progress(t)
        k += 1
        time.sleep(max(0.0, t0 + k / SETPOINT_HZ - time.monotonic()))
    caught_up(rec, first.t + min(time.monotonic() - t0, phase.duration) - CATCH_UP_SLACK)
    return Window(phase.name, mode, first.t, phase.duration, rec.telemetry[-1].t)


def caught_up(rec: Recorder, t: float, timeout: float = SWITCH_TIMEOUT) -> None:
    """Drain until a tick of daemon time ``t`` [s] or later has arrived (at most ``timeout`` s):
    on a loaded host this process's receive lags the daemon, and a phase's window ends at the
    newest tick received, so without the wait it would cut off ticks the daemon made in it."""
    end = time.monotonic() + timeout
    rec.drain()
    while rec.telemetry[-1].t < t and time.monotonic() < end:
        time.sleep(0.002)
        rec.drain()


def run_realtime(setup: Setup, scenario: Scenario, opts: StackOptions, *, progress: bool = True) -> RealtimeResult:
    """Run ``scenario`` through the daemon and the sim over Zenoh, in real time.

    Args:
        setup: the robot, the model and configs (the DM W and the log layout); the sim and the
            daemon load the setup's robot file and run under its name (``opts``).
        scenario: the phases.
        opts: how to start the processes (:func:`.stack.options`).
        progress: a progress bar on stderr.

    Returns:
        The trace and the service-side figures (``state_age_us``: the state's age at command
        publication [µs] {p50, p99, max}).

    Raises:
        RealtimeError: the processes did not come up, did not switch mode or produced no trace.
    """
    bar = Progress(f"{scenario.name} (realtime)", progress) if progress else None
    total = scenario.duration

    def drive(c: Client, rec: Recorder) -> tuple[list[Window], ClientProbe]:
        probe = ClientProbe(c)
        windows: list[Window] = []
        for phase in scenario.phases:
            before = sum(w.duration for w in windows)  # [s] of the scenario the phases so far took

            def show(t: float, before: float = before) -> None:
                if bar is not None:
                    bar.update(min(1.0, (before + t) / total))

            windows.append(run_phase(c, rec, phase, probe, show))
        return windows, probe

    try:
        (windows, probe), rec, service = on_stack(opts, drive)
    finally:
        if bar is not None:
            bar.close()
    trace, age = build_trace(setup, rec, windows, scenario.dm_direction, probe.face_x)
    trace.wall_time = service.pop("wall_time")
    service["state_age_us"] = age
    return RealtimeResult(trace=trace, service=service)


def build_trace(setup: Setup, rec: Recorder, windows: list[Window], u: FloatArray,
                box_origin: float = math.nan) -> tuple[Trace, dict[str, float]]:
    """The per-tick trace of the phases' ticks (see the module doc).

    Args:
        setup: the model and W (the DM along ``u``).
        rec: the recorded states, truths and telemetry.
        windows: the phases' ticks, in order.
        u: DM direction (unit).
        box_origin: [m] the placed box face's initial world x (nan: no box).

    Returns:
        (trace, state age at command publication [µs] {p50, p99, max}).
    """
    dec = msgspec.msgpack.Decoder(StateMsg)
    states = [dec.decode(b) for b in rec.states]
    tel: list[TelemetryMsg] = []
    starts: dict[str, int] = {}
    for w in windows:
        starts[w.phase] = len(tel)
        tel += [m for m in rec.telemetry if w.holds(m)]
    if not tel or not states:
        raise RealtimeError("no telemetry of the scenario arrived (is telemetry_every 0?)")
    t0 = windows[0].start
    idx = match_states(states, tel)
    m = setup.model
    W = np.asarray(setup.W, dtype=float)
    rows_st = [states[i] for i in idx]
    truth = rec.truth_by_seq()
    nan3 = [math.nan] * 3
    rows_tr = [truth.get(s.seq) for s in rows_st]
    last_truth = truth[max(truth)] if truth else None
    q = np.array([s.q_arm for s in rows_st])
    wheel = np.array([t.wheel_speeds for t in tel])
    ee_des = np.array([t.x if t.mode == "dm_cartesian" else t.x_d for t in tel])
    dm = np.array([directional_manipulability(m.arm.position_jacobian(qa)[1], u, W) for qa in q])
    age = np.array([(t.stamp - s.stamp) * 1e6 for t, s in zip(tel, rows_st, strict=True)])
    status_counts: dict[str, int] = {}
    for t in tel:
        if t.status != "ok":
            status_counts[f"status {t.status}"] = status_counts.get(f"status {t.status}", 0) + 1
    trace = Trace(
        t=np.array([t.t - t0 for t in tel]),
        mode=[t.mode for t in tel],
        status=[t.status for t in tel],
        q=q,
        qd_cmd=np.array([t.arm_rates for t in tel]),
        wheel_cmd=wheel,
        base_twist_cmd=np.array([m.base.body_twist(w) for w in wheel]),
        base_odom=np.array([s.q_base for s in rows_st]),
        base_true=np.array([t.base_true if t is not None else nan3 for t in rows_tr]),
        ee_des=ee_des,
        ee_true=np.array([t.ee_true if t is not None else nan3 for t in rows_tr]),
        dm=dm,
        tau=np.array([s.tau for s in rows_st]),
        box_displacement=np.array([t.box_position - box_origin if t is not None else math.nan for t in rows_tr]),
        stalled_joint=np.array([t.stalled_joint if t is not None else -1 for t in rows_tr], dtype=int),
        violations=dict(last_truth.violations) if last_truth is not None else {},
        reasons=status_counts,
        phase_starts=starts,
        box_displacement_end=last_truth.box_position - box_origin if last_truth is not None else math.nan,
    )
    summary = {
        "p50": round(float(np.percentile(age, 50)), 1),
        "p99": round(float(np.percentile(age, 99)), 1),
        "max": round(float(age.max()), 1),
    }
    return trace, summary
