"""Whole stacks at once on one host: each a sim and a daemon (real-time priority, as shipped) with a
ball swept into its arm over Zenoh, as the suite's obstacle test does; what each stack's referee
counted, its faults, and the CPU its processes took while the ball was far (1-6 s into the sweep)
and after (6-14 s: its rows hold the arm from ~9 s).

    python benchmarks/reliability/stacks.py                # two stacks at once, one round
    python benchmarks/reliability/stacks.py --stacks 1     # one stack: its CPU alone
    python benchmarks/reliability/stacks.py --rounds 4 --json --out /tmp/stacks.json

The ball starts 0.25 m to the EE's left and comes at 1.25 cm/s for 14 s, to 7.5 cm from where
the EE was (the daemon holds; the ball's rows make the arm give way). Exit status: 0 when every
stack's referee counted no bound of (13) exceeded (acceleration, velocity, position and their
wheel kinds), 1 otherwise. Collisions are reported, not judged: a stack whose controller the host
cannot run in time stops its robot, and a moving obstacle then reaches a robot at rest (see
docs/reliability.md, "Whole stacks at once").
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

SWEEP_S = 14.0
SPEED = 0.0125  # [m/s]
BOUNDS = ("position", "velocity", "acceleration", "wheel_speed", "wheel_acceleration")


def one_stack(k: int, out: dict[str, Any], start: threading.Barrier) -> None:
    """Start a stack, sweep the ball at its arm, and put what it counted in ``out``."""
    import numpy as np
    from wmm_qp_service.client import Client
    from wmm_qp_service.machine import CpuMeter
    from wmm_qp_service.processes import Stack, isolated_config

    logs = Path(tempfile.mkdtemp(prefix=f"wmm-stacks-{k}-"))
    stack = Stack(isolated_config(), rate_hz=500.0, log_dir=logs).start()
    pids = {name: p.pid for name, p in stack.procs.items()}
    try:
        with Client(stack.svc, "perception") as c:
            end = time.monotonic() + 120.0
            while (info := c.info()) is None or not info.status.state_ok:
                if time.monotonic() > end:
                    out.update(error="the stack did not become ready in 120 s", logs=str(logs))
                    return
                time.sleep(0.1)
            x0 = np.array(info.status.x)
            start.wait()
            t0 = time.monotonic()
            meters: list[CpuMeter] = []  # from 1 s (the ball far), from 6 s (its rows soon holding)
            shares: list[dict[str, float | None]] = []
            while (t := time.monotonic() - t0) < SWEEP_S:
                centre = x0 + [0.0, 0.25 - SPEED * t, 0.0]
                c.put_obstacles([{"id": "ball", "kind": "sphere", "radius": 0.08,
                                  "xyz": [float(v) for v in centre], "velocity": [0.0, -SPEED, 0.0]}])
                if len(meters) < 2 and t >= (1.0, 6.0)[len(meters)]:
                    if meters:
                        shares.append(meters[-1].shares())  # 1-6 s
                    meters.append(CpuMeter(pids))
                time.sleep(0.05)
            shares.append(meters[-1].shares())  # 6-14 s
            time.sleep(1.0)
            st = c.latest_status()
        if st is None:
            out.update(error="no status", logs=str(logs))
            return
        out.update(referee=dict(st.robot_violations), faults=dict(st.faults),
                   tick_p50_us=round(st.loop.tick_p50_us), tick_p99_us=round(st.loop.tick_p99_us),
                   cpu_percent_ball_far=shares[0], cpu_percent_rows_holding=shares[1], logs=str(logs))
    finally:
        stack.stop()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--stacks", type=int, default=2, help="stacks at once (default 2)")
    ap.add_argument("--rounds", type=int, default=1, help="rounds, one after the other (default 1)")
    ap.add_argument("--json", action="store_true", help="print the result as JSON")
    ap.add_argument("--out", metavar="FILE", help="also write the JSON here")
    a = ap.parse_args()
    if a.stacks < 1 or a.rounds < 1:
        print("stacks.py: error: --stacks and --rounds must be at least 1", file=sys.stderr)
        return 2
    rounds: list[list[dict[str, Any]]] = []
    for r in range(a.rounds):
        outs: list[dict[str, Any]] = [{} for _ in range(a.stacks)]
        start = threading.Barrier(a.stacks)
        threads = [threading.Thread(target=one_stack, args=(k, outs[k], start)) for k in range(a.stacks)]
        for th in threads:
            th.start()
        for th in threads:
            th.join()
        rounds.append(outs)
        for k, o in enumerate(outs):
            line = (f"error: {o['error']}" if "error" in o else
                    f"referee {o['referee']}, tick p50/p99 {o['tick_p50_us']}/{o['tick_p99_us']} µs, CPU % ball far "
                    f"{o['cpu_percent_ball_far']}, rows holding {o['cpu_percent_rows_holding']}")
            print(f"round {r + 1}/{a.rounds}, stack {k + 1}/{a.stacks}: {line}", file=sys.stderr, flush=True)
    result = {"stacks": a.stacks, "rounds": rounds, "sweep_s": SWEEP_S, "ball_speed_m_s": SPEED}
    if a.json:
        print(json.dumps(result, indent=1))
    if a.out:
        Path(a.out).write_text(json.dumps(result, indent=1), encoding="utf-8")
    bad = [o for outs in rounds for o in outs if "error" in o or any(o["referee"].get(k, 0) for k in BOUNDS)]
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
