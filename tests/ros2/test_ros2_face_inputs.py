"""The ROS 2 face's inputs and status, in process (no ROS 2 needed): ``ee_target`` and ``mode``
pass the daemon's own validators before anything is sent; garbage is counted, never raised."""

from __future__ import annotations

import math

import numpy as np
import pytest
from wmm_qp_service.config import load_service_config
from wmm_qp_service.protocol import LoopStats, StatusMsg
from wmm_qp_service.ros2.face import Ros2Face, quat_of, rpy_matrix

import wmm_qp as w
from wmm_qp.scene import load_scene


@pytest.fixture(scope="module")
def face() -> Ros2Face:
    robot = w.load_robot_config()
    return Ros2Face(load_service_config().with_robot(robot), robot, load_scene())


def test_a_good_target_and_mode_are_sent(face: Ros2Face) -> None:
    assert face.on_ee_target("world", [0.5, 0.0, 0.4], [0.0, 0.0, 0.0, 1.0])
    assert face.on_ee_target("", [0.5, 0.0, 0.4], [0.0, 0.0, 0.0, 1.0])
    assert face.on_mode("track")
    assert face.sent["ee_target"] >= 2 and face.sent["mode"] >= 1


@pytest.mark.parametrize(("frame", "x", "q", "reason"), [
    ("world", [math.nan, 0.0, 0.4], [0.0, 0.0, 0.0, 1.0], "ee_target_invalid"),
    ("world", [1e9, 0.0, 0.4], [0.0, 0.0, 0.0, 1.0], "ee_target_invalid"),  # out of the validation range
    ("world", [0.5, 0.0, 0.4], [0.0, 0.0, 0.0, 0.0], "ee_target_invalid"),  # not a rotation
    ("map", [0.5, 0.0, 0.4], [0.0, 0.0, 0.0, 1.0], "frame"),  # a frame the daemon does not know
])
def test_a_malformed_target_is_counted_and_not_sent(face: Ros2Face, frame: str, x: list[float], q: list[float],
                                                    reason: str) -> None:
    sent, n = face.sent["ee_target"], face.refused[reason]
    assert not face.on_ee_target(frame, x, q)
    assert face.refused[reason] == n + 1 and face.sent["ee_target"] == sent


def test_an_unknown_mode_is_counted_and_not_sent(face: Ros2Face) -> None:
    n = face.refused["mode_invalid"]
    assert not face.on_mode("fly")
    assert face.refused["mode_invalid"] == n + 1


def test_the_diagnostics_name_mode_faults_by_code_loop_and_refusals(face: Ros2Face) -> None:
    face.refused["frame"] += 0  # (a key that exists)
    st = StatusMsg(robot="wmm", seq=1, stamp=0.0, mode="track", state_ok=True, safe_stop=False, robot_alive=True,
                   fault_active=True, last_fault="robot protective stop", last_fault_code="robot_protective_stop",
                   faults={"stream_broken": 2}, loop=LoopStats(rate_hz=500.0, deadline_misses=3))
    level, text, vals = face.diagnostics(st, True)
    assert level == 1 and text.startswith("robot_protective_stop")
    assert vals["mode"] == "track" and vals["fault.stream_broken"] == "2" and vals["loop.deadline_misses"] == "3"
    assert vals["loop.rate_hz"] == "500" and "refused.frame" in vals
    assert face.diagnostics(None, False)[0] == 2


def test_the_orientation_conversions_agree() -> None:
    R = rpy_matrix([0.3, -0.2, 1.1])
    x, y, z, wq = quat_of(R)
    R2 = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * wq), 2 * (x * z + y * wq)],
                   [2 * (x * y + z * wq), 1 - 2 * (x * x + z * z), 2 * (y * z - x * wq)],
                   [2 * (x * z - y * wq), 2 * (y * z + x * wq), 1 - 2 * (x * x + y * y)]])
    assert np.allclose(R, R2) and abs(x * x + y * y + z * z + wq * wq - 1.0) < 1e-12
    assert np.allclose(quat_of(rpy_matrix([0.0, 0.0, np.pi])), [0, 0, 1, 0], atol=1e-12) or np.allclose(
        quat_of(rpy_matrix([0.0, 0.0, np.pi])), [0, 0, -1, 0], atol=1e-12)


def test_the_markers_show_the_target_the_fence_and_every_obstacle_of_a_scene() -> None:
    pytest.importorskip("visualization_msgs", reason="needs ROS 2's messages (pip install 'wmm-qp[ros2]')")
    from visualization_msgs.msg import Marker, MarkerArray

    from wmm_qp.config import default_config_dir

    robot = w.load_robot_config()
    scene = load_scene(default_config_dir() / "scenes" / "cluttered.toml")
    face = Ros2Face(load_service_config().with_robot(robot), robot, scene)
    face._target = [0.5, 0.0, 0.4]
    arr = face.markers({"Marker": Marker, "MarkerArray": MarkerArray}, None)
    ns = [m.ns for m in arr.markers]
    solids = [o for o in scene.obstacles if o.kind != "plane"]
    assert ns.count("ee_target") == 1 and ns.count("fence") == 1 and ns.count("obstacles") == len(solids) > 0
    for m in arr.markers:
        q = m.pose.orientation
        assert abs(q.x**2 + q.y**2 + q.z**2 + q.w**2 - 1.0) < 1e-9 and m.header.frame_id == "world"
