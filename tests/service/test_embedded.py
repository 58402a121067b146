"""The embedded mode in process, with a fake clock: the sim and the control core in one cycle
(read → update → write, no transport), and every safety behaviour of the split processes in it:
the state-age and stale-command watchdogs, a tick that overruns, faults and the manual resume,
the operator lock, the fence and the collision rows, the referee judging each command as the
robot received it. No Zenoh, no timing (the lease over Zenoh: tests/integration/test_integration_embedded.py)."""

from __future__ import annotations

import gc
import itertools
from collections.abc import Callable, Iterator
from typing import Any

import msgspec
import numpy as np
import pytest
from support.clocks import Clock
from support.controllers import OverLimitOnce
from wmm_qp_service.config import ServiceConfig
from wmm_qp_service.daemon import reports
from wmm_qp_service.embedded import EmbeddedControl, SlackCollector, decimation
from wmm_qp_service.embedded.sim import EmbeddedSim
from wmm_qp_service.protocol import CommandMsg, ModeMsg, SetpointMsg, StateMsg, encode
from wmm_qp_service.validation import Validator
from wmm_qp_sim import load_sim_config
from wmm_qp_sim.robot import SimState

import wmm_qp as w


@pytest.fixture(scope="module")
def robot() -> w.RobotConfig:
    return w.load_robot_config()


@pytest.fixture
def host(robot: w.RobotConfig) -> Iterator[Callable[..., tuple[EmbeddedSim, Clock]]]:
    """Factory of started embedded sims on a fake clock; stopped at teardown."""
    made: list[EmbeddedSim] = []

    def make(ctl_cfg: w.ControllerConfig | None = None, **kw: Any) -> tuple[EmbeddedSim, Clock]:
        clk = Clock()
        emb = EmbeddedSim(ServiceConfig(), load_sim_config(), robot, ctl_cfg or w.load_controller_config(),
                          clock=clk, sleep=clk.sleep, wall=clk.wall, **kw)
        made.append(emb)
        emb.start()
        return emb, clk

    yield make
    for emb in made:
        emb.control.stop()


class Recorder:
    """Keeps what the robot side received (the commands) and reported (the states)."""

    def __init__(self, emb: EmbeddedSim) -> None:
        self.commands: list[CommandMsg] = []
        self.states: list[SimState] = []
        put = emb.inbox.put

        def deliver(msg: CommandMsg) -> None:
            self.commands.append(msg)
            put(msg)

        emb.control.link._deliver = deliver


def cycles(emb: EmbeddedSim, clk: Clock, n: int, rec: Recorder | None = None,
           each: Callable[[int], None] | None = None) -> SimState:
    st = emb.node.sim.state()
    for k in range(n):
        if each is not None:
            each(k)
        st = emb.cycle(clk.t)
        if rec is not None:
            rec.states.append(st)
        emb.wait()
    return st


def post(emb: EmbeddedSim, kind: str, msg: msgspec.Struct) -> None:
    """What the service thread forwards: a payload as it came off Zenoh."""
    emb.control.inbox.append((kind, encode(msg)))


def mode(emb: EmbeddedSim, clk: Clock, name: str) -> None:
    post(emb, "mode", ModeMsg(robot=emb.svc.robot, seq=1, stamp=clk.wall(), mode=name))


def setpoint(emb: EmbeddedSim, clk: Clock, x: np.ndarray, source: str = "op") -> None:
    post(emb, "setpoint", SetpointMsg(robot=emb.svc.robot, seq=1, stamp=clk.wall(), x=x.tolist(), source=source))


def violations(st: SimState) -> int:
    return sum(st.violations.values())


def tracking(emb: EmbeddedSim, clk: Clock, offset: tuple[float, float, float], n: int,
             rec: Recorder | None = None) -> SimState:
    """Track a target ``offset`` [m] from the EE for n cycles (a setpoint every 10)."""
    st = cycles(emb, clk, 20)
    mode(emb, clk, "track")
    x = np.array(st.ee_true) + np.array(offset)
    return cycles(emb, clk, n, rec, each=lambda k: setpoint(emb, clk, x) if k % 10 == 0 else None)


