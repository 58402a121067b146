"""Rows of the QP: named linear constraints l ≤ C v ≤ u on v = [v_b; v_m], and the sources that
give them each tick (pink's and mink's ``Limit.compute_qp_inequalities``).

A :class:`RowSource` returns its :class:`Rows` for the tick (the EE box of eq. (17),
:mod:`.ee_box`; the collision dampers, :mod:`.collision`; the fence, :mod:`.fence`; the σ_min
floor, :mod:`.singularity_floor`) and says how the QP's stages treat them (:class:`Retry`,
``rechecked``); the stages stack the sources' rows and treat every source alike.

Every row yields to bounds (13): it is relaxed, where the bounds cannot meet it, to what they
admit (``l``). Each row alone is then feasible; should rows together not be, the stage is solved
again with them relaxed further (``l_brake``): the dampers together, to their joint command
(:meth:`Rows.relax_together`): no row ever makes a stage infeasible.
"""

from __future__ import annotations

import copy
import enum
import math
from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from .._jit import jit
from .._typing import FloatArray
from ..model.wmm import Kinematics
from ..types import Mode

RELAX_MARGIN = 1e-9
"""[m/s] a row relaxed to a command of the box passes this far below it: a relaxed row would pass
through a vertex of the box exactly, and no solver's tolerance may read that degenerate (feasible)
problem as infeasible."""
JOINT_ITERATIONS = 300  # projected-gradient iterations of the rows' joint command (``Rows.relax_together``)
JOINT_WEIGHT = 1e-6  # its pull towards the braking command [-]: breaks ties, the shortfalls decide
JOINT_FLOOR_WEIGHT = 10.0  # its penalty on a row below what the braking command gives it [-]


@dataclass
class Rows:
    """The rows one source gives one tick: l ≤ C v ≤ u.

    Attributes:
        C: (k, n_v) the rows, on v = [v_b; v_m].
        l: (k,) the lower bound, relaxed to what bounds (13) admit (a damper: to the most
            separating rate they admit).
        l_brake: (k,) the lower bound of the stage solved again when the rows exclude each other:
            relaxed to admit the braking command v₀ = clip(0, lb, ub), or, after
            :meth:`relax_together`, the rows' joint command.
        damper: (k,) the bound the source asks for before any relaxation (a damper's own bound).
        names: one per row, e.g. "a/b" (a pair of bodies), "a/floor", "fence:ee x", "EE box z".
        distances: (k,) how far each row's quantity is from its limit ([m]: a pair's distance, the
            fence's margin, the EE's to the box; [m/rad] σ_min − σ_f).
        min_distance: [m] the closest monitored pair this tick of those the broad phase computed
            (beyond the influence distance it may not be the closest of all).
        closest: that pair's name.
        u: (k,) the upper bound, or None: none (l ≤ C v).
    """

    C: FloatArray
    l: FloatArray
    l_brake: FloatArray = field(default_factory=lambda: np.zeros(0))
    damper: FloatArray = field(default_factory=lambda: np.zeros(0))
    names: Sequence[str] = field(default_factory=list)
    distances: FloatArray = field(default_factory=lambda: np.zeros(0))
    min_distance: float = math.inf
    closest: str = ""
    u: FloatArray | None = None

    @property
    def n(self) -> int:
        """The number of rows."""
        return int(self.l.shape[0])

    def upper(self) -> FloatArray:
        """(k,) the upper bound, +inf where there is none."""
        return self.u if self.u is not None else np.full(self.l.shape[0], np.inf)

    @staticmethod
    def stack(parts: list[Rows], n_v: int) -> Rows:
        """One Rows of several, in order; ``min_distance``, ``closest``: the nearest part's. A part
        that is the only one with rows and the nearest is returned as it is; the only one with
        rows but not the nearest, as a copy that shares its arrays and names."""
        nearest = min(parts, key=lambda r: r.min_distance) if parts else Rows(np.zeros((0, n_v)), np.zeros(0))
        full = [r for r in parts if r.l.shape[0]]
        if not full or (len(full) == 1 and full[0] is nearest):
            return nearest
        if len(full) == 1:
            out = copy.copy(full[0])
            out.min_distance, out.closest = nearest.min_distance, nearest.closest
            return out
        out = Rows(np.vstack([r.C for r in full]), np.concatenate([r.l for r in full]),
                   l_brake=np.concatenate([r.l_brake for r in full]), damper=np.concatenate([r.damper for r in full]),
                   names=[name for r in full for name in r.names],
                   distances=np.concatenate([r.distances for r in full]),
                   u=None if all(r.u is None for r in full) else np.concatenate([r.upper() for r in full]))
        out.min_distance, out.closest = nearest.min_distance, nearest.closest
        return out

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


class Retry(enum.Enum):
    """How the stage solved again when rows exclude each other treats a source's rows."""

    TOGETHER = "together"
    """Velocity dampers: pooled with every other TOGETHER source's rows, relaxed together to their
    joint command (:meth:`Rows.relax_together`), reported together (the task cut by the nearest)."""
    KEEP = "keep"
    """Kept as they are (they admit the braking command already); the joint command must meet them."""
    ADMIT = "admit"
    """Relaxed (``l_brake``) to admit the braking command, and then the dampers' joint command too."""


@dataclass(slots=True)
class Tick:
    """What a row source reads each tick.

    Attributes:
        mode: the controller's mode.
        kin: the tick's kinematics (eqs. (2), (5); the arm's data is current, for the collision
            rows' joint placements).
        v_prev: [v_b; v_m] the bounds' centre: the last command [rad/s, rad/s or m/s].
        lb, ub: the bounds on v: the wheel bounds and eq. (13).
    """

    mode: Mode
    kin: Kinematics
    v_prev: FloatArray
    lb: FloatArray
    ub: FloatArray


class RowSource(ABC):
    """A source of hard QP rows (pink's and mink's ``Limit``): each tick, named rows l ≤ C v ≤ u.

    Attributes:
        name: what the rows are, in reasons ("EE box", "collision", "fence", "sigma_min floor").
        retry: how the stage solved again when rows exclude each other treats them (:class:`Retry`).
        rechecked: whatever solved a stage, the command is re-checked on these rows and projected
            back onto any it leaves (the EE box, the dampers); False: met to the solver's
            tolerance (the σ_min floor, which steers the DM ascent).
    """

    name: str = "rows"
    retry: Retry = Retry.KEEP
    rechecked: bool = True

    @abstractmethod
    def compute_rows(self, tick: Tick) -> Rows | None:
        """This tick's rows (every array with one entry per row), or None: none in this mode."""

    def yields_to_task(self, mode: Mode) -> bool:
        """In this mode the task outranks the rows: a stage whose task they cut (or that no solver
        solves with them) is solved again without them, and that command taken if it meets the task."""
        return False

    def cut_reason(self, rows: Rows, v: FloatArray) -> str:
        """Why the task was cut, if the command v sits on one of these rows ("" if not)."""
        return ""

    def row_label(self, rows: Rows, k: int) -> str:
        """Row k in a reason (the re-check's: "<label>: the solution left it by ...")."""
        return self.name
