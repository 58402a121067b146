"""The best DM the robot can reach with its EE held at a given height (offline, SciPy SLSQP).

In the null-space DM mode (eqs. (18)–(19)) the task holds the EE in the world; the base (x, y,
yaw) moves freely, so relative to the arm the EE may go anywhere at the same height, and u is
fixed in the base frame (H2 depends on q_m only, eq. (8)). The best DM reachable there is

    max_{q_m}  H2(q_m)   subject to   p_m(q_m)_z = z,   q_min ≤ q_m ≤ q_max

(p_m of eq. (2) with the mount; joint position limits of the robot file). Solved as
min uᵀ J A Jᵀ u = H2⁻² (smooth; its gradient −2 H2⁻³ ∇H2 from eq. (9)) by SLSQP from the
robot's start configuration and from ``starts`` seeded random configurations inside the
limits (continuous joints in [−π, π]); the best feasible local optimum is reported. It is a
lower bound on the global optimum (a local method), which is why it starts from many points.

    python -m wmm_qp_tools.experiments.dm_optimum --direction x --z 0.458 --starts 200 --json

(default z: the true EE height after the Cartesian phase of
``wmm-qp experiment dm --direction D``, computed by running that phase.)
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from typing import Any

import numpy as np

import wmm_qp
from wmm_qp.config import FloatArray
from wmm_qp.manipulability import directional_manipulability, dm_gradient
from wmm_qp_tools.experiments.dm import DIRECTIONS


def best_dm(robot: wmm_qp.RobotConfig, u: FloatArray, z: float, starts: int = 200, seed: int = 0) -> dict[str, Any]:
    """The best H2 along u found with the EE at height z [m] (see the module docstring).

    Returns:
        ``dm`` (the best H2), ``q`` (its joint angles), ``ee`` (its EE position, base frame),
        ``at_limit`` (joints within 1e-6 of a position limit), ``starts``, ``feasible`` (how many
        local optima met the height to 1e-7 m), ``top`` (the five best distinct optima's H2).
    """
    from scipy.optimize import minimize

    model = wmm_qp.WmmModel(robot)
    arm = model.arm
    W = robot.arm.default_W()
    lo = np.where(np.isfinite(robot.arm.position_lower), robot.arm.position_lower, -math.pi)
    hi = np.where(np.isfinite(robot.arm.position_upper), robot.arm.position_upper, math.pi)
    bounds = [
        (None if not np.isfinite(a) else float(a), None if not np.isfinite(b) else float(b))
        for a, b in zip(robot.arm.position_lower, robot.arm.position_upper, strict=True)
    ]

    def objective(q: FloatArray) -> tuple[float, FloatArray]:
        _, J = arm.position_jacobian(q)
        dJ = arm.jacobian_derivatives(q)
        h, grad = dm_gradient(J, dJ, u, W)  # eq. (9)
        return 1.0 / (h * h), -2.0 * grad / h**3  # uᵀ J A Jᵀ u = H2⁻² and its gradient

    def height(q: FloatArray) -> float:
        return float(arm.position(q)[2] - z)

    def height_jac(q: FloatArray) -> FloatArray:
        return arm.position_jacobian(q)[1][2]

    rng = np.random.default_rng(seed)
    x0s = [np.array(robot.arm.start, dtype=float)] + [rng.uniform(lo, hi) for _ in range(starts)]
    found: list[tuple[float, FloatArray]] = []
    for x0 in x0s:
        try:
            res = minimize(
                objective,
                x0,
                jac=True,
                method="SLSQP",
                bounds=bounds,
                constraints=[{"type": "eq", "fun": height, "jac": height_jac}],
                options={"maxiter": 500, "ftol": 1e-12},
            )
        except (ValueError, FloatingPointError):
            continue
        q = np.asarray(res.x, dtype=float)
        inside = np.all(q >= robot.arm.position_lower - 1e-9) and np.all(q <= robot.arm.position_upper + 1e-9)
        if abs(height(q)) > 1e-7 or not inside:
            continue
        found.append((directional_manipulability(arm.position_jacobian(q)[1], u, W), q))
    found.sort(key=lambda f: -f[0])
    best_h, best_q = found[0]
    top: list[float] = []
    for h, _ in found:
        if not top or abs(h - top[-1]) > 1e-4:
            top.append(h)
        if len(top) == 5:
            break
    near = (np.abs(best_q - robot.arm.position_lower) < 1e-6) | (np.abs(best_q - robot.arm.position_upper) < 1e-6)
    return {
        "direction": u.tolist(),
        "z": z,
        "dm": best_h,
        "q": best_q.tolist(),
        "ee": arm.position(best_q).tolist(),
        "at_limit": np.flatnonzero(near).tolist(),
        "starts": len(x0s),
        "feasible": len(found),
        "top": top,
    }


def cartesian_phase_height(direction: str) -> float:
    """[m] the true EE height at the end of the dm experiment's Cartesian phase (qp, default configs)."""
    from wmm_qp_tools.experiments.dm import cartesian_phase
    from wmm_qp_tools.experiments.runner import run
    from wmm_qp_tools.experiments.scenario import Scenario
    from wmm_qp_tools.experiments.setup import make_setup

    s = make_setup("qp")
    u = DIRECTIONS[direction]
    tr = run(s, Scenario(f"dm {direction}: cartesian", (cartesian_phase(u),), u))
    return float(tr.sim.state().ee_true[2]) if tr.sim is not None else float(tr.ee_true[-1, 2])


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        prog="python -m wmm_qp_tools.experiments.dm_optimum", description=(__doc__ or "").split("\n")[0]
    )
    p.add_argument("--direction", choices=tuple(DIRECTIONS), default="x")
    p.add_argument("--z", type=float, default=None, help="EE height [m] (default: after the dm Cartesian phase)")
    p.add_argument("--starts", type=int, default=200, help="random starts besides the start configuration")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--json", action="store_true")
    a = p.parse_args(argv)
    try:
        import scipy  # noqa: F401
    except ImportError:
        print("dm_optimum needs SciPy: pip install scipy", file=sys.stderr)
        return 2
    z = cartesian_phase_height(a.direction) if a.z is None else a.z
    r = best_dm(wmm_qp.load_robot_config(), DIRECTIONS[a.direction], z, a.starts, a.seed)
    if a.json:
        print(json.dumps(r))
    else:
        for k, v in r.items():
            print(f"{k:10s} {v}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
