"""The experiments in real time: the same scenarios through the daemon and the sim over Zenoh.

``wmm-qp experiment circle|dm --realtime`` starts ``wmm-qp sim`` and ``wmm-qp serve`` as
separate processes on loopback (unique key prefix and ports, :class:`~..processes.Stack`),
drives the daemon with the client API (modes, setpoint stream) and records, from the
client's side, every state the sim publishes and every tick's telemetry of the daemon.

A log row is one daemon tick: the command and the reference come from the tick's telemetry,
the state (joint angles, odometry, ground truth, torques) is *the state the daemon used*:
the telemetry carries that state's ground-truth EE position, which identifies it exactly
among the recorded states (fallback: the newest state stamped before the tick). The per-tick
trace has the in-process :class:`~.runner.Trace` layout, so the same metrics and the same CSV
columns apply. Time ``t`` is the daemon's tick time since the scenario's first tick.

The push is not available in real time: the sim process can only be given a box in its
config at start-up, not placed in front of the EE after the DM enhancement (see
:data:`PUSH_UNAVAILABLE`).
"""

from __future__ import annotations

import bisect
import math
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import msgspec
import numpy as np
import zenoh

from wmm_qp.config import FloatArray
from wmm_qp.exceptions import WmmQpError
from wmm_qp.manipulability import directional_manipulability

from ..client import Client
from ..processes import Stack, isolated_config
from ..protocol import StateMsg, TelemetryMsg
from .circle import circle
from .dm import DIRECTIONS, cartesian_end
from .runner import Progress, Setup, Trace

PUSH_UNAVAILABLE = (
    "push --realtime is not available: the sim process cannot place the box in front of the EE "
    "after the DM phase (a box exists only from its config at start-up); run push in-process"
)
SETPOINT_HZ = 100.0  # [Hz] rate of the scripted setpoint stream (feed-forward velocity included)
HOLD_HZ = 50.0  # [Hz] rate of the standing target in the null-space phase
STARTUP_TIMEOUT = 60.0  # [s] for the daemon to answer with a valid state


class RealtimeError(WmmQpError):
    """The real-time stack did not come up or did not produce a trace."""


@dataclass
class Recorder:
    """Collects the raw states and the telemetry from a client's session.

    Attributes:
        client: an open client with ``telemetry=True``.
        states: raw StateMsg payloads, in arrival order (decoded at the end).
        telemetry: decoded telemetry messages, in arrival order.
    """

    client: Client
    states: list[bytes] = field(default_factory=list)
    telemetry: list[TelemetryMsg] = field(default_factory=list)
    _sub: Any = None

    def open(self) -> Recorder:
        """Subscribe to every state (FIFO: none dropped on the client's side)."""
        assert self.client.session is not None
        self._sub = self.client.session.declare_subscriber(self.client.keys.state, zenoh.handlers.FifoChannel(200_000))
        return self

    def drain(self) -> None:
        """Move what arrived into the lists (cheap: states stay raw bytes)."""
        while (s := self._sub.try_recv()) is not None:
            self.states.append(s.payload.to_bytes())
        self.telemetry.extend(self.client.telemetry())

    def last_x(self) -> np.ndarray | None:
        """[m] the model EE position of the newest telemetry (None: none yet)."""
        return np.array(self.telemetry[-1].x) if self.telemetry else None

    def close(self) -> None:
        if self._sub is not None:
            self._sub.undeclare()
            self._sub = None


@dataclass
class RealtimeResult:
    """A real-time run: the per-tick trace and the service-side figures.

    Attributes:
        trace: per-tick trace (in-process layout).
        t_switch: [s] trace time of the first null-space tick (dm), else None.
        service: loop figures, state age, rejections, faults, exit codes (JSON-able).
    """

    trace: Trace
    t_switch: float | None
    service: dict[str, Any]


def _sim_config_file(slip: bool, tmp: Path) -> list[str]:
    """Extra ``wmm-qp sim`` arguments for the slip switch (a minimal TOML when off)."""
    if slip:
        return []
    p = tmp / "sim_no_slip.toml"
    p.write_text("[slip]\nenabled = false\n")
    return ["--sim-config", str(p)]


def _wait_ready(c: Client, timeout: float) -> bool:
    """Wait until the daemon answers and has a valid state from the sim."""
    end = time.monotonic() + timeout
    info = c.wait_for_daemon(timeout)
    while info is not None and not info.status.state_ok and time.monotonic() < end:
        time.sleep(0.1)
        info = c.info()
    return info is not None and info.status.state_ok


def _pace(
    rec: Recorder,
    duration: float,
    rate_hz: float,
    bar: Progress | None,
    t_bar0: float,
    total: float,
    send: Callable[[float], None],
) -> None:
    """Call ``send(t)`` at ``rate_hz`` for ``duration`` [s] (t from 0), draining the recorder."""
    t0 = time.monotonic()
    k = 0
    while (t := time.monotonic() - t0) < duration:
        send(t)
        rec.drain()
        if bar is not None:
            bar.update(min(1.0, (t_bar0 + t) / total))
        k += 1
        time.sleep(max(0.0, t0 + k / rate_hz - time.monotonic()))


