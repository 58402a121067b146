"""Frozen, validated configuration: the robot and the controller.

Configs are TOML files (``configs/robot.toml``, ``configs/controller.toml``), loaded once
at start-up into frozen dataclasses. Every check names the file and the dotted key. Inside
the library the types are trusted.
"""

from __future__ import annotations

import math
import sys
import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from . import urdf as urdf_io
from ._typing import FloatArray, readonly
from .exceptions import ConfigError
from .solvers import SOLVER_NAMES

BASE_KINDS = ("mecanum", "omni", "diff_drive", "fixed")
SHAPE_KINDS = ("box", "sphere", "capsule", "cylinder")


@dataclass(frozen=True)
class ShapeConfig:
    """A collision primitive fixed to a link (or to the base, or to the world for obstacles).

    Attributes:
        name: its name (reported with every collision it is part of).
        link: the URDF link it is attached to ("base" for the base frame, "" for the world).
        kind: "box", "sphere", "capsule" or "cylinder" (capsules and cylinders along their local z).
        size: [m] box edge lengths (x, y, z); for the others [radius, length, 0] (a sphere's length 0).
        xyz, rpy: [m], [rad] its pose in the link's frame.
        exempt: an obstacle's links that may touch it ("ee": the bodies that move with the EE frame,
            e.g. the push experiment's box, which only the EE may touch).
        velocity: [m/s] an obstacle's velocity (world frame; a moving obstacle's rows make the
            robot give way at its approach speed), None: at rest.
    """

    name: str
    link: str
    kind: str
    size: FloatArray
    xyz: FloatArray
    rpy: FloatArray
    exempt: tuple[str, ...] = ()
    velocity: FloatArray | None = None  # [m/s] an obstacle's (world frame), None: at rest

    @property
    def radius(self) -> float:
        return float(self.size[0])

    @property
    def length(self) -> float:
        return float(self.size[1])


@dataclass(frozen=True)
class GripperConfig:
    """A parallel gripper (the robot file's ``[gripper]`` table, docs/robots.md).

    Attributes:
        width_max: [m] the fingers' full opening.
        speed_max: [m/s] the fingers' top speed (a command's speed is clamped to it).
        force_max: [N] the largest grasp force (a command's force is clamped to it).
    """

    width_max: float
    speed_max: float
    force_max: float


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

    from_urdf: bool = False
    urdf: Path | None = None
    shapes: tuple[ShapeConfig, ...] = ()
    exclude: tuple[tuple[str, str], ...] = ()
    ignore_links: tuple[str, ...] = ()
    influence_distance: float | None = None
TASK_KINDS = ("position", "pose")


@dataclass(frozen=True)
class ArmConfig:
    """The manipulator, resolved against its URDF (every vector has one entry per joint).

    Attributes:
        urdf: path of the arm's URDF.
        ee_frame: name of the end-effector link (a URDF link, not a joint; the tool flange).
        joints: the controlled joints, in order (from the URDF's root towards ``ee_frame``).
        joint_types: "revolute", "continuous" or "prismatic", per joint.
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

    urdf: Path
    ee_frame: str
    joints: tuple[str, ...]
    joint_types: tuple[str, ...]
    locked: tuple[tuple[str, float], ...]
    mount_xyz: FloatArray
    mount_rpy: FloatArray
    position_lower: FloatArray
    position_upper: FloatArray
    velocity_max: FloatArray
    acceleration_max: FloatArray
    torque_limit: FloatArray
    torque_weight: FloatArray | None
    start: FloatArray
    ee_offset_xyz: FloatArray = field(default_factory=lambda: readonly([0.0, 0.0, 0.0]))
    ee_offset_rpy: FloatArray = field(default_factory=lambda: readonly([0.0, 0.0, 0.0]))
    jerk_max: FloatArray | None = None

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

    kind: str
    wheel_radius: float = 0.0
    l1: float = 0.0
    l2: float = 0.0
    base_radius: float = 0.0
    track_width: float = 0.0
    wheel_speed_max: FloatArray = field(default_factory=lambda: readonly([]))
    wheel_acceleration_max: FloatArray = field(default_factory=lambda: readonly([]))
    floor_z: float = -math.inf
    body: ShapeConfig | None = None

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
    """

    arm: ArmConfig
    base: BaseConfig
    name: str = "wmm"
    path: Path | None = None
    collision: RobotCollisionConfig = field(default_factory=RobotCollisionConfig)
    gripper: GripperConfig | None = None
    """The robot's gripper (None: none)."""

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


