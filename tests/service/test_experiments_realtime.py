"""The real-time driver of a scenario (experiments/realtime.py) without processes: a faked client,
recorder and daemon. What it sends for a phase, and which daemon ticks the trace keeps."""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np
import pytest
from wmm_qp_service.protocol import StateMsg, TelemetryMsg, TruthMsg, encode
from wmm_qp_sim import BoxConfig
from wmm_qp_tools.experiments.realtime import ClientProbe, Window, build_trace, caught_up, run_phase
from wmm_qp_tools.experiments.recorder import Recorder
from wmm_qp_tools.experiments.scenario import Anchor, Phase, Probe, Target
from wmm_qp_tools.experiments.setup import make_setup

import wmm_qp as w

X = np.array([1.0, 0.0, 0.0])
EE_TRUE = [0.65, 0.02, 0.49]  # [m] the sim's truth
X_HOLD = [0.6, 0.0, 0.5]  # [m] the daemon's EE estimate in its ticks before the phase's mode
X_PHASE = [0.64, 0.01, 0.48]  # [m] and in the phase's mode
STEP = 0.011  # [m] the box moves this much per setpoint once placed


def telemetry(t: float, mode: str, x: list[float] | None = None, state_seq: int = -1) -> TelemetryMsg:
    x = x or X_HOLD
    return TelemetryMsg(robot="r", t=t, mode=mode, x=x, x_d=x, xd_d=[0.0] * 3, ee_true=EE_TRUE, ee_error=math.nan,
                        wheel_speeds=[0.0] * 4, arm_rates=[0.0] * 7, status="ok", dm=0.0, task_error=0.0,
                        tick_us=0.0, state_seq=state_seq, stamp=t)


class FakeLink:
    """The client, the recorder and the daemon of a run at once: each drain is one daemon tick
    (2 ms of daemon time) in the mode last sent; once placed, the box moves ``STEP`` per setpoint."""

    def __init__(self) -> None:
        self.mode = "hold"
        self.t = 0.0
        self.telemetry: list[TelemetryMsg] = []
        self.calls: list[tuple[Any, ...]] = []
        self.box_position = math.nan

    def set_mode(self, mode: str, direction: list[float] | None = None) -> None:
        self.calls.append(("mode", mode, direction))
        self.mode = mode

    def send_setpoint(self, x: Any, xd: Any = None, q: Any = None) -> bool:
        self.calls.append(("setpoint", np.array(x), np.array(xd), q))
        self.box_position += STEP
        return True

    def place_box(self, mass: float, mu: float, face_x: float, center_y: float, width: float, height: float) -> None:
        self.calls.append(("box", face_x, center_y))
        self.box_position = face_x

    def wait_truth(self, timeout: float = 5.0) -> TruthMsg:
        return TruthMsg(robot="r", t=self.t, instance="i", state_seq=0, base_true=[0.0] * 3, ee_true=EE_TRUE,
                        contact_force=[0.0] * 3, box_position=self.box_position)

    latest_truth = wait_truth

    def drain(self) -> None:  # the recorder's
        self.t += 0.002
        self.telemetry.append(telemetry(self.t, self.mode, X_PHASE if self.mode != "hold" else X_HOLD))


def test_a_phase_in_real_time_places_its_box_sends_its_mode_and_streams_its_target_from_the_daemons_first_tick(
) -> None:
    link = FakeLink()
    link.drain()  # a hold tick before the phase: not its anchor
    anchors: list[tuple[float, np.ndarray]] = []

    def target(t: float, start: Anchor) -> Target:
        anchors.append((t, start.x))
        return Target(start.x + t * X, X)

    def box(ee_true: Any) -> BoxConfig:
        return BoxConfig(mass=1.0, mu=0.5, face_x=float(ee_true[0]) + 0.01, center_y=float(ee_true[1]))

    def moved(_t: float, robot: Probe) -> bool:
        return robot.box_moved() >= 0.05

    phase = Phase("p", w.Mode.TRACK, 5.0, direction=X, target=target, box=box, done=moved)
    window = run_phase(link, link, phase, ClientProbe(link), lambda _t: None)  # type: ignore[arg-type]
    assert link.calls[0] == ("box", pytest.approx(0.66), pytest.approx(0.02))  # 1 cm ahead of the true EE
    assert link.calls[1] == ("mode", "track", [1.0, 0.0, 0.0])  # after the box, before any setpoint
    setpoints = link.calls[2:]
    assert len(setpoints) == 5 and all(c[0] == "setpoint" for c in setpoints)  # done once the box moved 5 cm
    for (t, x0), c in zip(anchors, setpoints, strict=True):
        np.testing.assert_array_equal(x0, X_PHASE)  # the daemon's estimate at its first tick in track
        np.testing.assert_allclose(c[1], np.array(X_PHASE) + t * X)
        np.testing.assert_allclose(c[2], X)
    first = next(m for m in link.telemetry if m.mode == "track")
    assert window == Window("p", "track", first.t, 5.0, link.telemetry[-1].t)


