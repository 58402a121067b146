"""libfranka's side of the Franka driver (``drivers/franka_link.py``) against a stand-in for
pylibfranka that keeps libfranka's rules: one control at a time, recovery and a new control
refused while one is held, the robot readable without one. (The real library against
franky-sim: ``tests/integration/test_franka_driver.py``.)"""

from __future__ import annotations

import weakref
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
from wmm_qp_service.drivers.franka_link import FrankaLink


class FrankaException(Exception):
    pass


class NetworkException(RuntimeError):
    pass


class InvalidOperationException(FrankaException):
    pass


class CommandException(RuntimeError):
    pass


class JointVelocities:
    def __init__(self, dq: list[float]) -> None:
        self.dq, self.motion_finished = dq, False


class Robot:
    """libfranka's rules that the link must respect, and a log of what it was asked."""

    def __init__(self) -> None:
        self._held: weakref.ref[Control] | None = None  # libfranka's lock is the control's, not the robot's
        self.ms = 0
        self.log: list[str] = []
        self.refuse_recovery = ""
        self.lost = False

    @property
    def held(self) -> Control | None:
        """The control that holds libfranka's lock (None: none)."""
        return self._held() if self._held is not None else None

    def state(self) -> Any:
        self.ms += 1
        return SimpleNamespace(time=SimpleNamespace(to_sec=lambda ms=self.ms: ms * 1e-3), q=[0.0] * 7)

    def read_once(self) -> Any:
        self.log.append("read_once")
        return self.state()

    def start_joint_velocity_control(self, mode: str) -> Control:
        if self.held is not None:
            raise InvalidOperationException("another control or read operation is running")
        self.log.append("start")
        ctl = Control(self)
        self._held = weakref.ref(ctl)
        return ctl

    def automatic_error_recovery(self) -> None:
        if self.lost:
            raise NetworkException("connection lost")
        if self.held is not None:
            raise InvalidOperationException("another control or read operation is running")
        if self.refuse_recovery:
            raise CommandException(self.refuse_recovery)
        self.log.append("recover")


class Control:
    def __init__(self, robot: Robot) -> None:
        self.robot = robot

    def readOnce(self) -> tuple[Any, Any]:
        self.robot.log.append("readOnce")
        return self.robot.state(), None

    def writeOnce(self, cmd: JointVelocities) -> None:
        self.robot.log.append("finish" if cmd.motion_finished else "writeOnce")
        if cmd.motion_finished:
            self.robot._held = None  # finished: the lock is given back


FR = SimpleNamespace(FrankaException=FrankaException, NetworkException=NetworkException,
                     JointVelocities=JointVelocities, ControllerMode=SimpleNamespace(JointImpedance="ji"))


@pytest.fixture
def link() -> FrankaLink:
    lk = FrankaLink(FR, Robot())
    lk.start()
    return lk


def test_a_cycle_reads_the_control_and_answers_it_with_the_robots_time_between_states(link: FrankaLink) -> None:
    robot: Robot = link.robot
    _, dt0 = link.read()
    link.write(np.zeros(7))
    _, dt1 = link.read()
    assert (dt0, dt1) == (0.0, pytest.approx(1e-3)) and link.controlling
    assert robot.log == ["start", "readOnce", "writeOnce", "readOnce"]


def test_after_a_reflex_the_control_is_given_back_the_robot_only_read_and_recovery_starts_a_new_one(
        link: FrankaLink) -> None:
    robot: Robot = link.robot
    link.read()
    link.lose()  # libfranka raised its ControlException
    assert robot.held is None and not link.controlling
    link.read()
    link.write(np.zeros(7))  # no control: nothing written
    assert robot.log[-1] == "read_once"
    assert link.recover() is None and link.controlling
    link.write(np.zeros(7))  # the new control has not been read yet: its first command answers a state
    link.read()
    link.write(np.zeros(7))
    assert robot.log[-5:] == ["read_once", "recover", "start", "readOnce", "writeOnce"]


def test_a_refused_recovery_is_a_reason_a_lost_connection_raises(link: FrankaLink) -> None:
    robot: Robot = link.robot
    link.lose()
    robot.refuse_recovery = "libfranka: Automatic Error Recovery command rejected: manual error recovery required!"
    assert link.recover() == f"CommandException: {robot.refuse_recovery}" and not link.controlling
    robot.lost = True
    with pytest.raises(NetworkException):
        link.recover()


def test_finishing_the_motion_gives_the_control_back(link: FrankaLink) -> None:
    link.read()
    link.write(np.zeros(7), finished=True)
    assert link.robot.log[-1] == "finish" and not link.controlling and link.robot.held is None
