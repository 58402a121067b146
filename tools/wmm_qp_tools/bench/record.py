"""What recording costs the daemon (``--only record``): its tick with and without ``--record``.

Two measurements in one run:

* ``journal``: in process, no transport: the daemon's core (:class:`~wmm_qp_service.daemon.ControlCore`)
  ticking at the service config's rate on states of a plant that executes its commands exactly, the
  paper's circle as setpoints, in track mode; each tick's ``core.tick`` and the recording hook's
  ``TickJournal.tick`` timed apart (the writer process serialises in parallel: its CPU time per
  tick once started); every tick must reach the file.
* ``daemon``: the real loop over Zenoh (:mod:`.e2e`'s stack, the fixed-rate trigger at 1 kHz, the
  circle tracked, ``--breakdown``), once without and once with ``--record``, back to back: the
  daemon's tick p50 each, and their ratio (on a shared machine the two runs differ by the load of
  the moment too; ``journal`` isolates the hook's own cost).
"""

from __future__ import annotations

import math
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

import wmm_qp as w


def journal_cost(ticks: int, robot: w.RobotConfig, cfg: w.ControllerConfig) -> dict[str, Any]:
    """p50/p99 [µs] of ``core.tick`` and of ``TickJournal.tick`` over ``ticks`` ticks, and the ticks
    the file holds."""
    from wmm_qp_service.config import load_service_config
    from wmm_qp_service.daemon import ControlCore
    from wmm_qp_service.protocol import ModeMsg, SetpointMsg, StateMsg
    from wmm_qp_service.recording.journal import TickJournal, recording_meta
    from wmm_qp_service.recording.reader import RecordingReader
    from wmm_qp_service.streams import circle

    svc = load_service_config().with_robot(robot)
    core = ControlCore(svc, cfg, robot)
    dt = core.dt
    path = Path(tempfile.mkdtemp(prefix="wmm-qp-bench-record-")) / "bench.mcap"
    journal = TickJournal(path, recording_meta(core, "bench", "rate"), robot.n_arm, robot.n_wheels,
                          rate_hz=svc.loop.rate_hz)
    q_base, q_arm = np.zeros(3), np.array(robot.arm.start, dtype=float)
    v_arm, wheels = np.zeros(robot.n_arm), np.zeros(robot.n_wheels)
    x0 = core.model.ee_position(q_base, q_arm)
    t_tick, t_rec = np.empty(ticks), np.empty(ticks)
    seq = 0
    for k in range(ticks):
        now = k * dt
        core.on_state(StateMsg(robot=svc.robot, seq=k + 1, stamp=now, t=now, q_base=q_base.tolist(),
                               q_arm=q_arm.tolist(), v_arm=v_arm.tolist(), wheel_speeds=wheels.tolist(),
                               tau=[0.0] * robot.n_arm, instance="bench", lease="core", cmd_seq=seq,
                               protective_stops=0, refused={}), now)
        if k == 1:
            core.on_mode(ModeMsg(robot=svc.robot, seq=1, stamp=now, mode="track"))
        if k > 1:
            x, xd = circle(x0, now)
            core.on_setpoint(SetpointMsg(robot=svc.robot, seq=k, stamp=now, x=list(x), xd=list(xd),
                                         source="bench"), now)
        a = time.perf_counter_ns()
        cmd = core.tick(now)
        b = time.perf_counter_ns()
        journal.tick(core, None, k, now, 0.0)
        c = time.perf_counter_ns()
        t_tick[k], t_rec[k] = (b - a) * 1e-3, (c - b) * 1e-3
        if cmd is not None:  # executed exactly, confirmed by the next state
            seq = core.stream.numbered()
            core.stream.sent(seq, now)
            v_arm, wheels = cmd.arm_rates.copy(), cmd.wheel_speeds.copy()
            q_arm = q_arm + dt * v_arm
            q_base = q_base + dt * (core.model.base.P(float(q_base[2])) @ wheels)
    summary = journal.close(ticks)
    rd = RecordingReader(path)
    recorded = sum(1 for _ in rd.messages({"/wmm/tick"}))
    p = {"tick": t_tick, "journal": t_rec}
    out: dict[str, Any] = {f"{n}_us": {"p50": round(float(np.percentile(v, 50)), 2),
                                       "p99": round(float(np.percentile(v, 99)), 2)} for n, v in p.items()}
    out["journal_over_tick_p50"] = round(out["journal_us"]["p50"] / out["tick_us"]["p50"], 4)
    out |= {"ticks": ticks, "recorded": recorded, "dropped": summary.get("dropped"), "rate_hz": svc.loop.rate_hz,
            "solver": cfg.qp.solver,
            # the writer process's CPU time per tick, once started (its imports left out)
            "writer_cpu_us_per_tick": round(float(summary.get("cpu_s", math.nan)) / ticks * 1e6, 1)}
    return out


def run(ticks: int, robot: w.RobotConfig | None = None, cfg: w.ControllerConfig | None = None,
        controller_file: Path | None = None, e2e_ticks: int = 5000) -> dict[str, Any]:
    """{"available", "journal": :func:`journal_cost`, "daemon": {"without", "with", "ratio_p50"}}."""
    from wmm_qp_service.recording import RecordingUnavailable, require

    from . import e2e

    try:
        require()
    except RecordingUnavailable as e:
        return {"available": False, "reason": str(e)}
    robot = robot or w.load_robot_config()
    cfg = cfg or w.load_controller_config()
    print(f"record: the recording hook in process, {ticks} ticks", file=sys.stderr, flush=True)
    out: dict[str, Any] = {"available": True, "journal": journal_cost(ticks, robot, cfg)}
    runs: dict[str, Any] = {}
    for name in ("without", "with"):
        print(f"record: the daemon over Zenoh at 1 kHz, {e2e_ticks} ticks, {name} --record", file=sys.stderr,
              flush=True)
        log_dir = Path(tempfile.mkdtemp(prefix=f"wmm-qp-bench-record-{name}-"))
        extra = ["--record", str(log_dir / "run.mcap")] if name == "with" else []
        res = e2e.run_case("rate", 1000.0, e2e_ticks, log_dir=log_dir, robot=robot, controller_file=controller_file,
                           breakdown=True, extra_daemon_args=extra)
        tick = res.get("breakdown", {}).get("tick", {})
        runs[name] = {"tick_us": tick, "available": bool(res.get("available")) and bool(tick.get("n")),
                      "reason": res.get("reason"), "logs": str(log_dir)}
    d = {**runs}
    p_with, p_without = (runs[k]["tick_us"].get("p50", math.nan) for k in ("with", "without"))
    d["ratio_p50"] = round(p_with / p_without, 3) if p_without and p_without == p_without else None
    out["daemon"] = d
    return out
