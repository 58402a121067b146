"""The ROS 2 driver's firmware and message checks, in process (no ROS 2 needed): what
``wmm-qp driver ros2`` lets through to a ros2_control robot, attacked the ways its topics and the
daemon's wire can be (docs/ros2.md "What the firmware refuses")."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest
from wmm_qp_service.config import load_service_config
from wmm_qp_service.protocol import CommandMsg, encode
from wmm_qp_service.ros2.driver import Ros2Driver
from wmm_qp_service.ros2.hardware import Ros2Measured
from wmm_qp_service.ros2.messages import JointIndex, odom_sample

import wmm_qp as w
from wmm_qp.config import default_config_dir
from wmm_qp.exceptions import ConfigError

ROBOTS = default_config_dir() / "robots"
DT = 1.0 / 250.0


@pytest.fixture(scope="module")
def robot() -> w.RobotConfig:
    return w.load_robot_config(ROBOTS / "panda_diffdrive.toml")


def driver(robot: w.RobotConfig) -> Ros2Driver:
    d = Ros2Driver(load_service_config(), robot, stale_timeout=0.025)
    d.on_lease("L1", True)
    return d


def meas(robot: w.RobotConfig, received: float, q: np.ndarray | None = None) -> Ros2Measured:
    q = np.array(robot.arm.start, dtype=float) if q is None else q
    z = np.zeros(robot.n_arm)
    return Ros2Measured(q, z, np.zeros(robot.n_wheels), z, np.zeros(3), received)


def cmd(d: Ros2Driver, seq: int, arm: list[float], wheels: list[float] | None = None, stream: int = 1) -> bytes:
    return encode(CommandMsg(robot=d.svc.robot, seq=seq, stamp=time.time(), lease="L1", instance=d.instance,
                             arm_rates=[float(v) for v in arm],
                             wheel_speeds=[float(v) for v in (wheels or [0.0] * d.robot.n_wheels)],
                             period=0.002, stream=stream))


def run(d: Ros2Driver, robot: w.RobotConfig, t0: float, cycles: int, fresh: bool = True) -> tuple[float, np.ndarray]:
    """``cycles`` cycles from driver time t0 with fresh joint states (or the last one kept); the
    largest |output| per joint and wheel."""
    peak = np.zeros(robot.n_arm + robot.n_wheels)
    t = t0
    stamp = t0
    for _ in range(cycles):
        t += DT
        if fresh:
            stamp = t
        v = d.cycle(t, meas(robot, stamp), t)
        peak = np.maximum(peak, np.abs(v))
    return t, peak


# ------------------------------------------------------------------ joint states and odometry
def test_joint_states_map_by_name_in_any_order_and_ignore_extra_joints() -> None:
    ix = JointIndex(["a", "b", "c"])
    s = ix.map(1.0, ["wheel_l", "c", "a", "b"], [9.0, 3.0, 1.0, 2.0], [0.0, 0.3, 0.1, 0.2], [])
    assert not isinstance(s, str)
    assert s.q.tolist() == [1.0, 2.0, 3.0] and s.v.tolist() == [0.1, 0.2, 0.3] and s.tau.tolist() == [0, 0, 0]


@pytest.mark.parametrize(("names", "pos", "vel", "why"), [
    (["x1", "x2", "x3"], [0.0, 0.0, 0.0], [], "foreign"),  # another robot's joints
    (["a", "b"], [0.0, 0.0], [], "partial"),  # one of ours missing
    (["a", "b", "c"], [0.0, float("nan"), 0.0], [], "invalid"),
    (["a", "b", "c"], [0.0, 0.0], [], "invalid"),  # fewer positions than names
    (["a", "b", "c"], [0.0, 0.0, 0.0], [0.0], "invalid"),  # a velocity list of the wrong length
    (["a", "a", "b", "c"], [0.0, 1.0, 0.0, 0.0], [], "invalid"),  # a joint named twice
])
def test_a_joint_state_that_is_not_the_robots_is_refused_with_its_reason(names: list[str], pos: list[float],
                                                                         vel: list[float], why: str) -> None:
    assert JointIndex(["a", "b", "c"]).map(0.0, names, pos, vel, []) == why


def test_odometry_gives_the_planar_pose_and_refuses_a_non_finite_or_zero_quaternion() -> None:
    yaw = 0.7
    s = odom_sample(0.0, 1.0, 2.0, (0.0, 0.0, np.sin(yaw / 2), np.cos(yaw / 2)), 0.1, 0.0, 0.2)
    assert s is not None and np.allclose(s.pose, [1.0, 2.0, yaw]) and s.twist.tolist() == [0.1, 0.0, 0.2]
    assert odom_sample(0.0, float("inf"), 0.0, (0, 0, 0, 1), 0, 0, 0) is None
    assert odom_sample(0.0, 0.0, 0.0, (0, 0, 0, 0), 0, 0, 0) is None


# ------------------------------------------------------------------ the firmware in front of the robot
def test_a_command_past_a_velocity_limit_is_refused_and_never_reaches_the_robot(robot: w.RobotConfig) -> None:
    """Attack: a lease holder commands joint 1 at twice its limit; the driver writes nothing past
    the limit, stops (protective, refused_command) and refuses the stream until a new one at rest."""
    d = driver(robot)
    t, _ = run(d, robot, 0.0, 3)
    v_max = np.asarray(robot.arm.velocity_max)
    bad = [0.0] * robot.n_arm
    bad[0] = 2.0 * v_max[0]
    assert not d.on_command(cmd(d, 1, bad), t)
    t, peak = run(d, robot, t, 50)
    assert d.shaper.protective and d.shaper.protective_code == "refused_command"
    assert (peak[: robot.n_arm] <= v_max + 1e-12).all() and not peak.any()
    assert d.refused["firmware"] == 1
    ok = [0.0] * robot.n_arm
    ok[0] = 0.5 * v_max[0]
    assert not d.on_command(cmd(d, 2, ok), t)  # the stopped stream stays stopped
    assert d.on_command(cmd(d, 3, ok, stream=2), t)  # a new stream, at rest: followed
    assert not d.shaper.protective


def test_a_wheel_speed_past_its_limit_is_refused_too(robot: w.RobotConfig) -> None:
    d = driver(robot)
    t, _ = run(d, robot, 0.0, 3)
    w_max = float(robot.base.wheel_speed_max[0])
    assert not d.on_command(cmd(d, 1, [0.0] * robot.n_arm, [1.5 * w_max, 0.0]), t)
    assert d.shaper.protective and "joint 8" in d.shaper.protective_reason  # the first wheel after the 7 joints


def test_a_command_that_could_not_stop_before_a_position_limit_is_refused(robot: w.RobotConfig) -> None:
    d = driver(robot)
    q = np.array(robot.arm.start, dtype=float)
    q[3] = robot.arm.position_upper[3] - 1e-3  # joint 4 a millimetre-radian below its upper limit
    d.cycle(DT, meas(robot, DT, q), DT)
    up = [0.0] * robot.n_arm
    up[3] = 1.0
    assert not d.on_command(cmd(d, 1, up), DT)
    assert d.shaper.protective_code == "cannot_stop_before_limit"


def test_stale_commands_brake_the_robot_to_rest_within_the_stale_timeout(robot: w.RobotConfig) -> None:
    """The daemon killed: its last command was a motion; the driver's output brakes to exactly 0."""
    d = driver(robot)
    t, _ = run(d, robot, 0.0, 2)
    go = [0.0] * robot.n_arm
    go[6] = 0.5
    assert d.on_command(cmd(d, 1, go, [2.0, 2.0]), t)
    t, _ = run(d, robot, t, 5)  # ramping up, within the stale timeout
    assert not d.shaper.stale and d.shaper.v[6] > 0
    t, _ = run(d, robot, t, 5)  # 40 ms without a command
    assert d.shaper.stale
    t, _ = run(d, robot, t, 250)
    assert d.shaper.at_rest
    assert not d.on_command(cmd(d, 2, go), t) and d.refused["ended"] == 1  # the stale stop ended the stream


