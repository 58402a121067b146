"""The recording's writer process: the journal's rings → MCAP with the ``ros2`` profile.

Channels (docs/recording.md lists each with its fields and counts):

* ROS 2 types, CDR (``rosbags``' type store, ROS 2 Humble definitions; the schema of each, as
  ``ros2msg``, is in the file): ``/arm/joint_states`` and ``/base/wheel_states``
  (``sensor_msgs/msg/JointState``, measured), ``/arm/joint_commands`` and ``/base/wheel_commands``
  (the same type, the rates commanded), ``/ee/pose`` and ``/ee/target``
  (``geometry_msgs/msg/PoseStamped``), ``/tf`` (``tf2_msgs/msg/TFMessage``: world → base, base →
  each arm link; every :data:`TF_EVERY`-th state), ``/odom`` (``nav_msgs/msg/Odometry``);
* wmm-qp's own, JSON with a JSON schema: ``/wmm/tick`` (the controller's inputs and command, what
  the replay reads), ``/wmm/telemetry`` (timings, DM, σ_min, task error), ``/wmm/mode`` (each mode
  change), ``/wmm/status`` (each status published), ``/wmm/events`` (command reasons, live
  obstacle sets, notes about the recording itself).

The metadata record ``wmm_qp`` (written first, so a truncated file keeps it) holds what the replay
needs to rebuild the controller; ``wmm_qp_end`` (written last) the tick count and the rows lost.
"""

from __future__ import annotations

import contextlib
import math
import os
import time
from multiprocessing import shared_memory
from pathlib import Path
from typing import Any

import msgspec
import numpy as np

from . import cdr
from .layout import MODES, SCALARS, STATUSES, Layout
from .reader import split_name

CHUNK_BYTES = 256 * 1024
"""MCAP chunk size (uncompressed): a writer that dies loses at most the chunk it was filling (the demo
of docs/recording.md: 82 ticks a chunk, 0.08 s at 1 kHz)."""
POLL_S = 0.01
TF_EVERY = 10
"""``/tf`` goes out with every 10th measured state (100 Hz at 1 kHz): the arm's links cost the writer
about as much as every other channel together (a 1 kHz recording must not outrun its writer)."""

ROS_TOPICS = {
    "/arm/joint_states": "sensor_msgs/msg/JointState",
    "/base/wheel_states": "sensor_msgs/msg/JointState",
    "/arm/joint_commands": "sensor_msgs/msg/JointState",
    "/base/wheel_commands": "sensor_msgs/msg/JointState",
    "/ee/pose": "geometry_msgs/msg/PoseStamped",
    "/ee/target": "geometry_msgs/msg/PoseStamped",
    "/tf": "tf2_msgs/msg/TFMessage",
    "/odom": "nav_msgs/msg/Odometry",
}

_NUM = {"type": ["number", "null"]}
_VEC = {"type": "array", "items": _NUM}
JSON_TOPICS: dict[str, dict[str, Any]] = {
    "/wmm/tick": {"tick": {"type": "integer"}, "seq": {"type": "integer"}, "call": {"type": "string"},
                  "latches": {"type": "integer"}, "latency": _NUM, "mode": {"type": "string"},
                  "q_base": _VEC, "q_arm": _VEC, "v_arm": _VEC, "wheel_speeds": _VEC, "x_d": _VEC, "xd_d": _VEC,
                  "direction": _VEC, "quat_d": _VEC, "omega_d": _VEC, "cmd_wheel_speeds": _VEC,
                  "cmd_arm_rates": _VEC, "status": {"type": ["string", "null"]}},
    "/wmm/telemetry": {"tick": {"type": "integer"}, "t": _NUM, "tick_us": _NUM, "step_us": _NUM,
                       "mode": {"type": "string"}, "status": {"type": ["string", "null"]}, "dm": _NUM,
                       "sigma_min": _NUM, "task_error": _NUM, "alpha": _NUM, "ee_error": _NUM, "x": _VEC,
                       "seq": {"type": "integer"}, "state_seq": {"type": "integer"}},
    "/wmm/mode": {"tick": {"type": "integer"}, "mode": {"type": "string"}, "previous": {"type": ["string", "null"]}},
    "/wmm/status": {"tick": {"type": "integer"}, "status": {"type": "object"}},
    "/wmm/events": {"tick": {"type": "integer"}, "kind": {"type": "string"}, "data": {"type": "object"}},
}
CALLS = ("none", "step", "safe_stop", "repeat")
EVENT_KINDS = {1: "status", 2: "reason", 3: "obstacles", 4: "note"}


def _attach(name: str) -> shared_memory.SharedMemory:
    shm = shared_memory.SharedMemory(name=name)
    return shm


