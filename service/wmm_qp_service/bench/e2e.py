"""End-to-end over Zenoh: daemon + sim processes at 500 Hz and 1 kHz (``--only e2e``).

Per rate: start ``wmm-qp sim`` and ``wmm-qp serve --rate R`` on loopback (unique prefix and
ports), wait for a valid state, then track the paper's circle (a setpoint stream at 100 Hz
with feed-forward velocity, so the QP works on a moving reference and the robot moves) for
``ticks`` control ticks. A client records every state of the sim and every tick's telemetry
of the daemon (``loop.telemetry_every = 1``) and the daemon's loop counters before and after.

Figures per rate:

- ``achieved_hz``: daemon ticks per second of daemon time over the window (telemetry ``t``).
- ``tick_us``: the daemon's work per tick (telemetry ``tick_us``: inputs, validation,
  watchdogs, smoothing, ``ctl.step``, command encode and publish), p50/p99/max over all ticks.
- ``deadline_misses`` and ``misses_per_10k``: the daemon's own counter over the window
  (a tick that starts after its deadline).
- ``state_to_cmd_us``: from the sim publishing a state to the daemon publishing the command
  computed from it (stamps of the two processes, same machine clock). The telemetry carries
  the ground-truth EE of the state the daemon used, which identifies that state exactly
  among the recorded ones while the robot moves. Includes the wait for the daemon's next tick
  (up to one period) and the tick's work. The telemetry stamp is taken right after the
  command's publication (a few µs later).
- ``cmd_to_applied_us``: from the command's publication to the first sim state reporting it
  applied (``StateMsg.cmd_seq``); ``cmds_not_applied``: commands the sim never applied
  (overwritten in its depth-1 ring by a newer one before its tick).
- ``telemetry_lost``: gaps in the telemetry's seq (transport drops to the recording client).
"""

from __future__ import annotations

import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import msgspec
import numpy as np

from wmm_qp import RobotConfig

RATES: tuple[float, ...] = (500.0, 1000.0)
SETPOINT_HZ = 100.0  # [Hz]
STARTUP_TIMEOUT = 60.0  # [s]


def _pct(a: np.ndarray) -> dict[str, float]:
    if a.size == 0:
        nan = float("nan")
        return {"p50": nan, "p99": nan, "max": nan, "n": 0}
    p50, p99 = np.percentile(a, [50.0, 99.0])
    return {"p50": round(float(p50), 1), "p99": round(float(p99), 1), "max": round(float(a.max()), 1), "n": int(a.size)}


