"""The daemon's safety logic , driven through ControlCore with a fake clock.

Each test is an attack from the blind drill or the review, and what the daemon does now: one
robot per key (instance latch), sim faults it reacts to, one operator per stream, setpoint
stamps, the acceleration anchor, the state's age without shared clocks, manual resume and
bounded queries. No transport, no timing.
"""

from __future__ import annotations

import collections
import math

import numpy as np
import pytest
from support.daemon_drive import DT, Plant, max_step_ratio, mode, setpoint, tick
from wmm_qp_service.config import ServiceConfig
from wmm_qp_service.daemon import ControlCore, Daemon
from wmm_qp_service.protocol import StateMsg, TruthMsg

import wmm_qp as w


@pytest.fixture(scope="module")
def robot() -> w.RobotConfig:
    return w.load_robot_config()


def make(robot: w.RobotConfig, **watchdog: object) -> tuple[ControlCore, Plant]:
    svc = ServiceConfig().with_(watchdog=watchdog) if watchdog else ServiceConfig()
    core = ControlCore(svc, w.load_controller_config(), robot)
    return core, Plant(core.model)


def track(core: ControlCore, plant: Plant, t: float, n: int, target: np.ndarray) -> float:
    """n ticks streaming a fixed target, states fresh; returns the time after them."""
    for _ in range(n):
        core.on_state(plant.msg(), t)
        core.on_setpoint(setpoint(target, t), t)
        tick(core, plant, t)
        t += DT
    return t


# ---------------------------------------------------------------- 1. two robots under one id
def test_a_second_sim_instance_is_a_fault_not_mixed(robot: w.RobotConfig) -> None:
    core, plant = make(robot)
    other = Plant(core.model)
    other.instance = "sim-B"
    other.q_arm = other.q_arm + 0.3  # another robot, elsewhere
    t = 0.0
    for _ in range(20):
        core.on_state(plant.msg(), t)
        tick(core, plant, t)
        t += DT
    assert core.gate.instance == "sim-A" and not core.safe
    used = []
    for k in range(100):  # both sims publish on the key, interleaved
        src = plant if k % 2 else other
        accepted = core.on_state(src.msg(), t)
        assert accepted == (src is plant)
        cmd = tick(core, plant, t)
        used.append(core.state.q_arm.copy() if core.state is not None else None)
        t += DT
    assert core.safe and core.fault_record.last_code == "second_state_source"
    assert cmd.status == w.Status.SAFE_STOP
    assert core.refused["instance"] == 50
    # the controller never saw the other robot's joints
    assert all(np.max(np.abs(q - plant.q_arm)) < 0.05 for q in used)
    # the second source goes away: the fault clears; the daemon was holding, and holds on
    # (no task to resume: an idle robot's fault needs no operator)
    for _ in range(60):
        core.on_state(plant.msg(), t)
        tick(core, plant, t)
        t += DT
    assert not core.safe and not core.resume_needed and core.mode == w.Mode.HOLD
    assert core.fault_record.counts["second_state_source"] >= 1  # reported all the same


def test_a_second_source_is_reported_even_while_the_daemon_is_already_in_a_safe_stop(
        robot: w.RobotConfig) -> None:
    """The latched robot is in its own protective stop (the daemon's stream broken, in a safe
    stop), then another robot's states arrive on the key: the status counts the second source
    and names it, though the daemon was already stopped for another reason (under a state flood
    on a loaded host the daemon was already stopped and the twin was never reported)."""
    core, plant = make(robot)
    other = Plant(core.model)
    other.instance = "sim-B"
    t = 0.0
    for _ in range(20):
        core.on_state(plant.msg(), t)
        tick(core, plant, t)
        t += DT
    plant.protective_stops = 1
    for _ in range(20):  # the latched robot stops itself (its firmware's protective stop)
        core.on_state(plant.msg(protective_stop=True, protective_reason="bumper"), t)
        cmd = tick(core, plant, t)
        t += DT
    assert core.safe and "second_state_source" not in core.fault_record.counts, core.fault_record.counts
    for k in range(40):  # and now another robot publishes on the key too
        if k % 2:
            core.on_state(plant.msg(protective_stop=True, protective_reason="bumper"), t)
        else:
            assert not core.on_state(other.msg(), t)
        cmd = tick(core, plant, t)
        t += DT
    assert cmd.status == w.Status.SAFE_STOP
    assert core.fault_record.counts["second_state_source"] == 1  # once, as it appeared