def test_lost_joint_states_are_a_protective_stop_naming_the_topic(robot: w.RobotConfig) -> None:
    """The robot's joint states stop: past [ros2] state_timeout the driver brakes to rest, reports
    robot_state_lost with the topic, refuses every command; they come back: a new stream at rest runs."""
    d = driver(robot)
    t, _ = run(d, robot, 0.0, 2)
    go = [0.0] * robot.n_arm
    go[6] = 0.5
    assert d.on_command(cmd(d, 1, go), t)
    last = t
    for k in range(2, 60):  # the daemon keeps commanding; the states stopped at `last`
        t += DT
        d.on_command(cmd(d, k, go), t)
        d.cycle(t, meas(robot, last), t)
    assert d.shaper.protective and d.shaper.protective_code == "robot_state_lost"
    assert "'joint_states'" in d.shaper.protective_reason and "state_timeout 0.1 s" in d.shaper.protective_reason
    assert d.refused["state_lost"] > 0
    t, _ = run(d, robot, t, 200, fresh=False)
    assert d.shaper.at_rest and d.lost
    t, _ = run(d, robot, t, 2)  # the states are back
    assert d.on_command(cmd(d, 100, go, stream=2), t) and not d.shaper.protective


def test_the_robot_refused_messages_are_counted_in_the_state(robot: w.RobotConfig) -> None:
    d = driver(robot)
    d.cycle(DT, meas(robot, DT), DT)
    st = d.state_msg({"joint_states_foreign": 3, "odom_invalid": 0})
    assert st.refused == {"joint_states_foreign": 3}
    assert st.v_arm == [0.0] * robot.n_arm and len(st.wheel_speeds) == robot.n_wheels


