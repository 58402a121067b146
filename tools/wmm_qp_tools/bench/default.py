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
- ``ratios``: the figures the targets are judged on — per robot the rows' cost (with / without,
  p50) and the p99 with rows; per loop the in-loop ``ctl.step`` over the isolated step (p50, the
  default robot), and the embedded loop's deadline misses over the empty loop's; per holonomic
  robot pink over ours (p50).
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import wmm_qp as w
from wmm_qp_tools.bench import collision, e2e, pink_race
from wmm_qp_tools.bench.robot_files import loaded, shipped_robots

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
        loops[key] = {"in_loop_over_isolated_step_p50": round(step / iso, 2) if step and iso else None,
                      "misses_per_10k": misses, "floor_misses_per_10k": floor,
                      "misses_over_floor": round(misses / floor, 2) if misses is not None and floor else None}
    pink = {name: res.get("ratio_p50") for name, res in out.get("pink", {}).items() if res.get("available")}
    return {"rows": rows, "isolated_step_p50_us": iso, "loops": loops, "pink_over_ours_p50": pink}