class SlowOnce:
    """A controller that takes ``seconds`` (on the fake clock) in its ``n``-th step, then is itself."""

    def __init__(self, ctl: w.Controller, clk: Clock, n: int, seconds: float) -> None:
        self.ctl, self.clk, self.n, self.seconds, self.steps = ctl, clk, n, seconds, 0

    def step(self, state: w.RobotState, ref: w.Reference) -> w.Command:
        self.steps += 1
        if self.steps == self.n:
            self.clk.t += self.seconds
        return self.ctl.step(state, ref)

    def __getattr__(self, name: str) -> Any:
        return getattr(self.ctl, name)


# ---------------------------------------------------------------- read → update → write
def test_the_command_from_state_k_is_applied_at_step_k_plus_1_in_memory(host: Any) -> None:
    emb, clk = host()
    rec = Recorder(emb)
    tracking(emb, clk, (0.05, 0.0, 0.0), 300)
    by_state = {c.state_seq: c for c in rec.commands}
    states = [m for tag, m, *_ in emb.control.outbox if tag == "state"]
    assert len(states) > 250 and all(isinstance(m, StateMsg) for m in states)  # handed over, not encoded
    applied = [(s.seq, s.cmd_seq) for s in states if s.seq - 1 in by_state]
    assert len(applied) > 250
    assert all(cmd_seq == by_state[seq - 1].seq for seq, cmd_seq in applied)
    assert {c.lease for c in rec.commands} == {emb.control.core.lease}
    assert {c.instance for c in rec.commands} == {emb.node.instance}
    # the round trip is one period, measured: bounds (13) follow it (the robot's timeout + the age)
    core = emb.control.core
    assert core.stream.round_trip == pytest.approx(1e-3, abs=1e-6)
    assert core.stream.latency == pytest.approx(core.stream.command_timeout + 1e-3, abs=1e-5)
    assert emb.control.timing.ticks == emb.cycles and emb.control.timing.deadline_misses == 0


def test_a_control_rate_below_the_robots_ticks_every_nth_cycle(host: Any) -> None:
    emb, clk = host(control_rate=500.0)
    rec = Recorder(emb)
    cycles(emb, clk, 100, rec)
    assert emb.control.decimation == 2 and emb.control.timing.ticks == 50
    assert len(rec.commands) == 50 and {c.period for c in rec.commands} == {2e-3}
    assert [c.state_seq for c in rec.commands] == list(range(1, 101, 2))  # every other state
    assert [m.seq for tag, m, *_ in emb.control.outbox if tag == "state"] == list(range(1, 101))  # every state out


def test_a_control_rate_that_does_not_divide_the_robots_is_a_config_error() -> None:
    assert decimation(1000.0, 250.0) == 4
    with pytest.raises(w.ConfigError, match="must divide the robot's cycle rate 1000 Hz"):
        decimation(1000.0, 300.0)


