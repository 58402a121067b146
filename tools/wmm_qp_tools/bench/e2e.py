"""End-to-end: daemon + sim processes over Zenoh, each trigger and rate, beside the embedded
stack (one process: the control core in the sim's cycle) and the machine's floor (``--only e2e``).

Per case (:data:`CASES`: the fixed-rate loop at 500 Hz and 1 kHz, the state-triggered loop at
1 kHz, the sim's rate): start ``wmm-qp sim`` and ``wmm-qp serve --rate R --trigger T`` on
loopback (unique prefix and ports), wait for a valid state, then track the paper's circle (a
setpoint stream at 100 Hz with feed-forward velocity, so the QP works on a moving reference and
the robot moves) for ``ticks`` control ticks. A client records every state of the sim and every
tick's telemetry of the daemon (``loop.telemetry_every = 1``) and the daemon's loop counters
before and after.

Figures per case:

- ``achieved_hz``: daemon ticks per second of daemon time over the window (telemetry ``t``).
- ``tick_us``: the daemon's work per tick (telemetry ``tick_us``: inputs, validation,
  watchdogs, smoothing, ``ctl.step``, command encode and publish, telemetry), p50/p99/max over
  all ticks; ``step_us``: ``ctl.step`` alone in the same ticks (telemetry ``step_us``);
  ``tick_over_step_p50``: their ratio.
- ``deadline_misses`` and ``misses_per_10k``: the daemon's own counter over the window (rate:
  a tick that starts after its deadline; state: a tick whose command comes more than a period
  after its state, and every watchdog tick); ``watchdog_ticks`` (state: no state for 1.5
  periods, the prediction path).
- ``state_to_cmd_us``: from the sim publishing state k (its ``stamp``) to the daemon publishing
  the command computed from it (the telemetry's ``state_seq`` = k and ``cmd_stamp``), split into
  ``state_transport_us`` (to the daemon's receipt, ``state_rx``) and ``daemon_us`` (receipt to
  publication). Both processes' ``time.time()``, one machine.
- ``applied_next_step``: the fraction of the window's states k whose command (the one computed
  from k) is the one the sim applied at step k + 1 (state k + 1's ``cmd_seq``).
- ``cmd_to_applied_us``: from the command's publication to the first sim state reporting it
  applied; ``cmds_not_applied``: commands the sim never applied (a newer one arrived before its
  step: overwritten).
- ``cpu_pct``: each process's CPU share over the window, % of one core
  (:class:`~.machine.CpuMeter`: /proc CPU time over wall time): ``daemon``, ``sim`` and this
  recording client.
- ``telemetry_lost``: gaps in the telemetry's seq (transport drops to the recording client).

The embedded stack (``embedded.<rate>``, :data:`EMBEDDED_RATES`): ``wmm-qp sim --embedded
--control-rate R`` alone, the same circle and recording client, the same figures (its state →
command is the state's stamp → the command handed to the robot, in one thread: validation and
the tick; ``state_transport_us`` is the hand-over, ``daemon_us`` the rest); ``cpu_pct`` names
``embedded`` and ``client``; ``cycle``: the process's own cycle report (``--cycle-report``: its
ticks, misses, the tick's work, the garbage collector's collections in the slack). At 500 Hz the
core ticks every other cycle of the 1 kHz sim: half the states have no command of their own.

``embedded_plain.<rate>``: the embedded stack without its cycle's cost cuts (``--plain-cycle``:
the interpreter's own garbage collection, no spin before the deadline,
the service thread at normal priority), in the same run: what the cuts buy.

The floor (``floor.<rate>``): an empty loop at the sim's rate with the embedded loop's settings
(the service config's spin, the sim's SCHED_FIFO priority), :func:`~.jitter.run_one`: the misses
the machine makes whatever the work.
"""

from __future__ import annotations

import json
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import msgspec
import numpy as np
from wmm_qp_service.machine import CPU_HOW, CpuMeter, loadavg

from wmm_qp import RobotConfig

CASES: tuple[tuple[str, float], ...] = (("rate", 500.0), ("rate", 1000.0), ("state", 1000.0))
"""(trigger, rate [Hz]) of each case; the state-triggered loop runs at the sim's rate (1 kHz)."""
EMBEDDED_RATES: tuple[float, ...] = (500.0, 1000.0)
"""[Hz] the embedded stack's control rates (the sim's cycle is 1 kHz)."""
PLAIN_RATES: tuple[float, ...] = (1000.0,)
"""[Hz] the embedded stack without its cycle's cost cuts (``--plain-cycle``), beside it."""
FLOOR_RATES: tuple[float, ...] = (1000.0,)
"""[Hz] the empty loop's rates (the robot's cycle)."""
SETPOINT_HZ = 100.0  # [Hz]
STARTUP_TIMEOUT = 60.0  # [s]


