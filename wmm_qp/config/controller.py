"""The controller file's schema and loader (``configs/controller.toml``): the paper's gains, the
task, the QP's settings and the collision dampers.

Each field declares its key, table and check (``toml_key``), once: :func:`load_controller_config`
reads them all by :func:`~wmm_qp.config.toml.load`; absent keys keep the paper's values.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from .._typing import FloatArray, readonly
from ..exceptions import ConfigError
from ..solvers import SOLVER_NAMES
from .discovery import default_config_dir
from .robot import RobotConfig
from .toml import TomlTable, boolean, choice, load, number, read_toml, section, toml_key

TASK_KINDS = ("position", "pose")
CONTROLLER_KINDS = ("qp", "paper", "traditional")


@dataclass(frozen=True)
class TaskConfig:
    """The task of eq. (5) (docs/model.md "Any robot"; the file's ``[task]``).

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

    kind: str = field(default="position", metadata=toml_key(choice(TASK_KINDS)))
    K_R: float = field(default=10.0, metadata=toml_key(number(lo=0.0)))
    orientation_weight: float = field(default=0.2, metadata=toml_key(number(positive=True)))
    angular_speed_max: float = field(default=2.0, metadata=toml_key(number(positive=True)))
    angular_recovery_speed: float = field(default=0.5, metadata=toml_key(number(positive=True)))

    @property
    def r(self) -> int:
        """Dimension of the task space."""
        return 6 if self.kind == "pose" else 3


@dataclass(frozen=True)
class QpConfig:
    """Settings of the QP controller (docs/model.md "The QP"; the file's ``[qp]``).

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

    solver: str = field(default="proxsuite", metadata=toml_key(choice(SOLVER_NAMES)))
    alpha: float = field(default=0.2, metadata=toml_key(number(lo=1e-6, hi=1.0 - 1e-6)))
    dm_alpha: float = field(default=0.99, metadata=toml_key(number(lo=1e-6, hi=1.0 - 1e-6)))
    dm_speed: float = field(default=1.0, metadata=toml_key(number(lo=0.0)))
    dm_gradient_floor: float = field(default=0.1, metadata=toml_key(number(positive=True)))
    arm_first: bool = field(default=True, metadata=toml_key(boolean()))
    slack_l1: float = field(default=1e4, metadata=toml_key(number(positive=True)))
    slack_weight: float = field(default=1e4, metadata=toml_key(number(positive=True)))
    task_speed_max: float = field(default=2.0, metadata=toml_key(number(positive=True)))
    recovery_speed: float = field(default=0.25, metadata=toml_key(number(positive=True)))
    singular_arm_weight: float = field(default=100.0, metadata=toml_key(number(lo=0.0)))
    closed_form_first: bool = field(default=True, metadata=toml_key(boolean()))
    eps_abs: float = field(default=1e-9, metadata=toml_key(number(positive=True)))


@dataclass(frozen=True)
class CollisionParams:
    """The velocity dampers (docs/model.md "Collisions"; the file's ``[collision]``):
    ḋ ≥ −ξ (d − d_s)/(d_i − d_s) for every monitored pair closer than d_i.

    Attributes:
        enabled: add the damper rows to every stage of the qp controller (on by default: every
            command that drives a robot has them unless ``--no-collision`` or ``enabled = false``;
            ``wmm-qp experiment`` keeps the paper's setting, off, unless ``--scene``).
        influence_distance: [m] d_i, where a pair's row starts to act (> safety_distance and
            floor_margin).
        safety_distance: [m] d_s, the distance the pair settles at (robot vs robot, robot vs obstacles).
        floor_margin: [m] d_s for every link vs the floor.
        gain: [m/s] ξ, the approach speed a pair may keep at d_i.
        braking: [-] β, the share of a pair's deceleration capacity a_n (every joint braking for
            it at its acceleration limit) that the braking profile ḋ ≥ −√(2 β a_n (d − d_s))
            counts on; the rest is left to the other rows and the task.
    """

    enabled: bool = field(default=True, metadata=toml_key(boolean()))
    influence_distance: float = field(default=0.15, metadata=toml_key(number(positive=True)))
    safety_distance: float = field(default=0.03, metadata=toml_key(number(lo=0.0)))
    floor_margin: float = field(default=0.03, metadata=toml_key(number(lo=0.0)))
    gain: float = field(default=0.5, metadata=toml_key(number(positive=True)))
    braking: float = field(default=0.25, metadata=toml_key(number(positive=True)))


def _weights(t: TomlTable, k: str, default: Any) -> FloatArray | None:
    """``dm.W``: one positive number per joint of the robot (its length is checked against the robot's)."""
    W = t.get(k, None)
    if W is None:
        return None
    if not isinstance(W, list):
        raise ConfigError(t.path, t.key(k), f"must be a list of numbers (one per joint of the robot), got {W!r}")
    return t.vector(k, len(W), positive=True)


def _direction(t: TomlTable, k: str, default: Any) -> FloatArray:
    """``dm.direction``: a non-zero vector, stored as a unit vector."""
    u = t.vector(k, 3, default)
    if np.linalg.norm(u) < 1e-9:
        raise ConfigError(t.path, t.key(k), "must not be the zero vector")
    return readonly(u / np.linalg.norm(u))


def _free_vector(t: TomlTable, k: str, default: Any) -> FloatArray:
    """Three numbers, ±inf allowed (an open side of a box)."""
    return t.vector(k, 3, default, finite=False)


@dataclass(frozen=True)
class ControllerConfig:
    """Gains and parameters of the paper, and the QP's settings.

    Attributes:
        rate_hz: [Hz] control rate; dt = 1 / rate_hz.
        kind: default controller: "qp", "paper" or "traditional" (the file's ``controller``).
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
        collision: the velocity dampers.
        path: the file it was read from (for errors that name it), or None.
    """

    rate_hz: float = field(default=500.0, metadata=toml_key(number(lo=1.0, hi=10_000.0)))
    kind: str = field(default="qp", metadata=toml_key(choice(CONTROLLER_KINDS), key="controller"))
    K_x: float = field(default=10.0, metadata=toml_key(number(lo=0.0), table="gains"))
    alpha: float = field(default=0.2, metadata=toml_key(number(lo=0.0, hi=1.0), table="gains"))
    k_C: float = field(default=0.01, metadata=toml_key(number(lo=0.0), table="gains"))
    k_N: float = field(default=0.2, metadata=toml_key(number(lo=0.0), table="gains"))
    W: FloatArray | None = field(default=None, metadata=toml_key(_weights, table="dm"))
    direction: FloatArray = field(default_factory=lambda: readonly([1.0, 0.0, 0.0]),
                                  metadata=toml_key(_direction, table="dm"))
    ee_box_lower: FloatArray = field(default_factory=lambda: readonly([-np.inf, -np.inf, 0.36]),
                                     metadata=toml_key(_free_vector, table="dm"))
    ee_box_upper: FloatArray = field(default_factory=lambda: readonly([np.inf, np.inf, 0.56]),
                                     metadata=toml_key(_free_vector, table="dm"))
    sigma_min_floor: float = field(default=0.085, metadata=toml_key(number(lo=0.0), table="dm"))
    state_latency: float = field(default=0.0, metadata=toml_key(number(lo=0.0, hi=1.0)))
    sigma_threshold: float = field(default=0.08, metadata=toml_key(number(lo=0.0), table="singularity"))
    damping_max: float = field(default=0.05, metadata=toml_key(number(lo=0.0), table="singularity"))
    qp: QpConfig = field(default_factory=QpConfig, metadata=section(QpConfig))
    task: TaskConfig = field(default_factory=TaskConfig, metadata=section(TaskConfig))
    collision: CollisionParams = field(default_factory=CollisionParams, metadata=section(CollisionParams))
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


def load_controller_config(path: Path | str | None = None) -> ControllerConfig:
    """Load and validate ``controller.toml``; absent keys keep the paper's values.

    Raises:
        ConfigError: naming the file and key of the first problem found.
    """
    path = Path(path) if path is not None else default_config_dir() / "controller.toml"
    c = load(TomlTable(path, read_toml(path)), ControllerConfig, ControllerConfig(), path=path)
    col = c.collision
    if col.influence_distance <= max(col.safety_distance, col.floor_margin):
        raise ConfigError(path, "collision.influence_distance", "must be > safety_distance and floor_margin")
    if (c.ee_box_lower >= c.ee_box_upper).any():
        raise ConfigError(path, "dm.ee_box_lower", "must be < ee_box_upper on every axis")
    return c