def test_a_restarted_sim_is_latched_after_the_old_one_fell_silent(robot: w.RobotConfig) -> None:
    core, plant = make(robot)
    t = 0.0
    for _ in range(5):
        core.on_state(plant.msg(), t)
        tick(core, plant, t)
        t += DT
    t += 2 * core.svc.watchdog.state_timeout  # the old sim is gone
    plant.instance, plant.seq = "sim-C", 0
    assert core.on_state(plant.msg(), t)
    assert core.gate.instance == "sim-C" and core.fault_record.last_code == "robot_instance_changed"


def test_a_state_whose_seq_does_not_increase_is_refused(robot: w.RobotConfig) -> None:
    core, plant = make(robot)
    m1, m2 = plant.msg(), plant.msg()
    assert core.on_state(m2, 0.0)
    assert not core.on_state(m1, 0.001)  # older: replayed or reordered
    assert core.refused["state_seq"] == 1


# ---------------------------------------------------------------- 3. the sim's referee and firmware
def test_rising_firmware_counts_are_a_fault(robot: w.RobotConfig) -> None:
    """The robot's own reports (protective stops, commands its firmware refused), not an
    evaluation's referee, are what the daemon reacts to: a rise is a fault."""
    core, plant = make(robot)
    plant.protective_stops, plant.refused = 2, {"firmware": 5}  # from before this daemon: the baseline
    t = 0.0
    for _ in range(5):
        core.on_state(plant.msg(), t)
        tick(core, plant, t)
        t += DT
    assert not core.safe
    plant.refused = {"firmware": 8}  # e.g. a rogue client's commands, refused by the firmware
    core.on_state(plant.msg(), t)
    cmd = tick(core, plant, t)
    assert cmd.status == w.Status.SAFE_STOP and core.safe
    assert "robot firmware reported 3 new protective stop(s) or refused command(s)" in core.fault_record.last
    assert core.fault_record.counts["robot_firmware"] == 1


def test_the_daemon_ignores_the_truth_on_the_control_path(robot: w.RobotConfig) -> None:
    """``sim/truth`` feeds telemetry's ee_error only: rising referee counts in it are no fault,
    and a truth of another instance is not kept."""
    core, plant = make(robot)
    t = 0.0
    x = core.model.ee_position(plant.q_base, plant.q_arm).tolist()
    for k in range(5):
        core.on_state(plant.msg(), t)
        core.on_truth(TruthMsg(robot="wmm", t=t, instance=plant.instance, state_seq=plant.seq, base_true=[0.0] * 3,
                               ee_true=x, contact_force=[0.0] * 3, violations={"velocity": 3 * k}))
        tick(core, plant, t)
        t += DT
    assert not core.safe and not core.fault_record.counts
    assert core.truth is not None and core.truth.violations == {"velocity": 12}
    core.on_truth(TruthMsg(robot="wmm", t=t, instance="another", state_seq=1, base_true=[0.0] * 3,
                           ee_true=x, contact_force=[0.0] * 3))
    assert core.truth.instance == plant.instance


