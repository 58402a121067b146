"""How the QP controller solves one stage: the closed form, the configured solver, DAQP, the task first.

1. The closed-form optimum (no bound active, zero slack), taken only when it meets every KKT
   condition (``qp.closed_form_first``): exact, an active-set solver's first iterate.
2. The configured backend (one workspace per stage: shapes differ, warm starts stay meaningful).
3. DAQP (dual active set, exact), when the configured backend failed: iterative solvers stall on
   rare hard instances. Only when it fails too has the stage no solution (the stage logic then
   relaxes its rows, or stops safely). Hard instances come in runs (a moving obstacle's rows
   holding the arm: about every other solve ended at proxsuite's iteration cap, and so did its
   cold retry, before DAQP solved it; ``benchmarks/collision/ball_tick.py``), so after the
   configured backend failed on a stage, that stage's next :data:`DAQP_FIRST` solves go to DAQP
   first. DAQP's verdict that a stage is infeasible stands (it is exact; next to a singularity,
   where a huge DM term can make it call a barely feasible stage infeasible, the stage logic's
   relaxation gives a safe, more cautious command); any other DAQP failure in that window ends
   it (the configured backend then tries the same problem); at its end the configured backend
   starts again cold. If it fails again on its first solve after a window, the next window is
   four times as long (up to :data:`DAQP_FIRST_MAX`): on a robot whose rows keep every stage
   hard (TIAGo's 48 rows at its column) each failure costs the iteration cap twice (~1.5 ms), and
   a window of fixed length met one every 50 solves. A solve the backend reports hard
   (``QPSolution.hard``: proxsuite's cold retry after its cap, or at least ``HARD_ITERATIONS``
   iterations, 0.6-1.5 ms on those stages) counts as a failure for the windows, its answer kept.
   An easy success of the configured backend brings the window back to ``DAQP_FIRST``.
4. The answer clipped to the box bounds: a no-op for exact solvers, the guarantee for iterative
   solvers' tolerances.
5. Strict priority: the slack's exact penalty keeps s = 0 only while ρ₁ exceeds the task's
   Lagrange multiplier, which near a singularity or with a large DM gradient (∝ H2³) it may not.
   So whenever a stage leaves slack (judged on |J v − ẋ_ref| itself), it is solved again with
   s ≡ 0 by DAQP (exact infeasibility detection): if the task is feasible that optimum is used
   (task, then cost); if not, the penalised best effort.
"""

from __future__ import annotations

import numpy as np

from ..._typing import FloatArray
from ...config import ControllerConfig
from ...model.wmm import WmmModel
from ...solvers import QPBackend, QPProblem, available_solvers, make_backend
from ..base import Controller
from .kernels import _closed_form, task_residual

SLACK_ACCEPT = 1e-7  # [m/s] slack below this counts as "the task is met"
DAQP_FIRST = 50
"""Solves of a stage that go to DAQP first after the configured backend failed on it."""
DAQP_FIRST_MAX = 6400
"""The longest such window (after repeated failures at the windows' ends: ×4 each)."""


