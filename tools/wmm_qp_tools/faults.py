"""Fault scenarios against the real processes, each returning what it measured.

Used by ``benchmarks/reliability/faults.py`` (which records the figures in
docs/reliability.md) and by ``tests/integration/test_reliability_faults.py`` (which asserts behaviour,
never timing). Latencies are measured with the publishers' own wall-clock stamps
(``time.time()`` in the daemon's telemetry and status, in the sim's state): all processes run
on one machine, so a latency is ``stamp of the first message showing the reaction −
time.time() just before the fault``, free of the observer's polling delay.
"""

from __future__ import annotations

import contextlib
import itertools
import signal
import subprocess
import sys
import time
from collections import Counter
from collections.abc import Callable
from typing import Any

import msgspec
import numpy as np
import zenoh
from wmm_qp_service.client import Client
from wmm_qp_service.processes import Stack
from wmm_qp_service.protocol import StateMsg, StatusMsg, TelemetryMsg, TruthMsg

import wmm_qp as w

SAFE = w.Status.SAFE_STOP.value


class Probe:
    """A client that keeps every telemetry, state, truth and status message with its stamp.

    Args:
        stack: the running stack.
        name: the client's name.
    """

    def __init__(self, stack: Stack, name: str = "probe") -> None:
        self.stack = stack
        self.client = Client(stack.svc, name=name, telemetry=True).open()
        s = self.client.session
        assert s is not None
        k = self.client.keys
        self._sub_state = s.declare_subscriber(k.state, zenoh.handlers.FifoChannel(200_000))
        self._sub_status = s.declare_subscriber(k.status, zenoh.handlers.FifoChannel(10_000))
        self._sub_truth = s.declare_subscriber(k.sim_truth, zenoh.handlers.RingChannel(1))
        self._dec_state = msgspec.msgpack.Decoder(StateMsg)
        self._dec_truth = msgspec.msgpack.Decoder(TruthMsg)
        self.truth: TruthMsg | None = None
        """The sim's last evaluation data (``sim/truth``)."""
        self._dec_status = msgspec.msgpack.Decoder(StatusMsg)
        self.tel: list[TelemetryMsg] = []
        self.states: list[StateMsg] = []
        self.statuses: list[StatusMsg] = []
        self.misrouted: Counter[str] = Counter()
        """Messages of another type received on the state or status key, by key."""
        self.robot = w.load_robot_config(stack.robot_file)
        self._asked = 0.0

    def keep_tracking(self) -> None:
        """Ask for ``track`` again when a fault held the robot (mode ``hold`` outside a safe stop),
        as an operator does, at most every 0.5 s: on a loaded host a deadline fault may hold the
        robot in the middle of a drill that is about something else."""
        st = self.client.latest_status()
        now = time.monotonic()
        if st is not None and st.mode == "hold" and not st.safe_stop and now - self._asked > 0.5:
            self.client.set_mode("track")
            self._asked = now

    def close(self) -> None:
        """Close the client's session."""
        self.client.close()

    def drain(self) -> None:
        """Collect everything received so far."""
        self.tel += self.client.telemetry()
        while (s := self._sub_state.try_recv()) is not None:
            try:
                self.states.append(self._dec_state.decode(s.payload.to_bytes()))
            except msgspec.DecodeError:  # not a state on the state key: count it
                self.misrouted[str(s.key_expr)] += 1
        if (s := self._sub_truth.try_recv()) is not None:
            with contextlib.suppress(msgspec.DecodeError):
                self.truth = self._dec_truth.decode(s.payload.to_bytes())
        while (s := self._sub_status.try_recv()) is not None:
            try:
                self.statuses.append(self._dec_status.decode(s.payload.to_bytes()))
            except msgspec.DecodeError:
                self.misrouted[str(s.key_expr)] += 1

    def clear(self) -> None:
        """Forget what was collected (and drain what is pending)."""
        self.drain()
        self.tel, self.states, self.statuses, self.truth = [], [], [], None

    def until(self, pred: Callable[[], Any], timeout: float = 30.0, stream: np.ndarray | None = None) -> Any:
        """Drain (and stream ``stream`` as setpoint) until ``pred()`` is truthy; returns it."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if stream is not None:
                self.client.send_setpoint(stream)
            self.drain()
            if v := pred():
                return v
            time.sleep(0.005)
        raise TimeoutError(f"condition not met within {timeout} s")

    def ready(self, timeout: float = 30.0) -> Any:
        """Wait for the daemon to answer with a fresh state; returns its info."""
        if self.client.wait_for_daemon(timeout) is None:
            raise TimeoutError("the daemon did not answer")
        return self.until(lambda: (i := self.client.info()) is not None and i.status.state_ok and i,
                          timeout)

    def move(self, x0: np.ndarray, seconds: float, radius: float = 0.05, until_moving: float = 0.0,
             keep_tracking: bool = False) -> float:
        """Stream a circle of ``radius`` [m] around ``x0`` for ``seconds`` (the robot moves); with
        ``until_moving`` > 0 go on streaming (up to that many seconds more) until a fresh state shows
        the robot moving, and return its largest executed rate [rad/s] (0 if it never moved); with
        ``keep_tracking``, ask for track again whenever a fault holds the robot."""
        t0 = time.monotonic()
        while (t := time.monotonic() - t0) < seconds + until_moving:
            om = 2.0
            self.client.send_setpoint(x0 + radius * np.array([np.sin(om * t), 1 - np.cos(om * t), 0.0]),
                                      radius * om * np.array([np.cos(om * t), np.sin(om * t), 0.0]))
            self.drain()
            if keep_tracking:
                self.keep_tracking()
            if until_moving > 0.0 and t >= seconds and self.states and _moving(self.states[-1]) > 1e-3:
                return _moving(self.states[-1])
            time.sleep(0.01)
        return _moving(self.states[-1]) if self.states else 0.0

    def violations(self) -> dict[str, int]:
        """The sim's referee counts from a fresh ``sim/truth`` message."""
        tr = self.until(lambda: self.truth)
        return dict(tr.violations)

    def first_tel(self, pred: Callable[[TelemetryMsg], bool], after: float) -> TelemetryMsg | None:
        """The first telemetry stamped after ``after`` [s, wall] satisfying ``pred``."""
        return next((m for m in self.tel if m.stamp >= after and pred(m)), None)

    def first_state(self, pred: Callable[[StateMsg], bool], after: float) -> StateMsg | None:
        """The first state stamped after ``after`` satisfying ``pred``."""
        return next((m for m in self.states if m.stamp >= after and pred(m)), None)

    def first_status(self, pred: Callable[[StatusMsg], bool], after: float) -> StatusMsg | None:
        """The first status stamped after ``after`` satisfying ``pred``."""
        return next((m for m in self.statuses if m.stamp >= after and pred(m)), None)

    def step_bound_ratio(self, cmd: TelemetryMsg, v_arm: np.ndarray, wheels: np.ndarray, dt: float) -> float:
        """max |cmd − v| / (A·dt) over joints and wheels (≤ 1: inside the acceleration bounds)."""
        a = np.asarray(self.robot.arm.acceleration_max) * dt
        wa = np.asarray(self.robot.base.wheel_acceleration_max) * dt
        ratios = np.concatenate([np.abs(np.subtract(cmd.arm_rates, v_arm)) / a,
                                 np.abs(np.subtract(cmd.wheel_speeds, wheels)) / wa])  # no wheels: arm only
        return float(ratios.max())


