"""CDR (XCDR1, little endian: the ``cdr`` encoding of ROS 2) of the few message types a recording writes.

Built on one buffer per message: several times cheaper than building ``rosbags``' message objects
and serialising them, which cost a 1 kHz recording's writer more than its share of a core.
The bytes are the same as ``rosbags``' ``serialize_cdr`` of the same message
(tests/service/test_recording_cdr.py compares them type by type); readers decode them with the
``ros2msg`` schemas the file carries.

Alignment: each primitive at a multiple of its size, counted from the end of the 4-byte
encapsulation header; strings as uint32 length (with the NUL) + bytes + NUL; sequences as uint32
count + elements.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence

import numpy as np

ENCAPSULATION = b"\x00\x01\x00\x00"  # CDR_LE


class CdrWriter:
    """One message's bytes, appended field by field."""

    __slots__ = ("buf",)

    def __init__(self) -> None:
        self.buf = bytearray(ENCAPSULATION)

    def _align(self, n: int) -> None:
        pad = (-(len(self.buf) - 4)) % n
        if pad:
            self.buf += b"\x00" * pad

    def u32(self, v: int) -> None:
        self._align(4)
        self.buf += struct.pack("<I", v)

    def time(self, ns: int) -> None:
        self._align(4)
        self.buf += struct.pack("<iI", ns // 1_000_000_000, ns % 1_000_000_000)

    def string(self, s: bytes) -> None:
        self.u32(len(s) + 1)
        self.buf += s + b"\x00"

    def strings(self, items: Sequence[bytes]) -> None:
        self.u32(len(items))
        for s in items:
            self.string(s)

    def f64s(self, values: Sequence[float] | np.ndarray) -> None:
        """Fixed-size float64 fields (a Point, a Quaternion, an array of 36)."""
        self._align(8)
        self.buf += np.ascontiguousarray(values, dtype="<f8").tobytes()

    def f64_seq(self, values: np.ndarray) -> None:
        """A float64[] sequence."""
        self.u32(len(values))
        if len(values):
            self.f64s(values)

    def header(self, ns: int, frame: bytes) -> None:
        """std_msgs/msg/Header."""
        self.time(ns)
        self.string(frame)

    def bytes(self) -> bytes:
        return bytes(self.buf)


ZERO36 = np.zeros(36)


def joint_state(ns: int, names: Sequence[bytes], position: np.ndarray | None, velocity: np.ndarray) -> bytes:
    """sensor_msgs/msg/JointState (no effort; no position: an empty sequence)."""
    w = CdrWriter()
    w.header(ns, b"")
    w.strings(names)
    w.f64_seq(np.empty(0) if position is None else position)
    w.f64_seq(velocity)
    w.u32(0)  # effort
    return w.bytes()


def pose_stamped(ns: int, frame: bytes, p: np.ndarray, q: np.ndarray) -> bytes:
    """geometry_msgs/msg/PoseStamped: position p, orientation q = [x, y, z, w]."""
    w = CdrWriter()
    w.header(ns, frame)
    w.f64s(np.concatenate([p, q]))
    return w.bytes()


def odometry(ns: int, frame: bytes, child: bytes, p: np.ndarray, q: np.ndarray, linear: np.ndarray,
             angular: np.ndarray) -> bytes:
    """nav_msgs/msg/Odometry with zero covariances."""
    w = CdrWriter()
    w.header(ns, frame)
    w.string(child)
    w.f64s(np.concatenate([p, q, ZERO36, linear, angular, ZERO36]))
    return w.bytes()


def tf_message(ns: int, transforms: Sequence[tuple[bytes, bytes, np.ndarray, np.ndarray]]) -> bytes:
    """tf2_msgs/msg/TFMessage: (parent frame, child frame, translation, rotation [x, y, z, w]) each."""
    w = CdrWriter()
    w.u32(len(transforms))
    for parent, child, t, q in transforms:
        w.header(ns, parent)
        w.string(child)
        w.f64s(np.concatenate([t, q]))
    return w.bytes()
