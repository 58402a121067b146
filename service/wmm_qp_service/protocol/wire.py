"""The wire: the envelope every message shares (its header fields and protocol version) and
the msgpack codec."""

from __future__ import annotations

from typing import TypeVar

import msgspec

PROTOCOL_VERSION = 4
"""Bumped on any incompatible change of a schema (:mod:`.robot`, :mod:`.service`; 2: the sim
instance, the control lease, the setpoint's source and the command's period and state seq are
required fields; 3: the state holds only what a real robot reports, the sim's evaluation data
moved to :class:`~.robot.TruthMsg`; 4: "robot", not "sim", where any robot is meant — the
liveliness token ``alive/robot``, the status's ``robot_alive``, ``robot_instance`` and
``robot_violations``, the faults keyed by code with ``last_fault_code``, the state's
``protective_code``; the sim's evaluation data stays on ``sim/truth``). Optional fields with a
default may be added within a
version (2 gained the setpoint's ``q`` and ``w``, the status's ``quat_d``,
``orientation_ignored``, ``fault_active``, ``last_fault_age`` and ``orientation_error``, and the
info reply's robot description)."""


class Msg(msgspec.Struct, kw_only=True, forbid_unknown_fields=True, tag_field="type"):
    """The base of every message: its tag (``type``), the protocol version and the header fields."""

    v: int = PROTOCOL_VERSION
    robot: str
    seq: int = 0
    stamp: float = 0.0


class Header(msgspec.Struct, forbid_unknown_fields=False):
    """The fields every message has (checked for presence on receipt, and used to explain a
    rejected message)."""

    type: str | None = None
    v: int | None = None
    robot: str | None = None
    seq: int | None = None
    stamp: float | None = None


_ENC = msgspec.msgpack.Encoder()

T = TypeVar("T", bound=msgspec.Struct)


def encode(msg: msgspec.Struct) -> bytes:
    """msgpack bytes of a message."""
    return _ENC.encode(msg)


def decoder(cls: type[T]) -> msgspec.msgpack.Decoder[T]:
    """A reusable strict decoder for one message type."""
    return msgspec.msgpack.Decoder(cls)


def decode(cls: type[T], data: bytes) -> T:
    """Decode one message of a known type (raises :class:`msgspec.DecodeError`)."""
    return msgspec.msgpack.decode(data, type=cls)
