"""The experiments in real time: the same scenarios through the daemon and the sim over Zenoh.

``wmm-qp experiment circle|dm --realtime`` starts ``wmm-qp sim`` and ``wmm-qp serve`` as
separate processes on loopback (unique key prefix and ports, :class:`~..processes.Stack`),
drives the daemon with the client API (modes, setpoint stream) and records, from the
client's side, every state the sim publishes, its evaluation data (``sim/truth``: ground truth,
box, referee, one per state, naming the state's seq) and every tick's telemetry of the daemon.

A log row is one daemon tick: the command and the reference come from the tick's telemetry,
the state (joint angles, odometry, torques) is *the state the daemon used*: the telemetry's
``state_seq`` identifies it exactly among the recorded states (a predicted tick: the newest
state stamped before the tick), and the truth of that seq gives its ground truth. The per-tick
trace has the in-process :class:`~.runner.Trace` layout, so the same metrics and the same CSV
columns apply. Time ``t`` is the daemon's tick time since the scenario's first tick.

The push (:func:`run_push_realtime`) runs each of its two runs on a fresh pair of processes:
optionally the DM enhancement along x, then the client places the box 1 cm in front of the
true EE (``sim/box``, :meth:`~..client.Client.place_box`) and streams the quasi-static TRACK
reference of :mod:`.push`. Its metrics come from the states the sim published after the box
was placed (torques, box position, stalled joint).
"""

from __future__ import annotations

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

from wmm_qp.config import FloatArray, RobotConfig
from wmm_qp.exceptions import WmmQpError
from wmm_qp.manipulability import directional_manipulability

from ..client import Client
from ..processes import Stack, isolated_config
from ..protocol import StateMsg, TelemetryMsg, TruthMsg
from . import push
from .circle import circle
from .dm import DIRECTIONS, cartesian_end
from .runner import Progress, Setup, Trace

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
        truths: raw TruthMsg payloads (``sim/truth``), in arrival order.
        telemetry: decoded telemetry messages, in arrival order.
    """

    client: Client
    states: list[bytes] = field(default_factory=list)
    truths: list[bytes] = field(default_factory=list)
    telemetry: list[TelemetryMsg] = field(default_factory=list)
    _sub: Any = None
    _sub_truth: Any = None

    def open(self) -> Recorder:
        """Subscribe to every state and truth (FIFO: none dropped on the client's side)."""
        s = self.client.session
        assert s is not None
        self._sub = s.declare_subscriber(self.client.keys.state, zenoh.handlers.FifoChannel(200_000))
        self._sub_truth = s.declare_subscriber(self.client.keys.sim_truth, zenoh.handlers.FifoChannel(200_000))
        return self

    def drain(self) -> None:
        """Move what arrived into the lists (cheap: states stay raw bytes)."""
        while (s := self._sub.try_recv()) is not None:
            self.states.append(s.payload.to_bytes())
        while (s := self._sub_truth.try_recv()) is not None:
            self.truths.append(s.payload.to_bytes())
        self.telemetry.extend(self.client.telemetry())

    def truth_by_seq(self) -> dict[int, TruthMsg]:
        """The recorded truths, decoded, by the seq of their state."""
        dec = msgspec.msgpack.Decoder(TruthMsg)
        return {t.state_seq: t for t in (dec.decode(b) for b in self.truths)}

    def last_x(self) -> np.ndarray | None:
        """[m] the model EE position of the newest telemetry (None: none yet)."""
        return np.array(self.telemetry[-1].x) if self.telemetry else None

    def close(self) -> None:
        if self._sub is not None:
            self._sub.undeclare()
            self._sub = None
        if self._sub_truth is not None:
            self._sub_truth.undeclare()
            self._sub_truth = None


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
    stop: Callable[[], bool] | None = None,
) -> None:
    """Call ``send(t)`` at ``rate_hz`` for ``duration`` [s] (t from 0) or until ``stop()``,
    draining the recorder."""
    t0 = time.monotonic()
    k = 0
    while (t := time.monotonic() - t0) < duration and not (stop is not None and stop()):
        send(t)
        rec.drain()
        if bar is not None:
            bar.update(min(1.0, (t_bar0 + t) / total))
        k += 1
        time.sleep(max(0.0, t0 + k / rate_hz - time.monotonic()))