def run_rate(
    rate_hz: float,
    ticks: int,
    log_dir: Path | None = None,
    robot: RobotConfig | None = None,
    controller_file: Path | None = None,
) -> dict[str, Any]:
    """One rate: start the stack, track the circle for ``ticks`` ticks, measure, stop.

    Args:
        rate_hz: [Hz] daemon rate.
        ticks: control ticks to measure (duration = ticks / rate_hz).
        log_dir: the processes' logs (None: a temporary folder).
        robot: the robot; the sim and the daemon load its file and run under its name (None:
            their default).
        controller_file: the daemon's controller config (None: its default).

    Returns:
        The figures of the module docstring, plus the load average, exit codes and faults.
    """
    from ..client import Client
    from ..experiments.circle import circle
    from ..experiments.realtime import Recorder, match_states
    from ..processes import Stack, isolated_config
    from ..protocol import StateMsg

    log_dir = log_dir or Path(tempfile.mkdtemp(prefix=f"wmm-qp-e2e-{rate_hz:g}-"))
    svc = isolated_config(robot=robot)
    duration = ticks / rate_hz
    out: dict[str, Any] = {
        "rate_hz": rate_hz,
        "duration_s": round(duration, 2),
        "loadavg_before": [round(x, 2) for x in os.getloadavg()],
        "logs": str(log_dir),
    }
    ctl_args = [] if controller_file is None else ["--controller-config", str(controller_file)]
    stack = Stack(svc, rate_hz=rate_hz, log_dir=log_dir, extra_daemon_args=ctl_args,
                  robot_file=None if robot is None else robot.path)  # fmt: skip
    svc = stack.svc
    try:
        stack.start()
        with Client(svc, name="bench-e2e", telemetry=True) as c:
            info = c.wait_for_daemon(STARTUP_TIMEOUT)
            end = time.monotonic() + STARTUP_TIMEOUT
            while info is not None and not info.status.state_ok and time.monotonic() < end:
                time.sleep(0.1)
                info = c.info()
            st = c.wait_state(5.0)
            if info is None or not info.status.state_ok or st is None:
                return out | {"available": False, "reason": f"the stack did not come up (logs: {log_dir})"}
            out["controller"] = info.config.get("controller", {}).get("kind")
            out["solver"] = info.config.get("controller", {}).get("solver")
            x0 = np.array(st.ee_true)
            rec = Recorder(c).open()
            c.set_mode("track")
            time.sleep(0.2)  # let the mode switch settle; measure from here
            rec.drain()
            rec.states.clear()
            rec.telemetry.clear()
            info0 = c.info()
            t0 = time.monotonic()
            k = 0
            while (t := time.monotonic() - t0) < duration:
                x, xd = circle(x0, t + 0.2)
                c.send_setpoint(x, xd)
                rec.drain()
                k += 1
                time.sleep(max(0.0, t0 + k / SETPOINT_HZ - time.monotonic()))
            info1 = c.info()
            rec.drain()
            c.set_mode("hold")
            rec.close()
    finally:
        out["exit_codes"] = stack.stop()
    if info0 is None or info1 is None or not rec.telemetry or not rec.states:
        return out | {"available": False, "reason": "no status or no telemetry during the window"}
    dec = msgspec.msgpack.Decoder(StateMsg)
    states = [dec.decode(b) for b in rec.states]
    tel = rec.telemetry
    l0, l1 = info0.status.loop, info1.status.loop
    n_ticks = l1.ticks - l0.ticks
    misses = l1.deadline_misses - l0.deadline_misses
    t_tel = np.array([m.t for m in tel])
    seqs = np.array([m.seq for m in tel])
    idx = match_states(states, tel)
    s2c = np.array([(m.stamp - states[i].stamp) * 1e6 for m, i in zip(tel, idx, strict=True)])
    cmd_stamp = {m.seq: m.stamp for m in tel}
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
    return out | {
        "available": True,
        "ticks": n_ticks,
        "achieved_hz": round(float(seqs[-1] - seqs[0]) / span, 2) if span > 0 else None,
        "tick_us": _pct(np.array([m.tick_us for m in tel])),
        "deadline_misses": misses,
        "misses_per_10k": round(1e4 * misses / n_ticks, 2) if n_ticks else None,
        "skipped_ticks_note": "a miss by more than a period skips the missed deadlines (no burst)",
        "state_to_cmd_us": _pct(s2c),
        "cmd_to_applied_us": _pct(np.array(applied)),
        "cmds_not_applied": sum(1 for q in in_window if q not in seen),
        "cmds_in_window": len(in_window),
        "telemetry_lost": int(np.sum(np.diff(seqs) - 1)),
        "daemon_loop_end": msgspec.to_builtins(l1),
        "violations": dict(states[-1].violations),
        "rejected": dict(info1.status.rejected),
        "last_fault": info1.status.last_fault,
        "loadavg_after": [round(x, 2) for x in os.getloadavg()],
    }


def run(
    ticks: int,
    rates: tuple[float, ...] = RATES,
    robot: RobotConfig | None = None,
    controller_file: Path | None = None,
) -> dict[str, Any]:
    """Every rate in turn: {"available", "<rate>": figures of :func:`run_rate`}."""
    out: dict[str, Any] = {"available": True}
    for r in rates:
        print(f"e2e: {r:g} Hz for {ticks} ticks ({ticks / r:.0f} s)", file=sys.stderr, flush=True)
        res = run_rate(r, ticks, robot=robot, controller_file=controller_file)
        out[f"{r:g}"] = res
        out["available"] = out["available"] and bool(res.get("available"))
    return out