@dataclass(frozen=True)
class TaskConfig:
    """The task of eq. (5) (docs/model.md "Any robot").

    Attributes:
        kind: "position" (r = 3, the paper's) or "pose" (r = 6: position and orientation of the
            EE frame).
        K_R: [1/s] orientation-error gain (pose): ω_ref = ω_d + K_R·log(R_d Rᵀ).
        orientation_weight: [m/rad] the angular rows of the pose task are scaled by this in the
            QP, so where the bounds cannot meet the whole task, 1 rad/s of orientation error
            costs as much as this many m/s of position error. While the task is feasible it is
            met exactly (both parts are hard), so the weight only shapes the best effort.
        angular_speed_max: [rad/s] the angular part of the task velocity is capped at this norm.
        angular_recovery_speed: [rad/s] K_R·e_R is saturated at this norm (like qp.recovery_speed).
    """

    kind: str = "position"
    K_R: float = 10.0
    orientation_weight: float = 0.2
    angular_speed_max: float = 2.0
    angular_recovery_speed: float = 0.5

    @property
    def r(self) -> int:
        """Dimension of the task space."""
        return 6 if self.kind == "pose" else 3


@dataclass(frozen=True)
class QpConfig:
    """Settings of the QP controller (docs/model.md "The QP").

    Attributes:
        solver: backend name from :func:`wmm_qp.solvers.available_solvers`.
        alpha: the α of eq. (12) in the QP's cost ½ vᵀ W_x⁻¹ v; small = base expensive.
        dm_alpha: the α used in the null-space DM mode, where the whole robot's null space,
            base included, must serve the DM objective (eq. (18)). Wheel speeds are in rad/s
            and move the EE by only ~R/4 per rad/s, so with α = 0.2 the base barely helps and
            the arm alone tops out near DM 4.1 along x; α = 0.99 lets the base move so the arm
            can stretch (the paper's 5.88).
        dm_speed: [rad/s] ρ of the normalised null-space DM preference
            (manipulability/preference.py): v_n = max(k_N, ρ/sqrt(‖∇H2‖² + g₀²))·∇H2, so the
            ascent does not crawl where ∇H2 is flat (ρ is capped at the slowest joint's velocity
            limit); 0 = eq. (19) as printed, k_N ∇H2. The paper's and the traditional
            controllers always use eq. (19).
        dm_gradient_floor: [1/rad] g₀ of the normalised preference: below this gradient norm
            the preference fades out linearly (gain ρ/g₀), so the ascent settles at the optimum.
        arm_first: in track mode, keep the wheels still whenever the arm alone can realise
            the task inside its bounds (a first, arm-only stage).
        slack_l1: weight ρ₁ of the exact penalty ρ₁‖s‖₁ on the task slack: above the task's
            Lagrange multiplier, the slack is exactly 0 whenever the task is feasible.
        slack_weight: weight ρ₂ of ½ρ₂‖s‖², which shapes how the task degrades when infeasible.
        task_speed_max: [m/s] ẋ_ref is scaled down to this norm (keeps the QP well scaled).
        recovery_speed: [m/s] the error term K_x (x_d − x) of eq. (18) is saturated at this norm:
            a large error (the robot pushed off its hold target) is recovered at this speed,
            not at K_x·error with the arm at its speed limits.
        singular_arm_weight: near an arm singularity the arm's cost is multiplied by
            1 + singular_arm_weight·(λ/λ_max)², and the base's yaw's by the same factor, so the
            base's translation takes over (the QP's damping).
        closed_form_first: try the closed-form optimum (no bound active, zero slack) before the
            solver; it is taken only when it satisfies every KKT condition, so it is exact.
        eps_abs: absolute tolerance handed to iterative backends.
    """

    solver: str = "proxsuite"
    alpha: float = 0.2
    dm_alpha: float = 0.99
    dm_speed: float = 1.0
    dm_gradient_floor: float = 0.1
    arm_first: bool = True
    slack_l1: float = 1e4
    slack_weight: float = 1e4
    task_speed_max: float = 2.0
    recovery_speed: float = 0.25
    singular_arm_weight: float = 100.0
    closed_form_first: bool = True
    eps_abs: float = 1e-9


