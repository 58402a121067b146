"""Frozen, validated configuration of the simulated robot (``configs/sim.toml``).

The file is read once into :class:`SimConfig`; every check names the file and the key.
Absent keys keep the defaults below (the same values ``configs/sim.toml`` documents).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from wmm_qp_robot.config import RefereeConfig

from wmm_qp import default_config_dir
from wmm_qp.config import TomlTable, read_toml
from wmm_qp.exceptions import ConfigError


@dataclass(frozen=True)
class SlipConfig:
    """Base slip and drift: how the true base motion departs from odometry.

    True body twist: ``M · (w ⊙ (1 + b + n(t))) + [0, 0, yaw_drift_per_meter·‖(v_x, v_y)‖]``.

    Attributes:
        enabled: False = the base executes the wheel speeds exactly (odometry == truth).
        wheel_scale_std: [-] std of the per-wheel systematic scale error b_i, drawn per reset.
        wheel_noise_std: [-] stationary std of the per-wheel Ornstein–Uhlenbeck slip n_i(t).
        wheel_noise_tau: [s] correlation time of n_i(t).
        yaw_drift_per_meter: [rad/m] extra true yaw rate per metre of base travel.
    """

    enabled: bool = True
    wheel_scale_std: float = 0.02
    wheel_noise_std: float = 0.05
    wheel_noise_tau: float = 0.2
    yaw_drift_per_meter: float = 0.01


@dataclass(frozen=True)
class BoxConfig:
    """A box on the floor in front of the EE, pushed along +x (world), quasi-static.

    Attributes:
        mass: [kg] box mass m.
        mu: [-] Coulomb friction coefficient box/floor; sliding needs F = μ m g.
        face_x: [m] initial world x of the face the EE pushes on.
        center_y: [m] world y of the face's centre.
        width: [m] face extent along y.
        height: [m] face extent along z (from the floor, z = 0).
        g: [m/s²] gravity.
    """

    mass: float = 26.0
    mu: float = 0.3
    face_x: float = 0.70
    center_y: float = 0.0
    width: float = 0.4
    height: float = 0.6
    g: float = 9.81

    @property
    def friction_force(self) -> float:
        """[N] μ m g: the force that keeps the box sliding."""
        return self.mu * self.mass * self.g


PLANTS = ("kinematic", "mujoco")
"""The plants a :class:`PhysicsConfig` may name (``plant``)."""


@dataclass(frozen=True)
class PhysicsConfig:
    """The plant the simulated robot drives, and the physics plant's parameters.

    Attributes:
        plant: "kinematic" (:class:`~.kinematic_plant.KinematicPlant`: the rates happen exactly)
            or "mujoco" (:class:`~.mujoco_plant.MujocoPlant`: rigid-body physics, needs
            ``pip install 'wmm-qp[physics]'``); the other keys are the physics plant's.
        mu_wheel: [-] wheel/floor friction coefficient: the base's traction limit is μ_wheel·m·g
            (m the whole robot's mass), its yaw torque limit that times the wheels' lever.
        base_mass: [kg] the base's own mass (the arm's comes from its URDF).
        base_time_constant: [s] time constant of the wheels' force servo toward the commanded twist.
        servo_error: [rad/s or m/s] the velocity error at which a joint's servo reaches its
            torque limit (its gain is torque_limit / servo_error).
        tracking_error: [rad/s or m/s] a joint further than this from its commanded rate could
            not follow (counted in ``SimState.physics["tracking"]``).
        armature: [kg·m²] rotor inertia added to every arm joint (a real drive's gearbox).
        limit_margin: [rad or m] the drives' own position limits sit this far inside the robot
            file's: each servo's target rate is capped at the rate that reaches its line in one
            step, so a joint the controller stops at its limit is held there under loads its
            servo alone would yield to (a velocity servo's error is load / gain).
        ee_tip_radius: [m] the sphere at the task point that touches the push box.
        g: [m/s²] gravity.
    """

    plant: str = "kinematic"
    mu_wheel: float = 0.5
    base_mass: float = 60.0
    base_time_constant: float = 0.02
    servo_error: float = 0.05
    tracking_error: float = 0.1
    armature: float = 0.01
    limit_margin: float = 1e-5
    ee_tip_radius: float = 0.02
    g: float = 9.81


@dataclass(frozen=True)
class SimConfig:
    """The simulated robot.

    Attributes:
        rate_hz: [Hz] the sim loop's integration rate (the tick of its Zenoh node, ``wmm-qp sim``).
        seed: seed of the slip/drift noise.
        stale_timeout: [s] without a new command the sim brakes the robot to rest itself.
        firmware: model the robot's own protections: refuse commands beyond the rate limits
            and any motion that could not stop before a position limit, with a protective
            stop (see :mod:`.robot`). The in-process experiments turn it off, so that the
            referee measures the controllers themselves.
        rt_priority: SCHED_FIFO priority (1–99) of ``wmm-qp sim``'s step loop, as the daemon's
            ``loop.rt_priority``; 0: normal scheduling. Without root or CAP_SYS_NICE the sim
            says so and runs with normal scheduling.
        slip: base slip and drift model.
        referee: tolerance of the limit referee.
        box: the box of the push experiment, or None (no box).
        physics: the plant and the physics plant's parameters (the file's ``[physics]`` table).
    """

    rate_hz: float = 1000.0
    seed: int = 0
    stale_timeout: float = 0.025
    firmware: bool = True
    rt_priority: int = 50
    slip: SlipConfig = field(default_factory=SlipConfig)
    referee: RefereeConfig = field(default_factory=RefereeConfig)
    box: BoxConfig | None = None
    physics: PhysicsConfig = field(default_factory=PhysicsConfig)

    @property
    def dt(self) -> float:
        """[s] integration step 1 / rate_hz."""
        return 1.0 / self.rate_hz

    def with_(self, **changes: Any) -> SimConfig:
        """A copy with some fields changed; ``slip``, ``referee`` and ``physics`` may be dicts of
        fields."""
        for k in ("slip", "referee", "physics"):
            if isinstance(changes.get(k), dict):
                changes[k] = replace(getattr(self, k), **changes[k])
        return replace(self, **changes)


def load_sim_config(path: Path | str | None = None) -> SimConfig:
    """Load and validate ``sim.toml``.

    Args:
        path: the file; default ``<wmm_qp.default_config_dir()>/sim.toml``. A missing default
            file gives the defaults of :class:`SimConfig`.

    Raises:
        ConfigError: naming the file and key of the first problem found.
    """
    if path is None:
        path = default_config_dir() / "sim.toml"
        if not path.is_file():
            return SimConfig()
    path = Path(path)
    r = TomlTable(path, read_toml(path))
    r.unknown({"rate_hz", "seed", "stale_timeout", "firmware", "rt_priority", "slip", "referee", "box", "physics"})
    d = SimConfig()
    rt_priority = r.integer("rt_priority", d.rt_priority, lo=0)
    if rt_priority > 99:
        raise ConfigError(path, "rt_priority", f"must be in [0, 99] (0: normal scheduling), got {rt_priority}")
    seed = r.get("seed", d.seed)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ConfigError(path, "seed", f"must be a non-negative integer, got {seed!r}")
    s = r.table("slip", required=False)
    s.unknown({"enabled", "wheel_scale_std", "wheel_noise_std", "wheel_noise_tau", "yaw_drift_per_meter"})
    ds = SlipConfig()
    slip = SlipConfig(
        enabled=s.boolean("enabled", ds.enabled),
        wheel_scale_std=s.number("wheel_scale_std", ds.wheel_scale_std, lo=0.0),
        wheel_noise_std=s.number("wheel_noise_std", ds.wheel_noise_std, lo=0.0),
        wheel_noise_tau=s.number("wheel_noise_tau", ds.wheel_noise_tau, positive=True),
        yaw_drift_per_meter=s.number("yaw_drift_per_meter", ds.yaw_drift_per_meter),
    )
    t = r.table("referee", required=False)
    t.unknown({"rtol", "atol", "collision_distance", "collisions"})
    referee = RefereeConfig(rtol=t.number("rtol", 1e-9, lo=0.0), atol=t.number("atol", 1e-9, lo=0.0),
                            collision_distance=t.number("collision_distance", 0.01),
                            collisions=t.boolean("collisions", True))
    b = r.table("box", required=False)
    b.unknown({"enabled", "mass", "mu", "face_x", "center_y", "width", "height", "g"})
    db = BoxConfig()
    box = None
    if b.boolean("enabled", False):
        box = BoxConfig(
            mass=b.number("mass", db.mass, positive=True),
            mu=b.number("mu", db.mu, lo=0.0),
            face_x=b.number("face_x", db.face_x),
            center_y=b.number("center_y", db.center_y),
            width=b.number("width", db.width, positive=True),
            height=b.number("height", db.height, positive=True),
            g=b.number("g", db.g, positive=True),
        )
    return SimConfig(
        physics=_physics(path, r),
        rate_hz=r.number("rate_hz", d.rate_hz, positive=True),
        seed=seed,
        stale_timeout=r.number("stale_timeout", d.stale_timeout, positive=True),
        firmware=r.boolean("firmware", d.firmware),
        rt_priority=rt_priority,
        slip=slip,
        referee=referee,
        box=box,
    )


def _physics(path: Path, r: TomlTable) -> PhysicsConfig:
    """The ``[physics]`` table (absent: the defaults)."""
    p = r.table("physics", required=False)
    p.unknown({"plant", "mu_wheel", "base_mass", "base_time_constant", "servo_error", "tracking_error", "armature",
               "limit_margin", "ee_tip_radius", "g"})
    d = PhysicsConfig()
    plant = p.get("plant", d.plant)
    if plant not in PLANTS:
        raise ConfigError(path, "physics.plant", f"must be one of {', '.join(PLANTS)}, got {plant!r}")
    return PhysicsConfig(
        plant=plant,
        mu_wheel=p.number("mu_wheel", d.mu_wheel, lo=0.0),
        base_mass=p.number("base_mass", d.base_mass, positive=True),
        base_time_constant=p.number("base_time_constant", d.base_time_constant, positive=True),
        servo_error=p.number("servo_error", d.servo_error, positive=True),
        tracking_error=p.number("tracking_error", d.tracking_error, positive=True),
        armature=p.number("armature", d.armature, lo=0.0),
        limit_margin=p.number("limit_margin", d.limit_margin, lo=0.0),
        ee_tip_radius=p.number("ee_tip_radius", d.ee_tip_radius, positive=True),
        g=p.number("g", d.g, positive=True),
    )
