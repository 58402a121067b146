"""ROS 2 end to end: ``wmm-qp sim --ros2`` (a stand-in ros2_control robot), ``wmm-qp driver ros2``,
``wmm-qp serve --ros2`` and ROS 2 nodes of the test's own, every one in a network namespace with
only loopback up (no DDS traffic can leave the machine; docs/ros2.md "Discovery").

:func:`test_in_a_network_namespace_with_only_loopback` re-runs this file's ``test_live_*`` tests
under ``unshare -n`` (root, or user namespaces; CI runs as root) and passes only when every one of
them passed there; outside it they skip, saying so. Without rclpy, unshare or ip, it skips saying
which.
"""

from __future__ import annotations

import contextlib
import importlib.util
import json
import math
import os
import re
import shutil
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from support.service_robots import gen3_text

import wmm_qp as w
from wmm_qp.config import default_config_dir

pytestmark = [pytest.mark.integration, pytest.mark.ros2]

ROOT = Path(__file__).resolve().parents[2]
ROBOTS = default_config_dir() / "robots"
NETNS = "WMM_QP_ROS2_NETNS"
INSIDE = os.environ.get(NETNS) == "1"
LIVE = 7  # the test_live_* tests (parametrised cases counted)
inside_only = pytest.mark.skipif(not INSIDE, reason="runs inside the network namespace that "
                                 "test_in_a_network_namespace_with_only_loopback makes")


def why_not_live() -> str | None:
    """Why the live tests cannot run here (None: they can)."""
    if importlib.util.find_spec("rclpy") is None:
        return "needs ROS 2's rclpy (pip install 'wmm-qp[ros2]')"
    if shutil.which("unshare") is None or shutil.which("ip") is None:
        return "needs unshare (util-linux) and ip (iproute2) for a network namespace"
    r = subprocess.run(["unshare", "-n", "sh", "-c", "ip link set lo up"], capture_output=True, text=True,
                       timeout=30, check=False)
    if r.returncode != 0:
        return f"cannot make a network namespace (unshare -n: {r.stderr.strip()[:200]}): needs root or user namespaces"
    return None


def test_in_a_network_namespace_with_only_loopback(tmp_path: Path) -> None:
    if INSIDE:
        pytest.skip("this run is the namespace's own")
    if (why := why_not_live()) is not None:
        pytest.skip(why)
    env = {**os.environ, NETNS: "1", "PYTHONUNBUFFERED": "1"}
    argv = ["unshare", "-n", "sh", "-c", 'ip link set lo up && exec "$@"', "sh", sys.executable, "-P", "-m", "pytest",
            str(Path(__file__)), "-q", "-x", "-rs", "-p", "no:cacheprovider", "-k", "test_live_",
            f"--basetemp={tmp_path / 'inside'}"]
    r = subprocess.run(argv, env=env, cwd=ROOT, capture_output=True, text=True, timeout=2400, check=False)
    out = r.stdout + r.stderr
    assert r.returncode == 0, out[-12000:]
    m = re.search(r"(\d+) passed", r.stdout)
    assert m is not None and int(m.group(1)) == LIVE and " skipped" not in r.stdout, out[-4000:]