@dataclass(frozen=True)
class CollisionParams:
    """The velocity dampers (docs/model.md "Any robot", docs/model.md): ḋ ≥ −ξ (d − d_s)/(d_i − d_s) for every
    monitored pair closer than d_i.

    Attributes:
        enabled: add the damper rows to every stage of the qp controller (on by default: every
            command that drives a robot has them unless ``--no-collision`` or ``enabled = false``;
            ``wmm-qp experiment`` keeps the paper's setting, off, unless ``--scene``).
        influence_distance: [m] d_i, where a pair's row starts to act.
        safety_distance: [m] d_s, the distance the pair settles at (robot vs robot, robot vs obstacles).
        floor_margin: [m] d_s for every link vs the floor.
        gain: [m/s] ξ, the approach speed a pair may keep at d_i.
        braking: [-] β, the share of a pair's deceleration capacity a_n (every joint braking for
            it at its acceleration limit) that the braking profile ḋ ≥ −√(2 β a_n (d − d_s))
            counts on; the rest is left to the other rows and the task.
    """

    enabled: bool = True
    influence_distance: float = 0.15
    safety_distance: float = 0.03
    floor_margin: float = 0.03
    gain: float = 0.5
    braking: float = 0.25


@dataclass(frozen=True)
class ControllerConfig:
    """Gains and parameters of the paper, and the QP's settings.

    Attributes:
        rate_hz: [Hz] control rate; dt = 1 / rate_hz.
        kind: default controller: "qp", "paper" or "traditional".
        K_x: [1/s] position-error gain, eq. (18) (K_x = k·I).
        alpha: the α used by the paper's switch, eq. (14), when the arm saturates.
        k_C: Cartesian DM gain, eq. (17).
        k_N: null-space DM gain, eq. (19).
        W: diagonal of the torque scaling W of eq. (8); None = the robot's (ArmConfig.default_W).
        direction: default DM direction u, in the base (yaw-compensated) frame.
        ee_box_lower, ee_box_upper: [m] the EE box of eq. (17) (world frame), ±inf = free.
        sigma_min_floor: [m/rad] σ_f: in the DM modes the QP controller keeps σ_min(J_m) of the
            arm's translational Jacobian at or above it (a velocity damper on σ_min,
            limits/singularity_floor.py), so raising DM never leaves the arm near a singularity;
            0 = no floor (eqs. (16)–(19) alone). Just above ``sigma_threshold``, so that the arm a
            DM phase leaves behind is not under the singularity damping.
        state_latency: [s] age of the state when the command starts to act; the bounds (13)
            brake from where the joints will be by then (0 = the state is current).
        sigma_threshold: σ_min(J_m) below which damped least squares replaces J#.
        damping_max: [-] the DLS damping λ reached at σ_min = 0.
        qp: the QP controller's settings.
        task: the task kind and its orientation settings.
        path: the file it was read from (for errors that name it), or None.
    """

    rate_hz: float = 500.0
    kind: str = "qp"
    K_x: float = 10.0
    alpha: float = 0.2
    k_C: float = 0.01
    k_N: float = 0.2
    W: FloatArray | None = None
    direction: FloatArray = field(default_factory=lambda: readonly([1.0, 0.0, 0.0]))
    ee_box_lower: FloatArray = field(default_factory=lambda: readonly([-np.inf, -np.inf, 0.36]))
    ee_box_upper: FloatArray = field(default_factory=lambda: readonly([np.inf, np.inf, 0.56]))
    sigma_min_floor: float = 0.085
    state_latency: float = 0.0
    sigma_threshold: float = 0.08
    damping_max: float = 0.05
    qp: QpConfig = field(default_factory=QpConfig)
    task: TaskConfig = field(default_factory=TaskConfig)
    collision: CollisionParams = field(default_factory=CollisionParams)
    path: Path | None = field(default=None, compare=False)

    @property
    def dt(self) -> float:
        """[s] control period."""
        return 1.0 / self.rate_hz

    def with_(self, **changes: Any) -> ControllerConfig:
        """A copy with some fields changed (``qp``, ``task`` and ``collision`` may be given as dicts
        of their fields)."""
        for name in ("qp", "task", "collision"):
            if isinstance(changes.get(name), dict):
                changes[name] = replace(getattr(self, name), **changes[name])
        return replace(self, **changes)

    def weights_for(self, robot: RobotConfig) -> FloatArray:
        """W of eq. (8) for this robot: ``dm.W`` if the file sets it, else the robot's.

        Raises:
            ConfigError: ``dm.W`` has another length than the robot's number of joints.
        """
        if self.W is None:
            return robot.arm.default_W()
        if self.W.shape != (robot.n_arm,):
            where = self.path if self.path is not None else "controller config"
            raise ConfigError(
                where, "dm.W", f"has {self.W.shape[0]} entries, the robot {robot.name!r} has {robot.n_arm} joints"
            )
        return self.W


CONTROLLER_KINDS = ("qp", "paper", "traditional")


# --------------------------------------------------------------------------- loading


