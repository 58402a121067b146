"""proxsuite's dense ProxQP with a persistent, warm-started workspace (the default backend)."""

from __future__ import annotations

import numpy as np
import proxsuite

from .base import QPBackend
from .problem import QPProblem, QPSolution

_OUT = proxsuite.proxqp.QPSolverOutput


class ProxsuiteBackend(QPBackend):
    name = "proxsuite"

    def __init__(self, eps_abs: float = 1e-9, max_iter: int = 200) -> None:
        super().__init__(eps_abs, max_iter)
        self._qp: proxsuite.proxqp.dense.QP | None = None
        self._shape: tuple[int, int, int] | None = None

    def reset(self) -> None:
        self._qp, self._shape = None, None

    def solve(self, problem: QPProblem) -> QPSolution:
        sol = self._solve(problem)
        if not sol.ok and self._qp is not None:
            # A warm start from a very different previous solution (a jump in the reference)
            # can stall ProxQP at its iteration cap although the problem solves cold in ~20
            # iterations: retry once from a fresh workspace.
            self.reset()
            cold = self._solve(problem)
            cold.iterations += sol.iterations
            if cold.ok:
                cold.status = f"{cold.status} (cold retry)"
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
                s.eps_abs, s.eps_rel, s.max_iter, s.verbose = self.eps_abs, 0.0, self.max_iter, False
                s.initial_guess = proxsuite.proxqp.InitialGuess.WARM_START_WITH_PREVIOUS_RESULT
                qp.init(problem.H, problem.g, problem.A, problem.b, C, l, u, problem.lb, problem.ub)
                self._qp, self._shape = qp, shape
            else:
                qp = self._qp
                qp.update(problem.H, problem.g, problem.A, problem.b, C, l, u, problem.lb, problem.ub)
            qp.solve()
            info = qp.results.info
            ok = info.status == _OUT.PROXQP_SOLVED
            return QPSolution(
                z=np.array(qp.results.x) if ok else None,
                ok=ok,
                status=str(info.status).rsplit(".", 1)[-1],
                iterations=int(info.iter),
            )
        except Exception as e:  # a backend's exception never leaks
            self.reset()
            return QPSolution(z=None, ok=False, status=f"proxsuite raised {type(e).__name__}: {e}")
