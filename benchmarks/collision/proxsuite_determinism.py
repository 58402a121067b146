"""Is proxsuite the same in every process? TIAGo with its collision rows, two ticks in process with
the sim (the floor test's drive): prints, for each QP the backend is given, a hash of its data
(H, g, C, l, u, lb, ub), a hash of its solution (None: not solved) and its iterations. Run it in
several processes and compare the lines:

    for i in 1 2 3 4 5; do PYTHONHASHSEED=$i python benchmarks/collision/proxsuite_determinism.py; done

Warm-started (before f8f70aa): 433-454 iterations, and the fourth QP solved in 4 of 5 processes.
With the caps of solvers/proxsuite_backend.py and its cold retry after a failure: the same line in
every process, each QP given up after 76-88 iterations in all (they are barely feasible: DAQP
solves them).
"""

from __future__ import annotations

import hashlib
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tests"))

from support import collision_robots as t
from wmm_qp_sim import SimCommand, SimRobot, load_sim_config

import wmm_qp as w
from wmm_qp.solvers import proxsuite_backend
from wmm_qp.solvers.problem import QPProblem, QPSolution

NAME = "tiago.toml"


def digest(*arrays: np.ndarray | None) -> str:
    h = hashlib.md5()
    for a in arrays:
        if a is not None:
            h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()[:8]


def main() -> None:
    seen: list[tuple[str, str | None, int]] = []
    solve = proxsuite_backend.ProxsuiteBackend.solve

    def traced(self: proxsuite_backend.ProxsuiteBackend, p: QPProblem) -> QPSolution:
        sol = solve(self, p)
        seen.append((digest(p.H, p.g, p.C, p.l, p.u, p.lb, p.ub), None if sol.z is None else digest(sol.z),
                     sol.iterations))
        return sol

    proxsuite_backend.ProxsuiteBackend.solve = traced  # type: ignore[method-assign]
    ctl = t.qp(NAME)
    sim = SimRobot(t.model(NAME), replace(load_sim_config(), firmware=False), seed=1, collisions=True)
    sim.reset()
    ref = w.Reference("track", x_d=t.start_x(NAME) + [0.1, 0.0, -1.5])
    for k in range(2):
        cmd = ctl.step(sim.robot_state(), ref)
        sim.step(SimCommand(cmd.wheel_speeds, cmd.arm_rates, period=ctl.dt, seq=k), ctl.dt)
    print(seen)


if __name__ == "__main__":
    main()