# ---------------------------------------------------------------- watchdogs: a tick that overruns
def test_a_tick_that_overruns_breaks_the_stream_and_the_robot_brakes_by_itself(host: Any) -> None:
    """A tick that takes 60 ms: its command is not sent (too late), the robot lives through the
    time it took, holding the last command, then braking in its own stale stop; the core brakes its
    stream (the robot refuses the stream it stopped), starts a new one only from the robot at rest
    in that stop, then holds until a mode message resumes. 0 violations."""
    emb, clk = host()
    rec = Recorder(emb)
    core = emb.control.core
    core.ctl = SlowOnce(core.ctl, clk, 400, 0.060)  # type: ignore[assignment]
    st = tracking(emb, clk, (0.15, 0.05, 0.0), 360, rec)
    moving = np.abs(st.v_arm).max()
    assert moving > 0.1  # the robot moves
    sent, n0 = len(rec.commands), len(rec.states)
    cycles(emb, clk, 30, rec)  # the slow tick is among these
    assert dict(core.fault_record.counts) == {"stall_braking": 1, "stream_broken": 1}
    assert core.fault_record.last == "the robot stopped following the commands (its command timeout)"
    assert emb.control.timing.deadline_misses == 1 and emb.node.caught_up >= 59  # the missed steps ran
    after = rec.states[n0:]
    stale = [s for s in after if s.stale_stop]
    assert stale and stale[0].t - after[0].t > 0.05, "the robot did not stop by itself at the slow tick"
    speeds = [np.abs(s.v_arm).max() for s in stale]
    assert 0.0 < speeds[0] < moving and all(b < a for a, b in itertools.pairwise(speeds))  # braking
    st = cycles(emb, clk, 500, rec)
    # the old stream's braking commands went to a robot that refused them; the new stream starts
    # from the robot at rest in the stop of the old one
    states = {m.seq: m for tag, m, *_ in emb.control.outbox if tag == "state"}
    old = [c for c in rec.commands if c.stream == rec.commands[0].stream]
    new = [c for c in rec.commands if c.stream != rec.commands[0].stream]
    assert len(old) > sent and new
    assert all(c.seq > o.seq for c in new for o in old)  # no old command after the new stream began
    at = states[new[0].state_seq]
    assert new[0].stream == new[0].seq
    assert at.stale_stop and not any(at.v_arm) and not any(at.wheel_speeds)
    assert core.resume_needed and core.mode == w.Mode.HOLD
    mode(emb, clk, "track")
    st = cycles(emb, clk, 200, rec)
    assert not core.resume_needed and core.mode == w.Mode.TRACK
    assert violations(st) == 0, st.violations


def test_a_slow_tick_inside_the_robots_timeout_is_sent_late_and_judged_legal(host: Any) -> None:
    emb, clk = host()
    core = emb.control.core
    core.ctl = SlowOnce(core.ctl, clk, 300, 0.012)  # type: ignore[assignment]
    st = tracking(emb, clk, (0.15, 0.05, 0.0), 600)
    assert "stream_broken" not in core.fault_record.counts and not core.stream.broken
    assert emb.control.timing.deadline_misses >= 1 and emb.node.caught_up >= 10
    assert not st.stale_stop and violations(st) == 0, st.violations


def test_commands_applied_late_are_a_state_age_fault(host: Any) -> None:
    """A robot side that applies each command 15 ms after it was written (longer than
    ``state_age_max``): the measured age trips the watchdog, a safe stop, 0 violations."""
    emb, clk = host()
    late: list[tuple[float, CommandMsg]] = []
    put = emb.inbox.put

    def deliver(msg: CommandMsg) -> None:
        late.append((clk.t + 0.015, msg))

    def release(_: int) -> None:
        while late and late[0][0] <= clk.t:
            put(late.pop(0)[1])

    emb.control.link._deliver = deliver
    cycles(emb, clk, 20, each=release)
    mode(emb, clk, "track")
    core = emb.control.core
    st = cycles(emb, clk, 300, each=release)
    assert core.fault_record.counts["state_too_old"] >= 1 and core.stream.round_trip > 0.010
    assert violations(st) == 0, st.violations


# ---------------------------------------------------------------- faults, the referee, the firmware
def test_the_referee_judges_the_command_as_received_before_the_firmware_refuses_it(
        host: Any, robot: w.RobotConfig) -> None:
    emb, clk = host()
    core = emb.control.core
    core.ctl = OverLimitOnce(core.ctl, 100, float(robot.arm.velocity_max[0]))  # type: ignore[assignment]
    st = cycles(emb, clk, 150)
    assert st.violations["velocity"] == 1  # the referee saw the command as it was received
    assert st.protective_stops == 1 and "refused command: joint 1" in st.protective_reason  # the firmware refused it
    assert not np.abs(st.v_arm[0]) > robot.arm.velocity_max[0]  # never executed
    assert core.fault_record.counts["robot_firmware"] >= 1  # the core saw the robot's report: a fault


def test_a_state_the_robot_reports_with_nan_is_refused_and_the_robot_stops(host: Any) -> None:
    emb, clk = host()
    core = emb.control.core
    cycles(emb, clk, 50)
    real = emb.node.state_msg

    def broken(st: SimState, seq: int) -> StateMsg:
        m = real(st, seq)
        m.q_arm = [float("nan")] * len(m.q_arm)
        return m

    emb.node.state_msg = broken  # type: ignore[method-assign]
    st = cycles(emb, clk, 100)
    assert emb.control.rejected()["non_finite"] >= 99
    assert core.safe and core.fault_record.last_code == "state_stale"
    assert violations(st) == 0