def test_a_protective_stop_of_the_sim_breaks_the_stream(robot: w.RobotConfig) -> None:
    """The robot's firmware stopped it (e.g. a rogue command): the daemon sends nothing until
    the robot is at rest, then starts from rest and holds until told to resume. (Before, it
    braked from its own last command, which the robot was no longer executing: a review's
    attack re-accelerated a robot at rest to 0.73 rad/s.)"""
    core, plant = make(robot)
    x0 = core.model.ee_position(plant.q_base, plant.q_arm)
    mode(core, "track")
    t = track(core, plant, 0.0, 100, x0 + np.array([0.2, 0.0, 0.0]))
    plant.v_arm = 0.5 * plant.v_arm  # braking by itself
    core.on_state(plant.msg(protective_stop=True, protective_reason="refused command: joint 4"), t)
    assert core.tick(t) is None
    assert core.fault_record.last.startswith("the robot stopped following the commands (protective stop: refused")
    plant.v_arm, plant.wheels = np.zeros(robot.n_arm), np.zeros(robot.n_wheels)
    t += DT
    core.on_state(plant.msg(protective_stop=True, protective_reason="refused command: joint 4"), t)
    before = core.stream.start
    cmd = tick(core, plant, t)
    assert core.stream.start == core.stream.seq > before  # a new stream: judged against the robot's rates
    a = np.asarray(robot.arm.acceleration_max) * DT
    assert np.all(np.abs(cmd.arm_rates) <= a * (1 + 1e-9))  # from rest
    t += DT
    core.on_state(plant.msg(), t)  # the legal command ended the protective stop
    tick(core, plant, t)
    assert core.mode == w.Mode.HOLD and core.resume_needed


def test_commands_lost_long_enough_for_the_robots_timeout_break_the_stream(robot: w.RobotConfig) -> None:
    """Commands dropped on the way (congestion DROP) while states flow: the robot stops itself;
    the daemon must not go on by itself when its commands get through again."""
    core, plant = make(robot)
    x0 = core.model.ee_position(plant.q_base, plant.q_arm)
    mode(core, "track")
    t = track(core, plant, 0.0, 100, x0 + np.array([0.2, 0.0, 0.0]))
    applied = plant.cmd_seq
    for _ in range(20):  # the robot hears nothing: it brakes to rest in its stale stop
        core.on_state(plant.msg(stale_stop=True, cmd_seq=applied), t)
        core.on_setpoint(setpoint(x0 + np.array([0.2, 0.0, 0.0]), t), t)
        assert core.tick(t) is None
        t += DT
    assert "its command timeout" in core.fault_record.last
    plant.v_arm, plant.wheels = np.zeros(robot.n_arm), np.zeros(robot.n_wheels)
    for _ in range(300):
        core.on_state(plant.msg(stale_stop=plant.cmd_seq == applied, cmd_seq=plant.cmd_seq), t)
        core.on_setpoint(setpoint(x0 + np.array([0.2, 0.0, 0.0]), t), t)
        tick(core, plant, t)
        t += DT
    assert core.mode == w.Mode.HOLD and core.resume_needed  # it did not resume by itself


def test_a_lost_lease_sends_nothing_and_taking_it_back_needs_a_resume(robot: w.RobotConfig) -> None:
    core, plant = make(robot)
    mode(core, "track")
    t = 0.0
    for _ in range(20):
        core.on_state(plant.msg(), t)
        tick(core, plant, t)
        t += DT
    for _ in range(20):  # a partition healed: the sim applies another daemon's commands
        core.on_state(plant.msg(lease="other-daemon"), t)
        assert core.tick(t) is None
        t += DT
    assert core.fault_record.last.startswith("lease lost (the robot applies the commands of daemon other-daemon")
    # the other one ends; the robot stopped in its stale stop; the lease is ours again
    core.on_state(plant.msg(lease="core", stale_stop=True), t)
    tick(core, plant, t)
    assert core.mode == w.Mode.HOLD and core.resume_needed


def test_after_a_twin_was_seen_no_other_instance_is_latched(robot: w.RobotConfig) -> None:
    """A twin that hides the real sim (its states land just after the real one's): the real
    one falls silent for the daemon, but the twin is never latched as "a restarted sim"."""
    core, plant = make(robot)
    twin = Plant(core.model)
    twin.instance = "sim-B"
    t = 0.0
    core.on_state(plant.msg(), t)
    tick(core, plant, t)
    core.on_state(twin.msg(), t)  # seen once
    for _ in range(200):  # then only the twin, for 0.4 s
        t += DT
        assert not core.on_state(twin.msg(), t)
        if core.tick(t) is not None:
            core.stream.numbered()
            core.stream.sent(core.stream.seq, t)
    assert core.gate.instance == "sim-A" and core.safe and core.fault_record.counts["second_state_source"] >= 1