def _moving(st: StateMsg) -> float:
    return float(np.abs(np.concatenate([st.v_arm, st.wheel_speeds])).max())


def sim_kill_and_restart(p: Probe, rate_hz: float) -> dict[str, Any]:
    """SIGKILL the sim mid-motion, then restart it.

    Returns:
        ``detect_s``: kill → first safe-stop command; ``zero_s``: kill → first all-zero command;
        ``fault``, ``fault_code``: the daemon's last fault (message, code);
        ``resume_s``: restart → first normal command;
        ``first_cmd_ratio``: the first normal command against the acceleration bounds around
        the measured (restarted sim's) rates, as a fraction of A·dt (≤ 1 inside);
        ``max_step_ratio``: the largest step between consecutive commands in the 0.5 s after
        resuming, same units; ``violations``: the new sim's referee after that.
    """
    info = p.ready()
    p.client.set_mode("track")
    x0 = np.array(info.status.x)
    p.move(x0, 1.5)
    p.clear()
    t_kill = time.time()
    p.stack.kill("sim", signal.SIGKILL)
    safe = p.until(lambda: p.first_tel(lambda m: m.status == SAFE, t_kill))
    zero = p.until(lambda: p.first_tel(lambda m: m.status == SAFE and not np.any(m.arm_rates)
                                       and not np.any(m.wheel_speeds), t_kill))
    held = p.until(lambda: (i := p.client.info()) is not None and i.status.safe_stop and i).status
    p.clear()
    t_start = time.time()
    p.stack.start_sim()
    first = p.until(lambda: p.first_tel(lambda m: m.status != SAFE, t_start), timeout=60.0)
    # the restarted sim's state the command was computed from: the last state before it
    p.until(lambda: p.states and p.states[-1].stamp > first.stamp)
    before = [s for s in p.states if s.stamp <= first.stamp]
    st = before[-1] if before else p.states[0]
    dt = 1.0 / rate_hz
    ratio = p.step_bound_ratio(first, np.array(st.v_arm), np.array(st.wheel_speeds), dt)
    p.move(x0, 0.5)  # track again: resumed
    p.drain()
    seq = [m for m in p.tel if m.stamp >= first.stamp]
    steps = [p.step_bound_ratio(b, np.array(a.arm_rates), np.array(a.wheel_speeds), dt)
             for a, b in itertools.pairwise(seq) if b.seq == a.seq + 1]
    return {"detect_s": safe.stamp - t_kill, "zero_s": zero.stamp - t_kill, "fault": held.last_fault,
            "fault_code": held.last_fault_code,
            "resume_s": first.stamp - t_start, "first_cmd_ratio": ratio,
            "max_step_ratio": max(steps) if steps else float("nan"), "resumed_ticks": len(seq),
            "violations": p.violations()}


