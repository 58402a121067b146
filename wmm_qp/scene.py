"""The robot's surroundings: static obstacles and the workspace fence (a scene file, docs/model.md "Any robot").

A scene file (``configs/scenes/default.toml`` is the default; ``--scene FILE`` on the commands):

    [[obstacles]]
    id = "wall"
    kind = "box"                 # box | sphere | capsule | cylinder | plane
    size = [0.1, 4.0, 1.0]       # box: edge lengths [m]
    # sphere: radius = R; capsule, cylinder: radius = R, length = L (along the local z)
    xyz = [2.5, 0.0, 0.2]        # world frame [m]
    rpy = [0.0, 0.0, 0.0]        # [rad]
    exempt = []                  # links that may touch it; "ee": those moving with the EE frame
    velocity = [0.0, 0.0, 0.0]   # [m/s] world frame (a moving obstacle: the robot gives way at its speed)
    # a plane: normal = [nx, ny, nz], offset = c — the half-space n·p ≤ c is free, beyond it solid

    [fence]
    base = [[-3, -3], [3, -3], [3, 3], [-3, 3]]   # the base stays inside this polygon (world x, y)
    ee_lower = [-3.5, -3.5, -1.0]                 # the EE fence: the EE stays inside this box (world)
    ee_upper = [3.5, 3.5, 2.0]

Every obstacle is a hard constraint for every body of the robot (the velocity dampers of
:mod:`wmm_qp.limits.collision`) but its ``exempt`` ones; the fence is one for the base's origin and
the EE (the EE fence; not eq. (17)'s EE box of DM_CARTESIAN, a controller setting). The daemon
clamps every setpoint into the EE fence and above the floor margin
(:meth:`Scene.clamp_target`) before it chases it. Live obstacles (the daemon's
``<prefix>/<robot>/obstacles``) are tables of the same keys as ``[[obstacles]]``
(:func:`obstacle_from_table`); they replace the previous live set and add to the scene's.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ._typing import FloatArray, readonly
from .config import ConfigError, ShapeConfig, TomlTable, default_config_dir, load_shape, read_toml
from .config.toml import toml_key, toml_keys

OBSTACLE_KINDS = ("box", "sphere", "capsule", "cylinder", "plane")


@dataclass(frozen=True)
class Fence:
    """The workspace fence (world frame).

    Attributes:
        base: (k, 2) polygon the base's origin stays inside (counter-clockwise), or an empty (0, 2).
        ee_lower, ee_upper: [m] the EE fence, the box the EE stays inside (±inf: free).
    """

    base: FloatArray = field(default_factory=lambda: readonly(np.zeros((0, 2))), metadata=toml_key())
    ee_lower: FloatArray = field(default_factory=lambda: readonly([-np.inf] * 3), metadata=toml_key())
    ee_upper: FloatArray = field(default_factory=lambda: readonly([np.inf] * 3), metadata=toml_key())

    def half_planes(self) -> tuple[FloatArray, FloatArray]:
        """(A, c): the polygon as A p ≤ c, one row per edge (outward unit normals)."""
        P = self.base
        k = P.shape[0]
        if k < 3:
            return np.zeros((0, 2)), np.zeros(0)
        A, c = np.empty((k, 2)), np.empty(k)
        for i in range(k):
            a, b = P[i], P[(i + 1) % k]
            e = b - a
            n = np.array([e[1], -e[0]]) / np.linalg.norm(e)  # outward for a counter-clockwise polygon
            A[i], c[i] = n, n @ a
        return A, c

    def contains_base(self, p: FloatArray) -> bool:
        A, c = self.half_planes()
        return bool((A @ np.asarray(p[:2], dtype=float) <= c + 1e-12).all())


@dataclass(frozen=True)
class Scene:
    """Static obstacles (world frame) and the fence.

    Attributes:
        obstacles: each a primitive with ``link = ""`` and its world pose; ``name`` is its id.
        fence: the workspace fence.
        path: the file it was read from, or None.
    """

    obstacles: tuple[ShapeConfig, ...] = field(default=(), metadata=toml_key())
    fence: Fence = field(default_factory=Fence, metadata=toml_key())
    path: Path | None = None

    def clamp_target(self, x: FloatArray, z_min: float = -np.inf) -> tuple[FloatArray, str]:
        """An EE target clamped into the EE fence and above ``z_min`` (the floor margin).

        Returns:
            (the clamped target, "" when it was inside, else which axes were clamped, e.g.
            "x 20 -> 3.5, z -1.15 -> -0.32").
        """
        x = np.asarray(x, dtype=float)
        lo = np.array(self.fence.ee_lower, dtype=float)
        lo[2] = max(lo[2], z_min)
        hi = np.maximum(self.fence.ee_upper, lo)
        y = np.minimum(np.maximum(x, lo), hi)
        moved = np.flatnonzero(y != x)
        return y, ", ".join(f"{'xyz'[k]} {x[k]:.4g} -> {y[k]:.4g}" for k in moved)


def obstacle_from_table(path: Path | str, o: dict, i: int) -> ShapeConfig:
    """One obstacle from its table (the keys of ``[[obstacles]]``); ``i`` names it in errors.

    Raises:
        ConfigError: naming ``obstacles[i].<key>``.
    """
    path = Path(path)
    oid = o.get("id", f"obstacle_{i}")
    if not isinstance(oid, str) or not oid:
        raise ConfigError(path, f"obstacles[{i}].id", "must be a non-empty string")
    t = TomlTable(path, {k: v for k, v in o.items() if k not in ("id", "exempt", "velocity")}, f"obstacles[{i}].")
    velocity = TomlTable(path, o, f"obstacles[{i}].").vector("velocity", 3) if "velocity" in o else None
    exempt = o.get("exempt", [])
    if not isinstance(exempt, list) or not all(isinstance(x, str) for x in exempt):
        raise ConfigError(path, f"obstacles[{i}].exempt", "must be a list of link names (or \"ee\")")
    shape = load_shape(t, oid, "", OBSTACLE_KINDS)
    return replace(shape, exempt=tuple(exempt), velocity=velocity)


def obstacles_from_tables(path: Path | str, raw: list) -> tuple[ShapeConfig, ...]:
    """Every obstacle of a list of tables, ids unique (a scene file's, or a live message's)."""
    obstacles = tuple(obstacle_from_table(path, o, i) for i, o in enumerate(raw))
    ids = [o.name for o in obstacles]
    if len(set(ids)) != len(ids):
        raise ConfigError(Path(path), "obstacles", "obstacle ids must be unique")
    return obstacles


def default_scene_file() -> Path:
    """``<default_config_dir()>/scenes/default.toml``."""
    return default_config_dir() / "scenes" / "default.toml"


def load_scene(path: Path | str | None = None) -> Scene:
    """Load and validate a scene file (default: ``configs/scenes/default.toml``).

    Raises:
        ConfigError: naming the file and key of the first problem found.
    """
    path = Path(path) if path is not None else default_scene_file()
    r = TomlTable(path, read_toml(path))
    r.unknown(toml_keys(Scene))
    raw = r.get("obstacles", [])
    if not isinstance(raw, list) or not all(isinstance(o, dict) for o in raw):
        raise ConfigError(path, "obstacles", "must be a list of tables ([[obstacles]])")
    obstacles = obstacles_from_tables(path, raw)
    f = r.table("fence", required=False)
    f.unknown(toml_keys(Fence))
    fence = Fence()
    if f.data:
        poly = f.get("base", [])
        if not isinstance(poly, list) or (poly and (len(poly) < 3 or not all(
            isinstance(p, list) and len(p) == 2 and all(isinstance(v, int | float) for v in p) for p in poly
        ))):
            raise ConfigError(path, "fence.base", "must be a polygon: a list of at least 3 [x, y] points")
        P = np.array(poly, dtype=float).reshape(-1, 2)
        if P.shape[0] >= 3:
            area = 0.5 * float(np.sum(P[:, 0] * np.roll(P[:, 1], -1) - np.roll(P[:, 0], -1) * P[:, 1]))
            if abs(area) < 1e-9:
                raise ConfigError(path, "fence.base", "the polygon has no area")
            if area < 0:
                P = P[::-1].copy()  # counter-clockwise
        lo = f.vector("ee_lower", 3, [-np.inf] * 3, finite=False)
        hi = f.vector("ee_upper", 3, [np.inf] * 3, finite=False)
        if (lo >= hi).any():
            raise ConfigError(path, "fence.ee_lower", "must be < ee_upper on every axis")
        fence = Fence(base=readonly(P), ee_lower=lo, ee_upper=hi)
    return Scene(obstacles=tuple(obstacles), fence=fence, path=path)