# ---------------------------------------------------------------------------------------- helpers
class Recorder:
    """A ROS 2 node of the test's own: the robot's joint states and the commands its controllers get."""

    def __init__(self, robot: w.RobotConfig, namespace: str = "") -> None:
        from sensor_msgs.msg import JointState
        from std_msgs.msg import Float64MultiArray
        from wmm_qp_service.ros2.node import RosNode, qos

        self.robot = robot
        self.ros = RosNode("test_recorder")
        self.node = self.ros.node
        self.lock = threading.Lock()
        self.q: list[np.ndarray] = []
        self.v: list[np.ndarray] = []
        self.commands: list[np.ndarray] = []
        idx: dict[tuple[str, ...], np.ndarray] = {}

        def on_js(m: Any) -> None:
            names = tuple(m.name)
            if names not in idx:
                if not set(robot.arm.joints) <= set(names):
                    return  # (another node's garbage, sent by a test)
                idx[names] = np.array([names.index(j) for j in robot.arm.joints])
            i = idx[names]
            with self.lock:
                self.q.append(np.asarray(m.position, dtype=float)[i])
                self.v.append(np.asarray(m.velocity, dtype=float)[i])

        def on_cmd(m: Any) -> None:
            with self.lock:
                self.commands.append(np.asarray(m.data, dtype=float))

        self.node.create_subscription(JointState, robot.ros2.joint_states, on_js, qos(False, 100))
        self.node.create_subscription(Float64MultiArray, robot.ros2.arm_command, on_cmd, qos(True, 100))

    def limits_kept(self) -> tuple[int, str]:
        """(joint states seen, "" or the first joint past its position or velocity limit)."""
        a = self.robot.arm
        lo, hi, vmax = (np.asarray(x, dtype=float) for x in (a.position_lower, a.position_upper, a.velocity_max))
        with self.lock:
            q, v = list(self.q), list(self.v)
        tol = 1e-6
        for k, (qk, vk) in enumerate(zip(q, v, strict=True)):
            if (bad := np.flatnonzero((qk < lo - tol) | (qk > hi + tol))).size:
                j = bad[0]
                return len(q), f"joint state {k}: joint {j + 1} at {qk[j]:.5f} outside [{lo[j]}, {hi[j]}]"
            if (bad := np.flatnonzero(np.abs(vk) > vmax * (1 + 1e-3) + tol)).size:
                return len(q), f"joint state {k}: joint {bad[0] + 1} at {vk[bad[0]]:.5f} rad/s past {vmax[bad[0]]}"
        return len(q), ""

    def commands_past_limits(self) -> int:
        vmax = np.asarray(self.robot.arm.velocity_max, dtype=float)
        with self.lock:
            return sum(1 for c in self.commands if c.shape != vmax.shape or (np.abs(c) > vmax * (1 + 1e-9)).any())

    def close(self) -> None:
        self.ros.close()


def until(pred: Any, timeout: float, what: str) -> Any:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if (v := pred()):
            return v
        time.sleep(0.05)
    raise AssertionError(f"not within {timeout:g} s: {what}")


@contextlib.contextmanager
def stack(tmp: Path, robot_file: Path, physics: str = "kinematic", driver: bool = True, daemon: bool = False,
          daemon_args: tuple[str, ...] = ()) -> Iterator[Any]:
    """sim --ros2, and the ROS 2 driver, and a daemon, on an isolated prefix; logs in ``tmp``."""
    from wmm_qp_service.processes import Stack, isolated_config

    robot = w.load_robot_config(robot_file)
    s = Stack(isolated_config(robot=robot), log_dir=tmp, robot_file=robot_file,
              extra_sim_args=["--ros2", "--physics", physics], extra_daemon_args=list(daemon_args))
    try:
        s.start_sim()
        if driver:
            s.start_driver("ros2")
        if daemon:
            s.start_daemon()
        yield s
    finally:
        s.stop()


def log_tail(tmp: Path) -> str:
    return "\n".join(f"== {p.name}\n" + "\n".join(p.read_text(errors="replace").splitlines()[-15:])
                     for p in sorted(tmp.glob("*.log")))


# ---------------------------------------------------------------------------------------- the live tests
@inside_only
# both plants and both base kinds (holonomic vx, vy, wz; differential vx, wz), two runs: the other two
# pairings add nothing the firmware and kinematics tests (tests/ros2/test_ros2_firmware.py) do not cover
@pytest.mark.parametrize(("robot_file", "physics"), [("gen3_mecanum.toml", "kinematic"),
                                                     ("panda_diffdrive.toml", "mujoco")])
def test_live_the_demo_completes_every_mode_through_ros2_with_no_joint_past_its_limits(
        tmp_path: Path, robot_file: str, physics: str) -> None:
    """``wmm-qp demo --driver ros2`` against ``sim --ros2``: every phase run, 0 violations by the
    driver's referee, and the robot's own joint states (recorded here) never past a limit."""
    if physics == "mujoco":
        pytest.importorskip("mujoco", reason="needs MuJoCo (pip install 'wmm-qp[physics]')")
    from wmm_qp_service.processes import CLI

    robot = w.load_robot_config(ROBOTS / robot_file)
    with stack(tmp_path, ROBOTS / robot_file, physics, driver=False):
        rec = Recorder(robot)
        try:
            r = subprocess.run([*CLI, "demo", "--driver", "ros2", "--robot-config", str(ROBOTS / robot_file),
                                "--duration", "10", "--json", "--logs", str(tmp_path / "demo")],
                               capture_output=True, text=True, timeout=900, check=False)
            n, bad = rec.limits_kept()
        finally:
            rec.close()
    assert r.returncode == 0, r.stderr[-3000:] + log_tail(tmp_path / "demo") + log_tail(tmp_path)
    out = json.loads(r.stdout)
    assert out["violations_total"] == 0 and out["verdict"] == "PASS", out
    assert [p["phase"] for p in out["phases"]] == ["hold", "dm_cartesian", "dm_nullspace", "track_haptic", "hold",
                                                   "track_circle", "hold"]
    assert n > 500, f"only {n} joint states recorded"
    assert bad == "", bad