def default_config_dir() -> Path:
    """The folder holding controller.toml and robots/ (the shipped robot files).

    Looked up in order: ``$WMM_QP_CONFIG_DIR``; ``./configs``; the source tree's
    ``configs/`` (editable installs); ``<prefix>/share/wmm-qp/configs`` (wheel installs).
    """
    import os

    candidates = []
    if env := os.environ.get("WMM_QP_CONFIG_DIR"):
        candidates.append(Path(env))
    candidates += [
        Path.cwd() / "configs",
        Path(__file__).resolve().parents[1] / "configs",
        Path(sys.prefix) / "share" / "wmm-qp" / "configs",
    ]
    for c in candidates:
        if (c / "controller.toml").is_file():
            return c
    raise ConfigError(candidates[0], "", "no controller.toml found in any of: " + ", ".join(map(str, candidates)))


DEFAULT_ROBOT = "gen3_mecanum.toml"
"""The paper's robot, the default of every command (``configs/robots/``)."""


def default_robot_file() -> Path:
    """``<default_config_dir()>/robots/gen3_mecanum.toml``."""
    return default_config_dir() / "robots" / DEFAULT_ROBOT


class TomlTable:
    """Typed access to a TOML table, with errors that name the file and the dotted key.

    Shared by every config loader of the project (robot, controller, sim).
    """

    def __init__(self, path: Path, data: dict[str, Any], prefix: str = "") -> None:
        self.path, self.data, self.prefix = path, data, prefix

    def _key(self, k: str) -> str:
        return f"{self.prefix}{k}"

    def has(self, k: str) -> bool:
        return k in self.data

    def table(self, k: str, required: bool = True) -> TomlTable:
        v = self.data.get(k, None if required else {})
        if not isinstance(v, dict):
            raise ConfigError(self.path, self._key(k), "missing table" if v is None else "must be a table")
        return TomlTable(self.path, v, f"{self._key(k)}.")

    def get(self, k: str, default: Any = ...) -> Any:
        if k not in self.data:
            if default is ...:
                raise ConfigError(self.path, self._key(k), "missing")
            return default
        return self.data[k]

    def number(
        self, k: str, default: Any = ..., *, positive: bool = False, lo: float | None = None, hi: float | None = None
    ) -> float:
        v = self.get(k, default)
        if isinstance(v, bool) or not isinstance(v, int | float):
            raise ConfigError(self.path, self._key(k), f"must be a number, got {v!r}")
        v = float(v)
        if not math.isfinite(v):
            raise ConfigError(self.path, self._key(k), f"must be finite, got {v}")
        if positive and v <= 0:
            raise ConfigError(self.path, self._key(k), f"must be > 0, got {v}")
        if lo is not None and v < lo:
            raise ConfigError(self.path, self._key(k), f"must be >= {lo}, got {v}")
        if hi is not None and v > hi:
            raise ConfigError(self.path, self._key(k), f"must be <= {hi}, got {v}")
        return v

    def integer(self, k: str, default: Any = ..., *, lo: int | None = None) -> int:
        v = self.get(k, default)
        if isinstance(v, bool) or not isinstance(v, int):
            raise ConfigError(self.path, self._key(k), f"must be an integer, got {v!r}")
        if lo is not None and v < lo:
            raise ConfigError(self.path, self._key(k), f"must be >= {lo}, got {v}")
        return v

    def vector(self, k: str, n: int, default: Any = ..., *, positive: bool = False, finite: bool = True) -> FloatArray:
        v = self.get(k, default)
        if not isinstance(v, list | tuple | np.ndarray) or len(v) != n:
            raise ConfigError(self.path, self._key(k), f"must be a list of {n} numbers, got {v!r}")
        if any(isinstance(x, bool) or not isinstance(x, int | float) for x in v):
            raise ConfigError(self.path, self._key(k), f"must hold numbers only, got {v!r}")
        a = np.array(v, dtype=float)
        if np.isnan(a).any() or (finite and not np.isfinite(a).all()):
            raise ConfigError(self.path, self._key(k), f"must be finite, got {v!r}")
        if positive and (a <= 0).any():
            raise ConfigError(self.path, self._key(k), f"every entry must be > 0, got {v!r}")
        return readonly(a)

    def per_joint(self, k: str, n: int, default: Any = ..., *, positive: bool = False) -> FloatArray:
        """One number (the same for all n entries) or a list of n numbers."""
        v = self.get(k, default)
        if isinstance(v, int | float) and not isinstance(v, bool):
            v = [v] * n
        elif not isinstance(v, list | tuple | np.ndarray) or len(v) != n:
            raise ConfigError(self.path, self._key(k), f"must be one number or a list of {n} numbers, got {v!r}")
        return TomlTable(self.path, {k: list(v)}, self.prefix).vector(k, n, positive=positive)

    def string(self, k: str, default: Any = ..., choices: tuple[str, ...] | None = None) -> str:
        v = self.get(k, default)
        if not isinstance(v, str):
            raise ConfigError(self.path, self._key(k), f"must be a string, got {v!r}")
        if choices is not None and v not in choices:
            raise ConfigError(self.path, self._key(k), f"must be one of {', '.join(choices)}; got {v!r}")
        return v

    def boolean(self, k: str, default: Any = ...) -> bool:
        v = self.get(k, default)
        if not isinstance(v, bool):
            raise ConfigError(self.path, self._key(k), f"must be true or false, got {v!r}")
        return v

    def unknown(self, allowed: set[str]) -> None:
        extra = sorted(set(self.data) - allowed)
        if extra:
            raise ConfigError(self.path, self._key(extra[0]), f"unknown key (allowed: {', '.join(sorted(allowed))})")


