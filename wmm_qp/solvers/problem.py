"""The QP as data: what every backend solves, and what it returns.

    minimize    ½ zᵀ H z + gᵀ z
    subject to  A z = b,  l ≤ C z ≤ u,  lb ≤ z ≤ ub

Tests and logs inspect this object, not only the answer (build, then solve).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._typing import FloatArray

INF = 1e20  # what the backends get in place of ±inf


@dataclass(slots=True)
class QPProblem:
    """A dense QP (see the module docstring); C, l, u may have zero rows."""

    H: FloatArray
    g: FloatArray
    A: FloatArray
    b: FloatArray
    C: FloatArray
    l: FloatArray
    u: FloatArray
    lb: FloatArray
    ub: FloatArray

    @property
    def n(self) -> int:
        return int(self.H.shape[0])

    @property
    def n_eq(self) -> int:
        return int(self.A.shape[0])

    @property
    def n_in(self) -> int:
        return int(self.C.shape[0])

    def violation(self, z: FloatArray) -> float:
        """Largest violation of any constraint at z (0 when feasible)."""
        parts = [np.abs(self.A @ z - self.b), self.lb - z, z - self.ub]
        if self.n_in:
            Cz = self.C @ z
            parts += [self.l - Cz, Cz - self.u]
        return float(max(0.0, *(float(np.max(p)) for p in parts if p.size)))


@dataclass(slots=True)
class QPSolution:
    """A backend's answer: z (None if it failed), whether it is optimal, and why not; ``hard``:
    solved, but with what the backend counts as a hard instance's effort (proxsuite: a cold retry
    after a failed warm start, or at least its ``HARD_ITERATIONS``)."""

    z: FloatArray | None
    ok: bool
    status: str
    iterations: int = 0
    hard: bool = False
