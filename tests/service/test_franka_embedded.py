"""``wmm-qp driver franka --embedded`` in process: the control core in libfranka's cycle, against a
fake libfranka (a joint velocity interface that integrates what is written) and a fake clock.
No robot, no Zenoh, no timing (franky-sim: tests/integration/test_demo_franka.py)."""

from __future__ import annotations

import threading
from typing import Any

import numpy as np
import pytest
from support.clocks import Clock
from support.controllers import OverLimitOnce
from wmm_qp_service.config import ServiceConfig
from wmm_qp_service.drivers.franka import DT, FrankaDriver
from wmm_qp_service.drivers.franka_embedded import FrankaEmbedded
from wmm_qp_service.drivers.franka_link import FrankaLink
from wmm_qp_service.protocol import CommandMsg, ModeMsg, SetpointMsg, StateMsg, encode

import wmm_qp as w
from wmm_qp.config import default_config_dir

FR3 = default_config_dir() / "robots" / "fr3.toml"


class FakeFr:
    """What the driver uses of pylibfranka."""

    class NetworkException(Exception):
        pass

    class ControlException(Exception):
        pass

    class FrankaException(Exception):
        pass

    class ControllerMode:
        JointImpedance = 0

    class JointVelocities:
        def __init__(self, v: list[float]) -> None:
            self.v = v
            self.motion_finished = False


class Duration:
    def __init__(self, s: float) -> None:
        self.s = s

    def to_sec(self) -> float:
        return self.s


class RobotState:
    def __init__(self, q: np.ndarray, t: float) -> None:
        self.q = q.tolist()
        self.tau_ext_hat_filtered = [0.0] * 7
        self.O_F_ext_hat_K = [0.0] * 6
        self.time = Duration(t)


class FakeControl:
    """libfranka's joint velocity control: readOnce advances the clock a cycle (``late``: longer),
    writeOnce executes the velocities for a cycle; it keeps what was written."""

    def __init__(self, q0: np.ndarray, clk: Clock) -> None:
        self.q, self.clk = q0.astype(float), clk
        self.written: list[np.ndarray] = []
        self.late: dict[int, float] = {}
        self.finished = False
        self.on_read: Any = None  # called with the cycle's number before each read (a client's part)
        self.t_robot = 0.0  # [s] the robot's time (its states' ``time``)

    def link(self) -> FrankaLink:
        """The driver's link to a robot whose control is this one."""
        robot = type("FakeRobot", (), {"start_joint_velocity_control": lambda _self, _mode: self})()
        link = FrankaLink(FakeFr, robot)
        link.start()
        return link

    def readOnce(self) -> tuple[RobotState, Duration]:
        if self.on_read is not None:
            self.on_read(len(self.written))
        dt = self.late.pop(len(self.written), DT)
        self.clk.t += dt
        self.t_robot += dt
        return RobotState(self.q, self.t_robot), Duration(dt)

    def writeOnce(self, cmd: FakeFr.JointVelocities) -> None:
        v = np.array(cmd.v)
        self.written.append(v)
        self.q = self.q + DT * v
        self.finished = cmd.motion_finished


@pytest.fixture
def rig() -> Any:
    made: list[FrankaEmbedded] = []

    def make(**kw: Any) -> tuple[FrankaEmbedded, FakeControl, Clock]:
        robot = w.load_robot_config(FR3)
        clk = Clock()
        emb = FrankaEmbedded(FrankaDriver(ServiceConfig(), robot), w.load_controller_config(), clock=clk,
                             wall=clk.wall, **kw)
        made.append(emb)
        emb.start()
        return emb, FakeControl(np.array(robot.arm.start), clk), clk

    yield make
    for emb in made:
        emb.control.stop()


def post(emb: FrankaEmbedded, kind: str, msg: Any) -> None:
    emb.control.inbox.append((kind, encode(msg)))


def test_each_cycle_reads_ticks_and_writes_within_the_fr3s_limits(rig: Any) -> None:
    emb, ctl, clk = rig()
    robot = emb.driver.robot
    sent: list[CommandMsg] = []
    deliver = emb.control.link._deliver

    def keep(msg: CommandMsg) -> None:
        sent.append(msg)
        deliver(msg)

    emb.control.link._deliver = keep
    x0 = emb.control.core.model.ee_position(np.zeros(3), ctl.q)
    target = x0 + np.array([0.05, -0.03, 0.02])

    def client(k: int) -> None:
        if k == 50:
            post(emb, "mode", ModeMsg(robot=emb.driver.svc.robot, seq=1, stamp=clk.wall(), mode="track"))
        elif k > 50 and k % 10 == 0:
            post(emb, "setpoint", SetpointMsg(robot=emb.driver.svc.robot, seq=k, stamp=clk.wall(),
                                              x=target.tolist(), source="op"))

    ctl.on_read = client
    assert emb.loop(FakeFr, ctl.link(), threading.Event(), 1500, "fake") == 0  # then a clean stop
    assert ctl.finished and not ctl.written[-1].any()
    x = emb.control.core.model.ee_position(np.zeros(3), ctl.q)
    assert np.linalg.norm(x - target) < np.linalg.norm(x0 - target) / 2  # it tracked
    # each command came from the state of its own cycle and reached the shaper in that cycle
    states = [m for tag, m, *_ in emb.control.outbox if tag == "state"]
    assert all(isinstance(m, StateMsg) for m in states) and len(sent) > 1000
    by_seq = {m.seq: m for m in states}
    assert all(by_seq[c.state_seq + 1].cmd_seq == c.seq for c in sent[:-1] if c.state_seq + 1 in by_seq)
    v = np.array(ctl.written)
    assert np.all(np.abs(v) <= np.asarray(robot.arm.velocity_max) + 1e-9)
    assert np.all(np.abs(np.diff(v, axis=0)) <= np.asarray(robot.arm.acceleration_max) * DT * (1 + 1e-6) + 1e-12)
    assert not any(emb.driver.referee.counts.values()), emb.driver.referee.counts
    assert emb.control.core.lease == emb.driver.holder and not emb.control.core.fault_record.counts


def test_the_referee_judges_the_core_s_command_before_the_shaper_refuses_it(rig: Any) -> None:
    emb, ctl, _ = rig()
    robot = emb.driver.robot
    core = emb.control.core
    core.ctl = OverLimitOnce(core.ctl, 30, float(robot.arm.velocity_max[0]))  # type: ignore[assignment]
    assert emb.loop(FakeFr, ctl.link(), threading.Event(), 80, "fake") == 0
    assert emb.driver.referee.counts["velocity"] == 1  # judged as received
    assert emb.driver.shaper.protective_stops == 1 and emb.driver.refused["firmware"] == 1  # refused
    assert np.all(np.abs(np.array(ctl.written)[:, 0]) <= robot.arm.velocity_max[0])  # never written
    assert core.fault_record.counts["robot_firmware"] >= 1


def test_a_cycle_late_for_the_robot_is_a_miss(rig: Any) -> None:
    emb, ctl, _ = rig(control_rate=500.0)
    ctl.late = {20: 3 * DT, 41: 3 * DT}  # cycle 20 ticks, cycle 41 does not
    assert emb.loop(FakeFr, ctl.link(), threading.Event(), 60, "fake") == 0
    assert emb.control.decimation == 2 and emb.control.timing.ticks == 30
    assert emb.control.timing.deadline_misses == 1
