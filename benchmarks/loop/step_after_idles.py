"""What the work between two ticks costs the next one: the default robot's ``ctl.step`` (rows off,
track mode) timed back to back and after each of four other things (0.8 ms of each, the sweep as
long as it takes), the cases taking turns in rounds of 500 ticks (docs/benchmarks.md §12, "What the
idle costs the next step"):

- ``none``: nothing (the isolated step);
- ``sleep``: ``time.sleep`` (the core idles: what a loop that sleeps to its deadline does);
- ``pyspin``: a Python loop on ``time.perf_counter`` (a loop's spin to its deadline);
- ``cspin``: a compiled loop of arithmetic, no memory (a spin in compiled code);
- ``sweep``: numpy adding 1 to 4 MiB (every cache level below the last one overwritten);
- ``sleep+spin``: ``time.sleep`` for 0.6 ms, then a Python spin for 0.2 ms (what the loops do:
  ``loop.spin_us`` = 200);
- ``sleep+twin``: ``time.sleep`` for 0.6 ms, then one step of another controller of the same robot
  (its own instance and data, on its own circle): the same code run just before, not the same data.

    python benchmarks/loop/step_after_idles.py [--rounds 6]

Prints each case's p50 and p99 [µs] and its p50 over the isolated step's."""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import numpy as np
from numba import njit
from wmm_qp_tools.bench.controller import CleanCase

import wmm_qp as w

IDLE_S = 800e-6
PER_ROUND = 500


@njit(cache=False)
def _arithmetic(n: int) -> float:
    s = 0.0
    for i in range(n):
        s += i * 1e-9
    return s


def idles(robot: w.RobotConfig, cfg: w.ControllerConfig) -> dict[str, Callable[[], object]]:
    _arithmetic(10)
    t0 = time.perf_counter()
    _arithmetic(10_000_000)
    n = int(IDLE_S / ((time.perf_counter() - t0) / 10_000_000))  # iterations in IDLE_S
    buf = np.zeros(4 << 17)  # 4 MiB of float64


    def sweep() -> None:
        np.add(buf, 1.0, out=buf)

    def spin(s: float) -> None:
        end = time.perf_counter() + s
        while time.perf_counter() < end:
            pass

    def sleep_spin() -> None:
        time.sleep(0.75 * IDLE_S)
        spin(0.25 * IDLE_S)

    twin = CleanCase(robot, cfg, cfg.qp.solver)

    def sleep_twin() -> None:
        time.sleep(0.75 * IDLE_S)
        twin.run(1)

    return {"none": lambda: None, "sleep": lambda: time.sleep(IDLE_S), "pyspin": lambda: spin(IDLE_S),
            "cspin": lambda: _arithmetic(n), "sweep": sweep,
            "sleep+spin": sleep_spin, "sleep+twin": sleep_twin}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=int, default=6, help="rounds of 500 ticks per case (default 6)")
    a = ap.parse_args()
    robot, cfg = w.load_robot_config(), w.load_controller_config().with_(collision={"enabled": False})
    cases = {name: (idle, CleanCase(robot, cfg, cfg.qp.solver)) for name, idle in idles(robot, cfg).items()}
    for _ in range(a.rounds):
        for idle, case in cases.values():
            for _ in range(PER_ROUND):
                idle()
                case.run(1)
    p50 = {}
    for name, (_, case) in cases.items():
        us = np.array(case.samples[50:]) * 1e-3  # (the first ticks: the warm-up)
        p50[name] = float(np.percentile(us, 50))
        print(f"{name:10s} p50 {p50[name]:6.1f} µs  p99 {np.percentile(us, 99):6.1f} µs  "
              f"x{p50[name] / p50['none']:.2f}", flush=True)


if __name__ == "__main__":
    main()
