"""The machine's floor under the loop's figures (docs/benchmarks.md §5.3): the daemon's fixed-rate loop with no
work at all.

A :class:`~wmm_qp_service.rate_loop.RateLoop` at 500 Hz and at 1 kHz (the e2e section's rates),
with the service config's spin and SCHED_FIFO priority (``configs/service.toml``), ticks ``ticks``
times doing nothing.
Whatever it misses, the daemon misses too, whatever its work costs. Reported:

- its deadline misses (per 10,000 ticks) and skipped ticks, counted as the daemon counts them;
- each tick's lateness, from the deadline it ran for (after a skip: the one skipped to) to the
  moment ``wait`` returned; a tick that wakes more than a period late is a deadline miss at the
  next ``wait`` (the loop counts a tick that *starts* after its deadline), so
  ``late_over_a_period`` is the misses' count, give or take the last tick;
- the CPU time the hypervisor took from this guest meanwhile: *steal*, the ``cpu`` line of
  ``/proc/stat``, summed over all CPUs (a virtual machine's host running other guests);
- the scheduling the loop got, and the load average before and after.

And ``step_after_idle`` (:func:`step_after_idle`, the result's key beside ``jitter``): the same
``ctl.step`` (the paper's robot, tracking a circle in ``track``) timed back to back, after
sleeping 0.8 of a 1 kHz period (as a loop that sleeps between ticks does), and after spinning
as long; p50/p99 each and the ratios of the p50s to the back-to-back one. What a tick costs depends on what the core did
before it (caches, frequency, a virtual CPU descheduled while idle), whatever the code.
"""

from __future__ import annotations

import os
import threading
import time
from typing import Any

import numpy as np
from wmm_qp_service.config import load_service_config
from wmm_qp_service.machine import loadavg, steal_seconds
from wmm_qp_service.rate_loop import RateLoop, realtime_priority


def run(ticks: int, rates: tuple[float, ...] = (500.0, 1000.0)) -> dict[str, Any]:
    """The empty loop at each rate for ``ticks`` ticks, with the service config's spin and
    priority; {rate as text: :func:`run_one`'s result}."""
    loop_cfg = load_service_config().loop
    return {f"{r:g}": run_one(ticks, r, loop_cfg.spin_us, loop_cfg.rt_priority) for r in rates}


IDLE_S = 0.8e-3
"""[s] the idle time between two timed steps (0.8 of a 1 kHz period)."""


def step_after_idle(ticks: int) -> dict[str, Any]:
    """``ctl.step`` of the default robot and controller config (its solver, ``track``) timed
    ``ticks`` times after each of three idles: none, a sleep of :data:`IDLE_S`, a spin of
    :data:`IDLE_S`; the three take turns in rounds of 500 ticks (a change of the machine's load
    meanwhile touches them alike)."""
    import wmm_qp as w
    from wmm_qp_tools.bench.controller import CleanCase

    robot, cfg = w.load_robot_config(), w.load_controller_config().with_(collision={"enabled": False})
    idles = ("none", "sleep", "spin")
    cases = {i: CleanCase(robot, cfg, cfg.qp.solver) for i in idles}
    per_round = max(1, min(500, ticks))
    for _ in range(max(1, ticks // per_round)):
        for idle, case in cases.items():
            for _ in range(per_round):
                if idle == "sleep":
                    time.sleep(IDLE_S)
                elif idle == "spin":
                    end = time.perf_counter() + IDLE_S
                    while time.perf_counter() < end:
                        pass
                case.run(1)
    out: dict[str, Any] = {"idle_us": IDLE_S * 1e6, "solver": cfg.qp.solver,
                           "ticks_each": len(cases["none"].samples)}
    p50 = {}
    for idle, case in cases.items():
        us = np.array(case.samples[min(50, per_round // 2):]) * 1e-3  # (the first: the warm-up)
        p50[idle] = float(np.percentile(us, 50))
        out[idle] = {"p50": round(p50[idle], 1), "p99": round(float(np.percentile(us, 99)), 1)}
    out["sleep_over_none_p50"] = round(p50["sleep"] / p50["none"], 2)
    out["spin_over_none_p50"] = round(p50["spin"] / p50["none"], 2)
    return out


def run_one(ticks: int, rate_hz: float, spin_us: float, rt_priority: int) -> dict[str, Any]:
    """The empty loop for ``ticks`` ticks, in a thread of its own (so that the priority applies
    to it only)."""
    late = np.zeros(ticks)
    out: dict[str, Any] = {"rate_hz": rate_hz, "spin_us": spin_us, "ticks": ticks,
                           "loadavg_before": loadavg()}
    loop = RateLoop(rate_hz, spin_us * 1e-6)

    def body() -> None:
        out["scheduling"] = realtime_priority(rt_priority)
        loop.start()
        for k in range(ticks):  # late: from the deadline the tick ran for (after a skip, the one skipped to)
            late[k] = loop.wait() - loop.deadline

    steal0, t0 = steal_seconds(), time.monotonic()
    worker = threading.Thread(target=body, name="jitter-loop")
    worker.start()
    worker.join()
    wall, steal1 = time.monotonic() - t0, steal_seconds()
    ncpu = os.cpu_count() or 1
    stolen = None if steal0 is None or steal1 is None else steal1 - steal0
    us = late * 1e6
    out.update({
        "seconds": round(wall, 3),
        "deadline_misses": loop.deadline_misses,
        "misses_per_10k": round(1e4 * loop.deadline_misses / ticks, 2),
        "skipped": loop.skipped,
        "late_us": {"p50": round(float(np.percentile(us, 50)), 1), "p99": round(float(np.percentile(us, 99)), 1),
                    "max": round(float(us.max()), 1)},
        "late_over_a_period": int(np.count_nonzero(late > loop.period)),
        "steal_s": None if stolen is None else round(stolen, 3),
        "steal_percent": None if stolen is None or wall <= 0 else round(100.0 * stolen / (wall * ncpu), 2),
        "loadavg_after": loadavg(),
    })
    return out
