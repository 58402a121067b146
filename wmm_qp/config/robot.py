"""The robot file's schema: the arm, the base, their collision geometry and the gripper
(docs/robots.md), as frozen dataclasses. Each field that a key of the file sets says so
(``toml_key``); the loader, which resolves the arm against its URDF, is :mod:`.robot_file`.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .._typing import FloatArray, readonly
from ..exceptions import ConfigError
from .shapes import ShapeConfig
from .toml import TomlTable, choice, number, toml_key

BASE_KINDS = ("mecanum", "omni", "diff_drive", "fixed")

_KEY = toml_key()  # a key of the file that the loader reads itself (its default or check needs the URDF)


@dataclass(frozen=True)
class GripperConfig:
    """A parallel gripper (the robot file's ``[gripper]`` table, docs/robots.md).

    Attributes:
        width_max: [m] the fingers' full opening.
        speed_max: [m/s] the fingers' top speed (a command's speed is clamped to it).
        force_max: [N] the largest grasp force (a command's force is clamped to it).
    """

    width_max: float = field(metadata=toml_key(number(positive=True)))
    speed_max: float = field(metadata=toml_key(number(positive=True)))
    force_max: float = field(metadata=toml_key(number(positive=True)))


_ROS_NAME = re.compile(r"~?/?[A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*")


def _ros_topic(t: TomlTable, k: str, default: object) -> str:
    """A ROS 2 topic name (relative names resolve in the driver's namespace, ros2_control's way)."""
    s = t.string(k, default)
    if not _ROS_NAME.fullmatch(s):
        raise ConfigError(t.path, t.key(k), f"{s!r} is not a ROS 2 topic name (tokens of letters, digits and _ "
                          "joined by /, none starting with a digit)")
    return s


CMD_VEL_TYPES = ("geometry_msgs/Twist", "geometry_msgs/TwistStamped")


@dataclass(frozen=True)
class Ros2Config:
    """How a robot run by ROS 2 through ros2_control is reached (the robot file's ``[ros2]`` table,
    docs/ros2.md); the defaults are ros2_control's names.

    Attributes:
        joint_states: ``sensor_msgs/JointState`` topic (joint_state_broadcaster's): the arm's
            joints by name, any order; other joints are ignored.
        odom: ``nav_msgs/Odometry`` topic of the base (its controller's odometry).
        arm_command: ``std_msgs/Float64MultiArray`` topic of the arm's velocity controller
            (a forward command controller): one rate per joint, in the robot file's joint order.
        cmd_vel: the base controller's velocity topic.
        cmd_vel_type: its message type: a holonomic base takes vx, vy, wz; a differential drive
            vx, wz.
        rate_hz: [Hz] the driver's cycle: it reads the newest joint states and writes the
            commands this often (the controller manager's update rate is a good choice).
        state_timeout: [s] joint states older than this are a lost robot: a protective stop
            (``robot_state_lost``) until they come back and a new stream starts.
    """

    joint_states: str = field(default="joint_states", metadata=toml_key(_ros_topic))
    odom: str = field(default="odom", metadata=toml_key(_ros_topic))
    arm_command: str = field(default="forward_velocity_controller/commands", metadata=toml_key(_ros_topic))
    cmd_vel: str = field(default="cmd_vel", metadata=toml_key(_ros_topic))
    cmd_vel_type: str = field(default="geometry_msgs/Twist", metadata=toml_key(choice(CMD_VEL_TYPES)))
    rate_hz: float = field(default=250.0, metadata=toml_key(number(positive=True, hi=2000.0)))
    state_timeout: float = field(default=0.1, metadata=toml_key(number(positive=True, hi=5.0)))


@dataclass(frozen=True)
class RobotCollisionConfig:
    """The robot's collision geometry (the robot file's ``[collision]`` table, docs/robots.md).

    Attributes:
        from_urdf: take the URDF's collision elements (meshes as their convex hulls).
        urdf: another URDF of the same robot whose collision elements to take (e.g. one with
            primitives), or None (the arm's own URDF).
        shapes: primitives added to (or, without ``from_urdf``, replacing) the URDF's.
        exclude: pairs of link names that are never checked against each other (besides the
            adjacent links, which are excluded anyway).
        ignore_links: links whose URDF collision elements are dropped (e.g. a hand's fingers).
        influence_distance: [m] this robot's d_i when larger than the controller config's
            ``collision.influence_distance`` (a robot with low accelerations needs more distance
            to stop inside it), or None.
    """

    from_urdf: bool = field(default=False, metadata=_KEY)
    urdf: Path | None = field(default=None, metadata=_KEY)
    shapes: tuple[ShapeConfig, ...] = field(default=(), metadata=_KEY)
    exclude: tuple[tuple[str, str], ...] = field(default=(), metadata=_KEY)
    ignore_links: tuple[str, ...] = field(default=(), metadata=_KEY)
    influence_distance: float | None = field(default=None, metadata=_KEY)


@dataclass(frozen=True)
class ArmConfig:
    """The manipulator, resolved against its URDF (every vector has one entry per joint).

    Attributes:
        urdf: path of the arm's URDF.
        ee_frame: name of the end-effector link (a URDF link, not a joint; the tool flange).
        joints: the controlled joints, in order (from the URDF's root towards ``ee_frame``).
        joint_types: "revolute", "continuous" or "prismatic", per joint (from the URDF).
        locked: every other joint of the URDF and the value it is locked at [rad or m].
        mount_xyz: [m] the arm's URDF root in the base frame (eq. (2): p_mount).
        mount_rpy: [rad] its orientation (roll, pitch, yaw; R_mount of docs/model.md "Any robot").
        position_lower, position_upper: [rad or m] position limits, ±inf for continuous joints.
        velocity_max: [rad/s or m/s] symmetric velocity limits.
        acceleration_max: [rad/s² or m/s²] symmetric acceleration limits.
        torque_limit: [N·m or N] effort limits (W of eq. (8), the push experiment).
        torque_weight: W of eq. (8) the robot's file gives, or None (then τ_ref/τ_lim,i).
        start: [rad or m] where the sim and the experiments start.
        ee_offset_xyz: [m] the task point in the ``ee_frame`` link's frame (e.g. the tool tip).
        ee_offset_rpy: [rad] the task frame's orientation in it (roll, pitch, yaw; pose task).
        jerk_max: [rad/s³ or m/s³] symmetric jerk limits of a robot whose drives refuse a jerkier
            command stream (a driver's command shaper keeps within them), or None (no limit given).
    """

    urdf: Path = field(metadata=_KEY)
    ee_frame: str = field(metadata=_KEY)
    joints: tuple[str, ...] = field(metadata=_KEY)
    joint_types: tuple[str, ...]
    locked: tuple[tuple[str, float], ...] = field(metadata=_KEY)
    mount_xyz: FloatArray = field(metadata=_KEY)
    mount_rpy: FloatArray = field(metadata=_KEY)
    position_lower: FloatArray = field(metadata=_KEY)
    position_upper: FloatArray = field(metadata=_KEY)
    velocity_max: FloatArray = field(metadata=_KEY)
    acceleration_max: FloatArray = field(metadata=_KEY)
    torque_limit: FloatArray = field(metadata=_KEY)
    torque_weight: FloatArray | None = field(metadata=_KEY)
    start: FloatArray = field(metadata=_KEY)
    ee_offset_xyz: FloatArray = field(default_factory=lambda: readonly([0.0, 0.0, 0.0]), metadata=_KEY)
    ee_offset_rpy: FloatArray = field(default_factory=lambda: readonly([0.0, 0.0, 0.0]), metadata=_KEY)
    jerk_max: FloatArray | None = field(default=None, metadata=_KEY)

    @property
    def n(self) -> int:
        """Number of controlled joints."""
        return len(self.joints)

    def default_W(self) -> FloatArray:
        """W of eq. (8): the robot file's ``torque_weight``, else diag(τ_ref/τ_lim,i) with τ_ref the
        largest torque limit of the revolute and continuous joints (a prismatic joint's limit is a
        force, in N: TIAGo's torso lift's 2000 N would weight every arm joint 50–670×)."""
        if self.torque_weight is not None:
            return self.torque_weight
        rotary = [t for t, kind in zip(self.torque_limit, self.joint_types, strict=True) if kind != "prismatic"]
        tau_ref = float(np.max(rotary)) if rotary else float(np.max(self.torque_limit))
        return readonly(tau_ref / self.torque_limit)


BASE_GEOMETRY = {
    "mecanum": ("wheel_radius", "l1", "l2"),
    "omni": ("wheel_radius", "base_radius"),
    "diff_drive": ("wheel_radius", "track_width"),
    "fixed": (),
}
"""Each base kind's geometry keys (positive numbers [m]); the others' are unknown keys for it."""
N_WHEELS = {"mecanum": 4, "omni": 3, "diff_drive": 2, "fixed": 0}
WHEEL_LIMITS = ("wheel_speed_max", "wheel_acceleration_max")
"""Per wheel: one number or one per wheel; unknown keys for a fixed base."""


@dataclass(frozen=True)
class BaseConfig:
    """The mobile base (docs/model.md "Any robot"; docs/robots.md for the wheel order of each kind).

    Attributes:
        kind: "mecanum" (wheels FL, FR, RL, RR), "omni" (three omni wheels at 90°, 210°, 330°),
            "diff_drive" (wheels left, right) or "fixed" (no base, no wheels).
        wheel_radius: [m] R (0 for fixed).
        l1: [m] mecanum: half the distance between the front and rear axles.
        l2: [m] mecanum: half the track width.
        base_radius: [m] omni: distance of each wheel from the centre.
        track_width: [m] diff_drive: distance between the two wheels.
        wheel_speed_max: [rad/s] symmetric wheel speed limit, per wheel.
        wheel_acceleration_max: [rad/s²] symmetric wheel acceleration limit, per wheel.
        floor_z: [m] world z of the floor (the world origin is the base frame's, on the base).
        body: the base's collision box (base frame), or None.
    """

    kind: str = field(metadata=_KEY)
    wheel_radius: float = field(default=0.0, metadata=_KEY)
    l1: float = field(default=0.0, metadata=_KEY)
    l2: float = field(default=0.0, metadata=_KEY)
    base_radius: float = field(default=0.0, metadata=_KEY)
    track_width: float = field(default=0.0, metadata=_KEY)
    wheel_speed_max: FloatArray = field(default_factory=lambda: readonly([]), metadata=_KEY)
    wheel_acceleration_max: FloatArray = field(default_factory=lambda: readonly([]), metadata=_KEY)
    floor_z: float = field(default=-math.inf, metadata=_KEY)
    body: ShapeConfig | None = field(default=None, metadata=_KEY)

    @property
    def n_wheels(self) -> int:
        return int(self.wheel_speed_max.shape[0])


@dataclass(frozen=True)
class RobotConfig:
    """The whole wheeled mobile manipulator (one robot file, resolved against its URDF).

    Attributes:
        arm: the arm.
        base: the base.
        name: the robot's name (its Zenoh key segment).
        path: the robot file it was read from (None: built in code).
        collision: the robot's collision geometry.
        gripper: the robot's gripper (None: none).
    """

    arm: ArmConfig = field(metadata=_KEY)
    base: BaseConfig = field(metadata=_KEY)
    name: str = field(default="wmm", metadata=_KEY)
    path: Path | None = None
    collision: RobotCollisionConfig = field(default_factory=RobotCollisionConfig, metadata=_KEY)
    gripper: GripperConfig | None = field(default=None, metadata=_KEY)
    ros2: Ros2Config = field(default_factory=Ros2Config, metadata=_KEY)

    @property
    def n_arm(self) -> int:
        return self.arm.n

    @property
    def n_wheels(self) -> int:
        return self.base.n_wheels

    @property
    def n_v(self) -> int:
        """Length of v = [v_b; v_m]."""
        return self.base.n_wheels + self.arm.n
