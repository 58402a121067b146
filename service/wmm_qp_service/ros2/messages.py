"""The ROS 2 messages of a ros2_control robot as numbers, checked: pure, no rclpy.

Everything a robot's topics carry is judged before the driver uses it: a joint state is mapped by
joint name (any order, other joints ignored), and refused when it names none of the robot's joints
(another robot's, or garbage: ``foreign``), only some of them (``partial``), or has a length that
does not match its names, a duplicated name or a non-finite position (``invalid``); an odometry
with a non-finite pose or twist is ``invalid``. Refusals are counted by the caller, never raised.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from wmm_qp.config import FloatArray


@dataclass(frozen=True, slots=True)
class JointSample:
    """A joint state of the robot's arm, in the robot file's joint order.

    Attributes:
        received: [s] monotonic time it reached this process.
        q: [rad or m] positions.
        v: [rad/s or m/s] velocities (zeros when the message has none).
        tau: [N·m or N] efforts (zeros when the message has none).
    """

    received: float
    q: FloatArray
    v: FloatArray
    tau: FloatArray


@dataclass(frozen=True, slots=True)
class OdomSample:
    """A base odometry.

    Attributes:
        received: [s] monotonic time it reached this process.
        pose: [m, m, rad] x, y, yaw in the odometry frame.
        twist: [m/s, m/s, rad/s] vx, vy, wz in the base frame (ROS's child frame).
    """

    received: float
    pose: FloatArray
    twist: FloatArray


class JointIndex:
    """Maps ``sensor_msgs/JointState`` fields to the arm's joints (the robot file's order).

    Args:
        joints: the arm's joint names, in the robot file's order.
    """

    def __init__(self, joints: Sequence[str]) -> None:
        self.joints = tuple(joints)
        self._wanted = set(self.joints)
        self._cache: dict[tuple[str, ...], np.ndarray | str] = {}

    def _index(self, names: tuple[str, ...]) -> np.ndarray | str:
        if (hit := self._cache.get(names)) is not None:
            return hit
        where = {n: i for i, n in enumerate(names)}
        out: np.ndarray | str
        if len(where) != len(names):
            out = "invalid"  # a joint named twice
        elif not self._wanted & where.keys():
            out = "foreign"
        elif not self._wanted <= where.keys():
            out = "partial"
        else:
            out = np.array([where[j] for j in self.joints], dtype=np.intp)
        if len(self._cache) < 64:  # a robot publishes one or two name lists; garbage is not cached for ever
            self._cache[names] = out
        return out

    def map(self, received: float, names: Sequence[str], position: Sequence[float], velocity: Sequence[float],
            effort: Sequence[float]) -> JointSample | str:
        """The arm's sample, or why the message is refused (``foreign``, ``partial``, ``invalid``)."""
        names_t = tuple(names)
        n = len(names_t)
        if len(position) != n or len(velocity) not in (0, n) or len(effort) not in (0, n):
            return "invalid"
        idx = self._index(names_t)
        if isinstance(idx, str):
            return idx
        q = np.asarray(position, dtype=float)[idx]
        if not np.isfinite(q).all():
            return "invalid"
        v = np.asarray(velocity, dtype=float)[idx] if len(velocity) else np.zeros(len(idx))
        tau = np.asarray(effort, dtype=float)[idx] if len(effort) else np.zeros(len(idx))
        return JointSample(received, q, np.nan_to_num(v, nan=0.0), np.nan_to_num(tau, nan=0.0))


def yaw_of(x: float, y: float, z: float, w: float) -> float:
    """[rad] the heading of a unit quaternion (rotation about z)."""
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def odom_sample(received: float, px: float, py: float, quat: tuple[float, float, float, float],
                vx: float, vy: float, wz: float) -> OdomSample | None:
    """An odometry's planar pose and body twist (None: a non-finite or zero-norm field)."""
    vals = (px, py, *quat, vx, vy, wz)
    if not all(math.isfinite(v) for v in vals) or sum(c * c for c in quat) < 1e-12:
        return None
    return OdomSample(received, np.array([px, py, yaw_of(*quat)]), np.array([vx, vy, wz]))
