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
from numpy.typing import NDArray

from .exceptions import ConfigError

N_ARM = 7
N_WHEELS = 4

FloatArray = NDArray[np.float64]


def _ro(a: Any) -> FloatArray:
    out = np.array(a, dtype=float)
    out.setflags(write=False)
    return out


@dataclass(frozen=True)
class ArmConfig:
    """The manipulator: URDF, EE frame and limits (joint order joint_1..joint_7).

    Attributes:
        urdf: path of the arm's URDF.
        ee_frame: name of the end-effector frame (the tool flange).
        mount_offset: [m] arm base origin in the mobile-base frame (eq. (2): p_mount).
        position_lower, position_upper: [rad] position limits, ±inf for continuous joints.
        velocity_max: [rad/s] symmetric velocity limits.
        acceleration_max: [rad/s²] symmetric acceleration limits.
        torque_limit: [N·m] torque limits used by W (eq. (8)) and the push experiment.
    """

    urdf: Path
    ee_frame: str
    mount_offset: FloatArray
    position_lower: FloatArray
    position_upper: FloatArray
    velocity_max: FloatArray
    acceleration_max: FloatArray
    torque_limit: FloatArray


@dataclass(frozen=True)
class BaseConfig:
    """The four-wheel Mecanum base (wheels FL, FR, RL, RR).

    Attributes:
        wheel_radius: [m] R.
        l1: [m] half the distance between the front and rear axles.
        l2: [m] half the track width (between left and right wheels).
        wheel_speed_max: [rad/s] symmetric wheel speed limit.
        wheel_acceleration_max: [rad/s²] symmetric wheel acceleration limit.
    """

    wheel_radius: float
    l1: float
    l2: float
    wheel_speed_max: float
    wheel_acceleration_max: float


@dataclass(frozen=True)
class RobotConfig:
    """The whole wheeled mobile manipulator."""

    arm: ArmConfig
    base: BaseConfig
    name: str = "wmm"


@dataclass(frozen=True)
class QpConfig:
    """Settings of the QP controller (DESIGN.md §2).

    Attributes:
        solver: backend name from :func:`wmm_qp.solvers.available_solvers`.
        alpha: the α of eq. (12) in the QP's cost ½ vᵀ W_x⁻¹ v; small = base expensive.
        dm_alpha: the α used in the null-space DM mode, where the whole robot's null space,
            base included, must serve the DM objective (eq. (18)). Wheel speeds are in rad/s
            and move the EE by only ~R/4 per rad/s, so with α = 0.2 the base barely helps and
            the arm alone tops out near DM 4.1 along x; α = 0.99 lets the base move so the arm
            can stretch (the paper's 5.88).
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
            1 + singular_arm_weight·(λ/λ_max)², so the base takes over (the QP's damping).
        closed_form_first: try the closed-form optimum (no bound active, zero slack) before the
            solver; it is taken only when it satisfies every KKT condition, so it is exact.
        eps_abs: absolute tolerance handed to iterative backends.
    """

    solver: str = "proxsuite"
    alpha: float = 0.2
    dm_alpha: float = 0.99
    arm_first: bool = True
    slack_l1: float = 1e4
    slack_weight: float = 1e4
    task_speed_max: float = 2.0
    recovery_speed: float = 0.25
    singular_arm_weight: float = 100.0
    closed_form_first: bool = True
    eps_abs: float = 1e-9


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
        W: diagonal of the torque scaling W of eq. (8).
        direction: default DM direction u, in the base (yaw-compensated) frame.
        ee_box_lower, ee_box_upper: [m] the EE box of eq. (17) (world frame), ±inf = free.
        state_latency: [s] age of the state when the command starts to act; the bounds (13)
            brake from where the joints will be by then (0 = the state is current).
        sigma_threshold: σ_min(J_m) below which damped least squares replaces J#.
        damping_max: [-] the DLS damping λ reached at σ_min = 0.
        qp: the QP controller's settings.
    """

    rate_hz: float = 500.0
    kind: str = "qp"
    K_x: float = 10.0
    alpha: float = 0.2
    k_C: float = 0.01
    k_N: float = 0.2
    W: FloatArray = field(default_factory=lambda: _ro([1, 1, 1, 1, 2.5, 2.5, 2.5]))
    direction: FloatArray = field(default_factory=lambda: _ro([1.0, 0.0, 0.0]))
    ee_box_lower: FloatArray = field(default_factory=lambda: _ro([-np.inf, -np.inf, 0.36]))
    ee_box_upper: FloatArray = field(default_factory=lambda: _ro([np.inf, np.inf, 0.56]))
    state_latency: float = 0.0
    sigma_threshold: float = 0.08
    damping_max: float = 0.05
    qp: QpConfig = field(default_factory=QpConfig)

    @property
    def dt(self) -> float:
        """[s] control period."""
        return 1.0 / self.rate_hz

    def with_(self, **changes: Any) -> ControllerConfig:
        """A copy with some fields changed (``qp`` may be given as a dict of its fields)."""
        if isinstance(changes.get("qp"), dict):
            changes["qp"] = replace(self.qp, **changes["qp"])
        return replace(self, **changes)


CONTROLLER_KINDS = ("qp", "paper", "traditional")


# --------------------------------------------------------------------------- loading


def default_config_dir() -> Path:
    """The folder holding robot.toml and controller.toml.

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
        if (c / "robot.toml").is_file():
            return c
    raise ConfigError(candidates[0], "", "no robot.toml found in any of: " + ", ".join(map(str, candidates)))


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
        return _ro(a)

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
    """Load and validate ``robot.toml``.

    Args:
        path: the file; default ``<default_config_dir()>/robot.toml``.

    Raises:
        ConfigError: naming the file and key of the first problem found.
    """
    path = Path(path) if path is not None else default_config_dir() / "robot.toml"
    r = TomlTable(path, read_toml(path))
    r.unknown({"name", "arm", "base"})
    a = r.table("arm")
    a.unknown(
        {
            "urdf",
            "ee_frame",
            "mount_offset",
            "position_lower",
            "position_upper",
            "velocity_max",
            "acceleration_max",
            "torque_limit",
        }
    )
    urdf = (path.parent / a.string("urdf")).resolve()
    if not urdf.is_file():
        raise ConfigError(path, "arm.urdf", f"file not found: {urdf}")
    lower = a.vector("position_lower", N_ARM, finite=False)
    upper = a.vector("position_upper", N_ARM, finite=False)
    bad = np.flatnonzero(~(lower < upper))
    if bad.size:
        raise ConfigError(path, "arm.position_lower", f"must be < position_upper (joint {bad[0] + 1})")
    arm = ArmConfig(
        urdf=urdf,
        ee_frame=a.string("ee_frame", "end_effector_link"),
        mount_offset=a.vector("mount_offset", 3, [0.0, 0.0, 0.0]),
        position_lower=lower,
        position_upper=upper,
        velocity_max=a.vector("velocity_max", N_ARM, positive=True),
        acceleration_max=a.vector("acceleration_max", N_ARM, positive=True),
        torque_limit=a.vector("torque_limit", N_ARM, positive=True),
    )
    b = r.table("base")
    b.unknown({"wheel_radius", "l1", "l2", "wheel_speed_max", "wheel_acceleration_max"})
    base = BaseConfig(
        wheel_radius=b.number("wheel_radius", positive=True),
        l1=b.number("l1", positive=True),
        l2=b.number("l2", positive=True),
        wheel_speed_max=b.number("wheel_speed_max", positive=True),
        wheel_acceleration_max=b.number("wheel_acceleration_max", positive=True),
    )
    return RobotConfig(arm=arm, base=base, name=r.string("name", "wmm"))


