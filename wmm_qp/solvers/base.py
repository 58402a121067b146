"""Interface of a QP backend with a persistent workspace."""

from __future__ import annotations

from abc import ABC, abstractmethod

from .problem import QPProblem, QPSolution


class QPBackend(ABC):
    """One QP solver. An instance keeps its workspace between calls for problems of one shape
    (n, n_eq, n_in) and warm-starts from the previous solution where the solver allows it.

    Args:
        eps_abs: absolute tolerance for iterative solvers.
        max_iter: iteration cap (a cap reached is a failure, not a solution).
    """

    name = "backend"

    def __init__(self, eps_abs: float = 1e-9, max_iter: int = 200) -> None:
        self.eps_abs = eps_abs
        self.max_iter = max_iter

    @abstractmethod
    def solve(self, problem: QPProblem) -> QPSolution:
        """Solve; never raises (a backend exception becomes ``ok=False`` with its message)."""

    def reset(self) -> None:  # noqa: B027 (optional hook, no-op by default)
        """Drop warm-start information (next solve starts cold)."""