def read_toml(path: Path) -> dict[str, Any]:
    """Parse a TOML file; every failure is a :class:`ConfigError` naming the file."""
    try:
        with open(path, "rb") as f:
            return tomllib.load(f)
    except FileNotFoundError:
        raise ConfigError(path, "", "file not found") from None
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(path, "", f"not valid TOML: {e}") from None
    except OSError as e:
        raise ConfigError(path, "", f"cannot read: {e.strerror}") from None


def load_robot_config(path: Path | str | None = None) -> RobotConfig:
    """Load a robot file (``configs/robots/*.toml``, docs/robots.md) and resolve it against its URDF.

    Args:
        path: the file; default ``configs/robots/gen3_mecanum.toml`` (the paper's robot).

    Raises:
        ConfigError: naming the file and key of the first problem found.
    """
    path = Path(path) if path is not None else default_robot_file()
    r = TomlTable(path, read_toml(path))
    r.unknown({"name", "arm", "base", "collision", "gripper"})
    a = r.table("arm")
    a.unknown(
        {
            "urdf",
            "ee_frame",
            "ee_offset_xyz",
            "ee_offset_rpy",
            "joints",
            "locked",
            "mount_xyz",
            "mount_rpy",
            "position_lower",
            "position_upper",
            "velocity_max",
            "acceleration_max",
            "jerk_max",
            "torque_limit",
            "torque_weight",
            "start",
        }
    )
    urdf = urdf_io.resolve_urdf(path, a.string("urdf"))
    full = urdf_io.load_full_model(path, urdf)
    joints = a.get("joints", None)
    if joints is not None and (not isinstance(joints, list) or not all(isinstance(j, str) for j in joints)):
        raise ConfigError(path, "arm.joints", f"must be a list of joint names, got {joints!r}")
    ee_frame = a.string("ee_frame")
    chain = urdf_io.read_chain(path, full, ee_frame, joints)
    n = len(chain.joints)
    locked_t = a.table("locked", required=False)
    locked: dict[str, float] = {}
    for name in locked_t.data:
        if name in chain.joints:
            raise ConfigError(path, f"arm.locked.{name}", "is a controlled joint (listed in arm.joints)")
        if name not in chain.others:
            raise ConfigError(path, f"arm.locked.{name}", "the URDF has no other actuated joint of that name")
        locked[name] = locked_t.number(name)
    lower = a.vector("position_lower", n, chain.lower, finite=False)
    upper = a.vector("position_upper", n, chain.upper, finite=False)
    bad = np.flatnonzero(~(lower < upper))
    if bad.size:
        raise ConfigError(path, "arm.position_lower", f"must be < position_upper (joint {chain.joints[bad[0]]!r})")
    vel = a.vector("velocity_max", n, chain.velocity, finite=False)
    if not (vel > 0).all() or not np.isfinite(vel).all():
        j = chain.joints[int(np.flatnonzero(~((vel > 0) & np.isfinite(vel)))[0])]
        raise ConfigError(path, "arm.velocity_max", f"the URDF gives joint {j!r} no velocity limit: set it here")
    tau = a.vector("torque_limit", n, chain.effort, finite=False)
    if not (tau > 0).all() or not np.isfinite(tau).all():
        j = chain.joints[int(np.flatnonzero(~((tau > 0) & np.isfinite(tau)))[0])]
        raise ConfigError(path, "arm.torque_limit", f"the URDF gives joint {j!r} no effort limit: set it here")
    if not a.has("acceleration_max"):
        raise ConfigError(path, "arm.acceleration_max", "missing: URDFs have no acceleration limits; give one "
                          "number or one per joint")
    both = np.isfinite(lower) & np.isfinite(upper)
    finite_mid = np.where(both, 0.5 * (np.where(both, lower, 0.0) + np.where(both, upper, 0.0)), 0.0)
    start = a.vector("start", n, np.clip(finite_mid, lower, upper))
    outside = np.flatnonzero((start < lower) | (start > upper))
    if outside.size:
        bad_j = int(outside[0])
        raise ConfigError(
            path,
            "arm.start",
            f"joint {chain.joints[bad_j]!r} at {start[bad_j]} is outside [{lower[bad_j]}, {upper[bad_j]}]",
        )
    weight = a.vector("torque_weight", n, positive=True) if a.has("torque_weight") else None
    arm = ArmConfig(
        urdf=urdf,
        ee_frame=ee_frame,
        joints=chain.joints,
        joint_types=chain.types,
        locked=tuple(sorted(locked.items())),
        mount_xyz=a.vector("mount_xyz", 3, [0.0, 0.0, 0.0]),
        mount_rpy=a.vector("mount_rpy", 3, [0.0, 0.0, 0.0]),
        position_lower=lower,
        position_upper=upper,
        velocity_max=readonly(vel),
        acceleration_max=a.per_joint("acceleration_max", n, positive=True),
        torque_limit=readonly(tau),
        torque_weight=weight,
        start=start,
        ee_offset_xyz=a.vector("ee_offset_xyz", 3, [0.0, 0.0, 0.0]),
        ee_offset_rpy=a.vector("ee_offset_rpy", 3, [0.0, 0.0, 0.0]),
        jerk_max=a.per_joint("jerk_max", n, positive=True) if a.has("jerk_max") else None,
    )
    base = _load_base(r.table("base"))
    collision = _load_collision(r.table("collision", required=False), path, full, chain.joints)
    gripper = None
    if r.has("gripper"):
        g = r.table("gripper")
        g.unknown({"width_max", "speed_max", "force_max"})
        gripper = GripperConfig(width_max=g.number("width_max", positive=True),
                                speed_max=g.number("speed_max", positive=True),
                                force_max=g.number("force_max", positive=True))
    return RobotConfig(arm=arm, base=base, name=r.string("name", "wmm"), path=path, collision=collision,
                       gripper=gripper)