def case_key(trigger: str, rate_hz: float) -> str:
    """The result's key of a case: ``"rate 500"``, ``"state 1000"``."""
    return f"{trigger} {rate_hz:g}"


def _pct(a: np.ndarray) -> dict[str, float]:
    a = a[np.isfinite(a)] if a.size else a
    if a.size == 0:
        nan = float("nan")
        return {"p50": nan, "p99": nan, "p999": nan, "max": nan, "n": 0}
    p50, p99, p999 = np.percentile(a, [50.0, 99.0, 99.9])
    return {"p50": round(float(p50), 1), "p99": round(float(p99), 1), "p999": round(float(p999), 1),
            "max": round(float(a.max()), 1), "n": int(a.size)}


def run_case(
    trigger: str,
    rate_hz: float,
    ticks: int,
    log_dir: Path | None = None,
    robot: RobotConfig | None = None,
    controller_file: Path | None = None,
    breakdown: bool = False,
    plain: bool = False,
    extra_daemon_args: list[str] | None = None,
    collision: bool = False,
) -> dict[str, Any]:
    """One case: start the stack, track the circle for ``ticks`` ticks, measure, stop.

    Args:
        trigger: the daemon's ``loop.trigger`` (``rate`` or ``state``), or ``embedded`` (one
            process: ``wmm-qp sim --embedded``).
        rate_hz: [Hz] daemon rate.
        ticks: control ticks to measure (duration = ticks / rate_hz).
        log_dir: the processes' logs (None: a temporary folder).
        robot: the robot; the sim and the daemon load its file and run under its name (None:
            their default).
        controller_file: the daemon's controller config (None: its default).
        breakdown: the daemon times each stage of its ticks (``--breakdown``): the result gains
            ``breakdown`` (:meth:`~..tick_stages.TickStages.summary`, over the ticks that
            published a command, start-up included).
        plain: the embedded stack without its cycle's cost cuts (``--plain-cycle``).
        extra_daemon_args: more arguments of the daemon (``--record FILE``: :mod:`.record`).
        collision: the collision rows as the controller config has them (on by default, with the
            daemon's default scene); False: ``--no-collision``, the loop as §5's figures were taken.

    Returns:
        The figures of the module docstring, plus the load average, exit codes and faults.
    """
    from wmm_qp_service.client import Client, NotReady
    from wmm_qp_service.processes import Stack, isolated_config
    from wmm_qp_service.protocol import StateMsg
    from wmm_qp_service.streams import circle

    log_dir = log_dir or Path(tempfile.mkdtemp(prefix=f"wmm-qp-e2e-{trigger}-{rate_hz:g}-"))
    svc = isolated_config(robot=robot)
    duration = ticks / rate_hz
    out: dict[str, Any] = {
        "trigger": trigger,
        "rate_hz": rate_hz,
        "duration_s": round(duration, 2),
        "loadavg_before": loadavg(),
        "logs": str(log_dir),
        "collision": collision,
    }
    embedded = trigger == "embedded"
    args = [] if embedded else ["--trigger", trigger]
    args += [] if controller_file is None else ["--controller-config", str(controller_file)]
    if not collision:
        args += ["--no-collision"]  # the loop as §5 (docs/benchmarks.md) took its figures
    breakdown_file = log_dir / "breakdown.json"
    cycle_file = log_dir / "cycle.json"
    if breakdown and not embedded:
        args += ["--breakdown", str(breakdown_file)]
    if embedded:
        args += ["--cycle-report", str(cycle_file)] + (["--plain-cycle"] if plain else [])
    args += extra_daemon_args or []
    stack = Stack(svc, rate_hz=rate_hz, log_dir=log_dir, extra_daemon_args=args, embedded=embedded,
                  robot_file=None if robot is None else robot.path)  # fmt: skip
    svc = stack.svc
    info0 = info1 = None
    states_raw: list[bytes] = []
    truths: dict[int, Any] = {}
    tel: list[Any] = []
    cpu: dict[str, float | None] = {}
    load_during: list[float] = []
    try:
        stack.start()
        with Client(svc, name="bench-e2e", telemetry=True) as c:
            try:
                info = c.wait_ready(STARTUP_TIMEOUT, state_timeout=STARTUP_TIMEOUT, exited=stack.exited)
            except NotReady as e:
                return out | {"available": False, "reason": f"the stack did not come up: {e} (logs: {log_dir})"}
            st = c.wait_truth(5.0)
            if st is None:
                return out | {"available": False, "reason": f"the sim sent no evaluation data (logs: {log_dir})"}
            out["controller"] = info.config.get("controller", {}).get("kind")
            out["solver"] = info.config.get("controller", {}).get("solver")
            from wmm_qp_tools.experiments.realtime import Recorder

            x0 = np.array(st.ee_true)
            rec = Recorder(c).open()
            c.set_mode("track")
            time.sleep(0.2)  # let the mode switch settle; measure from here
            rec.drain()
            rec.states.clear()
            rec.telemetry.clear()
            info0 = c.info()
            meter = CpuMeter({**{n: p.pid for n, p in stack.procs.items()}, "client": os.getpid()})
            t0 = time.monotonic()
            k = 0
            next_load = t0
            while (t := time.monotonic() - t0) < duration:
                x, xd = circle(x0, t + 0.2)
                c.send_setpoint(x, xd)
                rec.drain()
                k += 1
                if time.monotonic() >= next_load:
                    load_during.append(round(os.getloadavg()[0], 2))
                    next_load += 5.0
                time.sleep(max(0.0, t0 + k / SETPOINT_HZ - time.monotonic()))
            cpu = meter.shares()
            info1 = c.info()
            rec.drain()
            c.set_mode("hold")
            rec.close()
            states_raw, tel, truths = rec.states, rec.telemetry, rec.truth_by_seq()
            out["not_truths"] = rec.not_truths  # messages on the truth key that were no truth
    finally:
        out["exit_codes"] = stack.stop()
    for key, wanted, path in (("breakdown", breakdown and not embedded, breakdown_file),
                              ("cycle", embedded, cycle_file)):
        if wanted:
            try:
                out[key] = json.loads(path.read_text(encoding="utf-8"))
            except (OSError, ValueError) as e:
                out[key] = {"available": False, "reason": f"{path}: {e}"}
    if info0 is None or info1 is None or not tel or not states_raw:
        return out | {"available": False, "reason": "no status or no telemetry during the window"}
    dec = msgspec.msgpack.Decoder(StateMsg)
    states = [dec.decode(b) for b in states_raw]
    return out | figures(states, tel, info0.status.loop, info1.status.loop) | {
        "cpu_pct": cpu,
        "cpu_how": CPU_HOW,
        "loadavg_during": load_during,
        "violations": dict(truths[max(truths)].violations) if truths else {},
        "rejected": dict(info1.status.rejected),
        "last_fault": info1.status.last_fault,
        "faults": dict(info1.status.faults),
        "collision": bool(info1.status.collision),  # the daemon's own word: its controller had rows
        "collision_summary": info1.status.collision_summary,
        "loadavg_after": loadavg(),
    }