# ---------------------------------------------------------------- 5. one operator per stream
def test_a_second_operator_is_refused_and_counted(robot: w.RobotConfig) -> None:
    core, plant = make(robot)
    x0 = core.model.ee_position(plant.q_base, plant.q_arm)
    mode(core, "track")
    t = 0.0
    a, b = x0 + np.array([0.04, 0.0, 0.0]), x0 + np.array([-0.04, 0.0, 0.0])
    for k in range(400):  # two clients stream alternately to targets 8 cm apart
        core.on_state(plant.msg(), t)
        assert core.on_setpoint(setpoint(a, t, "alice"), t)
        assert not core.on_setpoint(setpoint(b, t, "bob"), t)
        tick(core, plant, t)
        t += DT
        if k == 399:
            break
    x = core.model.ee_position(plant.q_base, plant.q_arm)
    assert np.linalg.norm(x - a) < 2e-3  # alice's target, never swung towards bob's
    assert core.refused["operator"] == 400 and core.setpoints.operator_conflicts == 400
    assert core.setpoints.operator == "alice" and core.fault_record.last_code == "setpoint_conflict"
    # alice stops; after operator_timeout bob may take the stream
    t += core.svc.watchdog.operator_timeout
    assert core.on_setpoint(setpoint(b, t, "bob"), t) and core.setpoints.operator == "bob"


# ---------------------------------------------------------------- 11. frozen setpoint stamps
def test_a_frozen_setpoint_stamp_is_refused_and_reported(robot: w.RobotConfig) -> None:
    core, plant = make(robot)
    x0 = core.model.ee_position(plant.q_base, plant.q_arm)
    mode(core, "track")
    accepted = 0
    t = 0.0
    for _ in range(250):
        core.on_state(plant.msg(), t)
        accepted += core.on_setpoint(setpoint(x0 + np.array([0.05, 0, 0]), 17.0), t)  # constant stamp
        tick(core, plant, t)
        t += DT
    assert accepted == 1 and core.refused["stamp"] == 249
    assert "setpoint stamp not increasing" in core.fault_record.last


# ---------------------------------------------------------------- 7. the acceleration anchor
def run_with_stale_states(robot: w.RobotConfig, every: int, age: int, n: int) -> list[w.Command]:
    """Track a moving target; the daemon gets a state every `every` ticks, `age` ticks old."""
    core, plant = make(robot)
    x0 = core.model.ee_position(plant.q_base, plant.q_arm)
    mode(core, "track")
    hist: collections.deque[StateMsg] = collections.deque(maxlen=age + 1)
    cmds = []
    t = 0.0
    for k in range(n):
        hist.append(plant.msg())
        if k % every == 0:
            core.on_state(hist[0], t)
        x = x0 + np.array([0.15 * np.sin(2.0 * t), 0.1 * (1 - np.cos(2.0 * t)), 0.0])
        core.on_setpoint(setpoint(x, t), t)
        cmds.append(tick(core, plant, t))
        t += DT
    return cmds


def test_consecutive_commands_stay_inside_the_acceleration_bound_with_stale_states(
    robot: w.RobotConfig,
) -> None:
    """A state every 4th tick, 4 ticks old: on the old anchor (the measured rates) consecutive
    commands differed by up to 2 A·dt; anchored on the last command they stay inside A·dt."""
    cmds = run_with_stale_states(robot, every=4, age=4, n=2000)
    assert max(np.abs(c.v).max() for c in cmds) > 0.05  # it does move
    assert max_step_ratio(robot, cmds) <= 1.0 + 1e-9


