"""Validation on receipt: bytes → a checked message, or a rejection reason (counted).

Nothing malformed reaches the controller. Checks, in order: the payload's length
(``size``, before decoding), msgpack at all (``decode``), the protocol version when the
header has one (``version``), the header's five fields present (``type``, ``v``, ``robot``,
``seq``, ``stamp``; else ``schema``), the expected schema (``schema``), the robot id (``robot``), NaN/inf in the
time stamp (``non_finite``), vector sizes (``size``: the robot's number of joints ``n_arm`` and
of wheels ``n_wheels`` for joint and wheel vectors, given to the :class:`Validator`; 3 for
task-space vectors, 4 for a quaternion), NaN/inf (``non_finite``), ranges (``range``), the mode
name (``mode``).
A box (:class:`~.protocol.BoxMsg`): finite, mass in (0, 1000] kg, μ in [0, 5], face x and
centre y within ``position_abs_max``, width and height in (0, 10] m. A command: a non-empty
``lease`` and ``instance``, ``period`` in (0, ``PERIOD_MAX``]. A setpoint: a non-empty
``source``; its optional orientation ``q`` finite, entries ≤ 1e6, norm > 1e-9 (the controller
normalises it), its angular velocity ``w`` finite with norm ≤ ``angular_speed_max``. A state: a
non-empty ``instance``. A truth (:class:`~.protocol.TruthMsg`): 3-vectors of size 3 (NaN
allowed: unknown). A gripper command (:class:`~.protocol.GripperMsg`): an action of
``GRIPPER_ACTIONS`` (else ``range``), a non-empty ``source``, finite width in [0, 1] m, speed
in (0, 1] m/s, force in [0, 1000] N (the robot clamps them to its own gripper). An obstacles message
(:class:`~.protocol.ObstaclesMsg`): a non-empty ``source``, at most ``obstacles_max`` obstacles,
each one a valid scene-file obstacle table
(:func:`wmm_qp.scene.obstacle_from_table`; else ``range`` with the key), ids unique, positions within
``position_abs_max`` and sizes within ``obstacle_size_max``; its payload may be up to
``obstacles_payload_max_bytes``. The validator keeps the accepted set's primitives in
:attr:`Validator.shapes`.
"""

from __future__ import annotations

import enum
import math
from collections import Counter
from collections.abc import Iterable
from typing import Generic, TypeVar

import msgspec
import numpy as np

from wmm_qp import ConfigError, Mode
from wmm_qp.config import ShapeConfig
from wmm_qp.scene import obstacles_from_tables

from .config import ValidationConfig
from .protocol import (
    GRIPPER_ACTIONS,
    PROTOCOL_VERSION,
    BoxMsg,
    CommandMsg,
    GripperMsg,
    Header,
    ModeMsg,
    ObstaclesMsg,
    SetpointMsg,
    StateMsg,
    TelemetryMsg,
    TruthMsg,
)

BOX_MASS_MAX = 1000.0  # [kg]
BOX_MU_MAX = 5.0  # [-]
BOX_SIZE_MAX = 10.0  # [m] face width, height
PERIOD_MAX = 0.1  # [s] the longest control period a command may claim
GRIPPER_SIZE_MAX = 1.0  # [m] a gripper width, [m/s] its speed (the robot clamps to its own limits)
GRIPPER_FORCE_MAX = 1000.0  # [N] a grasp force (the robot clamps to its own limit)
_HEADER_FIELDS = ("type", "v", "robot", "seq", "stamp")
QUAT_ABS_MAX = 1e6
"""A quaternion's entries are bounded (normalised later: |q|² must not overflow)."""
_SIZED = (StateMsg, CommandMsg, TelemetryMsg)
"""Messages with joint or wheel vectors: their validator needs the robot's sizes."""


class Reject(enum.StrEnum):
    """Why a message was rejected."""

    DECODE = "decode"  # not msgpack
    SCHEMA = "schema"  # msgpack, but not the expected message type / fields / types
    VERSION = "version"  # another protocol version
    ROBOT = "robot"  # addressed to another robot
    SIZE = "size"  # a vector has the wrong number of entries, or the payload is too large
    NON_FINITE = "non_finite"  # NaN or inf
    RANGE = "range"  # a value out of its allowed range
    MODE = "mode"  # unknown mode name


class Rejected(Exception):
    """A message failed validation.

    Attributes:
        reason: the :class:`Reject` reason.
        detail: a human-readable explanation.
    """

    def __init__(self, reason: Reject, detail: str) -> None:
        self.reason = reason
        self.detail = detail
        super().__init__(f"{reason}: {detail}")