@inside_only
def test_live_the_contract_kit_passes_and_the_robots_topics_refuse_garbage(tmp_path: Path) -> None:
    """The driver contract (docs/drivers.md) on the ROS 2 driver, its past-the-limit commands never
    reaching the robot's controller; then a node publishing another robot's joint names and
    garbage on the robot's ``joint_states``: refused and counted, the robot still driven."""
    from sensor_msgs.msg import JointState
    from wmm_qp_service.ros2.node import qos
    from wmm_qp_tools import contract

    # the robot given 0.5 s before its joint states count as lost: the stand-in robot, a Python
    # process on a loaded 2-core host, stalled its joint states for 0.10 s once in the middle of a
    # check (the driver rightly stopped: state lost, a verdict on the host, not on the driver; the
    # shipped 0.1 s is the lost joint states' live test's, below)
    robot_file = tmp_path / "gen3_mecanum.toml"
    robot_file.write_text(gen3_text() + "\n[ros2]\nstate_timeout = 0.5\n")
    robot = w.load_robot_config(robot_file)
    assert robot.ros2.state_timeout == 0.5
    with stack(tmp_path, robot_file) as s:
        rec = Recorder(robot)
        try:
            with contract.Controller(s.svc, robot) as c:
                try:
                    c.until(lambda st: True, 120.0, "a first state from the driver")
                    results = contract.check_all(c, robot.ros2.rate_hz, 0.025)
                except contract.ContractError as e:
                    raise AssertionError(f"{e}\n{log_tail(tmp_path)}") from None
                failed = {name: r.detail for name, r in results.items() if not r.passed}
                assert len(results) == len(contract.CHECKS) and not failed, f"{failed}\n{log_tail(tmp_path)}"
                assert rec.commands_past_limits() == 0
                assert len(rec.commands) > 100
                pub = rec.node.create_publisher(JointState, robot.ros2.joint_states, qos(True, 10))
                until(lambda: pub.get_subscription_count() >= 2, 30.0, "the driver's subscription matched (discovery)")
                cases = [(["other_joint_1", "other_joint_2"], [0.1, 0.2]),  # another robot
                         (list(robot.arm.joints), [math.nan] * robot.n_arm),  # garbage values
                         (list(robot.arm.joints[:3]), [0.0] * 3)]  # a partial state
                for names, pos in cases * 15:  # 0.9 s: longer than the state timeout (0.5 s here)
                    m = JointState()
                    m.name, m.position = names, pos
                    pub.publish(m)
                    time.sleep(0.02)
                st = until(lambda: (x := c.drain()) is not None and {"joint_states_foreign", "joint_states_invalid",
                                                                      "joint_states_partial"} <= x.refused.keys() and x,
                           10.0, "the garbage counted in the driver's state")
                assert not st.protective_stop, st.protective_reason  # the robot's own states still arrive
        finally:
            rec.close()


@inside_only
def test_live_lost_joint_states_are_a_protective_stop_and_the_robot_gets_zero_rates(tmp_path: Path) -> None:
    """The robot's joint states stop (its process killed): the driver reports a protective stop
    coded robot_state_lost naming the topic, and what it writes to the arm brakes to 0."""
    from wmm_qp_tools import contract

    robot = w.load_robot_config(ROBOTS / "gen3_mecanum.toml")
    with stack(tmp_path, ROBOTS / "gen3_mecanum.toml") as s:
        rec = Recorder(robot)
        try:
            with contract.Controller(s.svc, robot) as c:
                c.until(lambda st: True, 120.0, "a first state from the driver")
                c.hold_lease()
                c.new_stream()
                v = c.zeros()
                t0 = time.monotonic()
                while time.monotonic() - t0 < 1.0:  # the last joint moving slowly
                    v[-1] = 0.2 * min(1.0, (time.monotonic() - t0) / 0.3)
                    c.send(v)
                    time.sleep(0.004)
                s.kill("sim")
                end = time.monotonic() + 3.0
                while time.monotonic() < end:  # the daemon goes on commanding
                    c.send(v)
                    time.sleep(0.004)
                st = c.until(lambda x: x.protective_stop, 5.0, "a protective stop")
                assert st.protective_code == "robot_state_lost" and "'joint_states'" in st.protective_reason, st
                c.until(lambda x: not any(x.v_arm) and not any(x.wheel_speeds), 5.0, "the driver's output at rest")
                time.sleep(0.2)
                with rec.lock:
                    last = rec.commands[-1]
                assert not last.any(), last
                assert st.refused.get("state_lost", 0) > 0
        finally:
            rec.close()


