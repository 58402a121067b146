"""What the daemon's status tells a client about faults and orientation (ControlCore, fake clock).

A client must tell a fault that holds the robot now (``fault_active``) from a ``last_fault``
that cleared long ago (``last_fault_age``); a daemon that starts must not report a fault before
anyone sent anything, also when the robot was driven by an earlier daemon (a restart).
"""

from __future__ import annotations

import math
from collections import Counter

import numpy as np
import pytest
from support.daemon_drive import DT, Plant, mode, setpoint, tick
from wmm_qp_service.config import ServiceConfig
from wmm_qp_service.daemon import ControlCore, reports
from wmm_qp_service.protocol import SetpointMsg, StatusMsg
from wmm_qp_service.rate_loop import RateLoop

import wmm_qp as w


@pytest.fixture(scope="module")
def robot() -> w.RobotConfig:
    return w.load_robot_config()


def make(robot: w.RobotConfig, ctl: w.ControllerConfig | None = None) -> tuple[ControlCore, Plant]:
    core = ControlCore(ServiceConfig(), ctl or w.load_controller_config(), robot)
    return core, Plant(core.model)


def status(core: ControlCore) -> StatusMsg:
    return reports.status(core, RateLoop(500.0, 0.0), Counter(), {})


# ---------------------------------------------------------------- start-up
@pytest.mark.parametrize("earlier", [None, 3, 5000])
def test_a_starting_daemon_reports_no_fault_before_any_client(robot: w.RobotConfig, earlier: int | None) -> None:
    """The daemon starts next to a robot at rest: a fresh one (no command ever applied), or one
    an earlier daemon drove (``earlier``: that daemon's last command seq, the robot in its stale
    stop since that daemon ended). The robot hears nothing of this daemon for its first ticks
    (the sim has not seen its lease token yet), then applies its commands. Hold, no fault, no
    "resume needed", a command every tick. (A restarted daemon took the old daemon's command
    seq in the stale stop for its own stream's stop: a fault, then "resume needed".)"""
    core, plant = make(robot)
    applied = -1 if earlier is None else earlier
    t = 0.0
    for k in range(200):
        ours = applied != (-1 if earlier is None else earlier)
        core.on_state(plant.msg(stale_stop=not ours, cmd_seq=applied), t)
        cmd = core.tick(t)
        assert cmd is not None, core.fault_record.last
        core.stream.numbered()
        core.stream.sent(core.stream.seq, t)
        if k >= 10:  # the robot applies this daemon's commands from now on
            plant.apply(cmd)
            applied = core.stream.seq
        t += DT
    st = status(core)
    assert (st.mode, st.last_fault, st.fault_active, st.resume_needed) == ("hold", "", False, False)
    assert math.isnan(st.last_fault_age) and st.faults == {}
    # the marker of the earlier daemon's seq is gone: a stop of this stream is still seen
    core.on_state(plant.msg(stale_stop=True, cmd_seq=applied), t)
    core.tick(t)  # (at rest already: the stream starts again at once, in hold: nothing to resume)
    assert "its command timeout" in core.fault_record.last
    assert core.fault_record.counts["stream_broken"] == 1 and not status(core).fault_active


# ---------------------------------------------------------------- fault_active and the fault's age
def test_fault_active_while_a_fault_holds_and_the_age_of_a_cleared_one(robot: w.RobotConfig) -> None:
    core, plant = make(robot)
    x0 = core.model.ee_position(plant.q_base, plant.q_arm)
    mode(core, "track")
    t = 0.0
    for _ in range(50):
        core.on_state(plant.msg(), t)
        tick(core, plant, t)
        t += DT
    assert not status(core).fault_active
    t_fault = None
    for _ in range(100):  # the sim hangs: no state, a safe stop
        tick(core, plant, t)
        if t_fault is None and core.fault_record.last:
            t_fault = t
        t += DT
    st = status(core)
    assert st.safe_stop and st.fault_active and st.last_fault_code == "state_stale"
    assert t_fault is not None and st.last_fault_age == pytest.approx(t - DT - t_fault)
    for _ in range(50):  # the sim is back: the daemon holds until a mode message
        core.on_state(plant.msg(), t)
        tick(core, plant, t)
        t += DT
    st = status(core)
    assert not st.safe_stop and st.resume_needed and st.fault_active
    mode(core, "track")  # the client resumes deliberately
    for _ in range(250):  # 0.5 s later
        core.on_state(plant.msg(), t)
        core.on_setpoint(setpoint(x0, t), t)
        tick(core, plant, t)
        t += DT
    st = status(core)
    assert not st.fault_active and st.mode == "track"
    assert st.last_fault_code == "state_stale"  # still there: the age says it is old news
    assert st.last_fault_age == pytest.approx(t - DT - t_fault) and st.last_fault_age > 0.5