M = TypeVar("M", bound=msgspec.Struct)

_HEADER = msgspec.msgpack.Decoder(Header)


def _finite(name: str, values: Iterable[float]) -> None:
    for v in values:
        if not math.isfinite(v):
            raise Rejected(Reject.NON_FINITE, f"{name} holds {v}")


def _vector(name: str, values: list[float] | None, n: int, abs_max: float) -> None:
    if values is None:
        return
    _size(name, values, n)
    _finite(name, values)
    for v in values:
        if abs(v) > abs_max:
            raise Rejected(Reject.RANGE, f"|{name}| entry {v:g} exceeds {abs_max:g}")


def _size(name: str, values: list[float], n: int) -> None:
    if len(values) != n:
        raise Rejected(Reject.SIZE, f"{name} has {len(values)} entries, expected {n}")


def _norm(values: list[float]) -> float:
    return math.sqrt(sum(v * v for v in values))


class Validator(Generic[M]):
    """Decodes and checks one message type for one robot, counting rejections.

    Args:
        cls: the expected message type.
        robot: the robot id messages must carry.
        limits: the ranges to check.
        n_arm: the robot's number of joints (the length of every joint vector); required for
            the messages that carry joint or wheel vectors (state, cmd, telemetry).
        n_wheels: the robot's number of wheels (0 for a fixed base); required with ``n_arm``.

    Raises:
        ValueError: the sizes are missing for a message that needs them, or negative.
    """

    def __init__(self, cls: type[M], robot: str, limits: ValidationConfig,
                 n_arm: int | None = None, n_wheels: int | None = None) -> None:
        if issubclass(cls, _SIZED) and (n_arm is None or n_wheels is None):
            raise ValueError(f"a {cls.__name__} validator needs the robot's n_arm and n_wheels")
        if (n_arm is not None and n_arm < 0) or (n_wheels is not None and n_wheels < 0):
            raise ValueError(f"n_arm and n_wheels must be >= 0, got {n_arm}, {n_wheels}")
        self.cls = cls
        self.robot = robot
        self.limits = limits
        self.n_arm = -1 if n_arm is None else n_arm
        self.n_wheels = -1 if n_wheels is None else n_wheels
        self._decoder = msgspec.msgpack.Decoder(cls)
        self.rejected: Counter[str] = Counter()
        self.accepted = 0
        self.last_rejection = ""
        self.shapes: tuple[ShapeConfig, ...] = ()  # an obstacles validator: the last accepted set
        self._payload_max = limits.obstacles_payload_max_bytes if cls is ObstaclesMsg else limits.payload_max_bytes

    def __call__(self, data: bytes) -> M | None:
        """The checked message, or None (the reason is counted in :attr:`rejected`)."""
        try:
            msg = self.check(data)
        except Rejected as e:
            self.rejected[e.reason.value] += 1
            self.last_rejection = f"{self.cls.__name__}: {e}"
            return None
        self.accepted += 1
        return msg

    def checked(self, msg: M) -> M | None:
        """The same checks on a message that was never encoded (a robot side and a control core
        in one process hand messages over in memory): the version, the robot id, the stamp and
        the fields; the reason of a rejection is counted as :meth:`__call__` counts it.

        Returns:
            ``msg`` itself, or None (rejected).
        """
        try:
            if not isinstance(msg, self.cls):
                raise Rejected(Reject.SCHEMA, f"{type(msg).__name__}, expected {self.cls.__name__}")
            self._check_message(msg)
        except Rejected as e:
            self.rejected[e.reason.value] += 1
            self.last_rejection = f"{self.cls.__name__}: {e}"
            return None
        except Exception as e:  # a field of the wrong type: never out into the loop
            self.rejected[Reject.SCHEMA.value] += 1
            self.last_rejection = f"{self.cls.__name__}: {type(e).__name__}: {e}"
            return None
        self.accepted += 1
        return msg

    def check(self, data: bytes) -> M:
        """Decode and check ``data``.

        Raises:
            Rejected: with the reason.
        """
        if len(data) > self._payload_max:  # never spend time decoding a huge payload
            raise Rejected(Reject.SIZE, f"payload of {len(data)} bytes exceeds {self._payload_max}")
        try:
            h = _HEADER.decode(data)
        except msgspec.ValidationError as e:
            raise Rejected(Reject.SCHEMA, f"header: {e}") from None
        except msgspec.DecodeError as e:
            raise Rejected(Reject.DECODE, str(e)) from None
        except Exception as e:  # never let anything escape into the loop
            raise Rejected(Reject.DECODE, f"{type(e).__name__}: {e}") from None
        if h.v is not None and h.v != PROTOCOL_VERSION:  # another version may have other fields
            raise Rejected(Reject.VERSION, f"version {h.v}, expected {PROTOCOL_VERSION}")
        for name in _HEADER_FIELDS:  # the constructors' defaults must not stand in for the wire's
            if getattr(h, name) is None:
                raise Rejected(Reject.SCHEMA, f"missing required field `{name}`")
        try:
            msg = self._decoder.decode(data)
        except msgspec.ValidationError as e:
            raise Rejected(Reject.SCHEMA, str(e)) from None
        except msgspec.DecodeError as e:
            raise Rejected(Reject.DECODE, str(e)) from None
        except Exception as e:  # never let anything escape into the loop
            raise Rejected(Reject.DECODE, f"{type(e).__name__}: {e}") from None
        self._check_message(msg)
        return msg

    def _check_message(self, msg: msgspec.Struct) -> None:
        """The checks of a decoded (or never encoded) message: version, robot id, stamp, fields.

        Raises:
            Rejected: with the reason.
        """
        if msg.v != PROTOCOL_VERSION:  # type: ignore[attr-defined]
            raise Rejected(Reject.VERSION, f"version {msg.v}, expected {PROTOCOL_VERSION}")  # type: ignore[attr-defined]
        if msg.robot != self.robot:  # type: ignore[attr-defined]
            raise Rejected(Reject.ROBOT, f"robot {msg.robot!r}, expected {self.robot!r}")  # type: ignore[attr-defined]
        _finite("stamp", [msg.stamp])  # type: ignore[attr-defined]
        self._check_fields(msg)

    def _check_fields(self, msg: msgspec.Struct) -> None:
        lim = self.limits
        if isinstance(msg, SetpointMsg):
            if not msg.source:
                raise Rejected(Reject.SCHEMA, "source is empty")
            _vector("x", msg.x, 3, math.inf)
            _vector("xd", msg.xd, 3, math.inf)
            if max(abs(msg.x[0]), abs(msg.x[1])) > lim.position_abs_max:
                raise Rejected(Reject.RANGE, f"x, y beyond ±{lim.position_abs_max:g} m")
            if not lim.z_min <= msg.x[2] <= lim.z_max:
                raise Rejected(Reject.RANGE, f"z = {msg.x[2]:g} m outside [{lim.z_min:g}, {lim.z_max:g}]")
            if msg.xd is not None and _norm(msg.xd) > lim.speed_max:
                raise Rejected(Reject.RANGE, f"|xd| beyond {lim.speed_max:g} m/s")
            _vector("q", msg.q, 4, QUAT_ABS_MAX)
            if msg.q is not None and _norm(msg.q) <= 1e-9:
                raise Rejected(Reject.RANGE, "q is not a rotation (norm <= 1e-9)")
            _vector("w", msg.w, 3, math.inf)
            if msg.w is not None and _norm(msg.w) > lim.angular_speed_max:
                raise Rejected(Reject.RANGE, f"|w| beyond {lim.angular_speed_max:g} rad/s")
        elif isinstance(msg, ModeMsg):
            if msg.mode not in Mode._value2member_map_:
                raise Rejected(Reject.MODE, f"unknown mode {msg.mode!r}")
            _vector("direction", msg.direction, 3, 1e6)  # normalised later: |u|² must not overflow
            if msg.direction is not None and _norm(msg.direction) < 1e-9:
                raise Rejected(Reject.RANGE, "direction is zero")
        elif isinstance(msg, StateMsg):
            if not msg.instance:
                raise Rejected(Reject.SCHEMA, "instance is empty")
            m = lim.state_abs_max
            na, nw = self.n_arm, self.n_wheels
            _finite("t", [msg.t])
            for name, n in (("q_base", 3), ("q_arm", na), ("v_arm", na), ("wheel_speeds", nw)):
                _vector(name, getattr(msg, name), n, m)
            _size("tau", msg.tau, na)
        elif isinstance(msg, TruthMsg):
            for name in ("base_true", "ee_true", "contact_force"):
                _size(name, getattr(msg, name), 3)
        elif isinstance(msg, GripperMsg):
            if msg.action not in GRIPPER_ACTIONS:
                raise Rejected(Reject.RANGE, f"gripper action {msg.action!r}: not one of {', '.join(GRIPPER_ACTIONS)}")
            if not msg.source:
                raise Rejected(Reject.SCHEMA, "source is empty")
            _finite("gripper", [msg.width, msg.speed, msg.force])
            for name, v, ok in (("width", msg.width, 0.0 <= msg.width <= GRIPPER_SIZE_MAX),
                                ("speed", msg.speed, 0.0 < msg.speed <= GRIPPER_SIZE_MAX),
                                ("force", msg.force, 0.0 <= msg.force <= GRIPPER_FORCE_MAX)):
                if not ok:
                    raise Rejected(Reject.RANGE, f"gripper {name} = {v:g} outside its range")
        elif isinstance(msg, BoxMsg):
            _finite("box", [msg.mass, msg.mu, msg.face_x, msg.center_y, msg.width, msg.height])
            for name, v, ok in (("mass", msg.mass, 0.0 < msg.mass <= BOX_MASS_MAX),
                                ("mu", msg.mu, 0.0 <= msg.mu <= BOX_MU_MAX),
                                ("width", msg.width, 0.0 < msg.width <= BOX_SIZE_MAX),
                                ("height", msg.height, 0.0 < msg.height <= BOX_SIZE_MAX)):
                if not ok:
                    raise Rejected(Reject.RANGE, f"box {name} = {v:g} outside its range")
            if max(abs(msg.face_x), abs(msg.center_y)) > lim.position_abs_max:
                raise Rejected(Reject.RANGE, f"box face x, y beyond ±{lim.position_abs_max:g} m")
        elif isinstance(msg, ObstaclesMsg):
            self.shapes = _obstacles(msg, lim)
        elif isinstance(msg, CommandMsg):
            if not (msg.lease and msg.instance):
                raise Rejected(Reject.SCHEMA, "lease or instance is empty")
            _finite("period", [msg.period])
            if not 0.0 < msg.period <= PERIOD_MAX:
                raise Rejected(Reject.RANGE, f"period {msg.period:g} s outside (0, {PERIOD_MAX:g}]")
            _vector("wheel_speeds", msg.wheel_speeds, self.n_wheels, lim.command_abs_max)
            _vector("arm_rates", msg.arm_rates, self.n_arm, lim.command_abs_max)
        elif isinstance(msg, TelemetryMsg):  # for clients: the daemon's view of one tick
            _finite("t", [msg.t])
            if msg.mode not in Mode._value2member_map_:
                raise Rejected(Reject.MODE, f"unknown mode {msg.mode!r}")
            _vector("wheel_speeds", msg.wheel_speeds, self.n_wheels, lim.command_abs_max)
            _vector("arm_rates", msg.arm_rates, self.n_arm, lim.command_abs_max)
            for name in ("x", "x_d", "xd_d", "ee_true"):  # nan: no target (x_d), no state (ee_true)
                _size(name, getattr(msg, name), 3)