def load_shape(t: TomlTable, name: str, link: str, kinds: tuple[str, ...] = SHAPE_KINDS) -> ShapeConfig:
    """A primitive of a robot or scene file (keys kind, size | radius + length, xyz, rpy)."""
    kind = t.string("kind", choices=kinds)
    extra = {"box": {"size"}, "sphere": {"radius"}, "capsule": {"radius", "length", "from", "to"},
             "cylinder": {"radius", "length"}, "plane": {"normal", "offset"}}[kind]
    t.unknown({"kind", "name", "link", "xyz", "rpy", *extra})
    if kind == "capsule" and (t.has("from") or t.has("to")):  # a capsule between two points of the link
        p0, p1 = t.vector("from", 3), t.vector("to", 3)
        axis = p1 - p0
        length = float(np.linalg.norm(axis))
        if length < 1e-9:
            raise ConfigError(t.path, t._key("to"), "must differ from 'from'")
        z = axis / length
        ref = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        x = np.cross(ref, z)
        x /= np.linalg.norm(x)
        R = np.column_stack([x, np.cross(z, x), z])
        import pinocchio as pin

        rpy = pin.rpy.matrixToRpy(R)
        return ShapeConfig(name, link, kind, readonly([t.number("radius", positive=True), length, 0.0]),
                           readonly(0.5 * (p0 + p1)), readonly(rpy))
    if kind == "box":
        size = t.vector("size", 3, positive=True)
    elif kind == "plane":
        n = t.vector("normal", 3)
        if np.linalg.norm(n) < 1e-9:
            raise ConfigError(t.path, t._key("normal"), "must not be the zero vector")
        size = readonly([*(n / np.linalg.norm(n))])
        return ShapeConfig(name, link, kind, size, readonly([0.0, 0.0, t.number("offset")]), readonly([0.0, 0.0, 0.0]))
    else:
        radius = t.number("radius", positive=True)
        length = t.number("length", positive=True) if kind != "sphere" else 0.0
        size = readonly([radius, length, 0.0])
    return ShapeConfig(
        name=name,
        link=link,
        kind=kind,
        size=size,
        xyz=t.vector("xyz", 3, [0.0, 0.0, 0.0]),
        rpy=t.vector("rpy", 3, [0.0, 0.0, 0.0]),
    )


