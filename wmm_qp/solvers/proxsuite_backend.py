"""proxsuite's dense ProxQP, warm-started from the last solve while solves succeed (the default backend).

Settings (measured on 180 collision-row QPs captured from ``wmm-qp verify`` with the cluttered
scene, 82 of them without a solution, and on the TIAGo floor drive;
benchmarks/collision/proxsuite_determinism.py):

* eps_abs as configured (1e-9): on the hard collision QPs ProxQP reaches it on about half of
  them (the rest go to DAQP); 1e-6 would double that but leaves rows ~6e-7 out and the task
  velocity ~2e-8 off (tests/core/test_collision.py, tests/core/test_qp.py).
* max_iter 30 (outer), max_iter_in 50 (inner, per outer one): a feasible QP here solves in < 30
  outer iterations; one without a solution (a state sampled inside an obstacle) ran 200 × 1500
  inner ones, seconds, before DAQP decided it. A cap reached is a failure: the controller
  re-solves with DAQP, which decides infeasibility exactly.
* Warm start (the previous solution and multipliers) while the solves succeed: on the paper's
  circle a cold start costs ~130 µs more a full stage (``wmm-qp bench --only collisions``: the
  tick without rows 193 → 323 µs). After a failure the workspace is dropped and the QP solved
  once more cold: the huge multipliers a failed solve leaves had the next solves stall at the
  cap, or stop "solved" off the optimum (|z − z_daqp| = 2.3e-2 once), and turned the last bits in
  which proxsuite's processes differ into a solve in one process and the cap in another.
* The preconditioner recomputed on every update (the update's default keeps the first QP's).

Not bit-identical across processes: proxsuite's AVX2/AVX-512 builds (loaded when the CPU has them)
give last bits that depend on the alignment of their heap buffers; its baseline build does not.
On the collision QPs those bits no longer decide between a solution and the cap
(benchmarks/collision/proxsuite_determinism.py: the same outcome in every process), but in a
closed loop a marginal QP can still go to DAQP in one process and not in another.
"""

from __future__ import annotations

import numpy as np
import proxsuite

from .base import QPBackend
from .problem import QPProblem, QPSolution

_OUT = proxsuite.proxqp.QPSolverOutput
MAX_ITER = 30  # outer iterations
MAX_ITER_IN = 50  # inner (semi-smooth Newton) iterations per outer one
HARD_ITERATIONS = 20
"""A solve that took this many outer iterations or more is a hard instance (``QPSolution.hard``):
on the default rows' QPs on the track circle 99.9 % of the Panda's solves take fewer (p99 9,
~70-180 µs), a cold start of the Gen3's stage 14; TIAGo's that take 20 or more ran 0.6-1.5 ms
(docs/benchmarks.md §12)."""


class ProxsuiteBackend(QPBackend):
    name = "proxsuite"

    def __init__(self, eps_abs: float = 1e-9, max_iter: int = MAX_ITER) -> None:
        super().__init__(eps_abs, max_iter)
        self._qp: proxsuite.proxqp.dense.QP | None = None
        self._shape: tuple[int, int, int] | None = None

    def reset(self) -> None:
        self._qp, self._shape = None, None

    def solve(self, problem: QPProblem) -> QPSolution:
        sol = self._solve(problem)
        if not sol.ok:  # nothing of a failed solve carried over: the same QP again, cold
            self.reset()
            cold = self._solve(problem)
            cold.iterations += sol.iterations
            cold.hard = True
            if cold.ok:
                cold.status = f"{cold.status} (cold retry)"
            else:
                self.reset()
            return cold
        return sol

    def _solve(self, problem: QPProblem) -> QPSolution:
        try:
            shape = (problem.n, problem.n_eq, problem.n_in)
            C = problem.C if problem.n_in else None
            l = problem.l if problem.n_in else None
            u = problem.u if problem.n_in else None
            if self._qp is None or shape != self._shape:
                qp = proxsuite.proxqp.dense.QP(*shape, True)
                s = qp.settings
                s.eps_abs, s.eps_rel, s.max_iter, s.max_iter_in = self.eps_abs, 0.0, self.max_iter, MAX_ITER_IN
                s.verbose = False
                s.initial_guess = proxsuite.proxqp.InitialGuess.WARM_START_WITH_PREVIOUS_RESULT
                qp.init(problem.H, problem.g, problem.A, problem.b, C, l, u, problem.lb, problem.ub)
                self._qp, self._shape = qp, shape
            else:
                qp = self._qp
                # the preconditioner of this QP, not of the first one of this shape
                qp.update(problem.H, problem.g, problem.A, problem.b, C, l, u, problem.lb, problem.ub,
                          update_preconditioner=True)
            qp.solve()
            info = qp.results.info
            ok = info.status == _OUT.PROXQP_SOLVED
            return QPSolution(
                z=np.array(qp.results.x) if ok else None,
                ok=ok,
                status=str(info.status).rsplit(".", 1)[-1],
                iterations=int(info.iter),
                hard=ok and int(info.iter) >= HARD_ITERATIONS,
            )
        except Exception as e:  # a backend's exception never leaks
            self.reset()
            return QPSolution(z=None, ok=False, status=f"proxsuite raised {type(e).__name__}: {e}")
