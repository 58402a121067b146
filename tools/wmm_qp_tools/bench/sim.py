"""The simulated robot's step on each plant, for every shipped robot (``wmm-qp bench --only sim``).

One sim step is what the sim's loop does per period: the firmware and the referees around the
plant's write / advance / read (:meth:`wmm_qp_sim.SimRobot.step`), here with a command every
step that moves every joint and the base (a slow sine within the robot's rate limits). The
realtime factor is the sim's period over the mean step time: how many times faster than real
time the plant runs on this machine at the sim config's rate.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

import wmm_qp as w
from wmm_qp_tools.bench.robot_files import loaded
from wmm_qp_tools.bench.stats import now_ns, summarize_ns

AMPLITUDE = 0.2  # [-] the command's share of each joint's and wheel's rate limit
PERIOD = 4.0  # [s] the command's sine


def run_plant(robot: w.RobotConfig, plant: str, steps: int, max_seconds: float) -> dict[str, Any]:
    """Time ``steps`` sim steps of ``robot`` on ``plant`` (fewer past ``max_seconds`` [s]).

    Returns:
        {"step_us": {p50, p99, max, mean, n}, "realtime_factor", "rate_hz", "violations"}.
    """
    from wmm_qp_sim import SimCommand, SimRobot, load_sim_config

    cfg = load_sim_config().with_(physics={"plant": plant})
    model = w.WmmModel(robot)
    sim = SimRobot(model, cfg)
    dt = cfg.dt
    v_max = np.minimum(np.asarray(robot.arm.velocity_max, dtype=float), 1.0)
    w_max = np.minimum(np.asarray(robot.base.wheel_speed_max, dtype=float), 5.0)
    samples = np.zeros(steps, dtype=np.int64)
    deadline = now_ns() + int(max_seconds * 1e9)
    n = 0
    for k in range(steps):
        s = AMPLITUDE * math.sin(2.0 * math.pi * k * dt / PERIOD)
        cmd = SimCommand(s * w_max, s * v_max, period=dt, seq=k)
        t0 = now_ns()
        st = sim.step(cmd, dt)
        samples[k] = now_ns() - t0
        n = k + 1
        if samples[k] and now_ns() > deadline:
            break
    summary = summarize_ns(samples[:n])
    return {"step_us": summary, "realtime_factor": round(dt * 1e6 / summary["mean"], 2) if n else None,
            "rate_hz": cfg.rate_hz, "violations": dict(st.violations) if n else {}}


def run(files: list[Path], plants: list[str], steps: int, max_seconds: float) -> dict[str, Any]:
    """Every robot file on every plant: {robot name: {plant: :func:`run_plant`'s result}}; a robot
    file that does not load gives {"file", "available": False, "reason"}."""
    out: dict[str, Any] = {}
    for f, robot in loaded(files, out):
        row: dict[str, Any] = {"file": str(f), "available": True}
        for plant in plants:
            row[plant] = run_plant(robot, plant, steps, max_seconds)
            r = row[plant]
            print(f"  sim: {robot.name} {plant}: step p50 {r['step_us']['p50']} µs p99 {r['step_us']['p99']} µs, "
                  f"realtime x{r['realtime_factor']}", file=sys.stderr, flush=True)
        out[robot.name] = row
    return out