def figures(states: list[Any], tel: list[Any], l0: Any, l1: Any) -> dict[str, Any]:
    """The latency and delivery figures of one window (module docstring) from the recorded sim
    states, the daemon's telemetry, and its loop counters before (``l0``) and after (``l1``)."""
    n_ticks = l1.ticks - l0.ticks
    misses = l1.deadline_misses - l0.deadline_misses
    t_tel = np.array([m.t for m in tel])
    seqs = np.array([m.seq for m in tel])
    by_seq = {s.seq: s for s in states}
    # state → command, exactly: the command's state_seq names the state
    from_state = [m for m in tel if m.state_seq >= 0 and m.state_seq in by_seq]
    s2c = np.array([(m.cmd_stamp - by_seq[m.state_seq].stamp) * 1e6 for m in from_state])
    transport = np.array([(m.state_rx - by_seq[m.state_seq].stamp) * 1e6 for m in from_state])
    daemon = np.array([(m.cmd_stamp - m.state_rx) * 1e6 for m in from_state])
    cmd_of_state = {m.state_seq: m.seq for m in from_state}
    cmd_stamp = {m.seq: m.cmd_stamp for m in tel}
    # the command from state k applied at step k + 1 (states of one sim: consecutive seq)
    lo, hi = min(by_seq), max(by_seq)
    window = [k for k in range(lo + 1, hi - 1) if k in by_seq and k + 1 in by_seq]
    on_time = sum(1 for k in window if k in cmd_of_state and by_seq[k + 1].cmd_seq == cmd_of_state[k])
    applied: list[float] = []
    seen: set[int] = set()
    prev = None
    for s in states:
        if s.cmd_seq != prev and s.cmd_seq in cmd_stamp:
            applied.append((s.stamp - cmd_stamp[s.cmd_seq]) * 1e6)
            seen.add(s.cmd_seq)
        prev = s.cmd_seq
    in_window = [q for q in cmd_stamp if seqs[0] < q < seqs[-1] - 2]  # the last ones may be in flight
    span = float(t_tel[-1] - t_tel[0])
    tick = _pct(np.array([m.tick_us for m in tel]))
    step = _pct(np.array([m.step_us for m in tel]))
    wd = getattr(l1, "watchdog_ticks", 0) - getattr(l0, "watchdog_ticks", 0)
    return {
        "available": True,
        "ticks": n_ticks,
        "achieved_hz": round(float(seqs[-1] - seqs[0]) / span, 2) if span > 0 else None,
        "tick_us": tick,
        "step_us": step,
        "tick_over_step_p50": round(tick["p50"] / step["p50"], 2) if step["n"] and step["p50"] > 0 else None,
        "deadline_misses": misses,
        "misses_per_10k": round(1e4 * misses / n_ticks, 2) if n_ticks else None,
        "watchdog_ticks": wd,
        "state_to_cmd_us": _pct(s2c),
        "state_transport_us": _pct(transport),
        "daemon_us": _pct(daemon),
        "states_in_window": len(window),
        "applied_next_step": round(on_time / len(window), 5) if window else None,
        "states_without_command": sum(1 for k in window if k not in cmd_of_state),
        "cmd_to_applied_us": _pct(np.array(applied)),
        "cmds_not_applied": sum(1 for q in in_window if q not in seen),
        "cmds_in_window": len(in_window),
        "predicted_cmds": sum(1 for m in tel if m.state_seq < 0),
        "telemetry_lost": int(np.sum(np.diff(seqs) - 1)),
        "daemon_loop_end": msgspec.to_builtins(l1),
    }