# ---------------------------------------------------------------- 10. a constant delay
def test_a_constant_state_delay_is_a_fault(robot: w.RobotConfig) -> None:
    """States 20 ms late (10 ticks at 500 Hz): the command → applied-state round trip shows it."""
    core, plant = make(robot)
    hist: collections.deque[StateMsg] = collections.deque(maxlen=11)
    t = 0.0
    for _ in range(200):
        hist.append(plant.msg())
        core.on_state(hist[0], t)
        tick(core, plant, t)
        t += DT
    assert core.stream.round_trip == pytest.approx(11 * DT)
    assert core.safe and core.fault_record.last_code == "state_too_old"


def test_one_fast_state_in_many_does_not_hide_a_delay(robot: w.RobotConfig) -> None:
    """A path that reorders: the states 20 ms old, one in 50 overtaking them fresh. The smallest
    round trip (the old check) saw 2 ms; the median of the per-state bounds sees the delay."""
    core, plant = make(robot)
    hist: collections.deque[StateMsg] = collections.deque(maxlen=11)
    t = 0.0
    for k in range(400):
        hist.append(plant.msg())
        old, fresh = hist[0], hist[-1]
        core.on_state(fresh if k % 50 == 0 else old, t)
        tick(core, plant, t)
        t += DT
    assert core.safe and core.fault_record.last_code == "state_too_old"


def test_a_rate_too_slow_for_the_state_age_check_is_a_config_error(robot: w.RobotConfig) -> None:
    with pytest.raises(w.ConfigError, match=r"loop\.rate_hz"):
        ControlCore(ServiceConfig().with_(loop={"rate_hz": 100.0}), w.load_controller_config(), robot)


def test_a_prompt_state_is_no_fault(robot: w.RobotConfig) -> None:
    core, plant = make(robot)
    t = 0.0
    for _ in range(200):
        core.on_state(plant.msg(), t)  # the state after the last command, one tick later
        tick(core, plant, t)
        t += DT
    assert core.stream.round_trip == pytest.approx(DT) and not core.safe and not core.fault_record.last


# ---------------------------------------------------------------- 15. resuming is an explicit act
@pytest.mark.parametrize("resume", ["manual", "auto"])
def test_resume_after_a_safe_stop(robot: w.RobotConfig, resume: str) -> None:
    core, plant = make(robot, resume=resume)
    x0 = core.model.ee_position(plant.q_base, plant.q_arm)
    target = x0 + np.array([0.1, 0.0, 0.0])
    mode(core, "track")
    t = 0.0
    for _ in range(100):
        core.on_state(plant.msg(), t)
        core.on_setpoint(setpoint(target, t), t)
        tick(core, plant, t)
        t += DT
    for _ in range(300):  # the sim hangs: no state
        core.on_setpoint(setpoint(target, t), t)
        tick(core, plant, t)
        t += DT
    assert core.safe
    x_stop = core.model.ee_position(plant.q_base, plant.q_arm)
    for _ in range(500):  # the sim is back, the operator still streams
        core.on_state(plant.msg(), t)
        core.on_setpoint(setpoint(target, t), t)
        tick(core, plant, t)
        t += DT
    x = core.model.ee_position(plant.q_base, plant.q_arm)
    if resume == "manual":
        assert core.mode == w.Mode.HOLD and core.resume_needed
        assert np.linalg.norm(x - x_stop) < 0.01  # it stayed where the stop left it
        mode(core, "track")  # the explicit act
        assert not core.resume_needed
        for _ in range(500):
            core.on_state(plant.msg(), t)
            core.on_setpoint(setpoint(target, t), t)
            tick(core, plant, t)
            t += DT
        x = core.model.ee_position(plant.q_base, plant.q_arm)
    else:
        assert core.mode == w.Mode.TRACK and not core.resume_needed
    assert np.linalg.norm(x - target) < 5e-3


