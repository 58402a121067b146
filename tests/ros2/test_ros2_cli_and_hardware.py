"""The ROS 2 commands' bad input (one line, exit 2), and the hardware side's mapping of the
daemon's wheel speeds to each base kind's twist and of the robot's messages, on a fake node."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
from wmm_qp_tools.cli import main

import wmm_qp as w
from wmm_qp.config import default_config_dir

ROBOTS = default_config_dir() / "robots"


def run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str]:
    try:
        code = main(list(argv))
    except SystemExit as e:
        code = int(e.code or 0)
    return code, capsys.readouterr().err


@pytest.mark.parametrize(("argv", "names"), [
    (["driver", "ros2", "--robot-config", str(ROBOTS / "panda_diffdrive.toml"), "--stale-timeout", "0"],
     "--stale-timeout"),
    (["driver", "ros2", "--robot-config", str(ROBOTS / "panda_diffdrive.toml"), "--rate", "nan"], "--rate"),
    (["sim", "--ros2", "--no-truth"], "--ros2"),
    (["sim", "--ros2", "--rate", "5000"], "--rate"),
    (["demo", "--driver", "ros2", "--robot-ip", "127.0.0.1"], "--driver ros2"),
])
def test_bad_ros2_arguments_are_one_line_and_exit_2(capsys: pytest.CaptureFixture[str], argv: list[str],
                                                    names: str) -> None:
    code, err = run(capsys, *argv)
    assert code == 2 and names in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err, err


def test_a_bad_ros2_table_stops_the_driver_naming_file_and_key(tmp_path: Path,
                                                               capsys: pytest.CaptureFixture[str]) -> None:
    f = tmp_path / "r.toml"
    f.write_text((ROBOTS / "panda_diffdrive.toml").read_text() + '\n[ros2]\ncmd_vel_type = "Twist"\n')
    code, err = run(capsys, "driver", "ros2", "--robot-config", str(f))
    assert code == 2 and f"{f}: ros2.cmd_vel_type" in err and len(err.strip().splitlines()) == 1, err


class FakeNode:
    """What Ros2Hardware asks of an rclpy node: subscriptions and publishers by topic."""

    def __init__(self) -> None:
        self.subs: dict[str, Any] = {}
        self.pubs: dict[str, list[Any]] = {}

    def create_subscription(self, _type: Any, topic: str, cb: Any, _qos: Any) -> None:
        self.subs[topic] = cb

    def create_publisher(self, _type: Any, topic: str, _qos: Any) -> Any:
        sent = self.pubs.setdefault(topic, [])
        return SimpleNamespace(publish=sent.append)

    def get_clock(self) -> Any:
        from rclpy.clock import Clock

        return Clock()


def js(names: list[str], pos: list[float]) -> Any:
    return SimpleNamespace(name=names, position=pos, velocity=[], effort=[],
                           header=SimpleNamespace(stamp=SimpleNamespace(sec=0, nanosec=0)))


@pytest.mark.parametrize(("robot_file", "holonomic"), [("gen3_mecanum.toml", True), ("ur5_omni.toml", True),
                                                       ("panda_diffdrive.toml", False)])
def test_wheel_speeds_become_the_base_kinds_twist_and_joint_states_map_by_name(robot_file: str,
                                                                               holonomic: bool) -> None:
    pytest.importorskip("geometry_msgs", reason="needs ROS 2's messages (pip install 'wmm-qp[ros2]')")
    from wmm_qp_service.ros2.hardware import Ros2Hardware

    robot = w.load_robot_config(ROBOTS / robot_file)
    node = FakeNode()
    hw = Ros2Hardware(node, robot, clock=lambda: 5.0)
    base = hw.base
    twist = np.array([0.3, 0.2, -0.4])
    wheels = base.wheel_speeds(twist)
    hw.write(wheels, np.arange(robot.n_arm) * 0.1)
    arm = node.pubs[robot.ros2.arm_command][-1]
    assert np.allclose(arm.data, np.arange(robot.n_arm) * 0.1)
    t = node.pubs[robot.ros2.cmd_vel][-1]
    got = [t.linear.x, t.linear.y, t.angular.z]
    want = twist if holonomic else np.array([0.3, 0.0, -0.4])  # a differential drive cannot go sideways
    assert np.allclose(got, want, atol=1e-12), got
    names = list(robot.arm.joints)
    node.subs[robot.ros2.joint_states](js(["wheel_x", *names[::-1]], [9.0, *range(robot.n_arm)[::-1]]))
    m = hw.read()
    assert m is not None and m.q_arm.tolist() == list(range(robot.n_arm)) and m.received == 5.0
    node.subs[robot.ros2.joint_states](js(["not_ours"], [0.0]))
    node.subs[robot.ros2.joint_states](js(names, [float("nan")] * robot.n_arm))
    node.subs[robot.ros2.joint_states](SimpleNamespace())  # not even a JointState
    assert hw.counts == {"joint_states_foreign": 1, "joint_states_invalid": 2}
    assert hw.read().q_arm.tolist() == list(range(robot.n_arm))  # the robot's own state kept


def test_the_bench_section_says_why_it_cannot_run(monkeypatch: pytest.MonkeyPatch) -> None:
    from wmm_qp_tools.bench import ros2

    monkeypatch.delenv(ros2.NETNS, raising=False)
    monkeypatch.setattr(ros2.importlib.util, "find_spec", lambda name: None)
    assert ros2.run(1.0) == {"available": False, "why": "needs ROS 2's rclpy (pip install 'wmm-qp[ros2]')"}
    monkeypatch.undo()
    monkeypatch.delenv(ros2.NETNS, raising=False)
    monkeypatch.setattr(ros2.importlib.util, "find_spec", lambda name: object())
    monkeypatch.setattr(ros2.shutil, "which", lambda name: None)
    out = ros2.run(1.0)
    assert out["available"] is False and "unshare" in out["why"]