def drive_circle(c: Client, rec: Recorder, duration: float, bar: Progress | None) -> list[str]:
    """The circle: TRACK, the paper's circle from the true EE position at rest, feed-forward."""
    tr = c.wait_truth(5.0)
    if tr is None:
        raise RealtimeError("no ground truth from the sim")
    x0 = np.array(tr.ee_true)
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


@dataclass
class StackOptions:
    """How to start the sim and the daemon for one run.

    Attributes:
        controller: the daemon's controller kind.
        solver: the daemon's QP backend (None: the config's).
        rate_hz: [Hz] control rate.
        slip: the sim's base slip on or off.
        seed: the sim's slip seed (None: the sim config's).
        log_dir: the processes' logs go here.
        robot: the robot; both processes load its file and run under its name (None: their default).
        controller_file: the daemon's controller config (None: its default).
        scene_file: the scene both processes load (``--scene``: the daemon's collision rows on;
            None: their default scene and, the paper's setting, no collision rows).
        physics: the sim's plant (``wmm-qp sim --physics``), "kinematic" or "mujoco".
    """

    controller: str
    solver: str | None
    rate_hz: float
    slip: bool
    seed: int | None
    log_dir: Path
    robot: RobotConfig | None = None
    controller_file: Path | None = None
    scene_file: Path | None = None
    physics: str = "kinematic"


def _on_stack(opts: StackOptions, drive: Callable[[Client, Recorder], Any]) -> tuple[Any, Recorder, dict[str, Any]]:
    """Start sim and daemon, run ``drive(client, recorder)``, stop them.

    Returns:
        (what ``drive`` returned, the closed recorder, the service-side figures).
    """
    svc = isolated_config(robot=opts.robot)
    daemon_args = ["--controller", opts.controller, *(["--solver", opts.solver] if opts.solver else []),
                   *([] if opts.controller_file is None else ["--controller-config", str(opts.controller_file)]),
                   *(["--no-collision"] if opts.scene_file is None else [])]  # the paper's setting: no rows
    sim_args = (_sim_config_file(opts.slip, opts.log_dir) + ([] if opts.seed is None else ["--seed", str(opts.seed)])
                + ["--physics", opts.physics])
    stack = Stack(svc, rate_hz=opts.rate_hz, log_dir=opts.log_dir, extra_daemon_args=daemon_args,
                  extra_sim_args=sim_args, robot_file=None if opts.robot is None else opts.robot.path,
                  scene_file=opts.scene_file)  # fmt: skip
    svc = stack.svc
    try:
        stack.start()
        with Client(svc, name="experiment", telemetry=True) as c:
            if not _wait_ready(c, STARTUP_TIMEOUT):
                raise RealtimeError(f"the daemon or the sim did not come up (logs: {opts.log_dir})")
            rec = Recorder(c).open()
            c.telemetry()  # start from here
            info0 = c.info()
            wall0 = time.perf_counter()
            out = drive(c, rec)
            time.sleep(0.05)
            rec.drain()
            c.set_mode("hold")
            info1 = c.info()
            rec.drain()
            rec.close()
            wall = time.perf_counter() - wall0
    finally:
        codes = stack.stop()
    service: dict[str, Any] = {
        "rate_hz": opts.rate_hz,
        "transport": "zenoh, loopback",
        "exit_codes": codes,
        "logs": str(opts.log_dir),
        "wall_time": wall,
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
            "collision": info1.status.collision,
        }
    return out, rec, service