def load_controller_config(path: Path | str | None = None) -> ControllerConfig:
    """Load and validate ``controller.toml``; absent keys keep the paper's values.

    Raises:
        ConfigError: naming the file and key of the first problem found.
    """
    from .solvers import SOLVER_NAMES

    path = Path(path) if path is not None else default_config_dir() / "controller.toml"
    r = TomlTable(path, read_toml(path))
    r.unknown({"rate_hz", "controller", "state_latency", "gains", "dm", "singularity", "qp"})
    d = ControllerConfig()
    g = r.table("gains", required=False)
    g.unknown({"K_x", "alpha", "k_C", "k_N"})
    dm = r.table("dm", required=False)
    dm.unknown({"W", "direction", "ee_box_lower", "ee_box_upper"})
    s = r.table("singularity", required=False)
    s.unknown({"sigma_threshold", "damping_max"})
    q = r.table("qp", required=False)
    q.unknown(
        {
            "solver",
            "alpha",
            "dm_alpha",
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
        W=dm.vector("W", N_ARM, d.W, positive=True),
        direction=_ro(direction / np.linalg.norm(direction)),
        ee_box_lower=lo,
        ee_box_upper=hi,
        sigma_threshold=s.number("sigma_threshold", d.sigma_threshold, lo=0.0),
        damping_max=s.number("damping_max", d.damping_max, lo=0.0),
        qp=QpConfig(
            solver=q.string("solver", d.qp.solver, SOLVER_NAMES),
            alpha=q.number("alpha", d.qp.alpha, lo=1e-6, hi=1.0 - 1e-6),
            dm_alpha=q.number("dm_alpha", d.qp.dm_alpha, lo=1e-6, hi=1.0 - 1e-6),
            arm_first=q.boolean("arm_first", d.qp.arm_first),
            slack_l1=q.number("slack_l1", d.qp.slack_l1, positive=True),
            slack_weight=q.number("slack_weight", d.qp.slack_weight, positive=True),
            task_speed_max=q.number("task_speed_max", d.qp.task_speed_max, positive=True),
            recovery_speed=q.number("recovery_speed", d.qp.recovery_speed, positive=True),
            singular_arm_weight=q.number("singular_arm_weight", d.qp.singular_arm_weight, lo=0.0),
            closed_form_first=q.boolean("closed_form_first", d.qp.closed_form_first),
            eps_abs=q.number("eps_abs", d.qp.eps_abs, positive=True),
        ),
    )