def daemon_kill_and_restart(p: Probe) -> dict[str, Any]:
    """SIGKILL the daemon mid-motion, then restart it.

    Returns:
        ``speed_at_kill``: [rad/s] largest executed rate; ``detect_s``: kill → first state with
        ``stale_stop``; ``stop_s``: kill → first state at rest; ``resume_s``: restart → the
        daemon answers with a fresh state; ``tracking_error``: [m] EE (ground truth) against
        a fixed target 2 s after resuming; ``violations``: the sim's referee.
    """
    info = p.ready()
    p.client.set_mode("track")
    x0 = np.array(info.status.x)
    p.clear()
    # kill while the stream goes on and a fresh state shows the robot moving (on a loaded machine
    # the robot could have come to rest between the end of a fixed-length stream and the kill)
    speed = p.move(x0, 1.5, until_moving=10.0)
    t_kill = time.time()
    p.stack.kill("daemon", signal.SIGKILL)
    det = p.until(lambda: p.first_state(lambda s: s.stale_stop, t_kill))
    stop = p.until(lambda: p.first_state(lambda s: s.stale_stop and _moving(s) == 0.0, t_kill))
    t_start = time.time()
    p.stack.start_daemon()
    info = p.ready(60.0)
    resume = time.time() - t_start
    p.client.set_mode("track")
    p.until(lambda: (i := p.client.info()) is not None and i.status.mode == "track")
    target = np.array(info.status.x) + np.array([0.03, 0.0, 0.0])
    # until the EE is there (2 s had left 1.6 cm on a loaded CI machine); a fault on a loaded host
    # holds the robot again, and the operator asks for track again, as a user would
    t_end = time.monotonic() + 20.0
    while time.monotonic() < t_end:
        p.keep_tracking()
        p.client.send_setpoint(target)
        time.sleep(0.01)
        p.drain()
        if p.truth is not None and float(np.linalg.norm(np.array(p.truth.ee_true) - target)) < 0.002:
            break
    p.clear()
    tr = p.until(lambda: p.truth)
    return {"speed_at_kill": speed, "detect_s": det.stamp - t_kill, "stop_s": stop.stamp - t_kill,
            "resume_s": resume, "tracking_error": float(np.linalg.norm(np.array(tr.ee_true) - target)),
            "violations": dict(tr.violations)}


