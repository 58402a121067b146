"""Where the daemon's tick goes (``--only daemon``): a per-stage breakdown of its real loop.

Per case (the fixed-rate and the state-triggered loop at 1 kHz), the same stack and stream as
:mod:`.e2e` (sim and daemon processes on loopback, a real Zenoh session, the circle tracked,
a client recording the states and the telemetry) with the daemon started with
``--breakdown FILE``: its loop times each stage of every tick that publishes a command
(:data:`~..tick_stages.STAGES`: poll and decode, validation, watchdogs, Ruckig, ``ctl.step``,
command encode + publish, telemetry, status, queries) and writes p50/p99/max per stage and of
the whole tick at exit. The lap clock reads add ~0.2 µs per stage to the tick.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

from wmm_qp import RobotConfig
from wmm_qp_tools.bench import e2e

CASES: tuple[tuple[str, float], ...] = (("rate", 1000.0), ("state", 1000.0))


def run(ticks: int, cases: tuple[tuple[str, float], ...] = CASES, robot: RobotConfig | None = None,
        controller_file: Path | None = None) -> dict[str, Any]:
    """{"available", "<trigger> <rate>": {"breakdown", "tick_over_step_p50", and the e2e figures}}."""
    out: dict[str, Any] = {"available": True}
    for trigger, r in cases:
        print(f"daemon: {trigger} trigger, {r:g} Hz, {ticks} ticks with the stage breakdown", file=sys.stderr,
              flush=True)
        res = e2e.run_case(trigger, r, ticks, robot=robot, controller_file=controller_file, breakdown=True)
        b = res.get("breakdown", {})
        if b.get("stages") and b.get("tick", {}).get("n"):
            st = b["stages"]["step"]["p50"]
            res["breakdown"]["tick_over_step_p50"] = round(b["tick"]["p50"] / st, 2) if st > 0 else None
        out[e2e.case_key(trigger, r)] = res
        out["available"] = out["available"] and bool(res.get("available")) and "stages" in b
    return out
