"""``wmm-qp sim --ros2``: the simulated robot behind ros2_control-shaped topics, a stand-in for a
real ROS 2 robot.

What a ros2_control robot with a joint state broadcaster, a forward velocity controller on the
arm and a base controller offers, on the topics of the robot file's ``[ros2]`` table:

- publishes ``joint_states`` (``sensor_msgs/JointState``: the arm's joints and the wheels, named
  ``wheel_<name>``, as extras a driver must ignore) and ``odom`` (``nav_msgs/Odometry``: the pose
  integrated from the measured wheel speeds with the base kind's nominal model, eq. (3), and the
  body twist), once per cycle;
- takes the arm's rates on ``forward_velocity_controller/commands`` (``std_msgs/Float64MultiArray``
  in the robot file's joint order; like ros2_control's forward command controller it ignores a
  message of the wrong length, counted, and holds the last one for ever) and the base's twist on
  ``cmd_vel`` (``Twist`` or ``TwistStamped``; the wheel speeds that realise it; like
  diff_drive_controller it stops the base when no twist came for :data:`CMD_VEL_TIMEOUT`).

Behind the topics is the plant alone (kinematic or MuJoCo, ``--physics``): hardware executes what
it is told, with no firmware, no stream rules and no limits enforced — the driver's firmware must
keep the robot safe, and a test node reading ``joint_states`` sees whether it did.
"""

from __future__ import annotations

import sys
import threading
import time
from collections import Counter
from typing import Any

import numpy as np
from wmm_qp_sim.config import SimConfig
from wmm_qp_sim.plants import make_plant
from wmm_qp_sim.slip import integrate_pose

import wmm_qp as w
from wmm_qp.scene import Scene

from ..rate_loop import RateLoop
from .node import RosNode, import_rclpy, qos

CMD_VEL_TIMEOUT = 0.5
"""[s] diff_drive_controller's default ``cmd_vel_timeout``: no twist for this long stops the base."""
CATCH_UP_MAX = 50
"""Cycles run at most in one wake-up to catch up with the wall clock (a longer stall is lost time)."""


