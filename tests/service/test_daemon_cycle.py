"""The daemon's cycle over a robot link in memory: state in → tick → command out, with no
transport (what a robot side that hosts the core in its own process would use), a fake clock."""

from __future__ import annotations

import numpy as np
import pytest
from support.daemon_drive import DT, Plant
from wmm_qp_service.config import ServiceConfig
from wmm_qp_service.daemon import ControlCore, Cycle, RobotLink
from wmm_qp_service.protocol import CommandMsg, ModeMsg, StateMsg

import wmm_qp as w

WALL0 = 1.7e9  # [s] the fake wall clock's epoch


class MemoryLink:
    """A robot link in memory: the robot side puts states, the cycle's commands are kept."""

    def __init__(self) -> None:
        self.taken_ns = 0
        self.inbox: list[tuple[float, StateMsg]] = []
        self.sent: list[CommandMsg] = []

    def take(self) -> tuple[float, StateMsg] | None:
        got = self.inbox[-1] if self.inbox else None  # the newest wins
        self.inbox.clear()
        return got

    def wait(self, timeout: float) -> bool:
        return bool(self.inbox)

    def send(self, msg: CommandMsg) -> None:
        self.sent.append(msg)

    def close(self) -> None:
        pass


class Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


@pytest.fixture(scope="module")
def robot() -> w.RobotConfig:
    return w.load_robot_config()


def make(robot: w.RobotConfig) -> tuple[ControlCore, Plant, MemoryLink, Clock, Cycle]:
    core = ControlCore(ServiceConfig(), w.load_controller_config(), robot)
    link, clock = MemoryLink(), Clock()
    link_: RobotLink = link  # the in-memory link is a RobotLink
    cycle = Cycle(core, link_, "wmm", DT, clock=clock, wall=lambda: WALL0 + clock.t)
    return core, Plant(core.model), link, clock, cycle


def run(core: ControlCore, plant: Plant, link: MemoryLink, clock: Clock, cycle: Cycle, n: int) -> None:
    """n robot cycles: the robot hands its state over, the cycle ticks, the robot executes."""
    for _ in range(n):
        link.inbox.append((WALL0 + clock.t, plant.msg()))
        assert cycle.poll_state() is not None
        sent = cycle.command(clock.t)
        assert sent is not None
        plant.apply(sent.cmd)
        plant.cmd_seq = sent.seq
        clock.t += DT


def test_each_state_in_gives_one_addressed_numbered_command_out(robot: w.RobotConfig) -> None:
    core, plant, link, clock, cycle = make(robot)
    run(core, plant, link, clock, cycle, 64)
    assert [m.seq for m in link.sent] == list(range(1, 65)) and core.stream.seq == 64
    assert [m.state_seq for m in link.sent] == list(range(1, 65))  # each from the state just taken
    assert {(m.robot, m.lease, m.instance, m.stream, m.period) for m in link.sent} == {
        ("wmm", core.lease, "sim-A", 1, DT)}
    assert link.sent[-1].stamp == pytest.approx(WALL0 + 63 * DT)
    assert cycle.state_rx == pytest.approx(WALL0 + 63 * DT)  # the last state's receipt (telemetry)
    # the send bookkeeping feeds the state-age window: each state applied the command sent one
    # period before it arrived
    assert core.stream.round_trip == pytest.approx(DT)
    assert np.allclose(link.sent[-1].arm_rates, plant.v_arm)


def test_a_state_the_core_refuses_is_not_received(robot: w.RobotConfig) -> None:
    core, plant, link, clock, cycle = make(robot)
    run(core, plant, link, clock, cycle, 3)
    link.inbox.append((WALL0 + 99.0, plant.msg(instance="sim-B")))  # a second robot on the key
    assert cycle.poll_state() is None and core.refused["instance"] == 1
    assert cycle.state_rx == pytest.approx(WALL0 + 2 * DT)


def test_a_command_its_own_tick_made_late_is_not_sent_and_the_stream_is_braked_from_the_last_sent(
        robot: w.RobotConfig) -> None:
    """The tick took longer than the robot's command timeout: its command is not sent, and the
    next one brakes the stream from the last command sent (within A·Δt of it), not from the one
    withdrawn, in the same stream."""
    core, plant, link, clock, cycle = make(robot)
    core.on_mode(ModeMsg(robot="wmm", seq=1, stamp=0.0, mode="dm_cartesian"))  # moving
    run(core, plant, link, clock, cycle, 50)
    last = link.sent[-1]
    link.inbox.append((WALL0 + clock.t, plant.msg()))
    assert cycle.poll_state() is not None
    now = clock.t
    clock.t = now + 1.0  # the tick took a second: the robot stopped by itself meanwhile
    assert cycle.command(now) is None
    assert len(link.sent) == 50 and core.stream.seq == 50 and not core.stream.broken
    assert core.fault_record.last.startswith("braking stream after a stall (the tick took 1000 ms")
    sent = cycle.command(clock.t)
    assert sent is not None and link.sent[-1].stream == last.stream and sent.seq == 51
    a = np.asarray(robot.arm.acceleration_max) * DT
    step = np.abs(np.asarray(link.sent[-1].arm_rates) - last.arm_rates)
    assert np.all(step <= a * (1 + 1e-9)) and np.any(step > 0.5 * a)  # braking from the last one sent