def _obstacles(msg: ObstaclesMsg, lim: ValidationConfig) -> tuple[ShapeConfig, ...]:
    """The message's obstacles as primitives (see the module docstring), or :class:`Rejected`."""
    if not msg.source:
        raise Rejected(Reject.SCHEMA, "source is empty")
    if len(msg.obstacles) > lim.obstacles_max:
        raise Rejected(Reject.SIZE, f"{len(msg.obstacles)} obstacles, at most {lim.obstacles_max}")
    try:
        shapes = obstacles_from_tables("<obstacles message>", msg.obstacles)
    except ConfigError as e:
        raise Rejected(Reject.RANGE, str(e)) from None
    except Exception as e:  # a table of unexpected types: never let anything escape into the loop
        raise Rejected(Reject.SCHEMA, f"{type(e).__name__}: {e}") from None
    for o in shapes:
        if o.kind == "plane":
            if abs(o.xyz[2]) > lim.position_abs_max:
                raise Rejected(Reject.RANGE, f"obstacle {o.name!r}: |offset| beyond {lim.position_abs_max:g} m")
            continue
        if float(np.max(np.abs(o.xyz))) > lim.position_abs_max:
            raise Rejected(Reject.RANGE, f"obstacle {o.name!r}: xyz beyond ±{lim.position_abs_max:g} m")
        if float(np.max(o.size)) > lim.obstacle_size_max:
            raise Rejected(Reject.RANGE, f"obstacle {o.name!r}: size beyond {lim.obstacle_size_max:g} m")
    return shapes