class Ros2SimRobot:
    """The plant behind the topics.

    Args:
        robot: the robot file (its ``[ros2]`` table names the topics, its ``rate_hz`` the cycle).
        sim_cfg: the sim's config (the plant's step, slip, physics).
        plant: "kinematic" or "mujoco".
        scene: the physics plant's static obstacles (None: none).
        rate_hz: [Hz] the cycle (None: the robot file's ``[ros2] rate_hz``).
        seed: the slip noise's seed (None: the sim config's).
    """

    def __init__(self, robot: w.RobotConfig, sim_cfg: SimConfig, plant: str = "kinematic",
                 scene: Scene | None = None, rate_hz: float | None = None, seed: int | None = None) -> None:
        self.robot = robot
        self.cfg = robot.ros2
        self.model = w.WmmModel(robot)
        self.base = self.model.base
        self.plant = make_plant(plant, self.model, sim_cfg, sim_cfg.seed if seed is None else seed, scene)
        self.plant.reset(np.zeros(3), np.array(robot.arm.start, dtype=float), None)
        self.rate_hz = float(rate_hz if rate_hz is not None else self.cfg.rate_hz)
        self.substeps = max(1, round(sim_cfg.rate_hz / self.rate_hz))  # plant steps of ~sim dt per cycle
        self.h = 1.0 / (self.rate_hz * self.substeps)
        self.odom = np.zeros(3)
        self.arm_cmd = np.zeros(robot.n_arm)  # held, as a forward command controller holds it
        self.twist = np.zeros(3)
        self.twist_t = -np.inf  # [s] monotonic arrival of the last twist
        self.ignored: Counter[str] = Counter()
        self.t = 0.0
        self.cycles = 0
        self.wheel_names = [f"wheel_{n}" for n in self.base.wheel_names]

    def on_arm(self, data: Any) -> None:
        """A forward command: one finite rate per joint, else ignored (counted)."""
        v = np.asarray(data, dtype=float)
        if v.shape != (self.robot.n_arm,) or not np.isfinite(v).all():
            self.ignored["arm_command"] += 1
            return
        self.arm_cmd = v

    def on_twist(self, vx: float, vy: float, wz: float, now: float) -> None:
        """A base twist (non-finite: ignored, counted)."""
        t = np.array([vx, vy, wz], dtype=float)
        if not np.isfinite(t).all():
            self.ignored["cmd_vel"] += 1
            return
        self.twist, self.twist_t = t, now

    def step(self, now: float) -> Any:
        """One cycle at monotonic time ``now``: the held commands to the plant, advanced; returns
        what it measured."""
        wheels = (self.base.wheel_speeds(self.twist) if now - self.twist_t <= CMD_VEL_TIMEOUT
                  else np.zeros(self.robot.n_wheels))
        self.plant.write(wheels, self.arm_cmd)
        for _ in range(self.substeps):
            self.plant.advance(self.h)
            ps = self.plant.read()
            self.odom = integrate_pose(self.odom, self.base.body_twist(ps.wheel_speeds), self.h)  # eq. (3)
        self.t += self.substeps * self.h
        self.cycles += 1
        return ps

    def run(self, stop: threading.Event, max_cycles: int | None = None) -> int:
        """Publish and obey until ``stop`` (or ``max_cycles``)."""
        import_rclpy()  # (Ros2Missing, before the messages' ImportError)
        from geometry_msgs.msg import Twist, TwistStamped
        from nav_msgs.msg import Odometry
        from sensor_msgs.msg import JointState
        from std_msgs.msg import Float64MultiArray

        cfg = self.cfg
        with RosNode("wmm_qp_sim") as ros:
            node = ros.node

            def on_twist(msg: Any) -> None:
                t = msg.twist if hasattr(msg, "header") else msg
                self.on_twist(t.linear.x, t.linear.y, t.angular.z, time.monotonic())

            node.create_subscription(Float64MultiArray, cfg.arm_command, lambda m: self.on_arm(m.data), qos(True, 10))
            stamped = cfg.cmd_vel_type.endswith("TwistStamped")
            if self.robot.n_wheels:
                node.create_subscription(TwistStamped if stamped else Twist, cfg.cmd_vel, on_twist, qos(True, 10))
            pub_js = node.create_publisher(JointState, cfg.joint_states, qos(True, 10))
            pub_odom = node.create_publisher(Odometry, cfg.odom, qos(True, 10)) if self.robot.n_wheels else None
            names = [*self.robot.arm.joints, *self.wheel_names]
            print(f"wmm-qp sim --ros2: {self.robot.name} at {self.rate_hz:g} Hz: publishing {cfg.joint_states!r}"
                  f"{f', {cfg.odom!r}' if pub_odom else ''}; taking {cfg.arm_command!r}"
                  f"{f', {cfg.cmd_vel!r} ({cfg.cmd_vel_type})' if self.robot.n_wheels else ''}",
                  file=sys.stderr, flush=True)
            loop = RateLoop(self.rate_hz, 0.0, clock=time.monotonic)
            now = t0 = loop.start()
            while not stop.is_set() and (max_cycles is None or self.cycles < max_cycles):
                due = min(CATCH_UP_MAX, max(1, int((now - t0) * self.rate_hz) + 1 - self.cycles))
                for _ in range(due):
                    ps = self.step(now)
                stamp = node.get_clock().now().to_msg()
                js = JointState()
                js.header.stamp, js.header.frame_id = stamp, ""
                js.name = names
                wheel_pos = np.zeros(self.robot.n_wheels)  # (the wheels' angles are not integrated)
                js.position = [*ps.q_arm.tolist(), *wheel_pos.tolist()]
                js.velocity = [*ps.v_arm.tolist(), *ps.wheel_speeds.tolist()]
                js.effort = [*ps.tau.tolist(), *np.zeros(self.robot.n_wheels).tolist()]
                pub_js.publish(js)
                if pub_odom is not None:
                    od = Odometry()
                    od.header.stamp, od.header.frame_id, od.child_frame_id = stamp, "odom", "base_link"
                    x, y, yaw = self.odom
                    od.pose.pose.position.x, od.pose.pose.position.y = float(x), float(y)
                    o, tw = od.pose.pose.orientation, od.twist.twist
                    o.z, o.w = float(np.sin(yaw / 2)), float(np.cos(yaw / 2))
                    vx, vy, wz = self.base.body_twist(ps.wheel_speeds)
                    tw.linear.x, tw.linear.y, tw.angular.z = float(vx), float(vy), float(wz)
                    pub_odom.publish(od)
                now = loop.wait()
            print(f"wmm-qp sim --ros2: stopped after {self.cycles} cycles ({self.t:.2f} s); ignored "
                  f"{dict(self.ignored) or 'none'}", file=sys.stderr, flush=True)
        return 0
