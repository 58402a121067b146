"""The largest circle the arm alone can draw from the start configuration inside bounds (13).

The paper says only a 0.11 m circle fits its arm's workspace. Here the question is answered by
running the circle experiment (``circle.py``: x_d = x0 + [r(cos ωt − 1), r sin ωt, 0], one full
turn, 40 s) with the robot's base replaced by a fixed one (``base.kind = "fixed"``: no wheel
columns in J of eq. (5)), so only the arm moves, with the qp controller, which keeps every joint
inside bounds (13) and lets the task degrade (its slack) where they cut it. A radius counts as
drawn by the arm alone when the EE error stays within ``tol`` (1 mm) over the whole circle after
its first second (``SETTLE``: the reference starts with a velocity step from rest) and the
sim's referee counts no violation; the largest such radius is found by bisection between a radius
drawn and one not drawn. (Bisection assumes that a radius between two drawn ones is drawn
too, which the geometry does not guarantee: below r = |x0|/2 the circle's near side comes within
|x0| − 2r of the arm's axis, where the arm must fold; the radii tested are listed in
docs/results.md §1.) A run stops at the first tick its EE error exceeds ``tol``. No
slip (a fixed base has none). Collision rows are off (``configs/controller.toml``), as in every
experiment: beyond r ≈ 0.33 m the circle encloses the arm's own axis and the arm reaches over
itself.

    python -m wmm_qp_tools.experiments.arm_reach --json
    python -m wmm_qp_tools.experiments.arm_reach --kinematic-bound --json   (an upper bound)
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from typing import Any

import numpy as np

import wmm_qp
from wmm_qp_tools.experiments import circle
from wmm_qp_tools.experiments.circle import DEFAULT_DURATION
from wmm_qp_tools.experiments.runner import run
from wmm_qp_tools.experiments.scenario import Probe
from wmm_qp_tools.experiments.setup import make_setup

TOL = 1e-3  # [m] max EE error of a circle the arm "draws"
SETTLE = 1.0  # [s] the reference's velocity step at t = 0 (r·ω from rest) is not judged before this
FARTHEST = 22.0  # [s] the circle's point farthest from the arm's axis is at t = 20 s (θ = π)


def arm_only_circle(radius: float, duration: float = DEFAULT_DURATION) -> dict[str, Any]:
    """Run the circle of ``radius`` [m] with the base fixed (the same reference as
    ``circle.run_circle``), stopping at the first tick whose EE error exceeds ``TOL``; the max EE
    error [m] (after ``SETTLE``: the circle starts with a velocity step r·ω from rest, which the
    arm's acceleration bounds (13) follow with a lag of ~1 mm for r ≈ 0.8 m; that is the start,
    not the reach), when it first exceeded TOL [s] (None: never), the referee's violations."""
    robot = wmm_qp.load_robot_config()
    fixed = dataclasses.replace(robot, base=wmm_qp.config.BaseConfig(kind="fixed", floor_z=robot.base.floor_z))
    s = make_setup("qp", slip=False, robot=fixed)
    x0 = s.model.ee_position(np.zeros(3), np.array(s.robot.arm.start))  # the circle's anchor

    def off(t: float, robot: Probe) -> bool:
        t1 = t + s.ctl_cfg.dt  # the robot after tick t, at t + dt
        return t1 >= SETTLE and bool(np.linalg.norm(circle.circle(x0, t1, radius)[0] - robot.ee_true()) > TOL)

    sc = circle.scenario(np.asarray(s.ctl_cfg.direction, dtype=float), duration, radius)
    tr = run(s, dataclasses.replace(sc, phases=(dataclasses.replace(sc.phases[0], done=off),)))
    err = np.linalg.norm(tr.ee_des - tr.ee_true, axis=1)
    over = len(tr.t) < round(duration / s.ctl_cfg.dt)
    return {
        "radius": radius,
        "duration": duration,
        "ee_error_max": float(err[tr.t >= SETTLE].max()) if (tr.t >= SETTLE).any() else 0.0,
        "ee_error_max_start": float(err[tr.t < SETTLE].max()),
        "first_over_tol": float(tr.t[-1]) if over else None,
        "violations": sum(tr.violations.values()),
        "saturated_ticks": sum(st == "saturated" for st in tr.status),
    }