def drive_circle(c: Client, rec: Recorder, duration: float, bar: Progress | None) -> list[str]:
    """The circle: TRACK, the paper's circle from the true EE position at rest, feed-forward."""
    st = c.wait_state(5.0)
    if st is None:
        raise RealtimeError("no state from the sim")
    x0 = np.array(st.ee_true)
    c.set_mode("track")

    def send(t: float) -> None:
        x, xd = circle(x0, t)
        c.send_setpoint(x, xd)

    _pace(rec, duration, SETPOINT_HZ, bar, 0.0, duration, send)
    return ["track"]


def drive_dm(c: Client, rec: Recorder, duration: float, direction: str, bar: Progress | None) -> list[str]:
    """DM: Cartesian phase, then null space holding the model EE position at the switch."""
    u = DIRECTIONS[direction].tolist()
    t_switch = cartesian_end(duration)
    c.set_mode("dm_cartesian", u)
    _pace(rec, t_switch, HOLD_HZ, bar, 0.0, duration, lambda t: None)
    c.set_mode("dm_nullspace", u)
    hold: list[np.ndarray] = []
    n_tel = len(rec.telemetry)

    def send(t: float) -> None:
        if not hold:  # the model EE of the first null-space tick (the daemon's own estimate)
            new = [m for m in rec.telemetry[n_tel:] if m.mode == "dm_nullspace"]
            if not new:
                return
            hold.append(np.array(new[0].x))
        c.send_setpoint(hold[0], [0.0, 0.0, 0.0])

    _pace(rec, duration - t_switch, HOLD_HZ, bar, t_switch, duration, send)
    return ["dm_cartesian", "dm_nullspace"]


def run_realtime(
    name: str,
    setup: Setup,
    controller: str,
    solver: str | None,
    duration: float,
    *,
    direction: str = "x",
    slip: bool = True,
    seed: int | None = None,
    rate_hz: float | None = None,
    progress: bool = True,
    log_dir: Path | None = None,
) -> RealtimeResult:
    """Run ``circle`` or ``dm`` through the daemon and the sim over Zenoh, in real time.

    Args:
        name: "circle" or "dm" (push: :class:`RealtimeError`, see :data:`PUSH_UNAVAILABLE`).
        setup: the model and configs (for the DM along u and the log layout).
        controller: the daemon's controller kind.
        solver: the daemon's QP backend (None: the config's).
        duration: [s] scenario length (real time).
        direction: DM direction "x" or "z" (dm).
        slip: the sim's base slip on or off.
        seed: the sim's slip seed (None: the sim config's).
        rate_hz: [Hz] control rate (None: the controller config's).
        progress: a progress bar on stderr (when it is a terminal).
        log_dir: keep the processes' logs here (None: a temporary folder).

    Returns:
        The trace and the service-side figures.
    """
    if name == "push":
        raise RealtimeError(PUSH_UNAVAILABLE)
    rate = float(rate_hz or setup.ctl_cfg.rate_hz)
    log_dir = log_dir or Path(tempfile.mkdtemp(prefix=f"wmm-qp-rt-{name}-"))
    log_dir.mkdir(parents=True, exist_ok=True)
    svc = isolated_config()
    daemon_args = ["--controller", controller, *(["--solver", solver] if solver else [])]
    sim_args = _sim_config_file(slip, log_dir) + ([] if seed is None else ["--seed", str(seed)])
    stack = Stack(svc, rate_hz=rate, log_dir=log_dir, extra_daemon_args=daemon_args, extra_sim_args=sim_args)
    u = DIRECTIONS[direction] if name == "dm" else np.asarray(setup.ctl_cfg.direction, dtype=float)
    bar = Progress(f"{name} (realtime)", progress) if progress else None
    try:
        stack.start()
        with Client(svc, name="experiment", telemetry=True) as c:
            if not _wait_ready(c, STARTUP_TIMEOUT):
                raise RealtimeError(f"the daemon or the sim did not come up (logs: {log_dir})")
            rec = Recorder(c).open()
            c.telemetry()  # start from here
            info0 = c.info()
            wall0 = time.perf_counter()
            if name == "circle":
                modes = drive_circle(c, rec, duration, bar)
            else:
                modes = drive_dm(c, rec, duration, direction, bar)
            time.sleep(0.05)
            rec.drain()
            c.set_mode("hold")
            info1 = c.info()
            rec.drain()
            rec.close()
            wall = time.perf_counter() - wall0
    finally:
        codes = stack.stop()
        if bar is not None:
            bar.close()
    trace, t_switch, age = build_trace(setup, rec, modes, duration, u)
    trace.wall_time = wall
    service: dict[str, Any] = {
        "rate_hz": rate,
        "transport": "zenoh, loopback",
        "exit_codes": codes,
        "logs": str(log_dir),
        "state_age_us": age,
    }
    if info0 is not None and info1 is not None:
        l0, l1 = info0.status.loop, info1.status.loop
        ticks = l1.ticks - l0.ticks
        misses = l1.deadline_misses - l0.deadline_misses
        service |= {
            "ticks": ticks,
            "deadline_misses": misses,
            "misses_per_10k": round(1e4 * misses / ticks, 2) if ticks else None,
            "tick_p50_us": round(l1.tick_p50_us, 1),
            "tick_p99_us": round(l1.tick_p99_us, 1),
            "rejected": dict(info1.status.rejected),
            "last_fault": info1.status.last_fault,
        }
    return RealtimeResult(trace=trace, t_switch=t_switch, service=service)