class McapSink:
    """One recording's MCAP files (rotated by size or time) and the serialisation of a tick into
    its channels."""

    def __init__(self, path: Path, meta: dict[str, str], layout: Layout,
                 split_size: float | None, split_time: float | None,
                 extra_json: dict[str, dict[str, Any]] | None = None) -> None:
        from rosbags.typesys import Stores, get_typestore

        import wmm_qp as w

        self.path, self.meta, self.layout = path, meta, layout
        self.json_topics = {**JSON_TOPICS, **(extra_json or {})}
        self.split_bytes = None if split_size is None else int(split_size * 1e6)
        self.split_time = split_time
        self.ts = get_typestore(Stores.ROS2_HUMBLE)
        self.joint_names = [str(n).encode() for n in msgspec.json.decode(meta["arm_joints"])]
        self.wheel_names = [str(n).encode() for n in msgspec.json.decode(meta["wheels"])]
        self.model: Any = None
        if meta.get("robot_file"):
            with contextlib.suppress(Exception):  # without the model: no /ee/pose, /tf links (said in a note)
                self.model = w.WmmModel(w.load_robot_config(meta["robot_file"]))
        self.frames: list[tuple[int, bytes]] = []
        if self.model is not None:
            import pinocchio as pin

            am = self.model.arm.model
            self.frames = [(i, f.name.encode()) for i, f in enumerate(am.frames) if f.type == pin.FrameType.BODY]
        self.files: list[str] = []
        self.k = 0
        self.writer: Any = None
        self.stream: Any = None
        self.ch: dict[str, int] = {}
        self.opened_at = math.nan
        self.ticks = 0
        self.mode: str | None = None
        self.counts: dict[str, int] = {}
        self.states = 0

    # ------------------------------------------------------------------ files
    def open(self, first_tick: int) -> None:
        from mcap.writer import CompressionType, Writer

        p = split_name(self.path, self.k)
        self.stream = open(p, "wb")  # noqa: SIM115 (closed in close_file)
        self.writer = wr = Writer(self.stream, chunk_size=CHUNK_BYTES, compression=CompressionType.ZSTD)
        wr.start(profile="ros2", library="wmm-qp")
        wr.add_metadata("wmm_qp", {**self.meta, "file_index": str(self.k), "first_tick": str(first_tick)})
        self.ch = {}
        for topic, typename in ROS_TOPICS.items():
            text, _ = self.ts.generate_msgdef(typename, ros_version=2)
            sid = wr.register_schema(typename, "ros2msg", text.encode())
            self.ch[topic] = wr.register_channel(topic, "cdr", sid)
        for topic, props in self.json_topics.items():
            schema = {"type": "object", "title": topic, "properties": props}
            sid = wr.register_schema(f"wmm_qp{topic.replace('/', '.')}", "jsonschema", msgspec.json.encode(schema))
            self.ch[topic] = wr.register_channel(topic, "json", sid)
        self.files.append(str(p))
        self.opened_at = time.monotonic()
        self.mode = None  # each file says its mode at its first tick: it stands alone
        self.stream.flush()

    def close_file(self, end: dict[str, str]) -> None:
        if self.writer is None:
            return
        self.writer.add_metadata("wmm_qp_end", end)
        self.writer.finish()
        self.stream.close()
        self.writer = None

    def maybe_rotate(self, next_tick: int) -> None:
        if self.writer is None:
            return
        big = self.split_bytes is not None and self.stream.tell() >= self.split_bytes
        old = self.split_time is not None and time.monotonic() - self.opened_at >= self.split_time
        if big or old:
            self.close_file({"ticks": str(self.ticks), "next_file": split_name(self.path, self.k + 1).name})
            self.k += 1
            self.open(next_tick)

    # ------------------------------------------------------------------ messages
    def _put(self, topic: str, ns: int, data: bytes) -> None:
        self.writer.add_message(self.ch[topic], log_time=ns, data=data, publish_time=ns)
        self.counts[topic] = self.counts.get(topic, 0) + 1

    def json(self, topic: str, ns: int, obj: dict[str, Any]) -> None:
        """A message of a JSON channel."""
        self._put(topic, ns, msgspec.json.encode(obj))

    def tick(self, row: np.ndarray) -> None:
        """Every channel's messages of one tick's row."""
        lay = self.layout
        sl = lay.slices
        sc = {k: float(row[i]) for k, i in lay.index.items()}
        ns = int(sc["t_wall"] * 1e9)
        tick = int(sc["tick"])
        call = int(sc["call"])
        mode = MODES[int(sc["mode"])].value
        status = None if math.isnan(sc["status"]) else STATUSES[int(sc["status"])].value
        self.ticks += 1
        if mode != self.mode:
            self.json("/wmm/mode", ns, {"tick": tick, "mode": mode, "previous": self.mode})
            self.mode = mode
        self.json("/wmm/tick", ns, {
            "tick": tick, "seq": int(sc["seq"]), "call": CALLS[call], "latches": int(sc["latches"]),
            "latency": sc["latency"], "mode": mode, "q_base": row[sl["ctl_q_base"]].tolist(),
            "q_arm": row[sl["ctl_q_arm"]].tolist(), "v_arm": row[sl["ctl_v_arm"]].tolist(),
            "wheel_speeds": row[sl["ctl_wheels"]].tolist(), "x_d": row[sl["x_d"]].tolist(),
            "xd_d": row[sl["xd_d"]].tolist(), "direction": row[sl["direction"]].tolist(),
            "quat_d": row[sl["quat_d"]].tolist(), "omega_d": row[sl["omega_d"]].tolist(),
            "cmd_wheel_speeds": row[sl["cmd_wheels"]].tolist(), "cmd_arm_rates": row[sl["cmd_arm"]].tolist(),
            "status": status})
        self.json("/wmm/telemetry", ns, {
            "tick": tick, "t": sc["t"], "tick_us": sc["tick_us"], "step_us": sc["step_us"], "mode": mode,
            "status": status, "dm": sc["dm"], "sigma_min": sc["sigma_min"], "task_error": sc["task_error"],
            "alpha": sc["alpha"], "ee_error": sc["ee_error"], "x": row[sl["cmd_x"]].tolist(),
            "seq": int(sc["seq"]), "state_seq": int(sc["state_seq"])})
        q_base = row[sl["meas_q_base"]]
        if not math.isnan(q_base[0]):  # a state was measured
            self.measured(ns, q_base, row[sl["meas_q_arm"]], row[sl["meas_v_arm"]], row[sl["meas_wheels"]])
        if sc["seq"] >= 0:  # a command went out
            self.commanded(ns, row[sl["cmd_arm"]], row[sl["cmd_wheels"]])
        x_d = row[sl["x_d"]]
        if call == 1 and not math.isnan(x_d[0]):
            self.target(ns, x_d, row[sl["quat_d"]])

    def measured(self, ns: int, q_base: np.ndarray, q_arm: np.ndarray, v_arm: np.ndarray,
                 wheels: np.ndarray) -> None:
        """A measured state: ``/arm/joint_states``, ``/base/wheel_states``, ``/odom``, ``/ee/pose``; and
        every :data:`TF_EVERY`-th one ``/tf`` (world → base, base → each link of the arm)."""
        self._put("/arm/joint_states", ns, cdr.joint_state(ns, self.joint_names, q_arm, v_arm))
        self._put("/base/wheel_states", ns, cdr.joint_state(ns, self.wheel_names, None, wheels))
        p_base = np.array([q_base[0], q_base[1], 0.0])
        q_yaw = np.array([0.0, 0.0, math.sin(0.5 * q_base[2]), math.cos(0.5 * q_base[2])])
        twist = self.model.base.body_twist(wheels) if self.model is not None else np.full(3, math.nan)
        self._put("/odom", ns, cdr.odometry(ns, b"world", b"base", p_base, q_yaw, np.array([twist[0], twist[1], 0.0]),
                                            np.array([0.0, 0.0, twist[2]])))
        if self.model is not None:
            x, R = self.model.ee_pose(q_base, q_arm)  # FK of the arm (Pinocchio's data now holds it)
            self._put("/ee/pose", ns, cdr.pose_stamped(ns, b"world", x, _rot_quat(R)))
        self.states += 1
        if (self.states - 1) % TF_EVERY:
            return
        tfs = [(b"world", b"base", p_base, q_yaw)]
        if self.model is not None:
            import pinocchio as pin

            am = self.model.arm
            pin.updateFramePlacements(am.model, am.data)
            for i, name in self.frames:
                M = am.data.oMf[i]
                tfs.append((b"base", name, M.translation, _rot_quat(M.rotation)))
        self._put("/tf", ns, cdr.tf_message(ns, tfs))

    def commanded(self, ns: int, arm: np.ndarray, wheels: np.ndarray) -> None:
        """A command sent: ``/arm/joint_commands``, ``/base/wheel_commands`` (velocity: the rates)."""
        self._put("/arm/joint_commands", ns, cdr.joint_state(ns, self.joint_names, None, arm))
        self._put("/base/wheel_commands", ns, cdr.joint_state(ns, self.wheel_names, None, wheels))

    def target(self, ns: int, x_d: np.ndarray, quat_d: np.ndarray) -> None:
        """The EE's target: ``/ee/target`` (orientation: the pose task's, else the identity)."""
        q = quat_d if not math.isnan(quat_d[0]) else np.array([0.0, 0.0, 0.0, 1.0])
        self._put("/ee/target", ns, cdr.pose_stamped(ns, b"world", x_d, q))

    def event(self, kind: int, tick: int, data: dict[str, Any], ns: int | None = None) -> None:
        """An event of the host's at ``ns`` [ns, wall clock] (None: now)."""
        ns = time.time_ns() if ns is None else ns
        if kind == 1:
            self.json("/wmm/status", ns, {"tick": tick, "status": data})
        else:
            self.json("/wmm/events", ns, {"tick": tick, "kind": EVENT_KINDS.get(kind, "note"), "data": data})