def kinematic_bound(starts: int = 20, seed: int = 0) -> dict[str, Any]:
    """An upper bound on the radius from the arm's kinematics alone (SciPy SLSQP).

    The circle x0 + r[cos θ − 1, sin θ] keeps the EE height; its point farthest from the arm's
    vertical axis (through the arm base, the base at the origin) is x0 for r ≤ |x0|/2 and
    otherwise the far side, 2r − |x0| away. So no radius beyond (ρ_max + |x0|)/2 can be drawn,
    ρ_max the largest horizontal distance from that axis the EE reaches at x0's height inside the
    joint position limits (the start configuration and ``starts`` random starts).
    """
    from scipy.optimize import minimize

    robot = wmm_qp.load_robot_config()
    arm = wmm_qp.WmmModel(robot).arm
    p0 = arm.position(np.array(robot.arm.start))
    bounds = [
        (float(a) if np.isfinite(a) else None, float(b) if np.isfinite(b) else None)
        for a, b in zip(robot.arm.position_lower, robot.arm.position_upper, strict=True)
    ]
    rng = np.random.default_rng(seed)
    best = 0.0
    for k in range(starts + 1):
        q0 = np.array(robot.arm.start) if k == 0 else rng.uniform(-2.0, 2.0, robot.n_arm)
        res = minimize(lambda q: -float(np.hypot(*arm.position(q)[:2])), q0, method="SLSQP", bounds=bounds,
                       constraints=[{"type": "eq", "fun": lambda q: float(arm.position(q)[2] - p0[2])}])  # fmt: skip
        if res.success:
            best = max(best, -float(res.fun))
    d0 = float(np.hypot(*p0[:2]))
    return {"ee_height": float(p0[2]), "reach": best, "x0_distance": d0, "radius_bound": 0.5 * (best + d0)}


def largest_radius(
    lo: float = 0.05, hi: float = 1.0, resolution: float = 0.005, duration: float = FARTHEST, check_ends: bool = True
) -> dict[str, Any]:
    """Bisection on the radius [m] between lo (drawn) and hi (not drawn) to ``resolution``,
    each run ``duration`` long (default: past the circle's farthest point from the arm's axis),
    then the largest drawn radius once more over the whole circle (40 s)."""
    ok = lambda r: r["first_over_tol"] is None and r["violations"] == 0  # noqa: E731
    runs: list[dict[str, Any]] = []
    if check_ends:
        runs = [arm_only_circle(lo, duration), arm_only_circle(hi, duration)]
        if not ok(runs[0]) or ok(runs[1]):
            return {"largest": None, "runs": runs}
    while hi - lo > resolution:
        mid = 0.5 * (lo + hi)
        r = arm_only_circle(mid, duration)
        runs.append(r)
        print(json.dumps(r), file=sys.stderr)
        lo, hi = (mid, hi) if ok(r) else (lo, mid)
    full = arm_only_circle(lo)
    print(json.dumps(full), file=sys.stderr)
    return {
        "largest": lo if ok(full) else None,
        "smallest_not_drawn": hi,
        "tol": TOL,
        "full_circle": full,
        "runs": runs,
    }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m wmm_qp_tools.experiments.arm_reach")
    p.add_argument("--radius", type=float, default=None, help="run only this radius [m]")
    p.add_argument("--kinematic-bound", action="store_true", help="only the kinematic upper bound (SLSQP)")
    p.add_argument("--lo", type=float, default=0.05, help="bisection: a radius the arm draws [m]")
    p.add_argument("--hi", type=float, default=0.6, help="bisection: a radius it does not [m]")
    p.add_argument("--resolution", type=float, default=0.005, help="[m]")
    p.add_argument("--no-check-ends", action="store_true", help="trust --lo (drawn) and --hi (not drawn)")
    p.add_argument("--json", action="store_true")
    a = p.parse_args(argv)
    if a.kinematic_bound:
        r = kinematic_bound()
    else:
        r = (
            arm_only_circle(a.radius)
            if a.radius is not None
            else largest_radius(a.lo, a.hi, a.resolution, check_ends=not a.no_check_ends)
        )
    print(json.dumps(r) if a.json else r)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