# ---------------------------------------------------------------- fault lines off the loop
def test_fault_lines_never_block_or_raise_in_the_control_thread(monkeypatch: pytest.MonkeyPatch) -> None:
    """A review's attack: 1,000 setpoints with new source names wrote 1,998 lines from the control
    thread; with stderr a closed pipe, on_setpoint raised BrokenPipeError."""
    import sys
    import threading

    from wmm_qp_service.daemon import FaultLog, _say

    class Broken:
        def write(self, s: str) -> int:
            raise BrokenPipeError

        def flush(self) -> None:
            raise BrokenPipeError

    class Stuck:  # a paused terminal (Ctrl-S): write blocks until released
        release = threading.Event()

        def write(self, s: str) -> int:
            self.release.wait()
            return len(s)

        def flush(self) -> None:
            pass

    monkeypatch.setattr(sys, "stderr", Broken())
    _say("nothing happens")  # does not raise
    stuck = Stuck()
    monkeypatch.setattr(sys, "stderr", stuck)
    log = FaultLog(depth=8)
    for k in range(1000):
        log(f"line {k}")  # returns at once although the writer is stuck on its first line
    assert 1000 - 8 - 1 <= log.dropped <= 1000 - 8  # at most 8 wait (+1 being written), the rest counted
    stuck.release.set()
    log.close()


# ---------------------------------------------------------------- 13. queries bounded per tick
class FakeQuery:
    def __init__(self) -> None:
        self.replies = 0

    def reply(self, key: str, payload: bytes) -> None:
        self.replies += 1


class FakeQueryable:
    def __init__(self, n: int) -> None:
        self.pending = [FakeQuery() for _ in range(n)]
        self.all = list(self.pending)

    def try_recv(self) -> FakeQuery | None:
        return self.pending.pop(0) if self.pending else None


def test_info_queries_are_bounded_per_tick(robot: w.RobotConfig) -> None:
    d = Daemon(ServiceConfig(), w.load_controller_config(), robot)
    q = FakeQueryable(64)
    assert d.answer_queries(q, 1) == 1 and len(q.pending) == 63  # one per tick; the rest wait
    answered = [d.answer_queries(q, 1) for _ in range(70)]
    assert sum(answered) == 63 and max(answered) == 1
    assert all(x.replies == 1 for x in q.all)


# ---------------------------------------------------------------- the daemon's own stall
def test_the_robots_own_stop_after_a_stall_is_no_state_age_for_the_next_stream(robot: w.RobotConfig) -> None:
    """While the stream is broken the robot brakes by itself for longer than the age window's 50
    states, each state naming the last command it applied; their growing ages are not the link's:
    the stream that starts from rest is not held in its safe stop as "state too old" (the old
    window's median of 341 ms held it until 50 new states had replaced it)."""
    core, plant = make(robot)
    x0 = core.model.ee_position(plant.q_base, plant.q_arm)
    mode(core, "track")
    t = track(core, plant, 0.0, 200, x0 + np.array([0.2, 0.0, 0.0]))
    t += 0.1  # the daemon stalled for 100 ms
    core.on_state(plant.msg(), t)  # a state from before the robot's stop: the stream is braked
    assert core.tick(t) is not None and core.fault_record.last_code == "stall_braking"
    for k in range(150):  # the robot brakes in its stale stop, 150 ms: its state breaks the stream
        t += DT
        plant.v_arm, plant.wheels = 0.97 * plant.v_arm, 0.97 * plant.wheels
        if k == 149:
            plant.v_arm, plant.wheels = np.zeros(robot.n_arm), np.zeros(robot.n_wheels)
        core.on_state(plant.msg(stale_stop=True), t)
        assert core.tick(t) is None or k == 149
    assert not core.stream.broken  # at rest: the new stream began
    assert core.hazard(t) is None and not core.stream.round_trip <= math.inf  # an empty window: no age yet
    for _ in range(60):
        t += DT
        core.on_state(plant.msg(), t)
        tick(core, plant, t)
        assert not core.safe
    assert "state_too_old" not in core.fault_record.counts and core.stream.round_trip < 0.01


