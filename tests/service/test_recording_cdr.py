"""The recording's own CDR (wmm_qp_service.recording.cdr) is byte for byte rosbags' serialize_cdr."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("rosbags")

from rosbags.typesys import Stores, get_typestore
from wmm_qp_service.recording import cdr

TS = get_typestore(Stores.ROS2_HUMBLE)
T = TS.types
RNG = np.random.default_rng(7)


def _header(ns: int, frame: str) -> object:
    return T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9),
                                    frame_id=frame)


def _pose(p: np.ndarray, q: np.ndarray) -> object:
    return T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=p[0], y=p[1], z=p[2]),
                                       orientation=T["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3]))


def _v3(v: np.ndarray) -> object:
    return T["geometry_msgs/msg/Vector3"](x=v[0], y=v[1], z=v[2])


@pytest.mark.parametrize("n", [0, 1, 4, 7])
def test_joint_state(n: int) -> None:
    ns = 1_733_390_000_123_456_789
    names = [f"joint_{i}" * (i + 1) for i in range(n)]  # names of every length: every padding
    pos, vel = RNG.normal(size=n), RNG.normal(size=n)
    for p in (pos, None):
        ref = TS.serialize_cdr(T["sensor_msgs/msg/JointState"](
            header=_header(ns, ""), name=names, position=pos if p is not None else np.empty(0), velocity=vel,
            effort=np.empty(0)), "sensor_msgs/msg/JointState")
        assert cdr.joint_state(ns, [s.encode() for s in names], p, vel) == bytes(ref)


@pytest.mark.parametrize("frame", ["", "w", "world", "world_frame"])
def test_pose_stamped_odometry_and_tf(frame: str) -> None:
    ns = 42_000_000_007
    p, q = RNG.normal(size=3), RNG.normal(size=4)
    ref = TS.serialize_cdr(T["geometry_msgs/msg/PoseStamped"](header=_header(ns, frame), pose=_pose(p, q)),
                           "geometry_msgs/msg/PoseStamped")
    assert cdr.pose_stamped(ns, frame.encode(), p, q) == bytes(ref)
    lin, ang = RNG.normal(size=3), RNG.normal(size=3)
    ref = TS.serialize_cdr(T["nav_msgs/msg/Odometry"](
        header=_header(ns, frame), child_frame_id="base",
        pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=_pose(p, q), covariance=np.zeros(36)),
        twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=T["geometry_msgs/msg/Twist"](linear=_v3(lin),
                                                                                            angular=_v3(ang)),
                                                         covariance=np.zeros(36))), "nav_msgs/msg/Odometry")
    assert cdr.odometry(ns, frame.encode(), b"base", p, q, lin, ang) == bytes(ref)
    frames = [(frame, f"link_{'x' * i}", RNG.normal(size=3), RNG.normal(size=4)) for i in range(5)]
    ref = TS.serialize_cdr(T["tf2_msgs/msg/TFMessage"](transforms=[
        T["geometry_msgs/msg/TransformStamped"](
            header=_header(ns, a), child_frame_id=b,
            transform=T["geometry_msgs/msg/Transform"](translation=_v3(t), rotation=T["geometry_msgs/msg/Quaternion"](
                x=r[0], y=r[1], z=r[2], w=r[3]))) for a, b, t, r in frames]), "tf2_msgs/msg/TFMessage")
    assert cdr.tf_message(ns, [(a.encode(), b.encode(), t, r) for a, b, t, r in frames]) == bytes(ref)