def _load_collision(c: TomlTable, path: Path, full: Any, joints: tuple[str, ...]) -> RobotCollisionConfig:
    c.unknown({"from_urdf", "urdf", "shapes", "exclude", "ignore_links", "influence_distance"})
    other = urdf_io.resolve_urdf(path, c.string("urdf"), "collision.urdf") if c.has("urdf") else None
    shapes = []
    raw = c.get("shapes", [])
    if not isinstance(raw, list) or not all(isinstance(x, dict) for x in raw):
        raise ConfigError(path, "collision.shapes", "must be a list of tables")
    for i, item in enumerate(raw):
        t = TomlTable(path, item, f"collision.shapes[{i}].")
        link = t.string("link")
        if link != "base" and not full.existFrame(link):
            raise ConfigError(path, f"collision.shapes[{i}].link", f"the URDF has no link named {link!r}")
        shapes.append(load_shape(t, t.string("name", f"{link}_{i}"), link))
    names = [s.name for s in shapes]
    if len(set(names)) != len(names):
        raise ConfigError(path, "collision.shapes", "shape names must be unique")
    exclude = c.get("exclude", [])
    if not isinstance(exclude, list) or not all(
        isinstance(p, list) and len(p) == 2 and all(isinstance(x, str) for x in p) for p in exclude
    ):
        raise ConfigError(path, "collision.exclude", "must be a list of [link, link] pairs")
    ignore = c.get("ignore_links", [])
    if not isinstance(ignore, list) or not all(isinstance(x, str) for x in ignore):
        raise ConfigError(path, "collision.ignore_links", "must be a list of link names")
    return RobotCollisionConfig(
        from_urdf=c.boolean("from_urdf", False),
        urdf=other,
        shapes=tuple(shapes),
        exclude=tuple((a, b) for a, b in exclude),
        ignore_links=tuple(ignore),
        influence_distance=c.number("influence_distance", positive=True) if c.has("influence_distance") else None,
    )


_BASE_KEYS = {
    "mecanum": ("wheel_radius", "l1", "l2"),
    "omni": ("wheel_radius", "base_radius"),
    "diff_drive": ("wheel_radius", "track_width"),
    "fixed": (),
}
_N_WHEELS = {"mecanum": 4, "omni": 3, "diff_drive": 2, "fixed": 0}


def _load_base(b: TomlTable) -> BaseConfig:
    kind = b.string("kind", "mecanum", BASE_KINDS)
    geometry = _BASE_KEYS[kind]
    limits = ("wheel_speed_max", "wheel_acceleration_max") if kind != "fixed" else ()
    b.unknown({"kind", "floor_z", "body", *geometry, *limits})
    n = _N_WHEELS[kind]
    values = {k: b.number(k, positive=True) for k in geometry}
    if not b.has("floor_z"):
        raise ConfigError(b.path, b._key("floor_z"), "missing: the world z of the floor [m] (the world origin is "
                          "the base frame's)")
    body = None
    if b.has("body"):
        body = load_shape(b.table("body"), "base_body", "base", ("box",))
    return BaseConfig(
        kind=kind,
        floor_z=b.number("floor_z", hi=0.0),
        body=body,
        **values,
        wheel_speed_max=b.per_joint("wheel_speed_max", n, positive=True) if n else readonly([]),
        wheel_acceleration_max=b.per_joint("wheel_acceleration_max", n, positive=True) if n else readonly([]),
    )