class LateLink:
    """A recorder whose receive lags: the daemon's ticks up to ``t_daemon`` arrive ``lag`` s of
    wall time after the test starts, all at once."""

    def __init__(self, t_daemon: float, lag: float) -> None:
        self.telemetry = [telemetry(0.0, "track")]
        self.at, self.t_daemon = time.monotonic() + lag, t_daemon

    def drain(self) -> None:
        if time.monotonic() >= self.at and self.telemetry[-1].t < self.t_daemon:
            self.telemetry += [telemetry(0.002 * i, "track") for i in range(1, round(self.t_daemon / 0.002) + 1)]


def test_a_phase_ends_at_the_daemons_tick_of_its_end_even_when_this_process_receives_late() -> None:
    """A loaded client receives the daemon's ticks late: the phase's window waits for the tick of
    its end rather than ending at the newest one received (which would drop the push's contact)."""
    link = LateLink(t_daemon=1.0, lag=0.2)
    caught_up(link, 0.99)  # type: ignore[arg-type]
    assert link.telemetry[-1].t >= 0.99
    never = LateLink(t_daemon=0.5, lag=0.0)  # the daemon stopped at 0.5 s: a bounded wait, no raise
    t0 = time.monotonic()
    caught_up(never, 0.99, timeout=0.1)  # type: ignore[arg-type]
    assert 0.1 <= time.monotonic() - t0 < 2.0 and never.telemetry[-1].t == pytest.approx(0.5)


def test_the_realtime_trace_keeps_each_phases_ticks_with_the_states_the_daemon_used() -> None:
    s = make_setup("qp")
    q0 = [float(v) for v in s.robot.arm.start]

    def state(seq: int) -> bytes:
        return encode(StateMsg(robot="r", seq=seq, stamp=0.01 * seq - 0.001, t=0.01 * seq,
                               q_base=[0.001 * seq, 0.0, 0.0], q_arm=q0, v_arm=[0.0] * 7, wheel_speeds=[0.0] * 4,
                               tau=[0.1 * seq] * 7, instance="i"))

    def truth(seq: int, box: float) -> bytes:
        return encode(TruthMsg(robot="r", t=seq * 1e-3, instance="i", state_seq=seq, base_true=[0.0] * 3,
                               ee_true=EE_TRUE, contact_force=[0.0] * 3, box_position=box,
                               stalled_joint=1 if seq == 30 else -1, violations={"position": seq}))

    rec = Recorder(client=None)  # type: ignore[arg-type]
    rec.states = [state(k) for k in range(1, 41)]
    rec.truths = [truth(k, math.nan if k < 20 else 0.70 + 0.001 * (k - 20)) for k in range(1, 41)]
    rec.telemetry = ([telemetry(0.01 * k, "hold", state_seq=k) for k in range(1, 5)]  # before the scenario
                     + [telemetry(0.01 * k, "dm_cartesian", state_seq=k) for k in range(5, 12)]
                     + [telemetry(0.01 * k, "dm_cartesian", state_seq=k) for k in range(12, 20)]  # beyond 0.05 s
                     + [telemetry(0.01 * k, "track", state_seq=k) for k in range(20, 35)]
                     + [telemetry(0.01 * k, "track", state_seq=-1) for k in range(35, 37)]  # predicted ticks
                     + [telemetry(0.01 * k, "hold", state_seq=k) for k in range(37, 40)])  # after it
    windows = [Window("a", "dm_cartesian", 0.05, 0.05, 0.19), Window("b", "track", 0.20, 1.0, 0.36)]
    tr, age = build_trace(s, rec, windows, X, box_origin=0.70)
    assert tr.phase_starts == {"a": 0, "b": 5}
    assert tr.mode == ["dm_cartesian"] * 5 + ["track"] * 17
    np.testing.assert_allclose(tr.t, [0.01 * k - 0.05 for k in [*range(5, 10), *range(20, 37)]], atol=1e-12)
    np.testing.assert_allclose(tr.base_odom[:5, 0], [0.001 * k for k in range(5, 10)])  # the state of each tick
    np.testing.assert_allclose(tr.tau[-2:, 0], [3.5, 3.6])  # a predicted tick: the newest state before it
    assert np.isnan(tr.box_displacement[:5]).all()  # no box yet
    np.testing.assert_allclose(tr.box_displacement[5:8], [0.0, 0.001, 0.002], atol=1e-12)
    assert list(tr.stalled_joint[5:]).count(1) == 1 and tr.stalled_joint[5 + 10] == 1  # seq 30
    assert tr.violations == {"position": 40} and tr.box_displacement_end == pytest.approx(0.020)
    assert math.isnan(tr.box_tilt_end) and set(age) == {"p50", "p99", "max"}