# ---------------------------------------------------------------- the operator's side
def test_one_operator_holds_the_stream_and_the_fence_clamps(host: Any) -> None:
    emb, clk = host()
    core = emb.control.core
    assert core.ctl.collision_on  # the rows are on by default, the fence among them
    st = cycles(emb, clk, 20)
    mode(emb, clk, "track")
    x = np.array(st.ee_true)
    cycles(emb, clk, 10, each=lambda k: setpoint(emb, clk, x + [0.02, 0, 0], "alice"))
    cycles(emb, clk, 10, each=lambda k: setpoint(emb, clk, x - [0.02, 0, 0], "bob"))
    cycles(emb, clk, 1)  # the last one, validated in the last slack, is applied by the next tick
    assert emb.control.rejected()["operator"] == 10 and core.setpoints.operator == "alice"
    far = x + [50.0, 0.0, 0.0]  # 50 m away: beyond the default fence
    cycles(emb, clk, 10, each=lambda k: setpoint(emb, clk, far, "alice"))
    status = reports.status(core, emb.control.timing, emb.control.rejected(), emb.control.accepted())
    assert status.clamped >= 1 and np.all(np.abs(core.smoother.target - x) < 3.5)


def test_modes_are_validated_in_the_slack_and_applied_in_order_by_the_next_tick(host: Any) -> None:
    emb, clk = host()
    core = emb.control.core
    cycles(emb, clk, 5)
    mode(emb, clk, "track")
    mode(emb, clk, "dm_nullspace")
    assert core.mode == w.Mode.HOLD  # nothing applied outside a cycle
    cycles(emb, clk, 1)  # validated in its slack, after its tick
    assert core.mode == w.Mode.HOLD and emb.control.inputs.v_mode.accepted == 2
    cycles(emb, clk, 1)  # applied in order by the next tick, before its command (where the daemon applies them)
    assert core.mode == w.Mode.DM_NULLSPACE
    post(emb, "mode", ModeMsg(robot="another-robot", seq=1, stamp=clk.wall(), mode="track"))
    cycles(emb, clk, 1)
    assert core.mode == w.Mode.DM_NULLSPACE and emb.control.rejected()["robot"] == 1


def test_status_telemetry_and_info_are_handed_over_not_built_for_nobody(host: Any) -> None:
    emb, clk = host()
    emb.control.queries.append("a query")
    cycles(emb, clk, 250)
    tags = [item[0] for item in emb.control.outbox]
    assert tags.count("status") == 3 and tags.count("reply") == 1 and tags.count("tel") == 250
    emb.control.tel_listened = False  # nobody subscribes (the service thread says)
    emb.control.outbox.clear()
    cycles(emb, clk, 100)
    assert [item[0] for item in emb.control.outbox].count("tel") == 0


# ---------------------------------------------------------------- the cycle's own cost
def test_the_collector_runs_in_the_slack_only_and_is_restored() -> None:
    was = gc.isenabled()
    c = SlackCollector()
    c.start()
    try:
        assert not gc.isenabled() and gc.get_freeze_count() > 0
        junk = [[i] for i in range(5 * c.threshold)]  # tracked allocations past the threshold
        assert gc.get_count()[0] >= c.threshold
        c.slack()
        assert c.collections[0] == 1 and gc.get_count()[0] < c.threshold
        del junk
    finally:
        c.stop()
    assert gc.isenabled() == was and gc.get_freeze_count() == 0