class SolveCascade(Controller):
    """The solve cascade of the module docstring, its backends and its counters.

    Raises:
        SolverNotFound: the configured solver cannot be used here (at construction).
    """

    _cost_rank1: tuple[FloatArray, float]  # (rot, c) of the stage built last (:class:`~.stages.QpStages`)
    _n_s: int  # the slack's variables, 2r

    def __init__(self, model: WmmModel, config: ControllerConfig) -> None:
        super().__init__(model, config)
        qp = config.qp
        # One backend (workspace) per stage: shapes differ, warm starts stay meaningful.
        self._arm = make_backend(qp.solver, qp.eps_abs)
        self._full = make_backend(qp.solver, qp.eps_abs)
        # DAQP (dual active set, exact) re-solves a stage another solver failed on (iterative
        # solvers stall on rare, hard instances) and decides, exactly, whether a task the
        # penalised solve left unmet is feasible (_task_first).
        self._fallback = make_backend("daqp", qp.eps_abs) if "daqp" in available_solvers() else None
        self.fallbacks = 0  # stages the fallback solved after the configured backend failed
        self.daqp_first = 0  # stages DAQP solved first, in a window after such a failure
        self._daqp_first: dict[int, int] = {}  # id(stage backend) -> solves left that go to DAQP first
        self._window: dict[int, int] = {}  # id(stage backend) -> the length of its next window
        self._after_window: set[int] = set()  # stage backends whose window just ended
        self.closed_form_hits = 0  # stages solved in closed form (no bound active)
        self._closed_form_hit = False  # the last _solve was answered in closed form
        self.task_checks = 0  # stages that left slack and were re-solved with the task as an equality
        self.task_recovered = 0  # ... and turned out feasible (the penalty alone was too weak)
        self.task_without_objective = 0  # ... of which only with the DM/return terms dropped
        self._last_problem: QPProblem | None = None

    @property
    def solver(self) -> str:
        return self.config.qp.solver

    @property
    def last_problem(self) -> QPProblem | None:
        """The last QP handed to a backend (for tests and logs)."""
        return self._last_problem

    def reset(self) -> None:
        self._arm.reset()
        self._full.reset()
        if self._fallback is not None:  # its primal start too: a reset forgets every warm start
            self._fallback.reset()
        self._daqp_first.clear()
        self._window.clear()
        self._after_window.clear()

    def clear_statistics(self) -> None:
        self.fallbacks = self.daqp_first = self.closed_form_hits = self.task_checks = 0
        self.task_recovered = self.task_without_objective = 0
        super().clear_statistics()

    def closed_form(self, problem: QPProblem) -> FloatArray | None:
        """The QP's optimum if no bound is active and the slack is zero, else None.

        With H = D + c·rot rotᵀ on v (D diagonal; c·rot rotᵀ the stage's base-rotation term, 0
        unless damped, recorded by the stage's builder), the candidate v = H⁻¹(Jᵀλ − g),
        λ = (J H⁻¹ Jᵀ)⁻¹(b + J H⁻¹ g), s = 0 satisfies stationarity and the task (H⁻¹ by
        Sherman–Morrison); it is the (unique) optimum by the KKT conditions iff lb ≤ v ≤ ub,
        l ≤ C v ≤ u and |λᵢ| ≤ ρ₁ (the exact penalty's subgradient condition). This is an
        active-set solver's first iterate: exact, no tolerance involved.
        """
        z = np.empty(problem.n)
        rot, c = self._cost_rank1
        ok = _closed_form(
            problem.H, problem.g, problem.A, problem.b, problem.C, problem.l, problem.u, problem.lb, problem.ub,
            rot, c, z,
        )
        return z if ok else None

    def _solve(self, backend: QPBackend, problem: QPProblem) -> FloatArray | None:
        """z of the stage ``problem`` by the cascade (the module docstring), None: no solution."""
        self._last_problem = problem
        self._closed_form_hit = False
        if self.config.qp.closed_form_first:
            z = self.closed_form(problem)
            if z is not None:  # its residual is already checked to 1e-10
                self.closed_form_hits += 1
                self._closed_form_hit = True
                return z
        fallback = self._fallback if self.solver != "daqp" else None
        key = id(backend)
        left = self._daqp_first.get(key, 0)
        if fallback is not None and left > 0:  # in a run of hard instances
            self._daqp_first[key] = left - 1
            if left == 1:
                backend.reset()  # the window ends: the configured backend starts again cold
                self._after_window.add(key)
            sol = fallback.solve(problem)
            self.daqp_first += int(sol.ok)
            if (not sol.ok or sol.z is None) and sol.status != "infeasible":
                self._daqp_first[key] = 0  # DAQP failed (not its exact verdict): the window ends here
                self._after_window.add(key)  # (the configured backend failing next grows the next one)
                sol = backend.solve(problem)
        else:
            sol = backend.solve(problem)
            failed = not sol.ok or sol.z is None
            window = self._window.get(key, DAQP_FIRST)
            if not (failed or sol.hard):
                self._window[key] = DAQP_FIRST
            elif fallback is not None:  # failed, or solved with a hard instance's effort
                # again right after a window: a longer one
                window = min(4 * window, DAQP_FIRST_MAX) if key in self._after_window else DAQP_FIRST
                self._window[key] = window
                self._daqp_first[key] = window
                if failed:
                    sol = fallback.solve(problem)
                    self.fallbacks += int(sol.ok)
            self._after_window.discard(key)
        if not sol.ok or sol.z is None:
            return None
        z = np.clip(sol.z, problem.lb, problem.ub)  # hard bounds exactly, whatever the tolerance
        if task_residual(problem, z) > SLACK_ACCEPT:
            z = self._task_first(problem, z)
        return z

    def _task_first(self, problem: QPProblem, z: FloatArray) -> FloatArray:
        """Strict task priority when the penalised solve left slack.

        The exact penalty keeps s = 0 only while ρ₁ exceeds the task's multiplier; near a
        singularity, with the null-space DM term (∝ H2³) or the return term, the multiplier can
        exceed it although the bounds admit the task. So: solve again with s ≡ 0 (the task a hard
        equality) by DAQP, whose infeasibility detection is exact. Feasible → that optimum is the
        lexicographic answer (task first, then the cost with its DM/return terms); infeasible →
        the task truly cannot be met and the penalised solution stands.

        Next to a singularity the DM term can be 10⁵× the cost's scale while a row of J is ~1e-6,
        and DAQP (and proxsuite) may then report such a feasible task infeasible. So a failed
        exact solve is repeated once without the linear term (DM and return terms: the lower
        priorities, given up for this tick) before the task is declared infeasible.
        """
        checker = self._fallback if self._fallback is not None else self._full
        self.task_checks += 1
        n = problem.n - self._n_s
        saved = problem.ub[n:].copy()
        problem.ub[n:] = 0.0  # s⁺ = s⁻ = 0
        try:
            sol = checker.solve(problem)
            if not (sol.ok and sol.z is not None) and problem.g[:n].any():
                g = problem.g[:n].copy()
                problem.g[:n] = 0.0
                try:
                    sol = checker.solve(problem)
                finally:
                    problem.g[:n] = g
                self.task_without_objective += int(sol.ok and sol.z is not None)
        finally:
            problem.ub[n:] = saved
        if sol.ok and sol.z is not None:
            self.task_recovered += 1
            exact = np.clip(sol.z, problem.lb, problem.ub)
            exact[n:] = 0.0
            return exact
        return z
