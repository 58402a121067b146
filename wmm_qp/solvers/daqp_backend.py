"""DAQP, a dual active-set solver: exact for these small dense problems.

Its Python API solves one problem per call (the setup of a 14-variable problem is a few
microseconds); we warm-start it with the previous primal solution.
"""

from __future__ import annotations

import daqp
import numpy as np

from .base import QPBackend
from .problem import QPProblem, QPSolution

_EQUALITY = 5
_FLAGS = {
    1: "solved",
    2: "solved (soft constraints)",
    -1: "infeasible",
    -2: "cycling",
    -3: "unbounded",
    -4: "iteration limit",
    -5: "nonconvex",
    -6: "initial working set overdetermined",
}


class DaqpBackend(QPBackend):
    name = "daqp"

    def __init__(self, eps_abs: float = 1e-9, max_iter: int = 200) -> None:
        super().__init__(eps_abs, max_iter)
        self._prev: np.ndarray | None = None
        self._shape: tuple[int, int, int] | None = None
        self._A = np.zeros((0, 0))
        self._upper = self._lower = np.zeros(0)
        self._sense = np.zeros(0, dtype=np.int32)

    def reset(self) -> None:
        self._prev = None

    def solve(self, problem: QPProblem) -> QPSolution:
        try:
            p = problem
            shape = (p.n, p.n_eq, p.n_in)
            if shape != self._shape:  # buffers reused tick after tick
                m = p.n + p.n_eq + p.n_in
                self._A = np.zeros((p.n_eq + p.n_in, p.n))
                self._upper, self._lower = np.zeros(m), np.zeros(m)
                self._sense = np.zeros(m, dtype=np.int32)
                self._sense[p.n : p.n + p.n_eq] = _EQUALITY
                self._shape = shape
            A, upper, lower, sense = self._A, self._upper, self._lower, self._sense
            A[: p.n_eq] = p.A
            A[p.n_eq :] = p.C
            upper[: p.n], upper[p.n : p.n + p.n_eq], upper[p.n + p.n_eq :] = p.ub, p.b, p.u
            lower[: p.n], lower[p.n : p.n + p.n_eq], lower[p.n + p.n_eq :] = p.lb, p.b, p.l
            kwargs = {}
            if self._prev is not None and self._prev.size == p.n:
                kwargs["primal_start"] = self._prev
            x, _f, flag, info = daqp.solve(p.H, p.g, A, upper, lower, sense, iter_limit=self.max_iter, **kwargs)
            ok = flag == 1 and bool(np.isfinite(x).all())
            self._prev = np.array(x) if ok else None
            return QPSolution(
                z=np.array(x) if ok else None,
                ok=ok,
                status=_FLAGS.get(flag, f"exitflag {flag}"),
                iterations=int(info.get("iterations", 0)),
            )
        except Exception as e:
            self.reset()
            return QPSolution(z=None, ok=False, status=f"daqp raised {type(e).__name__}: {e}")