def _options(name: str, setup: Setup, controller: str, solver: str | None, slip: bool, seed: int | None,
             rate_hz: float | None, log_dir: Path | None, controller_file: Path | None = None) -> StackOptions:
    log_dir = log_dir or Path(tempfile.mkdtemp(prefix=f"wmm-qp-rt-{name}-"))
    log_dir.mkdir(parents=True, exist_ok=True)
    return StackOptions(controller, solver, float(rate_hz or setup.ctl_cfg.rate_hz), slip, seed, log_dir,
                        setup.robot, controller_file, setup.scene.path if setup.scene is not None else None,
                        setup.sim_cfg.physics.plant)


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
    controller_file: Path | None = None,
) -> RealtimeResult:
    """Run ``circle`` or ``dm`` through the daemon and the sim over Zenoh, in real time.

    Args:
        name: "circle" or "dm" (the push: :func:`run_push_realtime`).
        setup: the robot, the model and configs (for the DM along u and the log layout); the
            sim and the daemon load the setup's robot file and run under its name.
        controller: the daemon's controller kind.
        solver: the daemon's QP backend (None: the config's).
        duration: [s] scenario length (real time).
        direction: DM direction "x" or "z" (dm).
        slip: the sim's base slip on or off.
        seed: the sim's slip seed (None: the sim config's).
        rate_hz: [Hz] control rate (None: the controller config's).
        progress: a progress bar on stderr (when it is a terminal).
        log_dir: keep the processes' logs here (None: a temporary folder).
        controller_file: the daemon's controller config (None: its default).

    Returns:
        The trace and the service-side figures.
    """
    if name not in ("circle", "dm"):
        raise RealtimeError(f"no realtime scenario {name!r} here (push: run_push_realtime)")
    opts = _options(name, setup, controller, solver, slip, seed, rate_hz, log_dir, controller_file)
    u = DIRECTIONS[direction] if name == "dm" else np.asarray(setup.ctl_cfg.direction, dtype=float)
    bar = Progress(f"{name} (realtime)", progress) if progress else None

    def drive(c: Client, rec: Recorder) -> list[str]:
        if name == "circle":
            return drive_circle(c, rec, duration, bar)
        return drive_dm(c, rec, duration, direction, bar)

    try:
        modes, rec, service = _on_stack(opts, drive)
    finally:
        if bar is not None:
            bar.close()
    trace, t_switch, age = build_trace(setup, rec, modes, duration, u)
    trace.wall_time = service.pop("wall_time")
    service["state_age_us"] = age
    return RealtimeResult(trace=trace, t_switch=t_switch, service=service)


@dataclass
class PushStart:
    """Where one realtime push phase started.

    Attributes:
        face_x: [m] the box face's initial world x.
        q_arm: [rad] joint angles when the box was placed.
    """

    face_x: float
    q_arm: list[float]


def drive_push(c: Client, rec: Recorder, model: Any, scale: float, bar: Progress | None) -> PushStart:
    """Place the box 1 cm ahead of the true EE, then push it with a slow TRACK reference.

    Same phase as :func:`.push._push_phase`: x_d moves from the model EE position along +x at
    ``PUSH_SPEED / scale`` by gap + target + overshoot, then stays; ends when the box has moved
    ``TARGET`` or after ``SETTLE * scale`` more seconds.
    """
    st, tr = c.wait_state(5.0), c.wait_truth(5.0)
    if st is None or tr is None:
        raise RealtimeError("no state or no ground truth from the sim")
    x_start = model.ee_position(np.array(st.q_base), np.array(st.q_arm))
    box = push.box_at(tr.ee_true)
    face_x = box.face_x
    c.place_box(box.mass, box.mu, box.face_x, box.center_y, box.width, box.height)
    end = time.monotonic() + 5.0
    while not ((s := c.wait_truth(0.5)) is not None and math.isfinite(s.box_position)):
        if time.monotonic() > end:
            raise RealtimeError("the sim did not place the box")
    speed = push.PUSH_SPEED / scale
    t_move = (push.GAP + push.TARGET + push.OVERSHOOT) / speed
    duration = t_move + push.SETTLE * scale
    c.set_mode("track", DIRECTIONS["x"].tolist())

    def send(t: float) -> None:
        s = min(t, t_move)
        c.send_setpoint(x_start + np.array([speed * s, 0.0, 0.0]), [speed if t < t_move else 0.0, 0.0, 0.0])

    def moved() -> bool:
        s = c.latest_truth()
        return s is not None and s.box_position - face_x >= push.TARGET

    _pace(rec, duration, SETPOINT_HZ, bar, 0.0, duration, send, moved)
    return PushStart(face_x=face_x, q_arm=list(st.q_arm))