def test_validation_in_memory_rejects_what_the_wire_rejects(robot: w.RobotConfig) -> None:
    svc = ServiceConfig().with_robot(robot)
    good = StateMsg(robot=svc.robot, seq=1, stamp=1.0, t=0.0, q_base=[0.0] * 3, q_arm=[0.0] * robot.n_arm,
                    v_arm=[0.0] * robot.n_arm, wheel_speeds=[0.0] * robot.n_wheels, tau=[0.0] * robot.n_arm,
                    instance="i")
    bad = {"robot": msgspec.structs.replace(good, robot="x"),
           "size": msgspec.structs.replace(good, q_arm=[0.0]),
           "non_finite": msgspec.structs.replace(good, v_arm=[float("inf")] * robot.n_arm),
           "range": msgspec.structs.replace(good, q_base=[1e9, 0.0, 0.0]),
           "schema": msgspec.structs.replace(good, instance="")}
    for reason, msg in {"": good, **bad}.items():
        wire = Validator(StateMsg, svc.robot, svc.validation, n_arm=robot.n_arm, n_wheels=robot.n_wheels)
        mem = Validator(StateMsg, svc.robot, svc.validation, n_arm=robot.n_arm, n_wheels=robot.n_wheels)
        assert (wire(encode(msg)) is None) == (mem.checked(msg) is None) == bool(reason), reason
        assert wire.rejected == mem.rejected and (not reason or mem.rejected[reason] == 1), reason
    mem = Validator(StateMsg, svc.robot, svc.validation, n_arm=robot.n_arm, n_wheels=robot.n_wheels)
    assert mem.checked(ModeMsg(robot=svc.robot, seq=1, stamp=0.0, mode="hold")) is None  # type: ignore[arg-type]
    assert mem.rejected["schema"] == 1


def test_the_embedded_control_knows_no_transport() -> None:
    import sys

    import wmm_qp_service.embedded.control as control

    assert "zenoh" not in control.__dict__ and "zenoh" not in vars(sys.modules[EmbeddedControl.__module__])


@pytest.mark.parametrize(("argv", "says"), [
    (["--control-rate", "500"], "--control-rate needs --embedded"),
    (["--no-collision"], "--no-collision needs --embedded"),
    (["--embedded", "--control-rate", "300"], "must divide the robot's cycle rate 1000 Hz"),
    (["--embedded", "--state-loss", "0.1"], "not with --embedded"),
    (["--embedded", "--control-rate", "5000"], "--control-rate must be in (0, 1000] Hz"),
])
def test_bad_embedded_flags_are_one_line_and_exit_2(argv: list[str], says: str,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    from wmm_qp_tools.cli import main

    assert main(["sim", *argv]) == 2
    err = capsys.readouterr().err
    assert says in err and len(err.strip().splitlines()) == 1, err


@pytest.mark.parametrize(("argv", "says"), [
    (["demo", "--embedded", "--rate", "300"], "must divide the robot's cycle rate 1000 Hz"),
    (["driver", "franka", "--robot-ip", "127.0.0.1", "--control-rate", "500"], "--control-rate needs --embedded"),
    (["driver", "franka", "--robot-ip", "127.0.0.1", "--embedded", "--control-rate", "0"],
     "--control-rate must be in (0, 1000] Hz"),
    (["soak", "--embedded", "--rate", "300"], "must divide the robot's cycle rate 1000 Hz"),
    (["soak", "--embedded", "--trigger", "state"], "--trigger is the split daemon's"),
])
def test_bad_embedded_demo_and_soak_flags_are_one_line_and_exit_2(argv: list[str], says: str,
                                                                  capsys: pytest.CaptureFixture[str]) -> None:
    from wmm_qp_tools.cli import main

    assert main(argv) == 2
    err = capsys.readouterr().err
    assert says in err and len(err.strip().splitlines()) == 1, err


def test_the_physics_plant_runs_embedded_too(host: Any, robot: w.RobotConfig) -> None:
    pytest.importorskip("mujoco")
    from wmm_qp_sim.robot import SimRobot

    cfg = load_sim_config().with_(physics={"plant": "mujoco"})
    sim = SimRobot(w.WmmModel(robot), cfg, ramp=True)
    emb, clk = host(sim=sim)
    rec = Recorder(emb)
    st = tracking(emb, clk, (0.05, 0.0, 0.0), 300)
    states = [m for tag, m, *_ in emb.control.outbox if tag == "state"]
    by_state = {c.state_seq: c.seq for c in rec.commands}
    assert all(s.cmd_seq == by_state[s.seq - 1] for s in states if s.seq - 1 in by_state)
    assert type(emb.node.sim.plant).__name__ == "MujocoPlant" and violations(st) == 0, st.violations
