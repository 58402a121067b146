"""The hook a control thread calls to record its ticks, without ever waiting for the recording.

:class:`TickJournal` owns two rings in shared memory and a writer process (:mod:`.writer`):

* the tick ring: one float64 row a tick (:class:`~.layout.Layout`): the measured state, the state
  and reference handed to the controller, what it was asked (``step``, ``safe_stop``, nothing),
  its command, the tick's timings. :meth:`TickJournal.tick` fills the next row (a few array copies,
  no allocation, no encoding) and advances the write count;
* the event ring: rare, variable-sized things as JSON (each status the host publishes, a new
  command reason, a live obstacle set).

The writer process polls the counts and serialises what is new to MCAP; its interpreter lock is
its own, so serialisation never delays the control thread. A writer that falls a whole ring
behind loses the oldest rows, and the file says so (``/wmm/events``: ``dropped``). When the
host dies without closing, the writer notices (its parent is gone), drains the rings and closes
the file: a crash of the host loses nothing the rings held; a crash of the writer loses at most
the chunk it was filling.
"""

from __future__ import annotations

import contextlib
import math
import multiprocessing as mp
import os
import time
import uuid
from multiprocessing import shared_memory
from pathlib import Path
from typing import TYPE_CHECKING, Any

import msgspec
import numpy as np

from wmm_qp.config.shapes import ShapeConfig

from ..protocol import StatusMsg
from . import proxsuite_build, require
from .layout import MODES, STATUSES, Layout, config_to_dict

if TYPE_CHECKING:
    from ..daemon.core import ControlCore
    from ..daemon.cycle import Sent

RING_SECONDS = 30.0
"""The tick ring holds this long of ticks (at least 4096): how far the writer may fall behind (a
machine busy with other work) before it loses a row. At 1 kHz for the Gen3: 30000 rows of 90
float64, 22 MB of shared memory."""
EVENT_SLOTS = 512
EVENT_BYTES = 16384
"""The event ring: slots of this many bytes (a status is ~1–2 kB; a longer event is cut)."""
HEADER = 8
"""int64 header: [0] ticks written, [1] events written, [2] closed by the host, [3] the host's pid,
[4] the host's final tick count."""

EV_STATUS, EV_REASON, EV_OBSTACLES, EV_NOTE = 1, 2, 3, 4
"""Event kinds: a status the host published, a new command reason, a live obstacle set, a note."""


def recording_meta(core: ControlCore, host: str, trigger: str) -> dict[str, str]:
    """The recording's metadata (MCAP metadata ``wmm_qp``): what the replay needs to rebuild the
    controller as the host ran it, and where the recording came from."""
    robot, svc = core.robot, core.svc
    return {
        "format": "wmm-qp recording 1",
        "recording_id": uuid.uuid4().hex,
        "host": host,
        "robot": svc.robot,
        "robot_name": robot.name,
        "robot_file": str(robot.path) if robot.path is not None else "",
        "arm_joints": msgspec.json.encode(list(robot.arm.joints)).decode(),
        "wheels": msgspec.json.encode(list(core.model.base.wheel_names)).decode(),
        "controller": core.kind,
        "controller_config": msgspec.json.encode(config_to_dict(core.cfg)).decode(),
        "scene": str(core.scene.path) if core.scene.path is not None else "",
        "rate_hz": repr(svc.loop.rate_hz),
        "trigger": trigger,
        "solver": core.cfg.qp.solver,
        "proxsuite_build": proxsuite_build(),
        "started": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
    }