_FLOODER = """
import sys, time
from wmm_qp_service.client import Client
from wmm_qp_service.config import load_service_config
prefix, rate, seconds, x, y, z = sys.argv[1], float(sys.argv[2]), float(sys.argv[3]), *map(float, sys.argv[4:7])
ep_d, ep_s, robot = sys.argv[7], sys.argv[8], sys.argv[9]
svc = load_service_config().with_(prefix=prefix, robot=robot,
                                  zenoh={"daemon_endpoint": ep_d, "sim_endpoint": ep_s})
with Client(svc, name="flooder") as c:
    c.wait_for_daemon(10.0)
    n, t0 = 0, time.perf_counter()
    while (el := time.perf_counter() - t0) < seconds:
        while n < el * rate:
            c.send_setpoint([x, y, z])
            n += 1
        time.sleep(0.0005)
    print(n / (time.perf_counter() - t0), flush=True)
"""


def setpoint_flood(p: Probe, factor: float = 10.0, seconds: float = 5.0) -> dict[str, Any]:
    """Another process floods setpoints at ``factor`` × the loop rate for ``seconds``.

    Returns:
        ``flood_rate``: [1/s] achieved; ``base_hz``/``flood_hz``: [Hz] ticks per second of the
        daemon without and during the flood; ``base_misses``/``flood_misses``: deadline misses
        in the same windows; ``setpoints_accepted``: during the flood.
    """
    info = p.ready()
    rate = info.status.loop.rate_hz
    p.client.set_mode("track")
    x = info.status.x

    def window(fn: Callable[[], Any]) -> tuple[float, int, int, Any]:
        a = p.client.info()
        t0 = time.monotonic()
        out = fn()
        b = p.client.info()
        el = time.monotonic() - t0
        assert a is not None and b is not None
        return ((b.status.loop.ticks - a.status.loop.ticks) / el,
                b.status.loop.deadline_misses - a.status.loop.deadline_misses,
                b.status.accepted.get("setpoint", 0) - a.status.accepted.get("setpoint", 0), out)

    svc = p.stack.svc
    base_hz, base_miss, _, _ = window(lambda: time.sleep(seconds))
    argv = [sys.executable, "-P", "-c", _FLOODER, svc.prefix, f"{factor * rate}", f"{seconds}",
            *(f"{v}" for v in x), svc.zenoh.daemon_endpoint, svc.zenoh.sim_endpoint, svc.robot]
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        time.sleep(2.0)  # the flooder's start-up (imports, session)
        flood_hz, flood_miss, acc, _ = window(lambda: time.sleep(seconds - 2.5))
        out, _ = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)
    return {"loop_rate_hz": rate, "flood_rate": float(out.strip() or "nan"), "base_hz": base_hz,
            "flood_hz": flood_hz, "base_misses": base_miss, "flood_misses": flood_miss,
            "flood_window_s": seconds - 2.5, "setpoints_accepted": acc}


