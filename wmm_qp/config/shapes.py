"""Collision primitives as a robot file and a scene file give them: ``[collision] shapes``,
``[base] body`` and a scene's ``[[obstacles]]``.

One table per primitive: ``kind`` and its size keys (box: ``size``; sphere: ``radius``; capsule:
``radius`` and ``length`` along its local z, or ``radius``, ``from`` and ``to``; cylinder:
``radius``, ``length``; plane, obstacles only: ``normal``, ``offset``), then its pose ``xyz``,
``rpy`` in its link's frame (the world's for an obstacle).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from .._typing import FloatArray, readonly
from ..exceptions import ConfigError
from .toml import TomlTable

SHAPE_KINDS = ("box", "sphere", "capsule", "cylinder")
_SIZE_KEYS = {"box": {"size"}, "sphere": {"radius"}, "capsule": {"radius", "length", "from", "to"},
              "cylinder": {"radius", "length"}, "plane": {"normal", "offset"}}


@dataclass(frozen=True)
class ShapeConfig:
    """A collision primitive fixed to a link (or to the base, or to the world for obstacles).

    Attributes:
        name: its name (reported with every collision it is part of).
        link: the URDF link it is attached to ("base" for the base frame, "" for the world).
        kind: "box", "sphere", "capsule" or "cylinder" (capsules and cylinders along their local
            z); obstacles may also be a "plane", the half-space beyond it solid.
        size: [m] box edge lengths (x, y, z); for spheres, capsules and cylinders [radius, length,
            0] (a sphere's length 0); a plane's unit normal n [-] (:attr:`normal`).
        xyz, rpy: [m], [rad] its pose in the link's frame; a plane's offset c [m] is xyz[2]
            (:attr:`offset`: n·p ≤ c is free), its pose the identity.
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
        """[m] a sphere's, capsule's or cylinder's radius."""
        return float(self.size[0])

    @property
    def length(self) -> float:
        """[m] a capsule's or cylinder's length (of its segment; a sphere's 0)."""
        return float(self.size[1])

    @property
    def normal(self) -> FloatArray:
        """A plane's unit normal n (world frame): n·p ≤ :attr:`offset` is free, beyond it solid."""
        return self.size

    @property
    def offset(self) -> float:
        """[m] a plane's offset c: n·p ≤ c is free."""
        return float(self.xyz[2])


def load_shape(t: TomlTable, name: str, link: str, kinds: tuple[str, ...] = SHAPE_KINDS) -> ShapeConfig:
    """A primitive of a robot or scene file (the module docstring's keys).

    Raises:
        ConfigError: naming the file and the dotted key of the first problem found.
    """
    kind = t.string("kind", choices=kinds)
    t.unknown({"kind", "name", "link", "xyz", "rpy", *_SIZE_KEYS[kind]})
    if kind == "capsule" and (t.has("from") or t.has("to")):  # a capsule between two points of the link
        p0, p1 = t.vector("from", 3), t.vector("to", 3)
        axis = p1 - p0
        length = float(np.linalg.norm(axis))
        if length < 1e-9:
            raise ConfigError(t.path, t.key("to"), "must differ from 'from'")
        z = axis / length
        ref = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        x = np.cross(ref, z)
        x /= np.linalg.norm(x)
        R = np.column_stack([x, np.cross(z, x), z])
        rpy = pin.rpy.matrixToRpy(R)
        return ShapeConfig(name, link, kind, readonly([t.number("radius", positive=True), length, 0.0]),
                           readonly(0.5 * (p0 + p1)), readonly(rpy))
    if kind == "box":
        size = t.vector("size", 3, positive=True)
    elif kind == "plane":
        n = t.vector("normal", 3)
        if np.linalg.norm(n) < 1e-9:
            raise ConfigError(t.path, t.key("normal"), "must not be the zero vector")
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