class TickJournal:
    """Record every tick of a control host into ``path`` (MCAP), from its control thread.

    Args:
        path: the file (rotated files follow as ``<stem>.001.mcap``, …).
        meta: :func:`recording_meta`.
        n_arm, n_wheels: the robot's sizes.
        split_size: [MB] start a new file past this size (None: never).
        split_time: [s] start a new file after this long (None: never).
        rate_hz: [Hz] the host's tick rate (the ring's size: :data:`RING_SECONDS`).

    Raises:
        RecordingUnavailable: the ``record`` extra is not installed.
        RecordingError: the writer could not open ``path``.
    """

    def __init__(self, path: str | Path, meta: dict[str, str], n_arm: int, n_wheels: int,
                 split_size: float | None = None, split_time: float | None = None,
                 rate_hz: float = 1000.0, rows: int | None = None) -> None:
        require()
        rows = rows if rows is not None else max(4096, int(RING_SECONDS * rate_hz))
        self.path = Path(path)
        self.layout = lay = Layout(n_arm, n_wheels)
        self._cap = rows
        self._shm_ticks = shared_memory.SharedMemory(create=True, size=8 * (HEADER + rows * lay.width))
        self._shm_events = shared_memory.SharedMemory(create=True, size=EVENT_SLOTS * EVENT_BYTES)
        buf = np.ndarray((HEADER + rows * lay.width,), dtype=np.float64, buffer=self._shm_ticks.buf)
        self._header = buf[:HEADER].view(np.int64)
        self._header[:] = 0
        self._header[3] = os.getpid()
        self._rows = buf[HEADER:].reshape(rows, lay.width)
        self._events = np.ndarray((EVENT_SLOTS, EVENT_BYTES), dtype=np.uint8, buffer=self._shm_events.buf)
        self._n = 0
        self._n_events = 0
        self._reason = ""
        self._obstacles: object = None
        self._closed = False
        sl = lay.slices
        self._s = [sl[k] for k in ("meas_q_base", "meas_q_arm", "meas_v_arm", "meas_wheels", "ctl_q_base",
                                   "ctl_q_arm", "ctl_v_arm", "ctl_wheels", "x_d", "xd_d", "direction",
                                   "quat_d", "omega_d", "cmd_wheels", "cmd_arm", "cmd_x")]
        self._mode_index = {m: float(i) for i, m in enumerate(MODES)}
        self._status_index = {s: float(i) for i, s in enumerate(STATUSES)}
        ctx = mp.get_context("spawn")  # never fork a process with Zenoh's threads
        self._replies = ctx.Queue()
        from .writer import writer_main

        self._proc = ctx.Process(
            target=writer_main, name="wmm-qp-recorder", daemon=False,
            args=(self._shm_ticks.name, self._shm_events.name, rows, n_arm, n_wheels, str(self.path), meta,
                  split_size, split_time, self._replies))
        self._proc.start()
        try:
            ready = self._replies.get(timeout=60.0)
        except Exception:
            ready = {"error": "the recording's writer did not start within 60 s"}
        if "error" in ready:
            self._release()
            from . import RecordingError

            raise RecordingError(str(ready["error"]))

    # ------------------------------------------------------------------ the control thread's calls
    def tick(self, core: ControlCore, sent: Sent | None, tick: int, t: float, tick_us: float) -> None:
        """Record tick ``tick`` (after its command went out, or did not): never blocks, never raises.

        Args:
            core: the control core after the tick.
            sent: the command that went out (None: none).
            t: [s] the tick's time since the loop's start; tick_us: [µs] the previous tick's work.
        """
        try:
            self._tick(core, sent, tick, t, tick_us)
        except Exception as e:  # a recording never stops the control loop
            self.note(tick, f"tick {tick} not recorded: {type(e).__name__}: {e}")

    def _tick(self, core: ControlCore, sent: Sent | None, tick: int, t: float, tick_us: float) -> None:
        row = self._rows[self._n % self._cap]
        row.fill(math.nan)
        s = self._s
        cmd = core.cmd
        call = core.ctl_call
        ref = core.ref
        row[:14] = (time.time() if sent is None else sent.stamp, t, tick, -1 if sent is None else sent.seq,
                    call, core.latches, core.ctl_latency, tick_us, core.step_ns * 1e-3,
                    self._mode_index[core.mode], self._status_index[cmd.status] if cmd is not None else math.nan,
                    core.gate.last_seq, core.ee_error, math.nan)
        m = core.state_msg
        if m is not None:
            row[s[0]], row[s[1]], row[s[2]], row[s[3]] = m.q_base, m.q_arm, m.v_arm, m.wheel_speeds
        if call:  # the controller's inputs this tick (a repeat: none, the last command again)
            st = core.ctl_state
            if call != 3 and st is not None:
                row[s[4]], row[s[5]], row[s[6]], row[s[7]] = st.q_base, st.q_arm, st.v_arm, st.wheel_speeds
            if call == 1:
                row[s[9]], row[s[12]] = ref.xd_d, ref.omega_d
                if ref.x_d is not None:
                    row[s[8]] = ref.x_d
                if ref.direction is not None:
                    row[s[10]] = ref.direction
                if ref.quat_d is not None:
                    row[s[11]] = ref.quat_d
            if cmd is not None:
                row[s[13]], row[s[14]], row[s[15]] = cmd.wheel_speeds, cmd.arm_rates, cmd.x
                row[13:17] = cmd.dm, cmd.sigma_min, cmd.task_error, cmd.alpha
                if cmd.reason != self._reason:
                    self._reason = cmd.reason
                    row[17] = 1.0
                    self._event(EV_REASON, tick, {"reason": cmd.reason, "status": cmd.status.value})
        shapes = core.obstacles.shapes
        if shapes is not self._obstacles:
            self._obstacles = shapes
            self._event(EV_OBSTACLES, tick, {"obstacles": [_shape(sh) for sh in shapes]})
        self._n += 1
        self._header[0] = self._n  # published after the row is complete

    def status(self, tick: int, msg: StatusMsg) -> None:
        """Record a status the host published at tick ``tick`` (never raises)."""
        with contextlib.suppress(Exception):
            self._event(EV_STATUS, tick, msgspec.to_builtins(msg))

    def note(self, tick: int, text: str) -> None:
        """Record a line about the recording itself (never raises)."""
        with contextlib.suppress(Exception):
            self._event(EV_NOTE, tick, {"note": text})

    def _event(self, kind: int, tick: int, payload: dict[str, Any]) -> None:
        data = msgspec.json.encode(payload)[: EVENT_BYTES - 32]
        slot = self._events[self._n_events % EVENT_SLOTS]
        head = slot[:32].view(np.int64)  # length, kind, tick, wall clock [ns]
        head[:] = len(data), kind, tick, time.time_ns()
        slot[32:32 + len(data)] = np.frombuffer(data, dtype=np.uint8)
        self._n_events += 1
        self._header[1] = self._n_events

    # ------------------------------------------------------------------ the end
    def close(self, host_ticks: int | None = None, timeout: float = 600.0) -> dict[str, Any]:
        """Let the writer drain both rings and close its file (a writer far behind on a busy machine
        takes a while); its summary (``files``, ``ticks``, ``dropped``; ``error`` if it failed or is
        not done after ``timeout`` [s]: then it finishes on its own). Never raises.

        Args:
            host_ticks: the host's own count of its ticks (the file's ``wmm_qp_end``), else the
                journal's.
        """
        if self._closed:
            return {}
        self._closed = True
        self._header[4] = self._n if host_ticks is None else host_ticks
        self._header[2] = 1
        summary: dict[str, Any] = {"error": f"the recording's writer did not finish within {timeout:g} s"}
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            try:
                summary = self._replies.get(timeout=0.5)
                break
            except Exception:
                if not self._proc.is_alive():
                    summary = {"error": f"the recording's writer died (exit code {self._proc.exitcode})"}
                    break
        self._proc.join(timeout=5.0)  # still alive: it finishes the file on its own (its host is gone)
        self._release()
        return summary

    def _release(self) -> None:
        # no view may outlive the memory
        self._rows, self._events, self._header = np.empty((0, 0)), np.empty((0, 0), np.uint8), np.empty(0, np.int64)
        for shm in (self._shm_ticks, self._shm_events):
            with contextlib.suppress(Exception):
                shm.close()
            with contextlib.suppress(Exception):
                shm.unlink()


def _shape(sh: ShapeConfig) -> dict[str, Any]:
    return {"name": sh.name, "link": sh.link, "kind": sh.kind, "size": sh.size.tolist(), "xyz": sh.xyz.tolist(),
            "rpy": sh.rpy.tolist(), "exempt": list(sh.exempt),
            "velocity": None if sh.velocity is None else sh.velocity.tolist()}