def state_faults(p: Probe, sim_args: list[str], seconds: float = 3.0) -> dict[str, Any]:
    """Restart the sim with fault-injection arguments (e.g. ``--state-loss 0.05``) and track a circle.

    Returns:
        ``safe_stop_ticks``: commands that were safe stops while tracking; ``ticks``;
        ``ee_error_max``/``ee_error_p50``: [m] ground truth against the target; ``faults``: the
        daemon's last_fault; ``violations``.
    """
    p.stack.kill("sim", signal.SIGKILL)
    p.stack.extra_sim_args = list(sim_args)
    p.stack.start_sim()
    info = p.ready(60.0)
    p.client.set_mode("track")
    p.until(lambda: (i := p.client.info()) is not None and i.status.mode == "track")
    x0 = np.array(info.status.x)
    time.sleep(0.3)
    p.clear()
    # the drill is about the lost states: a deadline fault of a loaded host that holds the robot is
    # answered as an operator would, so the window has track ticks to judge
    p.move(x0, seconds, keep_tracking=True)
    p.drain()
    tel = [m for m in p.tel if m.mode == "track"]
    err = [m.ee_error for m in tel if np.isfinite(m.ee_error)]
    i = p.client.info()
    out = {"sim_args": sim_args, "ticks": len(tel), "safe_stop_ticks": sum(m.status == SAFE for m in tel),
           "ee_error_max": max(err) if err else float("nan"),
           "ee_error_p50": float(np.median(err)) if err else float("nan"),
           "state_ok": bool(i and i.status.state_ok), "last_fault": i.status.last_fault if i else "",
           "faults": dict(i.status.faults) if i else {}, "violations": p.violations()}
    # the next scenarios need a healthy stack: a delayed state is a fault the daemon now holds on
    p.stack.kill("sim", signal.SIGKILL)
    p.stack.extra_sim_args = []
    p.stack.start_sim()
    p.ready(60.0)
    return out


def sigstop(p: Probe, name: str, hold_s: float = 3.0) -> dict[str, Any]:
    """SIGSTOP one process (``sim`` or ``daemon``) for ``hold_s``, then SIGCONT.

    Returns, for the sim: ``safe_s`` (first safe-stop command), ``liveliness_s`` (first status
    with ``robot_alive`` false: the lease); for the daemon: ``sim_stop_s`` (first sim state with
    ``stale_stop``), ``liveliness_s`` (the daemon's token gone from a liveliness query, observer
    clock); both: ``resume_s`` (SIGCONT → the daemon answers with a fresh state again).
    """
    info = p.ready()
    p.client.set_mode("track")
    x0 = np.array(info.status.x)
    p.move(x0, 1.0)
    p.clear()
    misrouted0 = sum(p.misrouted.values())
    proc = p.stack.procs[name]
    out: dict[str, Any] = {"peer": name}
    t0 = time.time()
    proc.send_signal(signal.SIGSTOP)
    try:
        if name == "sim":
            safe = p.until(lambda: p.first_tel(lambda m: m.status == SAFE, t0), timeout=10.0)
            out["safe_s"] = safe.stamp - t0
            gone = p.until(lambda: p.first_status(lambda s: not s.robot_alive, t0), timeout=15.0)
            out["liveliness_s"] = gone.stamp - t0
        else:
            det = p.until(lambda: p.first_state(lambda s: s.stale_stop, t0), timeout=10.0)
            out["sim_stop_s"] = det.stamp - t0
            p.until(lambda: "daemon" not in p.client.alive(0.5), timeout=15.0)
            out["liveliness_s"] = time.time() - t0
        time.sleep(max(0.0, hold_s - (time.time() - t0)))
    finally:
        proc.send_signal(signal.SIGCONT)
    t1 = time.time()
    p.clear()
    p.until(lambda: (i := p.client.info()) is not None and i.status.state_ok
            and i.status.loop.ticks > 0 and i, timeout=60.0)
    out["resume_s"] = time.time() - t1
    p.move(x0, 1.0)
    out["violations"] = p.violations()
    out["probe_misrouted"] = sum(p.misrouted.values()) - misrouted0
    i = p.client.info()
    out["daemon_rejected"] = dict(i.status.rejected) if i else {}
    return out