class FaceProbe:
    """A plain rclpy node on the face's topics under ``ns``: it records ``ee_pose``, ``status``
    (its values, their arrival) and ``markers``, and publishes ``ee_target`` and ``mode``."""

    def __init__(self, node: Any, ns: str) -> None:
        from diagnostic_msgs.msg import DiagnosticArray
        from geometry_msgs.msg import PoseStamped
        from std_msgs.msg import String
        from visualization_msgs.msg import MarkerArray
        from wmm_qp_service.ros2.node import qos

        self.PoseStamped, self.String = PoseStamped, String
        self.poses: list[np.ndarray] = []
        self.stamps: list[float] = []
        self.diag: list[dict[str, str]] = []
        self.marker_ns: set[str] = set()
        node.create_subscription(PoseStamped, f"{ns}/ee_pose", lambda m: self.poses.append(np.array(
            [m.pose.position.x, m.pose.position.y, m.pose.position.z])), qos(False, 10))
        node.create_subscription(DiagnosticArray, f"{ns}/status", self._status, qos(False, 10))
        node.create_subscription(MarkerArray, f"{ns}/markers", lambda m: self.marker_ns.update(
            x.ns for x in m.markers if x.header.frame_id == "world"), qos(False, 10))
        self.pub_t = node.create_publisher(PoseStamped, f"{ns}/ee_target", qos(True, 10))
        self.pub_m = node.create_publisher(String, f"{ns}/mode", qos(True, 10))
        until(lambda: self.poses and self.diag, 60.0, "ee_pose and status from the face")
        until(lambda: self.pub_t.get_subscription_count() and self.pub_m.get_subscription_count(), 30.0,
              "the face's subscriptions matched (discovery)")

    def _status(self, m: Any) -> None:
        self.stamps.append(time.monotonic())
        self.diag.append({kv.key: kv.value for kv in m.status[0].values})

    def pose(self, x: np.ndarray, frame: str = "world") -> Any:
        m = self.PoseStamped()
        m.header.frame_id = frame
        m.pose.position.x, m.pose.position.y, m.pose.position.z = (float(v) for v in x)
        m.pose.orientation.w = 1.0
        return m

    def mode(self, mode: str) -> None:
        self.pub_m.publish(self.String(data=mode))

    def follow(self, offset: tuple[float, float, float], tol: float = 0.005) -> None:
        """Mode track, then the target at the EE + offset until the EE is within ``tol`` of it,
        resuming after a fault as an operator would (a loaded host's watchdogs)."""

        def track() -> bool:
            self.mode("track")
            time.sleep(0.2)
            return self.diag[-1].get("mode") == "track"

        until(track, 20.0, "mode track through the face")
        target = self.poses[-1] + np.array(offset)
        end = time.monotonic() + 40.0
        resumed = 0.0
        while time.monotonic() < end and np.linalg.norm(self.poses[-1] - target) > tol:
            d = self.diag[-1]
            if (d.get("resume_needed") == "True" or d.get("mode") != "track") and time.monotonic() > resumed:
                self.mode("track")
                resumed = time.monotonic() + 0.3
            self.pub_t.publish(self.pose(target))
            time.sleep(0.05)
        err = float(np.linalg.norm(self.poses[-1] - target))
        assert err <= tol, f"EE {self.poses[-1]} vs target {target}: {err:.4f} m; {self.diag[-1]}"
        assert {"ee_target", "fence"} <= self.marker_ns, self.marker_ns
        gaps = np.diff(self.stamps[-20:])
        assert float(np.median(gaps)) <= 0.2, gaps  # status at 5 Hz or more

    def refuses_garbage(self) -> None:
        self.pub_t.publish(self.pose(np.array([math.nan, 0.0, 0.5])))
        self.pub_t.publish(self.pose(self.poses[-1], frame="map"))
        self.mode("fly")
        until(lambda: all(int(self.diag[-1].get(k, "0")) >= 1 for k in (
            "refused.ee_target_invalid", "refused.frame", "refused.mode_invalid")),
              10.0, "the malformed messages counted in the status")