def run(
    ticks: int,
    cases: tuple[tuple[str, float], ...] = CASES,
    robot: RobotConfig | None = None,
    controller_file: Path | None = None,
    embedded_rates: tuple[float, ...] = EMBEDDED_RATES,
    plain_rates: tuple[float, ...] = PLAIN_RATES,
    floor_rates: tuple[float, ...] = FLOOR_RATES,
) -> dict[str, Any]:
    """Every case in turn, in one run: {"available", "<trigger> <rate>": figures of
    :func:`run_case` (the split stack), "embedded": {"<rate>": the same figures of the embedded
    stack}, "embedded_plain": {"<rate>": the same without its cycle's cost cuts}, "floor":
    {"<rate>": :func:`~.jitter.run_one` of the embedded loop's settings, empty}}."""
    from wmm_qp_service.config import load_service_config
    from wmm_qp_sim import load_sim_config

    from wmm_qp_tools.bench.jitter import run_one

    out: dict[str, Any] = {"available": True}
    for trigger, r in cases:
        print(f"e2e: {trigger} trigger, {r:g} Hz for {ticks} ticks ({ticks / r:.0f} s)", file=sys.stderr, flush=True)
        res = run_case(trigger, r, ticks, robot=robot, controller_file=controller_file)
        out[case_key(trigger, r)] = res
        out["available"] = out["available"] and bool(res.get("available"))
    out["embedded"] = {}
    for r in embedded_rates:
        print(f"e2e: embedded, {r:g} Hz for {ticks} ticks ({ticks / r:.0f} s)", file=sys.stderr, flush=True)
        res = run_case("embedded", r, ticks, robot=robot, controller_file=controller_file)
        out["embedded"][f"{r:g}"] = res
        out["available"] = out["available"] and bool(res.get("available"))
    out["embedded_plain"] = {}
    for r in plain_rates:
        print(f"e2e: embedded without the cuts, {r:g} Hz for {ticks} ticks ({ticks / r:.0f} s)", file=sys.stderr,
              flush=True)
        res = run_case("embedded", r, ticks, robot=robot, controller_file=controller_file, plain=True)
        out["embedded_plain"][f"{r:g}"] = res
    sim_cfg, spin_us = load_sim_config(), load_service_config().loop.spin_us
    out["floor"] = {}
    for r in floor_rates:
        n = min(ticks, int(60 * r))
        print(f"e2e: the floor, an empty {r:g} Hz loop for {n} ticks ({n / r:.0f} s)", file=sys.stderr, flush=True)
        out["floor"][f"{r:g}"] = run_one(n, r, spin_us, sim_cfg.rt_priority)
    return out
