"""The daemon's ROS 2 face (``wmm-qp serve --ros2``): ROS 2 tools see and steer the robot.

Under ``/<robot>/`` (the robot id) it publishes, at the status rate (``service.toml``
``[loop] status_hz``, 10 Hz):

- ``ee_pose`` (``geometry_msgs/PoseStamped``, frame ``world``: the daemon's world, the odometry's
  frame): the EE pose of the robot's last state (the model's forward kinematics, eq. (2));
- ``status`` (``diagnostic_msgs/DiagnosticArray``): one ``DiagnosticStatus`` named ``wmm_qp``
  (level OK, WARN while a fault holds or the robot is in a protective stop, ERROR when no state
  arrives), its values the mode, the controller status, the last fault and its code, every fault
  by code (``fault.<code>``), the loop's rate and deadline misses, the robot's violations and the
  face's refused messages (``refused.<reason>``);
- ``markers`` (``visualization_msgs/MarkerArray``, frame ``world``): the EE target, the EE fence
  (its box, where finite) and the scene's obstacles — RViz shows them.

It takes:

- ``ee_target`` (``geometry_msgs/PoseStamped``): an EE target, position and orientation (the
  orientation followed by the pose task), smoothed by the daemon like any setpoint;
- ``mode`` (``std_msgs/String``): hold | track | dm_cartesian | dm_nullspace.

Both become the daemon's own messages (``setpoint``, ``mode``) and pass the same validation as
every Zenoh input (:class:`~wmm_qp_service.validation.Validator`) twice: here, where a refusal is
counted in ``refused`` and nothing is sent, and in the daemon's host inputs on receipt. A pose
in a frame other than ``world`` (or empty), non-finite or out of range, a zero quaternion, an
unknown mode: counted and refused, never raised.

The face is a client of the daemon over Zenoh in the daemon's process (:class:`~..client.Client`):
rclpy runs in its own executor thread (:class:`~.node.RosNode`); nothing of it runs in or waits
on the control thread.
"""

from __future__ import annotations

import math
import re
import time
from collections import Counter
from typing import Any

import numpy as np

import wmm_qp as w
from wmm_qp.scene import Scene

from ..client import Client
from ..config import ServiceConfig
from ..protocol import ModeMsg, SetpointMsg
from ..validation import Validator
from .node import RosNode, import_rclpy, qos

FRAMES = ("", "world")
"""The frames an ``ee_target`` may name: the daemon's world ("" for a tool that leaves it empty)."""