def match_states(states: list[StateMsg], tel: list[TelemetryMsg]) -> list[int]:
    """For each telemetry message, the index of the state the daemon used (see module doc)."""
    by_ee: dict[tuple[float, ...], tuple[list[float], list[int]]] = {}
    for i, s in enumerate(states):
        st, ix = by_ee.setdefault(tuple(s.ee_true), ([], []))
        st.append(s.stamp)
        ix.append(i)
    stamps = np.array([s.stamp for s in states])
    out = []
    for m in tel:
        st, ix = by_ee.get(tuple(m.ee_true), ([], []))
        k = bisect.bisect_right(st, m.stamp) - 1
        if k >= 0:
            out.append(ix[k])
        else:
            out.append(max(0, int(np.searchsorted(stamps, m.stamp, side="right")) - 1))
    return out


def build_trace(
    setup: Setup, rec: Recorder, modes: list[str], duration: float, u: FloatArray
) -> tuple[Trace, float | None, dict[str, float]]:
    """The per-tick trace of the scenario's ticks (first tick in ``modes[0]`` to ``duration``).

    Returns:
        (trace, t_switch [s] of the first ``modes[1]`` tick or None, state age at command
        publication [µs] {p50, p99, max}).
    """
    dec = msgspec.msgpack.Decoder(StateMsg)
    states = [dec.decode(b) for b in rec.states]
    tel = rec.telemetry
    first = next((i for i, m in enumerate(tel) if m.mode == modes[0]), None)
    if first is None or not states:
        raise RealtimeError("no telemetry of the scenario arrived (is telemetry_every 0?)")
    t0 = tel[first].t
    tel = [m for m in tel[first:] if m.mode in modes and m.t - t0 < duration - 1e-9]
    idx = match_states(states, tel)
    m = setup.model
    W = np.asarray(setup.ctl_cfg.W, dtype=float)
    u = np.asarray(u, dtype=float) / np.linalg.norm(u)
    rows_st = [states[i] for i in idx]
    q = np.array([s.q_arm for s in rows_st])
    wheel = np.array([t.wheel_speeds for t in tel])
    ee_des = np.array([t.x if t.mode == "dm_cartesian" else t.x_d for t in tel])
    dm = np.array([directional_manipulability(m.arm.position_jacobian(qa)[1], u, W) for qa in q])
    age = np.array([(t.stamp - s.stamp) * 1e6 for t, s in zip(tel, rows_st, strict=True)])
    status_counts: dict[str, int] = {}
    for t in tel:
        if t.status != "ok":
            status_counts[f"status {t.status}"] = status_counts.get(f"status {t.status}", 0) + 1
    n = len(tel)
    trace = Trace(
        t=np.array([t.t - t0 for t in tel]),
        mode=[t.mode for t in tel],
        status=[t.status for t in tel],
        q=q,
        qd_cmd=np.array([t.arm_rates for t in tel]),
        wheel_cmd=wheel,
        base_twist_cmd=np.array([m.base.body_twist(w) for w in wheel]),
        base_odom=np.array([s.q_base for s in rows_st]),
        base_true=np.array([s.base_true for s in rows_st]),
        ee_des=ee_des,
        ee_true=np.array([s.ee_true for s in rows_st]),
        dm=dm,
        tau=np.array([s.tau for s in rows_st]),
        box_displacement=np.full(n, math.nan),
        stalled_joint=np.full(n, -1, dtype=int),
        violations=dict(states[-1].violations),
        reasons=status_counts,
    )
    t_switch = None
    if len(modes) > 1:
        k = next((i for i, mode in enumerate(trace.mode) if mode == modes[1]), None)
        t_switch = float(trace.t[k]) if k is not None else None
    summary = {
        "p50": round(float(np.percentile(age, 50)), 1),
        "p99": round(float(np.percentile(age, 99)), 1),
        "max": round(float(age.max()), 1),
    }
    return trace, t_switch, summary
