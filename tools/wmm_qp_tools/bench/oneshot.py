"""The same QPs through qpsolvers' one-shot API versus our persistent warm-started workspaces.

The problems are the ones the controller really solves along the circle (the whole-robot
stage in DM_NULLSPACE mode; whatever shape the controller gives it). Each is solved by
``qpsolvers.solve_problem`` (a fresh solver setup per call, as most users call it) and by
``wmm_qp.solvers.make_backend(name).solve`` (one workspace for the whole sequence). Both
answers are compared.
"""

from __future__ import annotations

import sys
from typing import Any

import numpy as np
import qpsolvers

import wmm_qp as w
from wmm_qp.solvers import INF, QPProblem, make_backend
from wmm_qp_tools.bench.stats import now_ns, summarize_ns
from wmm_qp_tools.bench.trajectory import IdealRobot, circle

# our backend name → qpsolvers' name for the same solver
QPSOLVERS_NAME = {"proxsuite": "proxqp", "osqp": "osqp", "daqp": "daqp"}


def capture_problems(robot: w.RobotConfig, cfg: w.ControllerConfig, n: int) -> list[QPProblem]:
    """The whole-robot QPs of ``n`` DM_NULLSPACE ticks along the circle (daqp drives the robot)."""
    model = w.WmmModel(robot)
    ctl = w.make_controller("qp", model, cfg.with_(qp={"solver": "daqp"}))
    assert isinstance(ctl, w.QpController)
    bot = IdealRobot.at_start(model)
    x0 = bot.ee()
    out: list[QPProblem] = []
    for k in range(n):
        x_d, xd_d = circle(x0, k * ctl.dt)
        cmd = ctl.step(bot.state(), w.Reference(mode=w.Mode.DM_NULLSPACE, x_d=x_d, xd_d=xd_d))
        p = ctl.last_problem
        if ctl.last_stage not in ("arm", "failed") and p is not None:
            out.append(p)
        bot.apply(cmd, ctl.dt)
    return out


def to_qpsolvers(p: QPProblem) -> qpsolvers.Problem:
    """The same problem in qpsolvers' form (G z ≤ h from l ≤ C z ≤ u; ±INF → ±inf)."""
    G = np.vstack([p.C, -p.C]) if p.n_in else None
    h = np.concatenate([p.u, -p.l]) if p.n_in else None
    lb = np.where(p.lb <= -INF, -np.inf, p.lb)
    ub = np.where(p.ub >= INF, np.inf, p.ub)
    return qpsolvers.Problem(P=p.H, q=p.g, G=G, h=h, A=p.A, b=p.b, lb=lb, ub=ub)


def run(
    robot: w.RobotConfig, cfg: w.ControllerConfig, solvers: list[str], n: int
) -> dict[str, Any]:
    """{solver: {"oneshot_us", "persistent_us", "speedup", "max_abs_diff", "failures"}}."""
    print(f"oneshot: capturing {n} problems", file=sys.stderr, flush=True)
    problems = capture_problems(robot, cfg, n)
    qps = [to_qpsolvers(p) for p in problems]
    res: dict[str, Any] = {"n_problems": len(problems)}
    for s in solvers:
        qs = QPSOLVERS_NAME[s]
        if qs not in qpsolvers.available_solvers:
            res[s] = {"available": False}
            continue
        print(f"oneshot: {s}", file=sys.stderr, flush=True)
        kwargs: dict[str, Any] = {"eps_abs": cfg.qp.eps_abs} if s == "proxsuite" else {}
        if s == "osqp":
            kwargs = {"eps_abs": 1e-6, "eps_rel": 0.0, "polishing": True, "verbose": False}
        one_ns: list[int] = []
        per_ns: list[int] = []
        diff, fails_one, fails_per = 0.0, 0, 0
        backend = make_backend(s, cfg.qp.eps_abs)
        for p, q in zip(problems, qps, strict=True):
            t0 = now_ns()
            sol = qpsolvers.solve_problem(q, solver=qs, **kwargs)
            one_ns.append(now_ns() - t0)
            t0 = now_ns()
            mine = backend.solve(p)
            per_ns.append(now_ns() - t0)
            if not sol.found or sol.x is None:
                fails_one += 1
            if not mine.ok or mine.z is None:
                fails_per += 1
            if sol.found and sol.x is not None and mine.ok and mine.z is not None:
                diff = max(diff, float(np.max(np.abs(sol.x - mine.z))))
        one, per = summarize_ns(one_ns), summarize_ns(per_ns)
        res[s] = {
            "oneshot_us": one,
            "persistent_us": per,
            "speedup_p50": round(one["p50"] / per["p50"], 2),
            "max_abs_diff": diff,
            "failures_oneshot": fails_one,
            "failures_persistent": fails_per,
        }
    return res