def quat_of(R: np.ndarray) -> list[float]:
    """A rotation matrix as a unit quaternion [x, y, z, w] (Shepperd's method)."""
    t = float(np.trace(R))
    if t > 0.0:
        s = 2.0 * math.sqrt(t + 1.0)
        q = [(R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s, 0.25 * s]
    else:
        i = int(np.argmax(np.diag(R)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * math.sqrt(max(1e-300, 1.0 + R[i, i] - R[j, j] - R[k, k]))
        q = [0.0, 0.0, 0.0, (R[k, j] - R[j, k]) / s]
        q[i] = 0.25 * s
        q[j] = (R[j, i] + R[i, j]) / s
        q[k] = (R[k, i] + R[i, k]) / s
    return [float(v) for v in q]


def rpy_matrix(rpy: Any) -> np.ndarray:
    """URDF's roll-pitch-yaw: Rz(yaw)·Ry(pitch)·Rx(roll)."""
    r, p, y = (float(v) for v in rpy)
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def ros_namespace(robot: str) -> str:
    """``/<robot>``: the robot id as a ROS 2 namespace (a character ROS names do not take, e.g. ``-``,
    becomes ``_``; a leading digit gets a ``_`` before it)."""
    ns = re.sub(r"[^A-Za-z0-9_]", "_", robot)
    return "/" + ("_" + ns if ns[:1].isdigit() else ns)


class Ros2Face:
    """The face of one daemon.

    Args:
        svc: the daemon's service config (its robot id names the namespace).
        robot: the robot file (the EE pose's model).
        scene: the daemon's scene (the markers' fence and obstacles).
        rate_hz: [Hz] publication rate (None: the service config's ``loop.status_hz``).
    """

    def __init__(self, svc: ServiceConfig, robot: w.RobotConfig, scene: Scene, rate_hz: float | None = None) -> None:
        self.svc = svc
        self.robot = robot
        self.scene = scene
        self.model = w.WmmModel(robot)
        self.rate_hz = float(rate_hz if rate_hz is not None else svc.loop.status_hz)
        self.v_setpoint = Validator(SetpointMsg, svc.robot, svc.validation)
        self.v_mode = Validator(ModeMsg, svc.robot, svc.validation)
        self.refused: Counter[str] = Counter()
        self.sent = Counter[str]()
        self.published = 0
        self.client: Client | None = None
        self.ros: RosNode | None = None
        self._target: list[float] | None = None

    # ------------------------------------------------------------------ inputs (the executor's thread)
    def on_ee_target(self, frame: str, x: list[float], q: list[float]) -> bool:
        """A ``PoseStamped``'s fields: validated as a setpoint, sent (False: refused, counted)."""
        if frame not in FRAMES:
            self.refused["frame"] += 1
            return False
        msg = SetpointMsg(robot=self.svc.robot, seq=1, stamp=time.time(), x=x, source="ros2", q=q)
        if self.v_setpoint.checked(msg) is None:
            self.refused["ee_target_invalid"] += 1  # (why: self.v_setpoint.last_rejection)
            return False
        if self.client is not None:
            self.client.send_setpoint(x, q=q)
        self.sent["ee_target"] += 1
        return True

    def on_mode(self, mode: str) -> bool:
        """A ``String``: validated as a mode, sent (False: refused, counted)."""
        msg = ModeMsg(robot=self.svc.robot, seq=1, stamp=time.time(), mode=mode)
        if self.v_mode.checked(msg) is None:
            self.refused["mode_invalid"] += 1
            return False
        if self.client is not None:
            self.client.set_mode(mode)
        self.sent["mode"] += 1
        return True

    def _ee_target(self, msg: Any) -> None:
        try:
            p, o = msg.pose.position, msg.pose.orientation
            self.on_ee_target(str(msg.header.frame_id), [p.x, p.y, p.z], [o.x, o.y, o.z, o.w])
        except Exception:  # a message no check foresaw: refused, never raised into the executor
            self.refused["ee_target_invalid"] += 1

    def _mode(self, msg: Any) -> None:
        try:
            self.on_mode(str(msg.data))
        except Exception:
            self.refused["mode_invalid"] += 1

    # ------------------------------------------------------------------ outputs (a timer of the executor)
    def diagnostics(self, st: Any, alive: bool) -> tuple[int, str, dict[str, str]]:
        """(level 0 OK / 1 WARN / 2 ERROR, message, key → value) of a daemon status (None: none yet)."""
        if st is None:
            return 2, "no status from the daemon", {"refused." + k: str(n) for k, n in self.refused.items()}
        vals = {"mode": st.mode, "controller_status": st.controller_status, "reason": st.reason,
                "state_ok": str(st.state_ok), "robot_alive": str(st.robot_alive),
                "fault_active": str(st.fault_active), "last_fault": st.last_fault,
                "last_fault_code": st.last_fault_code, "resume_needed": str(st.resume_needed),
                "protective_stop": str(st.protective_stop),
                "loop.rate_hz": f"{st.loop.rate_hz:g}", "loop.measured_hz": f"{st.loop.measured_hz:.1f}",
                "loop.deadline_misses": str(st.loop.deadline_misses), "loop.ticks": str(st.loop.ticks)}
        vals |= {f"fault.{k}": str(n) for k, n in st.faults.items()}
        vals |= {f"violation.{k}": str(n) for k, n in st.robot_violations.items()}
        vals |= {f"refused.{k}": str(n) for k, n in self.refused.items()}
        if not st.state_ok or not alive:
            return 2, f"no state from the robot ({st.last_fault_code or 'no state'})", vals
        if st.fault_active or st.protective_stop:
            return 1, f"{st.last_fault_code}: {st.last_fault}", vals
        return 0, f"{st.mode}: {st.controller_status or 'ok'}", vals

    def _publish(self, pubs: dict[str, Any], msgs: Any) -> None:
        c = self.client
        if c is None:
            return
        st, state = c.latest_status(), c.latest_state()
        now = self.ros.node.get_clock().now().to_msg() if self.ros is not None else None
        if state is not None and len(state.q_arm) == self.robot.n_arm:
            x, R = self.model.ee_pose(np.asarray(state.q_base, dtype=float), np.asarray(state.q_arm, dtype=float))
            ps = msgs["PoseStamped"]()
            ps.header.stamp, ps.header.frame_id = now, "world"
            ps.pose.position.x, ps.pose.position.y, ps.pose.position.z = (float(v) for v in x)
            o = ps.pose.orientation
            o.x, o.y, o.z, o.w = quat_of(R)
            pubs["ee_pose"].publish(ps)
        level, text, vals = self.diagnostics(st, st is not None and st.robot_alive)
        da = msgs["DiagnosticArray"]()
        da.header.stamp = now
        ds = msgs["DiagnosticStatus"]()
        ds.level, ds.name, ds.message, ds.hardware_id = bytes([level]), "wmm_qp", text, self.svc.robot
        ds.values = [msgs["KeyValue"](key=k, value=v) for k, v in vals.items()]
        da.status = [ds]
        pubs["status"].publish(da)
        if st is not None and len(st.x_d) == 3 and all(math.isfinite(v) for v in st.x_d):
            self._target = list(st.x_d)
        pubs["markers"].publish(self.markers(msgs, now))
        self.published += 1

    def markers(self, msgs: Any, now: Any) -> Any:
        """The EE target (a sphere), the EE fence (a wire box, where finite), the obstacles."""
        Marker = msgs["Marker"]
        out = []

        def marker(ns: str, i: int, kind: int, xyz: Any, scale: Any, rgba: tuple[float, float, float, float],
                   quat: list[float] | None = None) -> Any:
            m = Marker()
            m.header.stamp, m.header.frame_id = now, "world"
            m.ns, m.id, m.type, m.action = ns, i, kind, Marker.ADD
            m.pose.position.x, m.pose.position.y, m.pose.position.z = (float(v) for v in xyz)
            q = quat or [0.0, 0.0, 0.0, 1.0]
            m.pose.orientation.x, m.pose.orientation.y, m.pose.orientation.z, m.pose.orientation.w = q
            m.scale.x, m.scale.y, m.scale.z = (float(v) for v in scale)
            m.color.r, m.color.g, m.color.b, m.color.a = rgba
            return m

        if self._target is not None:
            out.append(marker("ee_target", 0, Marker.SPHERE, self._target, (0.04, 0.04, 0.04), (0.1, 0.8, 0.1, 0.9)))
        lo, hi = np.asarray(self.scene.fence.ee_lower, dtype=float), np.asarray(self.scene.fence.ee_upper, dtype=float)
        if np.isfinite(lo).all() and np.isfinite(hi).all():
            out.append(marker("fence", 0, Marker.CUBE, 0.5 * (lo + hi), hi - lo, (0.2, 0.4, 1.0, 0.08)))
        for i, s in enumerate(self.scene.obstacles):
            quat = quat_of(rpy_matrix(s.rpy))
            size = np.asarray(s.size, dtype=float)
            if s.kind == "box":
                out.append(marker("obstacles", i, Marker.CUBE, s.xyz, size, (0.9, 0.3, 0.1, 0.6), quat))
            elif s.kind == "sphere":
                out.append(marker("obstacles", i, Marker.SPHERE, s.xyz, [2 * size[0]] * 3, (0.9, 0.3, 0.1, 0.6)))
            elif s.kind in ("capsule", "cylinder"):
                out.append(marker("obstacles", i, Marker.CYLINDER, s.xyz, (2 * size[0], 2 * size[0], size[1]),
                                  (0.9, 0.3, 0.1, 0.6), quat))
        arr = msgs["MarkerArray"]()
        arr.markers = out
        return arr

    # ------------------------------------------------------------------ life
    def start(self) -> None:
        """Open the Zenoh client and the node; publish from a timer of the node's executor.

        Raises:
            Ros2Missing: rclpy is not installed.
        """
        import_rclpy()
        from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
        from geometry_msgs.msg import PoseStamped
        from std_msgs.msg import String
        from visualization_msgs.msg import Marker, MarkerArray

        msgs = {"PoseStamped": PoseStamped, "DiagnosticArray": DiagnosticArray, "DiagnosticStatus": DiagnosticStatus,
                "KeyValue": KeyValue, "Marker": Marker, "MarkerArray": MarkerArray}
        self.client = Client(self.svc, name="ros2-face").open()
        self.ros = RosNode("wmm_qp_face", namespace=ros_namespace(self.svc.robot))
        node = self.ros.node
        pubs = {"ee_pose": node.create_publisher(PoseStamped, "ee_pose", qos(True, 10)),
                "status": node.create_publisher(DiagnosticArray, "status", qos(True, 10)),
                "markers": node.create_publisher(MarkerArray, "markers", qos(True, 10))}
        node.create_subscription(PoseStamped, "ee_target", self._ee_target, qos(True, 10))
        node.create_subscription(String, "mode", self._mode, qos(True, 10))

        def tick() -> None:
            try:
                self._publish(pubs, msgs)
            except Exception as e:  # never into the executor: counted, said once
                self.refused["publish_error"] += 1
                if self.refused["publish_error"] == 1:
                    import sys

                    print(f"wmm-qp serve: ros2 face: {type(e).__name__}: {e}", file=sys.stderr, flush=True)

        node.create_timer(1.0 / self.rate_hz, tick)

    def close(self) -> None:
        if self.ros is not None:
            self.ros.close()
        if self.client is not None:
            self.client.close()