def _rot_quat(R: np.ndarray) -> np.ndarray:
    from wmm_qp.tasks import rotation_to_quat

    return np.asarray(rotation_to_quat(R), dtype=float)


def writer_main(ticks_name: str, events_name: str, rows: int, n_arm: int, n_wheels: int, path: str,
                meta: dict[str, str], split_size: float | None, split_time: float | None, replies: Any) -> None:
    """The writer process's body (started by :class:`~.journal.TickJournal`)."""
    import signal

    from .journal import EVENT_BYTES, EVENT_SLOTS, HEADER

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # a Ctrl-C reaches the host, which closes the recording
    with contextlib.suppress(Exception):  # never the host's real-time priority, whatever it inherited
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    try:
        layout = Layout(n_arm, n_wheels)
        shm_t, shm_e = _attach(ticks_name), _attach(events_name)
        buf = np.ndarray((HEADER + rows * layout.width,), dtype=np.float64, buffer=shm_t.buf)
        header = buf[:HEADER].view(np.int64)
        ring = buf[HEADER:].reshape(rows, layout.width)
        events = np.ndarray((EVENT_SLOTS, EVENT_BYTES), dtype=np.uint8, buffer=shm_e.buf)
        host = int(header[3])
        sink = McapSink(Path(path), meta, layout, split_size, split_time)
        sink.open(0)
    except Exception as e:
        replies.put({"error": f"cannot record to {path}: {type(e).__name__}: {e}"})
        return
    replies.put({"ready": True})
    cpu0 = time.process_time()  # the writer's own CPU time from here: its start-up and imports left out
    done_t = done_e = dropped = 0
    ended = "closed by the host"
    try:
        while True:
            closed = bool(header[2])
            orphan = os.getppid() != host
            n_t, n_e = int(header[0]), int(header[1])
            if n_t - done_t > rows:  # the host lapped the writer: the oldest rows are gone
                lost = n_t - rows - done_t
                dropped += lost
                sink.event(4, done_t, {"note": f"{lost} ticks lost: the writer fell {rows} ticks behind",
                                       "dropped": lost})
                done_t = n_t - rows
            while done_e < n_e:
                slot = events[done_e % EVENT_SLOTS]
                ln, kind, tick, ns = (int(v) for v in slot[:32].view(np.int64))
                with contextlib.suppress(Exception):
                    sink.event(kind, tick, msgspec.json.decode(bytes(slot[32:32 + ln])), ns)
                done_e += 1
            if done_t < n_t:  # a new file starts with a tick, never empty
                sink.maybe_rotate(done_t)
            while done_t < n_t:
                row = ring[done_t % rows].copy()
                if int(header[0]) - rows > done_t:  # overwritten while it was copied: torn, lost
                    dropped += 1
                    sink.event(4, done_t, {"note": "1 ticks lost: overwritten while it was read", "dropped": 1})
                else:
                    sink.tick(row)
                done_t += 1
            sink.stream.flush()
            if closed or orphan:
                if orphan and not closed:
                    ended = "the host ended without closing the recording"
                if int(header[0]) == done_t and int(header[1]) == done_e:
                    break
                continue
            time.sleep(POLL_S)
        sink.close_file({"ticks": str(sink.ticks), "host_ticks": str(int(header[4]) if closed else done_t),
                         "dropped": str(dropped), "ended": ended})
        replies.put({"files": sink.files, "ticks": done_t, "dropped": dropped, "counts": sink.counts,
                     "cpu_s": time.process_time() - cpu0})
    except Exception as e:
        with contextlib.suppress(Exception):
            sink.close_file({"ticks": str(sink.ticks), "dropped": str(dropped),
                             "ended": f"writer failed: {type(e).__name__}: {e}"})
        replies.put({"error": f"recording failed: {type(e).__name__}: {e}", "files": sink.files})
    finally:
        del ring, header, buf, events
        for shm in (shm_t, shm_e):
            with contextlib.suppress(Exception):
                shm.close()


__all__ = ["JSON_TOPICS", "ROS_TOPICS", "SCALARS", "McapSink", "split_name", "writer_main"]
