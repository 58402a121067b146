"""Loading a robot file (``configs/robots/*.toml``, docs/robots.md): its keys checked, the arm
resolved against its URDF (the chain to the EE frame, the limits the file does not override).

Every problem is a :class:`~wmm_qp.exceptions.ConfigError` naming the file and the dotted key.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from .. import urdf as urdf_io
from .._typing import readonly
from ..exceptions import ConfigError
from .discovery import default_robot_file
from .robot import (
    BASE_GEOMETRY,
    BASE_KINDS,
    N_WHEELS,
    WHEEL_LIMITS,
    ArmConfig,
    BaseConfig,
    GripperConfig,
    RobotCollisionConfig,
    RobotConfig,
    Ros2Config,
)
from .shapes import load_shape
from .toml import TomlTable, load, read_toml, toml_keys


def load_robot_config(path: Path | str | None = None) -> RobotConfig:
    """Load a robot file (``configs/robots/*.toml``, docs/robots.md) and resolve it against its URDF.

    Args:
        path: the file; default ``configs/robots/gen3_mecanum.toml`` (the paper's robot).

    Raises:
        ConfigError: naming the file and key of the first problem found.
    """
    path = Path(path) if path is not None else default_robot_file()
    r = TomlTable(path, read_toml(path))
    r.unknown(toml_keys(RobotConfig))
    a = r.table("arm")
    a.unknown(toml_keys(ArmConfig))
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
    collision = _load_collision(r.table("collision", required=False), path, full)
    gripper = load(r.table("gripper"), GripperConfig) if r.has("gripper") else None
    ros2 = load(r.table("ros2", required=False), Ros2Config, Ros2Config())
    return RobotConfig(arm=arm, base=base, name=r.string("name", "wmm"), path=path, collision=collision,
                       gripper=gripper, ros2=ros2)


def _load_collision(c: TomlTable, path: Path, full: Any) -> RobotCollisionConfig:
    """The ``[collision]`` table; ``full``: the URDF's whole model (its links name the shapes')."""
    c.unknown(toml_keys(RobotCollisionConfig))
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


def _load_base(b: TomlTable) -> BaseConfig:
    """The ``[base]`` table: its kind's geometry and wheel limits only (another kind's are unknown keys)."""
    kind = b.string("kind", "mecanum", BASE_KINDS)
    geometry = BASE_GEOMETRY[kind]
    others = {k for keys in BASE_GEOMETRY.values() for k in keys} - set(geometry)
    b.unknown(toml_keys(BaseConfig) - others - (set(WHEEL_LIMITS) if kind == "fixed" else set()))
    n = N_WHEELS[kind]
    values = {k: b.number(k, positive=True) for k in geometry}
    if not b.has("floor_z"):
        raise ConfigError(b.path, b.key("floor_z"), "missing: the world z of the floor [m] (the world origin is "
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
