"""The workspace fence as hard QP rows: the base's origin inside the scene's polygon, the EE inside
its box (the EE fence, ``[fence] ee_lower``/``ee_upper``; not eq. (17)'s EE box of DM_CARTESIAN).

A workspace limit, not a collision: no geometry, one damper per edge or face within the influence
distance d_i, of the velocity damper's form (:mod:`.dampers`) with d_s = 0:

    base edge e (outward unit normal n_e, the polygon A p ≤ c):   −n_eᵀ ṗ_b ≥ −ξ d/d_i
    EE fence face (axis a, either side):                          ∓J_a v ≥ −ξ d/d_i

with d the base origin's distance to the edge's line, or the EE's to the face, ṗ_b = P₂(ψ)·M v_b
the base origin's world velocity (eq. (3)) and J_a the a-th row of the EE's world Jacobian (eq. (5)).
"""

from __future__ import annotations

import math

import numpy as np

from .._jit import jit
from .._typing import FloatArray
from ..config import CollisionParams
from ..scene import Fence
from .dampers import DamperRows, damper_bounds
from .rows import Rows, Tick


@jit
def _fence_near(A: FloatArray, c: FloatArray, q_base: FloatArray, n_w: int, lower: FloatArray,
                upper: FloatArray, x: FloatArray, d_i: float) -> bool:
    """Whether the base's origin (``q_base[:2]``) is within d_i of a fence edge or the EE within
    d_i of its fence."""
    if n_w:
        for k in range(A.shape[0]):
            if c[k] - (A[k, 0] * q_base[0] + A[k, 1] * q_base[1]) < d_i:
                return True
    for a in range(3):  # noqa: SIM110 (a loop numba compiles)
        if upper[a] - x[a] < d_i or x[a] - lower[a] < d_i:
            return True
    return False


class FenceRows(DamperRows):
    """The fence's dampers each tick (see the module docstring).

    Args:
        M: the base's 3 × n_wheels matrix (eq. (3)).
        n_arm: the arm's number of joints.
        params: d_i, ξ, β (``influence_distance``, ``gain``, ``braking``).
        latency: [s] τ, the state's age the rows account for.
        accel: A of each column of v = [wheels, arm] (the braking profile's deceleration).
    """

    def __init__(self, M: FloatArray, n_arm: int, params: CollisionParams, latency: float, accel: FloatArray) -> None:
        self.M = np.asarray(M, dtype=float)
        self.n_w = self.M.shape[1]
        self.n_v = self.n_w + n_arm
        self.p = params
        self.latency = latency
        self._accel = np.asarray(accel, dtype=float)
        self.fence = Fence()
        self._A, self._c = np.zeros((0, 2)), np.zeros(0)  # the polygon as A p ≤ c
        self._none = Rows(np.zeros((0, self.n_v)), np.zeros(0))

    def set_fence(self, fence: Fence) -> None:
        self.fence = fence
        self._A, self._c = fence.half_planes()

    @property
    def fenced(self) -> bool:
        """The fence bounds anything: a polygon for the base, or a finite face for the EE."""
        f = self.fence
        return f.base.shape[0] >= 3 or bool(np.isfinite(f.ee_lower).any()) or bool(np.isfinite(f.ee_upper).any())

    def compute_rows(self, tick: Tick) -> Rows | None:
        """The fence's rows at the tick's state; None while it has none (the usual tick: the
        stages then pool no empty part with the collision rows)."""
        kin, f = tick.kin, self.fence
        if not _fence_near(self._A, self._c, kin.q_base, self.n_w, f.ee_lower, f.ee_upper, kin.x,
                           self.p.influence_distance):
            return None  # the usual tick: one compiled call
        rows = self.rows(kin.q_base, kin.x, kin.J[:3], tick.v_prev, tick.lb, tick.ub)
        return None if rows is self._none else rows

    def rows(self, q_base: FloatArray, x_ee: FloatArray, J_ee: FloatArray, v_prev: FloatArray, lb: FloatArray,
             ub: FloatArray) -> Rows:
        """The fence's rows this tick (none while the base and the EE are further than d_i from it).

        Args:
            q_base: [m, m, rad] the base pose.
            x_ee: [m] the EE position (world), J_ee its 3 × n_v world Jacobian.
            v_prev: the bounds' centre (the last command), for the latency term.
            lb, ub: the stage's box bounds on v (for the relaxations).
        """
        f, d_i = self.fence, self.p.influence_distance
        A, c = self._A, self._c
        if not _fence_near(A, c, q_base, self.n_w, f.ee_lower, f.ee_upper, x_ee, d_i):
            return self._none
        rows: list[FloatArray] = []
        dist: list[float] = []
        names: list[str] = []
        if A.shape[0] and self.n_w:
            gaps = c - A @ q_base[:2]  # distance to each edge's line, inside ≥ 0
            near = np.flatnonzero(gaps < d_i)
            if near.shape[0]:
                cos, sin = math.cos(q_base[2]), math.sin(q_base[2])
                P2 = np.array([[cos, -sin], [sin, cos]]) @ self.M[:2]  # the base origin's world velocity, eq. (3)
                for k in near:
                    row = np.zeros(self.n_v)
                    row[: self.n_w] = -A[k] @ P2  # ḋ = −n_eᵀ ṗ_b
                    rows.append(row)
                    dist.append(float(gaps[k]))
                    names.append(f"fence:base edge {k}")
        up, lo = f.ee_upper - x_ee, x_ee - f.ee_lower  # inf where the fence is open
        if (up < d_i).any() or (lo < d_i).any():
            for ax in range(3):
                for sign, d in ((1.0, up[ax]), (-1.0, lo[ax])):
                    if d < d_i:
                        rows.append(-sign * np.asarray(J_ee[ax], dtype=float))
                        dist.append(float(d))
                        names.append(f"fence:ee {'xyz'[ax]}")
        if not rows:
            return self._none
        C, d = np.array(rows), np.array(dist)
        p = self.p
        l, l_brake, damper = damper_bounds(C, v_prev, lb, ub, d, np.zeros(d.shape[0]), d_i, p.gain, self.latency,
                                           np.zeros(d.shape[0]), self._accel, p.braking, np.zeros(d.shape[0]))
        return Rows(C, l, l_brake=l_brake, damper=damper, names=names, distances=d)
