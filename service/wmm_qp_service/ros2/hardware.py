"""A robot run by ros2_control, as a :class:`wmm_qp_robot.hardware.HardwareInterface`.

``read()`` gives the newest joint state (``sensor_msgs/JointState``, mapped by joint name) and
odometry (``nav_msgs/Odometry``); ``write(wheel_speeds, arm_rates)`` publishes the arm's rates on
its forward velocity controller (``std_msgs/Float64MultiArray``, the robot file's joint order) and
the base's body twist on ``cmd_vel`` (``geometry_msgs/Twist`` or ``TwistStamped``): the base
kind's M of eq. (3) maps the wheel speeds to (vx, vy, wz); a differential drive's vy is 0 by
its M. The hardware enforces nothing: the driver's firmware (:mod:`.driver`) decides what is
written. Subscriptions run on the node's executor thread and only store the newest sample.
"""

from __future__ import annotations

import math
import time
from collections import Counter, deque
from dataclasses import dataclass
from typing import Any

import numpy as np

import wmm_qp as w
from wmm_qp.config import FloatArray
from wmm_qp.model.bases import make_base

from .messages import JointIndex, JointSample, OdomSample, odom_sample
from .node import qos


@dataclass(frozen=True, slots=True)
class Ros2Measured:
    """What the robot measured (a :class:`wmm_qp_robot.hardware.Measured`), with its age."""

    q_arm: FloatArray
    v_arm: FloatArray
    wheel_speeds: FloatArray
    tau: FloatArray
    q_base: FloatArray
    received: float
    """[s] monotonic time the joint state arrived."""


class Ros2Hardware:
    """The topics of one ros2_control robot (its robot file's ``[ros2]`` table).

    Args:
        node: the rclpy node (its executor thread runs the callbacks).
        robot: the robot file.
        clock: monotonic clock [s] that stamps arrivals.
    """

    def __init__(self, node: Any, robot: w.RobotConfig, clock: Any = time.monotonic) -> None:
        from geometry_msgs.msg import Twist, TwistStamped
        from nav_msgs.msg import Odometry
        from sensor_msgs.msg import JointState
        from std_msgs.msg import Float64MultiArray

        self.robot = robot
        self.cfg = robot.ros2
        self.base = make_base(robot.base)
        self.index = JointIndex(robot.arm.joints)
        self.clock = clock
        self.counts: Counter[str] = Counter()  # refused messages: joint_states_foreign, ..., odom_invalid
        self.joint: JointSample | None = None  # the newest accepted joint state
        self.odom: OdomSample | None = None
        self.joint_states = 0  # accepted
        self.ros_in: deque[float] = deque(maxlen=500_000)  # [s] accepted joint states' header stamp → arrival
        self._node = node
        self._Float64MultiArray = Float64MultiArray
        self._stamped = self.cfg.cmd_vel_type.endswith("TwistStamped")
        self._Twist = TwistStamped if self._stamped else Twist
        node.create_subscription(JointState, self.cfg.joint_states, self._on_joint_state, qos(False, 10))
        self.pub_arm = node.create_publisher(Float64MultiArray, self.cfg.arm_command, qos(True))
        self.pub_base = None
        if robot.n_wheels:
            node.create_subscription(Odometry, self.cfg.odom, self._on_odom, qos(False, 10))
            self.pub_base = node.create_publisher(self._Twist, self.cfg.cmd_vel, qos(True))

    # ---------------------------------------------------------------- the executor's thread
    def _on_joint_state(self, msg: Any) -> None:
        try:
            s = self.index.map(self.clock(), msg.name, msg.position, msg.velocity, msg.effort)
        except Exception:  # a message no check foresaw: refused, never raised into the executor
            s = "invalid"
        if isinstance(s, str):
            self.counts[f"joint_states_{s}"] += 1
            return
        self.joint = s
        self.joint_states += 1
        st = msg.header.stamp
        if st.sec or st.nanosec:  # (wall clock: the publisher's ROS time, on this machine)
            self.ros_in.append(time.time() - (st.sec + 1e-9 * st.nanosec))

    def _on_odom(self, msg: Any) -> None:
        try:
            p, o, t = msg.pose.pose.position, msg.pose.pose.orientation, msg.twist.twist
            s = odom_sample(self.clock(), p.x, p.y, (o.x, o.y, o.z, o.w), t.linear.x, t.linear.y, t.angular.z)
        except Exception:
            s = None
        if s is None:
            self.counts["odom_invalid"] += 1
            return
        self.odom = s

    # ---------------------------------------------------------------- the control thread
    def read(self) -> Ros2Measured | None:
        """The newest measurements (None: no joint state yet)."""
        j, o = self.joint, self.odom
        if j is None:
            return None
        pose = o.pose if o is not None else np.zeros(3)
        wheels = self.base.wheel_speeds(o.twist) if o is not None else np.zeros(self.robot.n_wheels)
        return Ros2Measured(j.q, j.v, wheels, j.tau, pose, j.received)

    def write(self, wheel_speeds: FloatArray, arm_rates: FloatArray) -> None:
        """Publish the arm's rates and (a mobile base) the body twist of the wheel speeds."""
        m = self._Float64MultiArray()
        m.data = [float(x) for x in arm_rates]
        self.pub_arm.publish(m)
        if self.pub_base is None:
            return
        vx, vy, wz = (float(x) for x in self.base.body_twist(np.asarray(wheel_speeds, dtype=float)))
        msg = self._Twist()
        t = msg.twist if self._stamped else msg
        if self._stamped:
            msg.header.stamp = self._node.get_clock().now().to_msg()
            msg.header.frame_id = "base_link"
        t.linear.x, t.linear.y, t.angular.z = vx, (vy if self.base.holonomic else 0.0), wz
        if not all(math.isfinite(x) for x in (vx, vy, wz)):  # never: the firmware wrote finite rates
            t.linear.x = t.linear.y = t.angular.z = 0.0
        self.pub_base.publish(msg)