def test_a_fault_that_holds_nothing_is_not_active(robot: w.RobotConfig) -> None:
    """A second operator's setpoint is refused and reported; the robot goes on following the first."""
    core, plant = make(robot)
    x0 = core.model.ee_position(plant.q_base, plant.q_arm)
    mode(core, "track")
    t = 0.0
    for _ in range(20):
        core.on_state(plant.msg(), t)
        core.on_setpoint(setpoint(x0, t), t)
        core.on_setpoint(setpoint(x0, t, source="intruder"), t)
        tick(core, plant, t)
        t += DT
    st = status(core)
    assert st.last_fault_code == "setpoint_conflict" and not st.fault_active
    assert 0.0 <= st.last_fault_age <= DT + 1e-9  # recorded at the last tick (the clock of the ticks)


# ---------------------------------------------------------------- orientation error
def test_orientation_error_is_the_angle_to_the_target(robot: w.RobotConfig) -> None:
    from support.daemon_drive import rotated

    core, plant = make(robot, w.load_controller_config().with_(task={"kind": "pose"}))
    t = 0.0
    for _ in range(20):
        core.on_state(plant.msg(), t)
        tick(core, plant, t)
        t += DT
    assert status(core).orientation_error == pytest.approx(0.0, abs=1e-9)  # hold latches the EE's own
    x0 = core.model.ee_position(plant.q_base, plant.q_arm)
    mode(core, "track")
    core.on_state(plant.msg(), t)
    tick(core, plant, t)  # the mode change re-latches the targets
    t += DT
    target = rotated(core.orient.quat, [0.0, 0.0, 1.0], 0.3)
    core.on_state(plant.msg(), t)
    core.on_setpoint(SetpointMsg(robot="wmm", seq=1, stamp=t, x=x0.tolist(), source="op", q=target.tolist()), t)
    tick(core, plant, t)
    t += DT
    # the target jumped 0.3 rad; the EE turned one tick's worth towards it at most
    assert 0.25 < status(core).orientation_error < 0.3 + 1e-9
    for _ in range(1500):
        core.on_state(plant.msg(), t)
        core.on_setpoint(SetpointMsg(robot="wmm", seq=1, stamp=t, x=x0.tolist(), source="op",
                                     q=target.tolist()), t)
        tick(core, plant, t)
        t += DT
    assert status(core).orientation_error < 1e-3
    position, plant2 = make(robot)
    assert math.isnan(status(position).orientation_error)
    position.on_state(plant2.msg(), 0.0)
    tick(position, plant2, 0.0)
    assert math.isnan(status(position).orientation_error)
    assert np.isfinite(status(position).x).all()


def test_a_fault_while_holding_clears_without_a_resume_a_fault_in_a_task_needs_one(robot: w.RobotConfig) -> None:
    """An idle robot (the daemon in hold) whose states stall on a busy host: the fault is
    reported (counted, last_fault) but, once cleared, the daemon holds on by itself: there is
    no task to resume. The same stall in track needs the operator's mode message."""
    for task_mode in ("hold", "track"):
        core, plant = make(robot)
        if task_mode != "hold":
            mode(core, task_mode)
        t = 0.0
        for _ in range(20):
            core.on_state(plant.msg(), t)
            tick(core, plant, t)
            t += DT
        for _ in range(60):  # no state for 120 ms: state stale, a safe stop
            tick(core, plant, t)
            t += DT
        assert core.safe and core.fault_record.counts["state_stale"] == 1
        for _ in range(50):
            core.on_state(plant.msg(), t)
            tick(core, plant, t)
            t += DT
        st = status(core)
        assert not st.safe_stop and st.last_fault_code == "state_stale" and st.mode == "hold"
        assert st.resume_needed == (task_mode != "hold") == st.fault_active, task_mode


def test_fault_keys_are_stable_codes_with_the_message_beside_them(robot: w.RobotConfig) -> None:
    """The status's ``faults`` are keyed by code (what clients and JSON outputs match), whatever a
    message says: a stale state and a second operator, with numbers and names in their messages."""
    import json
    import re

    import msgspec

    from wmm_qp.fault_codes import FaultCode

    core, plant = make(robot)
    x0 = core.model.ee_position(plant.q_base, plant.q_arm)
    mode(core, "track")
    t = 0.0
    for _ in range(20):
        core.on_state(plant.msg(), t)
        core.on_setpoint(setpoint(x0, t), t)
        core.on_setpoint(setpoint(x0, t, source="intruder"), t)
        tick(core, plant, t)
        t += DT
    for _ in range(100):  # no state: the watchdog's stale stop
        tick(core, plant, t)
        t += DT
    out = json.loads(msgspec.json.encode(status(core)))
    assert set(out["faults"]) == {"setpoint_conflict", "state_stale"}, out["faults"]
    assert all(re.fullmatch(r"[a-z][a-z0-9_]*", k) and k in set(FaultCode) for k in out["faults"])
    assert out["last_fault_code"] == "state_stale" and out["last_fault"].startswith("state stale (none valid for > ")
    assert all(re.fullmatch(r"[a-z][a-z0-9_]*", c.value) for c in FaultCode)
    assert len({c.value for c in FaultCode}) == len(FaultCode)
