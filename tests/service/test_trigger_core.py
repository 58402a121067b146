"""The state-triggered daemon loop: ControlCore driven by a StateLoop on a fake clock (no real
timing). A tick per state, computed from that state; lost states take the prediction path; no
state for ``state_timeout`` is a safe stop; bounds (13)'s latency margin follows the measured
state age."""

from __future__ import annotations

import math

import numpy as np
import pytest
from support.clocks import FakeClock
from support.daemon_drive import Plant
from wmm_qp_service.config import ServiceConfig
from wmm_qp_service.daemon import ControlCore
from wmm_qp_service.protocol import ModeMsg
from wmm_qp_service.rate_loop import StateLoop

import wmm_qp as w

RATE = 1000.0
DT = 1.0 / RATE


class Robot:
    """A plant that publishes a state every DT (its own cycle) unless told to drop it, and
    applies the newest command it received before each of its steps."""

    def __init__(self, core: ControlCore, clock: FakeClock, drop: set[int]) -> None:
        self.plant = Plant(core.model)
        self.clock, self.drop = clock, drop
        self.t_next = clock.t + 0.2e-3
        self.k = 0
        self.inbox: list[tuple[int, w.Command]] = []  # (command seq, command)
        self.pending: list[tuple[float, object]] = []  # (arrival time, state message)
        self.applied: dict[int, int] = {}  # state seq -> command seq applied at that step

    def advance(self) -> None:
        while self.t_next <= self.clock.t:
            if self.inbox:
                seq, cmd = self.inbox[-1]
                self.inbox.clear()
                self.plant.apply(cmd)
                self.plant.cmd_seq = seq
            self.k += 1
            msg = self.plant.msg()  # seq = k
            self.applied[msg.seq] = self.plant.cmd_seq
            if self.k not in self.drop:
                self.pending.append((self.t_next + 50e-6, msg))  # 50 µs transport
            self.t_next += DT

    def block(self, timeout: float) -> bool:
        """The mailbox's wait: the clock runs (in 5 µs steps) until a state has arrived, or by
        ``timeout``."""
        end = self.clock.t + timeout
        while True:
            self.advance()
            if self.pending and self.pending[0][0] <= self.clock.t:
                return True
            if self.clock.t >= end:
                return False
            self.clock.t = min(end, self.clock.t + 5e-6)

    def poll(self) -> object | None:
        self.advance()
        newest = None
        while self.pending and self.pending[0][0] <= self.clock.t:
            newest = self.pending.pop(0)[1]
        return newest


def drive(n: int, drop: set[int], state_timeout: float = 0.05,
          blocking: bool = False) -> tuple[ControlCore, Robot, list[w.Command | None], StateLoop[object]]:
    svc = ServiceConfig().with_(loop={"rate_hz": RATE, "trigger": "state"},
                                watchdog={"state_timeout": state_timeout})
    core = ControlCore(svc, w.load_controller_config(), w.load_robot_config())
    core.stream.follow_state_age = True
    clock = FakeClock()
    robot = Robot(core, clock, drop)

    def poll() -> object | None:
        m = robot.poll()
        return m if m is not None and core.on_state(m, clock()) else None  # type: ignore[arg-type]

    loop: StateLoop[object] = StateLoop(RATE, poll, clock=clock, sleep=clock.sleep,
                                        block=robot.block if blocking else None)
    now = loop.start()
    core.on_mode(ModeMsg(robot="wmm", mode="hold"))
    cmds: list[w.Command | None] = []
    for _ in range(n):
        cmd = core.tick(now)
        if cmd is not None:
            core.stream.numbered()
            robot.inbox.append((core.stream.seq, cmd))
            core.stream.sent(core.stream.seq, clock.t)
        cmds.append(cmd)
        clock.t += 30e-6  # the tick's work
        now = loop.wait()
    return core, robot, cmds, loop


@pytest.mark.parametrize("blocking", [False, True], ids=["polling", "blocking"])
def test_each_state_gets_its_command_before_the_robots_next_step(blocking: bool) -> None:
    _core, robot, cmds, loop = drive(300, drop=set(), blocking=blocking)
    assert loop.watchdog_ticks == 0 and loop.deadline_misses == 0
    # state k's command is the one applied at step k + 1 (the Plant's seq counts from 1)
    assert all(robot.applied[k + 1] == k for k in range(2, 280))
    assert all(c is not None and c.status != w.Status.SAFE_STOP for c in cmds[1:])


@pytest.mark.parametrize("blocking", [False, True], ids=["polling", "blocking"])
def test_a_lost_state_takes_the_prediction_path_and_every_step_gets_one_new_command(blocking: bool) -> None:
    core, robot, cmds, loop = drive(300, drop={100, 200}, blocking=blocking)
    assert loop.watchdog_ticks == 2  # 1.5 periods after the last state: between two robot steps
    assert all(c is not None and c.status != w.Status.SAFE_STOP for c in cmds[1:])
    assert not core.safe
    # every robot step applied a new command (the watchdog tick's, after a lost state): none was
    # overwritten by a second command within one robot cycle, none came late
    steps = sorted(robot.applied)
    assert all(robot.applied[k] == robot.applied[k - 1] + 1 for k in steps[3:290])


@pytest.mark.parametrize("blocking", [False, True], ids=["polling", "blocking"])
def test_no_state_for_state_timeout_is_a_safe_stop(blocking: bool) -> None:
    core, _robot, cmds, _loop = drive(200, drop=set(range(50, 400)), blocking=blocking)
    assert core.safe and cmds[-1] is not None and cmds[-1].status == w.Status.SAFE_STOP
    assert core.fault_record.last_code == "state_stale"
    # before the timeout the watchdog ticks predicted (no safe stop within state_timeout)
    first_stop = next(i for i, c in enumerate(cmds) if c is not None and c.status == w.Status.SAFE_STOP)
    assert first_stop > 50 + 20


@pytest.mark.parametrize("blocking", [False, True], ids=["polling", "blocking"])
def test_bounds_latency_margin_follows_the_measured_state_age(blocking: bool) -> None:
    core, _robot, _cmds, _loop = drive(200, drop=set(), blocking=blocking)
    wd = core.svc.watchdog
    timeout = wd.command_hold - wd.state_age_max
    assert core.cfg.state_latency == pytest.approx(wd.command_hold)  # the worst case, before a measure
    assert math.isfinite(core.stream.round_trip)
    assert timeout < core.stream.latency < timeout + 5 * DT  # the robot's own timeout + the measured age
    assert core.ctl.bounds.latency == core.stream.latency  # type: ignore[attr-defined]
    core.stream.reset_age()  # a new stream: back to the worst case
    assert core.ctl.bounds.latency == pytest.approx(wd.command_hold)  # type: ignore[attr-defined]
    assert np.isfinite(core.stream.latency)