def load_controller_config(path: Path | str | None = None) -> ControllerConfig:
    """Load and validate ``controller.toml``; absent keys keep the paper's values.

    Raises:
        ConfigError: naming the file and key of the first problem found.
    """
    path = Path(path) if path is not None else default_config_dir() / "controller.toml"
    r = TomlTable(path, read_toml(path))
    r.unknown({"rate_hz", "controller", "state_latency", "gains", "dm", "singularity", "qp", "task", "collision"})
    d = ControllerConfig()
    g = r.table("gains", required=False)
    g.unknown({"K_x", "alpha", "k_C", "k_N"})
    dm = r.table("dm", required=False)
    dm.unknown({"W", "direction", "ee_box_lower", "ee_box_upper", "sigma_min_floor"})
    s = r.table("singularity", required=False)
    s.unknown({"sigma_threshold", "damping_max"})
    q = r.table("qp", required=False)
    q.unknown(
        {
            "solver",
            "alpha",
            "dm_alpha",
            "dm_speed",
            "dm_gradient_floor",
            "arm_first",
            "slack_l1",
            "slack_weight",
            "task_speed_max",
            "recovery_speed",
            "singular_arm_weight",
            "closed_form_first",
            "eps_abs",
        }
    )
    col = r.table("collision", required=False)
    col.unknown({"enabled", "influence_distance", "safety_distance", "floor_margin", "gain", "braking"})
    d_s = col.number("safety_distance", d.collision.safety_distance, lo=0.0)
    d_floor = col.number("floor_margin", d.collision.floor_margin, lo=0.0)
    d_i = col.number("influence_distance", d.collision.influence_distance, positive=True)
    if d_i <= max(d_s, d_floor):
        raise ConfigError(path, "collision.influence_distance", "must be > safety_distance and floor_margin")
    t = r.table("task", required=False)
    t.unknown({"kind", "K_R", "orientation_weight", "angular_speed_max", "angular_recovery_speed"})
    W = dm.get("W", None)
    if W is not None:
        if not isinstance(W, list):
            raise ConfigError(path, "dm.W", f"must be a list of numbers (one per joint of the robot), got {W!r}")
        W = dm.vector("W", len(W), positive=True)
    direction = dm.vector("direction", 3, d.direction)
    if np.linalg.norm(direction) < 1e-9:
        raise ConfigError(path, "dm.direction", "must not be the zero vector")
    lo = dm.vector("ee_box_lower", 3, d.ee_box_lower, finite=False)
    hi = dm.vector("ee_box_upper", 3, d.ee_box_upper, finite=False)
    if (lo >= hi).any():
        raise ConfigError(path, "dm.ee_box_lower", "must be < ee_box_upper on every axis")
    return ControllerConfig(
        rate_hz=r.number("rate_hz", d.rate_hz, lo=1.0, hi=10_000.0),
        state_latency=r.number("state_latency", d.state_latency, lo=0.0, hi=1.0),
        kind=r.string("controller", d.kind, CONTROLLER_KINDS),
        K_x=g.number("K_x", d.K_x, lo=0.0),
        alpha=g.number("alpha", d.alpha, lo=0.0, hi=1.0),
        k_C=g.number("k_C", d.k_C, lo=0.0),
        k_N=g.number("k_N", d.k_N, lo=0.0),
        W=W,
        direction=readonly(direction / np.linalg.norm(direction)),
        ee_box_lower=lo,
        ee_box_upper=hi,
        sigma_min_floor=dm.number("sigma_min_floor", d.sigma_min_floor, lo=0.0),
        sigma_threshold=s.number("sigma_threshold", d.sigma_threshold, lo=0.0),
        damping_max=s.number("damping_max", d.damping_max, lo=0.0),
        qp=QpConfig(
            solver=q.string("solver", d.qp.solver, SOLVER_NAMES),
            alpha=q.number("alpha", d.qp.alpha, lo=1e-6, hi=1.0 - 1e-6),
            dm_alpha=q.number("dm_alpha", d.qp.dm_alpha, lo=1e-6, hi=1.0 - 1e-6),
            dm_speed=q.number("dm_speed", d.qp.dm_speed, lo=0.0),
            dm_gradient_floor=q.number("dm_gradient_floor", d.qp.dm_gradient_floor, positive=True),
            arm_first=q.boolean("arm_first", d.qp.arm_first),
            slack_l1=q.number("slack_l1", d.qp.slack_l1, positive=True),
            slack_weight=q.number("slack_weight", d.qp.slack_weight, positive=True),
            task_speed_max=q.number("task_speed_max", d.qp.task_speed_max, positive=True),
            recovery_speed=q.number("recovery_speed", d.qp.recovery_speed, positive=True),
            singular_arm_weight=q.number("singular_arm_weight", d.qp.singular_arm_weight, lo=0.0),
            closed_form_first=q.boolean("closed_form_first", d.qp.closed_form_first),
            eps_abs=q.number("eps_abs", d.qp.eps_abs, positive=True),
        ),
        task=TaskConfig(
            kind=t.string("kind", d.task.kind, TASK_KINDS),
            K_R=t.number("K_R", d.task.K_R, lo=0.0),
            orientation_weight=t.number("orientation_weight", d.task.orientation_weight, positive=True),
            angular_speed_max=t.number("angular_speed_max", d.task.angular_speed_max, positive=True),
            angular_recovery_speed=t.number("angular_recovery_speed", d.task.angular_recovery_speed, positive=True),
        ),
        collision=CollisionParams(
            enabled=col.boolean("enabled", d.collision.enabled),
            influence_distance=d_i,
            safety_distance=d_s,
            floor_margin=d_floor,
            gain=col.number("gain", d.collision.gain, positive=True),
            braking=col.number("braking", d.collision.braking, positive=True),
        ),
        path=path,
    )