# ------------------------------------------------------------------ the [ros2] table
def test_the_ros2_table_defaults_to_ros2_controls_names(robot: w.RobotConfig) -> None:
    r = robot.ros2
    assert (r.joint_states, r.odom, r.arm_command, r.cmd_vel, r.cmd_vel_type) == (
        "joint_states", "odom", "forward_velocity_controller/commands", "cmd_vel", "geometry_msgs/Twist")


@pytest.mark.parametrize(("table", "key"), [
    ('joint_states = "2bad"', "ros2.joint_states"),
    ('cmd_vel_type = "geometry_msgs/Pose"', "ros2.cmd_vel_type"),
    ("rate_hz = 0", "ros2.rate_hz"),
    ('topic = "x"', "ros2.topic"),
])
def test_a_bad_ros2_table_is_one_error_naming_the_key(tmp_path: Path, table: str, key: str) -> None:
    src = (ROBOTS / "panda_diffdrive.toml").read_text()
    f = tmp_path / "r.toml"
    f.write_text(src + f"\n[ros2]\n{table}\n")
    with pytest.raises(ConfigError, match=key.replace(".", r"\.")):
        w.load_robot_config(f)


def test_a_ros2_table_sets_the_topics(tmp_path: Path) -> None:
    src = (ROBOTS / "panda_diffdrive.toml").read_text()
    f = tmp_path / "r.toml"
    f.write_text(src + '\n[ros2]\njoint_states = "/robot/joint_states"\ncmd_vel_type = "geometry_msgs/TwistStamped"\n')
    r = w.load_robot_config(f).ros2
    assert r.joint_states == "/robot/joint_states" and r.cmd_vel_type.endswith("TwistStamped")


def test_the_latency_is_timed_from_the_joint_state_the_command_was_computed_from(robot: w.RobotConfig) -> None:
    d = driver(robot)
    d.cycle(DT, meas(robot, 10.0), 10.0)
    st = d.state_msg({})  # state 1, from the joint state that arrived at 10.0 s
    msg = CommandMsg(robot=d.svc.robot, seq=1, stamp=time.time(), lease="L1", instance=d.instance,
                     arm_rates=[0.0] * robot.n_arm, wheel_speeds=[0.0] * robot.n_wheels, period=0.002, stream=1,
                     state_seq=st.seq)
    assert d.on_command(encode(msg), 10.003)
    d.written(10.005)
    assert list(d.latency) == pytest.approx([0.005])
    d.written(10.009)  # nothing new accepted: nothing timed
    assert len(d.latency) == 1
    predicted = CommandMsg(robot=d.svc.robot, seq=2, stamp=time.time(), lease="L1", instance=d.instance,
                           arm_rates=[0.0] * robot.n_arm, wheel_speeds=[0.0] * robot.n_wheels, period=0.002,
                           stream=1, state_seq=-1)
    assert d.on_command(encode(predicted), 10.01)
    d.written(10.012)
    assert len(d.latency) == 1 and d.report()["state_to_command"]["n"] == 1


def test_the_cannot_stop_check_judges_where_the_joints_are_now_not_where_an_old_state_says(
        robot: w.RobotConfig) -> None:
    """Attack on timing: the joint states arrive late (yet within state_timeout) while a joint moves
    towards its limit. Judged at the old state's position the motion could go on; carried on by the
    rates written since, it must stop before the limit: a cannot_stop_before_limit stop."""
    d = driver(robot)
    j = 1  # panda_joint2, [-1.7628, 1.7628] rad, 7.5 rad/s² at most
    q = np.array(robot.arm.start, dtype=float)
    q[j] = 0.0
    t, _ = run(d, robot, 0.0, 2)
    go = [0.0] * robot.n_arm
    go[j] = 1.0
    seq = 1
    assert d.on_command(cmd(d, seq, go), t)
    stamp = t
    while d.shaper.v[j] < 1.0 - 1e-9:  # up to speed, fresh states at q
        t += DT
        seq += 1
        d.on_command(cmd(d, seq, go), t)
        d.cycle(t, meas(robot, t, q), t)
        stamp = t
    stop = float(d.shaper.stop_distance(d.shaper.v, d.shaper.a)[j])
    q_old = q.copy()
    q_old[j] = robot.arm.position_upper[j] - stop - 0.06  # 60 mrad short of the last braking point
    for _ in range(20):  # 80 ms of commands, the joint state stuck at stamp: 80 mrad travelled since
        t += DT
        seq += 1
        d.on_command(cmd(d, seq, go), t)
        d.cycle(t, meas(robot, stamp, q_old), t)
    assert t - stamp < robot.ros2.state_timeout
    assert d.shaper.protective and d.shaper.protective_code == "cannot_stop_before_limit", d.shaper.protective_reason
