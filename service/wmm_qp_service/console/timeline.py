"""A recording as the console plays it: each channel it draws as samples over time.

:func:`load_timeline` reads a recording (``wmm-qp serve --record``, ``sim --embedded --record``, or a
client's ``wmm-qp record``; a rotated one as one) and keeps, per channel, its samples in time order
[s since the recording's earliest message, as ``wmm-qp plot``'s axis]: the measured states
(``/arm/joint_states``, ``/base/wheel_states``, ``/odom``), the EE (``/ee/pose``: forward
kinematics of the measured state) and its target (``/ee/target``), the statuses (``/wmm/status``),
the modes (``/wmm/mode``) and DM (``/wmm/telemetry``). Those channels are common to the host's and
the client's recordings; nothing here depends on the robot (its sizes come from the messages).
A recording cut short or damaged is read up to where reading stopped (:attr:`Timeline.error`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import msgspec
import numpy as np

from ..protocol import LoopStats, StatusMsg
from ..recording import RecordingError

CDR_TYPES = {"/arm/joint_states": "sensor_msgs/msg/JointState", "/base/wheel_states": "sensor_msgs/msg/JointState",
             "/odom": "nav_msgs/msg/Odometry", "/ee/pose": "geometry_msgs/msg/PoseStamped",
             "/ee/target": "geometry_msgs/msg/PoseStamped"}
JSON_TOPICS = {"/wmm/status", "/wmm/mode", "/wmm/telemetry"}
_STATUS_FIELDS = {f.encode_name for f in msgspec.structs.fields(StatusMsg)} | {"type"}
_LOOP_FIELDS = {f.encode_name for f in msgspec.structs.fields(LoopStats)}


@dataclass
class Channel:
    """One channel's samples: ``t`` [s] ascending, ``v`` the value of each (an array's rows or a list)."""

    t: np.ndarray
    v: Any

    def index(self, tau: float) -> int:
        """The last sample at or before ``tau`` [s]; -1: none yet."""
        return int(np.searchsorted(self.t, tau, side="right")) - 1

    def at(self, tau: float) -> Any:
        """The value recorded last at or before ``tau`` (None: none yet)."""
        i = self.index(tau)
        return None if i < 0 else self.v[i]

    def __len__(self) -> int:
        return len(self.t)


def _channel(rows: list[tuple[int, Any]], t0_ns: int, array: bool = True) -> Channel:
    rows.sort(key=lambda r: r[0])  # stable: a channel's order where two samples share a stamp
    t = np.array([(r[0] - t0_ns) * 1e-9 for r in rows], dtype=float)
    if array:
        width = max((len(r[1]) for r in rows), default=0)
        v: Any = np.full((len(rows), width), math.nan)
        for i, r in enumerate(rows):
            if len(r[1]) == width:  # a message of another size (a damaged one): nan
                v[i] = r[1]
    else:
        v = [r[1] for r in rows]
    return Channel(t, v)


@dataclass
class Timeline:
    """A recording's channels over time.

    Attributes:
        meta: the ``wmm_qp`` metadata of its first file.
        files: the files read.
        error: why reading stopped before the recording's end, one line (None: read to its end).
        t0: [s] wall clock of its earliest message (every ``t`` counts from it).
        duration: [s] from its earliest message to its latest.
        q_arm, v_arm: measured joint positions and rates; ``wheels``: measured wheel speeds;
        q_base: [m, m, rad] the base's pose (odometry); ``ee``: [m] the EE (forward kinematics of
            the measured state); ``target``: [m] x_d, and ``quat_d`` its [x, y, z, w];
        statuses: the statuses as recorded (dicts; :meth:`status` turns one into a
            :class:`StatusMsg`); ``modes``: each mode from its change on; ``dm``: DM per tick.
    """

    meta: dict[str, str]
    files: list[str]
    error: str | None
    t0: float
    duration: float
    q_arm: Channel
    v_arm: Channel
    wheels: Channel
    q_base: Channel
    ee: Channel
    target: Channel
    quat_d: Channel
    statuses: Channel
    modes: Channel
    dm: Channel
    _status_cache: dict[int, StatusMsg | None] = field(default_factory=dict)

    @property
    def states(self) -> int:
        """Measured states recorded."""
        return len(self.q_arm)

    def status(self, tau: float) -> StatusMsg | None:
        """The status published last at or before ``tau`` (None: none yet, or one that does not decode)."""
        i = self.statuses.index(tau)
        if i < 0:
            return None
        if i not in self._status_cache:
            self._status_cache[i] = status_from_dict(self.statuses.v[i])
        return self._status_cache[i]

    def tracking_error(self) -> Channel:
        """[m] ‖EE − target‖ at each EE sample, the target the last one at or before it (nan before any)."""
        j = np.searchsorted(self.target.t, self.ee.t, side="right") - 1
        err = np.full(len(self.ee), math.nan)
        ok = j >= 0
        if ok.any() and self.target.v.shape[1] == 3 and self.ee.v.shape[1] == 3:
            err[ok] = np.linalg.norm(self.ee.v[ok] - self.target.v[j[ok]], axis=1)
        return Channel(self.ee.t, err)


def status_from_dict(d: Any) -> StatusMsg | None:
    """A recorded status (``msgspec.to_builtins`` of a :class:`StatusMsg`, NaN as null) as the
    message again; fields this version does not know are left out (None: not a status)."""
    if not isinstance(d, dict):
        return None
    clean = {k: v for k, v in d.items() if k in _STATUS_FIELDS and v is not None}
    if isinstance(clean.get("loop"), dict):
        clean["loop"] = {k: v for k, v in clean["loop"].items() if k in _LOOP_FIELDS and v is not None}
    try:
        return msgspec.convert(clean, StatusMsg, strict=False)
    except msgspec.ValidationError:
        return None


def _num(v: Any) -> float:
    return math.nan if v is None else float(v)


def load_timeline(path: str | Path) -> Timeline:
    """The channels the console draws, of the recording at ``path`` and the rotated files that follow it.

    Raises:
        RecordingUnavailable: the ``record`` extra is not installed.
        RecordingError: no such file, not a wmm-qp recording, or no measured state in it.
    """
    from rosbags.typesys import Stores, get_typestore

    from ..recording.reader import RecordingReader, chain

    ts = get_typestore(Stores.ROS2_HUMBLE)
    rows: dict[str, list[tuple[int, Any]]] = {k: [] for k in (*CDR_TYPES, *JSON_TOPICS, "v_arm", "wheels",
                                                                 "quat_d")}
    meta: dict[str, str] = {}
    files: list[str] = []
    error = None
    first, last = 2**63, -1  # [ns] the earliest and latest log time (the channels interleave in the file)
    rid = None
    for f in chain(path):
        rd = RecordingReader(f)
        for topic, t, data in rd.messages(set(CDR_TYPES) | JSON_TOPICS):
            first, last = min(first, t), max(last, t)
            m: Any = ts.deserialize_cdr(data, CDR_TYPES[topic]) if topic in CDR_TYPES else msgspec.json.decode(data)
            if topic == "/arm/joint_states":
                rows[topic].append((t, m.position))
                rows["v_arm"].append((t, m.velocity))
            elif topic == "/base/wheel_states":
                rows["wheels"].append((t, m.velocity))
            elif topic == "/odom":
                p, q = m.pose.pose.position, m.pose.pose.orientation
                rows[topic].append((t, (p.x, p.y, 2.0 * math.atan2(q.z, q.w))))
            elif topic in ("/ee/pose", "/ee/target"):
                p, q = m.pose.position, m.pose.orientation
                rows[topic].append((t, (p.x, p.y, p.z)))
                if topic == "/ee/target":
                    rows["quat_d"].append((t, (q.x, q.y, q.z, q.w)))
            elif topic == "/wmm/status":
                rows[topic].append((t, m.get("status")))
            elif topic == "/wmm/mode":
                rows[topic].append((t, str(m.get("mode", ""))))
            elif topic == "/wmm/telemetry":
                rows[topic].append((t, (_num(m.get("dm")),)))
        if rid is not None and rd.meta.get("recording_id") != rid:
            break  # a file of another recording that happens to share the name
        files.append(str(f))
        if not meta:
            meta, rid = rd.meta, rd.meta.get("recording_id")
        if rd.error is not None:
            error = rd.error
            break
    if not meta:
        raise RecordingError(error or f"{path}: not a wmm-qp recording (no wmm_qp metadata)")
    if not rows["/arm/joint_states"] or not rows["/odom"]:
        raise RecordingError(f"{path}: no robot states recorded (no /arm/joint_states and /odom messages)"
                             + (f"; {error}" if error else ""))
    ch = {k: _channel(v, first, array=k not in ("/wmm/status", "/wmm/mode")) for k, v in rows.items()}
    return Timeline(meta=meta, files=files, error=error, t0=first * 1e-9, duration=(last - first) * 1e-9,
                    q_arm=ch["/arm/joint_states"], v_arm=ch["v_arm"], wheels=ch["wheels"], q_base=ch["/odom"],
                    ee=ch["/ee/pose"], target=ch["/ee/target"], quat_d=ch["quat_d"], statuses=ch["/wmm/status"],
                    modes=ch["/wmm/mode"], dm=ch["/wmm/telemetry"])