def test_after_its_own_stall_the_daemon_waits_for_the_robots_stop(robot: w.RobotConfig) -> None:
    """A SIGSTOPped daemon: the robot stopped following its commands after its timeout. The
    commands after the stall continue the stream, braking from its last command (the robot, having
    stopped the stream, refuses them); once a state shows the robot's stop, nothing goes out until
    it rests, and the next stream's first command starts from what the robot does."""
    core, plant = make(robot)
    x0 = core.model.ee_position(plant.q_base, plant.q_arm)
    mode(core, "track")
    t = track(core, plant, 0.0, 200, x0 + np.array([0.2, 0.0, 0.0]))
    assert core.cmd is not None and np.abs(core.cmd.v).max() > 0.05  # moving
    last, start = core.cmd, core.stream.start
    t += 0.2  # stalled for 200 ms
    core.on_state(plant.msg(), t)  # an old state, from before the stall, arrives first
    cmd = core.tick(t)
    assert cmd is not None and cmd.status == w.Status.SAFE_STOP and core.stream.start == start
    assert core.fault_record.last.startswith("braking stream after a stall (202 ms without a command")
    assert max_step_ratio(robot, [last, cmd]) <= 1.0 + 1e-6  # braking the stream from its last command
    core.stream.numbered()
    core.stream.sent(core.stream.seq, t)
    plant.cmd_seq = core.stream.seq  # received, and refused: the robot's stop ended the stream
    # the robot is braking itself; its state says so, but it is not at rest yet: nothing
    plant.v_arm, plant.wheels = 0.5 * plant.v_arm, 0.5 * plant.wheels
    core.on_state(plant.msg(stale_stop=True), t + DT)
    assert core.tick(t + DT) is None and core.stream.broken
    plant.v_arm, plant.wheels = np.zeros(robot.n_arm), np.zeros(robot.n_wheels)  # at rest
    t += 2 * DT
    core.on_state(plant.msg(stale_stop=True), t)
    cmd = core.tick(t)
    assert cmd is not None and not core.stream.broken
    assert not core.stream.late(t + 1.0)  # the new stream is not late by the old one's clock (it is published)
    old_seq = plant.cmd_seq - 1  # states that still show the old stream's last command
    for _ in range(60):
        t += DT
        core.on_state(plant.msg(cmd_seq=old_seq), t)
        core.tick(t)
    assert "state_too_old" not in core.fault_record.counts  # their age bound says nothing about this stream
    a = np.asarray(robot.arm.acceleration_max) * DT
    assert np.all(np.abs(cmd.arm_rates) <= a * (1 + 1e-9))  # from rest, inside A·dt
    assert np.all(np.abs(cmd.wheel_speeds) <= robot.base.wheel_acceleration_max * DT * (1 + 1e-9))


def test_a_lease_lost_while_braking_after_a_stall_sends_nothing(robot: w.RobotConfig) -> None:
    """The daemon brakes its stream after its own stall; the sim then names another lease holder:
    the braking ends with the stream (another daemon commands the robot), nothing goes out, and
    taking the lease back waits for the robot at rest in its stop, as any lost lease does."""
    core, plant = make(robot)
    x0 = core.model.ee_position(plant.q_base, plant.q_arm)
    mode(core, "track")
    t = track(core, plant, 0.0, 100, x0 + np.array([0.2, 0.0, 0.0]))
    t += 0.022  # a stall past the daemon's limit, inside the robot's timeout
    core.on_state(plant.msg(), t)
    tick(core, plant, t)
    assert core.fault_record.last_code == "stall_braking" and core.stream.stalled
    t += DT
    core.on_state(plant.msg(lease="other-daemon"), t)
    assert core.tick(t) is None and core.stream.broken and not core.stream.stalled
    assert core.fault_record.last_code == "lease_lost"
    plant.v_arm, plant.wheels = np.zeros(robot.n_arm), np.zeros(robot.n_wheels)
    t += DT
    core.on_state(plant.msg(lease="core", stale_stop=True), t)  # ours again, the robot at rest in its stop
    start = core.stream.start
    cmd = tick(core, plant, t)
    a = np.asarray(robot.arm.acceleration_max) * DT
    assert core.stream.start == core.stream.seq > start and np.all(np.abs(cmd.arm_rates) <= a * (1 + 1e-9))  # from rest
    assert core.mode == w.Mode.HOLD and core.resume_needed