@inside_only
def test_live_the_face_follows_ros2_targets_reports_and_refuses_garbage_and_the_robot_brakes_when_the_daemon_dies(
        tmp_path: Path) -> None:
    """``serve --ros2``: a plain rclpy node sends ``mode`` and ``ee_target`` poses and the EE follows;
    ``status`` arrives every ≤ 0.2 s (median) with faults and refusals; ``markers`` show the target
    and the fence; malformed messages counted. Then the daemon is killed (SIGKILL): the driver's
    stale stop brakes the robot to rest."""
    from wmm_qp_service.client import Client

    robot = w.load_robot_config(ROBOTS / "gen3_mecanum.toml")
    with stack(tmp_path, ROBOTS / "gen3_mecanum.toml", daemon=True, daemon_args=("--ros2",)) as s:
        rec = Recorder(robot)
        try:
            with Client(s.svc, name="test") as cl:
                cl.wait_ready(300.0, 60.0, exited=s.exited)
                face = FaceProbe(rec.node, f"/{s.svc.robot}")
                face.follow((0.05, -0.03, -0.04))
                face.refuses_garbage()
                assert rec.limits_kept()[1] == ""
                # the daemon killed mid-motion: the driver brakes the robot by itself
                face.pub_t.publish(face.pose(face.poses[-1] - np.array([0.05, -0.03, -0.04])))
                time.sleep(0.3)
                s.kill("daemon")
                st = until(lambda: (x := cl.latest_state()) is not None and x.stale_stop
                           and not any(x.v_arm) and not any(x.wheel_speeds) and x, 10.0, "the robot braked to rest")
                assert st.stale_stop
                time.sleep(0.2)
                with rec.lock:
                    assert not rec.commands[-1].any()
        finally:
            rec.close()


@inside_only
def test_live_the_embedded_mode_has_the_face_too(tmp_path: Path) -> None:
    """``sim --embedded --ros2``: the same face on the one embedded process."""
    from wmm_qp_service.client import Client
    from wmm_qp_service.processes import Stack, isolated_config
    from wmm_qp_service.ros2.node import RosNode

    robot_file = ROBOTS / "panda_diffdrive.toml"
    robot = w.load_robot_config(robot_file)
    with Stack(isolated_config(robot=robot), log_dir=tmp_path, robot_file=robot_file, embedded=True,
               extra_sim_args=["--ros2"]) as s, Client(s.svc, name="test") as cl:
        cl.wait_ready(300.0, 60.0, exited=s.exited)
        with RosNode("test_face_probe") as ros:
            face = FaceProbe(ros.node, f"/{s.svc.robot}")
            face.follow((0.04, 0.0, -0.03))
            face.refuses_garbage()


TALK = """
import sys, time, rclpy
from rclpy.node import Node
from std_msgs.msg import String
rclpy.init()
n = Node("probe_" + sys.argv[1])
got = []
if sys.argv[1] == "pub":
    p = n.create_publisher(String, "probe", 10)
    t = time.time()
    while time.time() - t < 6:
        p.publish(String(data="hi"))
        rclpy.spin_once(n, timeout_sec=0.05)
else:
    n.create_subscription(String, "probe", lambda m: got.append(m.data), 10)
    t = time.time()
    while time.time() - t < 6 and not got:
        rclpy.spin_once(n, timeout_sec=0.05)
    print("received", len(got))
"""


@inside_only
def test_live_the_fast_dds_profile_loads_binds_loopback_and_two_nodes_meet(tmp_path: Path) -> None:
    """configs/ros2/fastdds_localhost.xml with ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST: Fast DDS
    reads it without an error (a broken file, or an interface the machine lacks, is an error on
    stderr: the profile is in use), and a talker and a listener find each other."""
    script = tmp_path / "talk.py"
    script.write_text(TALK)
    env = {**os.environ, "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST", "RMW_IMPLEMENTATION": "rmw_fastrtps_cpp",
           "FASTDDS_DEFAULT_PROFILES_FILE": str(ROOT / "configs" / "ros2" / "fastdds_localhost.xml")}
    pub = subprocess.Popen([sys.executable, str(script), "pub"], env=env, stdout=subprocess.PIPE,
                           stderr=subprocess.PIPE, text=True)
    sub = subprocess.run([sys.executable, str(script), "sub"], env=env, capture_output=True, text=True, timeout=60,
                         check=False)
    _, pub_err = pub.communicate(timeout=60)
    assert "received 1" in sub.stdout, sub.stdout + sub.stderr
    assert "Error" not in sub.stderr + pub_err, sub.stderr + pub_err
