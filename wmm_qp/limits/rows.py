"""Rows of the QP: named linear constraints l ≤ C v (≤ u) on v = [v_b; v_m], one set per source
and tick, and how a stage relaxes them together when they exclude each other.

The dampers (collision pairs, the fence) yield to bounds (13): each row is relaxed, where the
bounds cannot meet it, to the most separating rate they admit (``l``, :mod:`.dampers`). Each row
alone is then feasible; should the rows together not be, the stage is solved again with them
relaxed together (:meth:`Rows.relax_together`, ``l_brake``): no row ever makes a stage infeasible.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .._jit import jit
from .._typing import FloatArray

RELAX_MARGIN = 1e-9
"""[m/s] a row relaxed to a command of the box passes this far below it: a relaxed row would pass
through a vertex of the box exactly, and no solver's tolerance may read that degenerate (feasible)
problem as infeasible."""
JOINT_ITERATIONS = 300  # projected-gradient iterations of the rows' joint command (``Rows.relax_together``)
JOINT_WEIGHT = 1e-6  # its pull towards the braking command [-]: breaks ties, the shortfalls decide
JOINT_FLOOR_WEIGHT = 10.0  # its penalty on a row below what the braking command gives it [-]


@dataclass
class Rows:
    """The collision and fence rows of one tick: l ≤ C v (no upper bound).

    Attributes:
        C: (k, n_v) the rows, on v = [v_b; v_m].
        l: (k,) the damper, relaxed to the most separating rate the bounds admit.
        l_brake: (k,) relaxed to admit the braking command (or, after :meth:`relax_together`, the
            rows' joint command).
        damper: (k,) the damper's own bound, before any relaxation.
        names: one per row: "a/b" (a pair of bodies), "a/floor", "a/<obstacle>", "fence:...".
        distances: [m] (k,) each row's distance (the pair's, or the fence's margin).
        min_distance: [m] the closest monitored pair this tick (also beyond the influence distance).
        closest: that pair's name.
    """

    C: FloatArray
    l: FloatArray
    l_brake: FloatArray = field(default_factory=lambda: np.zeros(0))
    damper: FloatArray = field(default_factory=lambda: np.zeros(0))
    names: list[str] = field(default_factory=list)
    distances: FloatArray = field(default_factory=lambda: np.zeros(0))
    min_distance: float = math.inf
    closest: str = ""

    def relax_together(self, lb: FloatArray, ub: FloatArray, C_box: FloatArray | None = None,
                       l_box: FloatArray | None = None, u_box: FloatArray | None = None) -> FloatArray:
        """Relax the rows together (``l_brake``), when relaxed one by one (``l``) they exclude each
        other: each row to min(damper, C_k v_r), v_r a command of the box lb ≤ v ≤ ub that does
        for no row worse than the braking command v₀ = clip(0, lb, ub) or its damper, whichever
        asks less (the floor C_k v_r ≥ min(C_k v₀, damper_k)), and within that comes nearest to
        stopping every approach the braking command lets go on (the target max(floor_k,
        min(damper_k, 0)); least squares of the shortfalls, :func:`_joint_command`, then moved
        back towards v₀ as far as the floors and the other rows l_box ≤ C_box v ≤ u_box, which
        admit v₀, need). Every row and bound admits v_r, so the stage is feasible; no row admits
        more than it would relaxed to v₀; where v₀ keeps a pair approaching, v_r slows that
        approach as far as the bounds allow with the others (relaxed to v₀ instead, a pair may
        keep approaching at v₀'s rate tick after tick); and v_r asks no pair for more than to stop
        approaching (not its full damper separation, which the bodies' row shapes need not
        follow). docs/model.md "Collisions", "priority".

        Returns:
            v_r (the stage's reference point: the re-check of the rows moves back towards it).
        """
        v0 = np.minimum(np.maximum(0.0, lb), ub)
        floor = np.minimum(self.C @ v0, self.damper)
        target = np.maximum(floor, np.minimum(self.damper, 0.0))  # no approach, where braking lets one go on
        v = np.empty(lb.shape[0])
        _joint_command(self.C, target, floor, lb, ub, v0, JOINT_ITERATIONS, v)
        lo, hi, C = floor, np.full(floor.shape[0], np.inf), self.C
        if C_box is not None and l_box is not None and u_box is not None and C_box.shape[0]:
            lo, hi, C = np.concatenate((lo, l_box)), np.concatenate((hi, u_box)), np.vstack((C, C_box))
        e0, e1 = C @ v0, C @ v
        t = 1.0  # the largest step from v₀ towards v that keeps every floor and every other row
        for k in range(C.shape[0]):
            if e1[k] > hi[k] and e1[k] > e0[k]:
                t = min(t, max(0.0, (hi[k] - e0[k]) / (e1[k] - e0[k])))
            elif e1[k] < lo[k] and e1[k] < e0[k]:
                t = min(t, max(0.0, (lo[k] - e0[k]) / (e1[k] - e0[k])))
        v = v0 + t * (v - v0)
        self.l_brake = np.minimum(self.damper, self.C @ v) - RELAX_MARGIN
        return v


@jit
def _joint_command(C: FloatArray, target: FloatArray, floor: FloatArray, lb: FloatArray, ub: FloatArray,
                   v0: FloatArray, iterations: int, out: FloatArray) -> None:
    """out ← the v of lb ≤ v ≤ ub minimising Σ_k max(0, target_k − C_k v)² + w Σ_k max(0,
    floor_k − C_k v)² + μ‖v − v₀‖² (w = ``JOINT_FLOOR_WEIGHT``, μ = ``JOINT_WEIGHT``): the command
    nearest to meeting every row at once while keeping each above its floor, by accelerated
    projected gradient (FISTA) from v₀. Convex; its step 1/L with L = 2((1 + w)‖C‖_F² + μ) (an
    upper bound of the gradient's Lipschitz constant) converges without line search. Not exact,
    and need not be: the caller steps back towards v₀ until every floor holds, and relaxes the
    rows to what that command achieves, so every row admits it."""
    m, n = C.shape
    fro = 0.0  # ‖CᵀC‖₂ ≤ ‖C‖_F²
    for k in range(m):
        for i in range(n):
            fro += C[k, i] * C[k, i]
    lip = 2.0 * ((1.0 + JOINT_FLOOR_WEIGHT) * fro + JOINT_WEIGHT)
    x = v0.copy()
    y = v0.copy()
    grad = np.empty(n)
    t = 1.0
    for _ in range(iterations):
        for i in range(n):
            grad[i] = 2.0 * JOINT_WEIGHT * (y[i] - v0[i])
        for k in range(m):
            e = 0.0
            for i in range(n):
                e += C[k, i] * y[i]
            pull = max(0.0, target[k] - e) + JOINT_FLOOR_WEIGHT * max(0.0, floor[k] - e)
            if pull > 0.0:
                for i in range(n):
                    grad[i] -= 2.0 * pull * C[k, i]
        t_next = 0.5 * (1.0 + math.sqrt(1.0 + 4.0 * t * t))
        moved = 0.0
        for i in range(n):
            xi = min(max(y[i] - grad[i] / lip, lb[i]), ub[i])
            y[i] = xi + (t - 1.0) / t_next * (xi - x[i])
            moved = max(moved, abs(xi - x[i]))
            x[i] = xi
        t = t_next
        if moved < 1e-12:
            break
    for i in range(n):
        out[i] = x[i]