def push_metrics_realtime(setup: Setup, rec: Recorder, start: PushStart) -> dict[str, Any]:
    """The in-process push metrics (:func:`.push.push_metrics` keys) from the sim's states."""
    dec = msgspec.msgpack.Decoder(StateMsg)
    truth = rec.truth_by_seq()
    pairs = [(s, t) for s in (dec.decode(b) for b in rec.states)
             if (t := truth.get(s.seq)) is not None and math.isfinite(t.box_position)]
    if not pairs:
        raise RealtimeError("no state with the box arrived")
    states = [t for _, t in pairs]
    tau = np.array([s.tau for s, _ in pairs])
    W = np.asarray(setup.W, dtype=float)
    stalled = np.array([s.stalled_joint for s in states])
    first = np.flatnonzero(stalled >= 0)
    distance = float(states[-1].box_position - start.face_x)
    J = setup.model.arm.position_jacobian(np.array(start.q_arm))[1]
    return {
        "completed": bool(distance >= push.TARGET - 1e-9),
        "distance": distance,
        "max_abs_torque": [float(v) for v in np.abs(tau).max(axis=0)],
        "max_weighted_torque_norm": float(np.linalg.norm(tau * W, axis=1).max()),
        "saturated_joint": int(stalled[first[0]]) if first.size else None,
        "stall_ticks": int(first.size),
        "dm_at_push_start": float(directional_manipulability(J, DIRECTIONS["x"], W)),
        "push_force": push.MU * push.MASS * 9.81,
        "violations": dict(states[-1].violations),
    }


def run_push_realtime(
    setup_factory: Callable[[], Setup],
    controller: str,
    solver: str | None,
    dm_duration: float,
    *,
    slip: bool = True,
    seed: int | None = None,
    rate_hz: float | None = None,
    progress: bool = True,
    log_dir: Path | None = None,
    controller_file: Path | None = None,
) -> dict[str, dict[str, Any]]:
    """The box push through the daemon and the sim over Zenoh: with and without DM first.

    Args:
        setup_factory: () → a fresh :class:`Setup` (model, configs).
        controller, solver, slip, seed, rate_hz, progress, log_dir, controller_file: as
            :func:`run_realtime` (the robot is the setup's).
        dm_duration: [s] DM enhancement before the push (with_dm); below 20 s it also speeds
            the push up in proportion, as in-process.

    Returns:
        {"with_dm": metrics, "without_dm": metrics}; each metrics dict also has "realtime"
        (the service-side figures of its run).
    """
    scale = min(1.0, dm_duration / push.DEFAULT_DM_DURATION)
    out: dict[str, dict[str, Any]] = {}
    for name in ("with_dm", "without_dm"):
        setup = setup_factory()
        opts = _options(f"push-{name}", setup, controller, solver, slip, seed, rate_hz,
                        None if log_dir is None else log_dir / name, controller_file)  # fmt: skip
        bar = Progress(f"push {name} (realtime)", progress) if progress else None

        def drive(c: Client, rec: Recorder, with_dm: bool = name == "with_dm",
                  bar: Progress | None = bar, setup: Setup = setup) -> PushStart:  # fmt: skip
            if with_dm:
                drive_dm(c, rec, dm_duration, "x", bar)
            return drive_push(c, rec, setup.model, scale, bar)

        try:
            start, rec, service = _on_stack(opts, drive)
        finally:
            if bar is not None:
                bar.close()
        out[name] = push_metrics_realtime(setup, rec, start) | {"realtime": service}
        reasons: dict[str, int] = {}
        for t in rec.telemetry:
            if t.status != "ok":
                reasons[f"status {t.status}"] = reasons.get(f"status {t.status}", 0) + 1
        out[name]["controller_reasons"] = reasons
    return out


def match_states(states: list[StateMsg], tel: list[TelemetryMsg]) -> list[int]:
    """For each telemetry message, the index of the state the daemon used (see module doc)."""
    by_seq = {s.seq: i for i, s in enumerate(states)}
    stamps = np.array([s.stamp for s in states])
    out = []
    for m in tel:
        i = by_seq.get(m.state_seq) if m.state_seq >= 0 else None
        out.append(i if i is not None else max(0, int(np.searchsorted(stamps, m.stamp, side="right")) - 1))
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
    W = np.asarray(setup.W, dtype=float)
    u = np.asarray(u, dtype=float) / np.linalg.norm(u)
    rows_st = [states[i] for i in idx]
    truth = rec.truth_by_seq()
    nan3 = [math.nan] * 3
    rows_tr = [truth.get(s.seq) for s in rows_st]
    last_truth = truth[max(truth)] if truth else None
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
        base_true=np.array([t.base_true if t is not None else nan3 for t in rows_tr]),
        ee_des=ee_des,
        ee_true=np.array([t.ee_true if t is not None else nan3 for t in rows_tr]),
        dm=dm,
        tau=np.array([s.tau for s in rows_st]),
        box_displacement=np.full(n, math.nan),
        stalled_joint=np.full(n, -1, dtype=int),
        violations=dict(last_truth.violations) if last_truth is not None else {},
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
