"""What users run: the default settings (collision rows on), every shipped robot, in process and in
the daemon's and the embedded loops at 500 Hz and 1 kHz, the empty loop's floor, in one run.

``wmm-qp bench --only default --json`` gives, side by side (one run, so the ratios hold on a
shared machine even when the absolute figures do not):

- ``in_process``: every shipped robot's track-mode ``step`` with the default rows and without
  (:func:`.collision.run_default`); ``ratio_p50`` per robot;
- ``loops``: the split stack (daemon + sim over Zenoh, fixed-rate trigger) and the embedded stack
  at each rate, default settings (:func:`.e2e.run_case`), and the empty loop at each rate
  (``floor``, :func:`.jitter.run_one`);
- ``pink``: pink's ``solve_ik`` against our step on every holonomic shipped robot, rows off as
  pink has none (:func:`.pink_race.run`);
- ``paced``: the default robot's step with rows, in this process alone (no transport, no other
  thread, no sim), back to back and paced at each rate (:func:`paced`): what the loops' step costs
  when the CPU sits idle between ticks, whatever the loop does;
- ``ratios``: the figures the targets are judged on — per robot the rows' cost (with / without,
  p50) and the p99 with rows; per loop the in-loop ``ctl.step`` over the isolated step (p50, the
  default robot), over the paced one at its rate (the loop's own share of the excess), and the
  embedded loop's deadline misses over the empty loop's; per holonomic robot pink over ours (p50).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Any

import wmm_qp as w
from wmm_qp.scene import load_scene
from wmm_qp_tools.bench import collision, e2e, pink_race
from wmm_qp_tools.bench.robot_files import loaded, shipped_robots
from wmm_qp_tools.bench.stats import now_ns, summarize_ns
from wmm_qp_tools.bench.trajectory import IdealRobot, circle

RATES = (500.0, 1000.0)


def run(cfg: w.ControllerConfig, robot: w.RobotConfig, ticks: int, max_seconds: float,
        controller_file: Path | None = None, rates: tuple[float, ...] = RATES) -> dict[str, Any]:
    """The section (module docstring); ``cfg``: the controller config as given (its rows on)."""
    from wmm_qp_service.config import load_service_config
    from wmm_qp_sim import load_sim_config

    from wmm_qp_tools.bench.jitter import run_one

    out: dict[str, Any] = {"robot": robot.name, "rates": list(rates)}
    print("default: every shipped robot's step with the default rows and without", file=sys.stderr, flush=True)
    out["in_process"] = collision.run_default(cfg, min(ticks, 10000), max_seconds)
    print("default: the default robot's step alone, back to back and paced at each rate", file=sys.stderr, flush=True)
    out["paced"] = paced(cfg, robot, rates, min(ticks, 5000))
    loops: dict[str, Any] = {}
    for r in rates:
        for trigger in ("rate", "embedded"):
            print(f"default: {trigger} loop, {r:g} Hz for {ticks} ticks ({ticks / r:.0f} s)", file=sys.stderr,
                  flush=True)
            loops[f"{trigger} {r:g}"] = e2e.run_case(trigger, r, ticks, robot=robot, controller_file=controller_file,
                                                     collision=True)
    spin_us, rt = load_service_config().loop.spin_us, load_sim_config().rt_priority
    for r in rates:
        n = min(ticks, int(60 * r))
        print(f"default: the floor, an empty {r:g} Hz loop for {n} ticks", file=sys.stderr, flush=True)
        loops[f"floor {r:g}"] = run_one(n, r, spin_us, rt)
    out["loops"] = loops
    pink: dict[str, Any] = {}
    for _, rob in loaded(shipped_robots(), {}):
        if w.WmmModel(rob).base.holonomic:
            print(f"default: pink's solve_ik against ours on {rob.name}", file=sys.stderr, flush=True)
            pink[rob.name] = pink_race.run(rob, cfg.with_(collision={"enabled": False}), min(ticks, 5000),
                                           max_seconds)
    out["pink"] = pink
    out["ratios"] = ratios(out)
    return out


def paced(cfg: w.ControllerConfig, robot: w.RobotConfig, rates: tuple[float, ...], ticks: int) -> dict[str, Any]:
    """The track step with ``cfg`` (the default: rows on) on the paper's circle, in this process alone: back to
    back, then at each rate r with the thread asleep until the next 1/r deadline between ticks
    (each from the robot's start, a fresh controller). No transport, thread or sim runs: a paced
    step slower than the back-to-back one is the idle CPU's (caches, predictors, clock) cost,
    which every loop pays; the in-loop step over the paced one is the loop's own.

    Returns:
        {"back_to_back": {p50, p99, …}, "<rate>": {p50, p99, …}, "ticks"}.
    """
    scene = load_scene()
    out: dict[str, Any] = {"ticks": ticks}
    for r in (None, *rates):
        model = w.WmmModel(robot)
        ctl = w.make_controller("qp", model, cfg)  # as the loops run it (the default: rows on)
        ctl.warm_up()
        ctl.set_scene(scene)
        bot = IdealRobot.at_start(model)
        x0 = model.ee_position(bot.q_base, bot.q_arm)
        samples: list[int] = []
        period = 0 if r is None else int(1e9 / r)
        deadline = now_ns()
        for k in range(ticks):
            x_d, xd_d = circle(x0, k * ctl.dt)
            ref = w.Reference(w.Mode.TRACK, x_d=x_d, xd_d=xd_d)
            st = bot.state()
            t0 = now_ns()
            cmd = ctl.step(st, ref)
            samples.append(now_ns() - t0)
            bot.apply(cmd, ctl.dt)
            if period:
                deadline += period
                gap = deadline - now_ns()
                if gap > 0:
                    time.sleep(gap / 1e9)
        out["back_to_back" if r is None else f"{r:g}"] = summarize_ns(samples[100:])
    return out


def _p(d: Any, *path: str) -> float | None:
    """``d[path…]`` as a float, or None where a part is missing."""
    for k in path:
        if not isinstance(d, dict) or k not in d:
            return None
        d = d[k]
    return float(d) if isinstance(d, int | float) else None


def ratios(out: dict[str, Any]) -> dict[str, Any]:
    """The ratios of one ``default`` run (module docstring), None where a figure is missing."""
    rows: dict[str, Any] = {}
    for name, res in out.get("in_process", {}).items():
        if res.get("available"):
            rows[name] = {"with_over_without_p50": res.get("ratio_p50"),
                          "with_rows_p99_us": _p(res, "with_rows", "p99")}
    iso = _p(out.get("in_process", {}), out.get("robot", ""), "with_rows", "p50")
    loops: dict[str, Any] = {}
    for key, res in out.get("loops", {}).items():
        if key.startswith("floor"):
            continue
        step = _p(res, "step_us", "p50")
        rate = key.split()[-1]
        misses, floor = _p(res, "misses_per_10k"), _p(out["loops"].get(f"floor {rate}", {}), "misses_per_10k")
        pace = _p(out.get("paced", {}), rate, "p50")
        loops[key] = {"in_loop_over_isolated_step_p50": round(step / iso, 2) if step and iso else None,
                      "in_loop_over_paced_step_p50": round(step / pace, 2) if step and pace else None,
                      "misses_per_10k": misses, "floor_misses_per_10k": floor,
                      "misses_over_floor": round(misses / floor, 2) if misses is not None and floor else None}
    pink = {name: res.get("ratio_p50") for name, res in out.get("pink", {}).items() if res.get("available")}
    return {"rows": rows, "isolated_step_p50_us": iso, "loops": loops, "pink_over_ours_p50": pink,
            "paced_step_p50_us": {k: _p(v, "p50") for k, v in out.get("paced", {}).items() if isinstance(v, dict)}}
