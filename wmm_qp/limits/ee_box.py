"""The EE box of eq. (17) as hard QP rows of DM_CARTESIAN (``dm.ee_box_lower``/``ee_box_upper``;
not the scene's EE fence, :mod:`.fence`).

Eq. (17) stops the Cartesian DM ascent on an axis once the EE leaves the box; the QP controller
makes the box a constraint of the tick, on each axis r with a finite bound (docs/model.md "The QP"):

    x_r + Δt J_r v ∈ [min(x_min,r, x_r, x_r + Δt J_r v₀), max(x_max,r, x_r, x_r + Δt J_r v₀)]

x the EE position this tick (eq. (2)), J its Jacobian (eq. (5)), v₀ = clip(0, lb, ub) the braking
command inside bounds (13): inside the box the predicted EE stays inside; outside it may not move
further out; where even full braking leaves the box, the row admits exactly as far as braking
goes. So the rows always admit v₀, and the stage is always feasible.
"""

from __future__ import annotations

import numpy as np

from .._jit import jit
from .._typing import FloatArray, IntArray
from ..types import Mode
from .rows import Retry, Rows, RowSource, Tick


@jit
def _ee_box(
    J: FloatArray,
    x: FloatArray,
    lo: FloatArray,
    hi: FloatArray,
    axes: IntArray,
    lb: FloatArray,
    ub: FloatArray,
    dt: float,
    C: FloatArray,
    l: FloatArray,
    u: FloatArray,
) -> None:
    """C, l, u of the rows (the module docstring) on the EE's ``axes``, C of the predicted motion Δt J."""
    for k in range(axes.shape[0]):
        r = axes[k]
        reach = 0.0  # where the command nearest zero inside the box bounds takes the EE
        for i in range(J.shape[1]):
            C[k, i] = dt * J[r, i]
            reach += C[k, i] * min(max(0.0, lb[i]), ub[i])
        l[k] = min(min(lo[r], x[r]) - x[r], reach)  # never further out than x already is
        u[k] = max(max(hi[r], x[r]) - x[r], reach)


class EeBox(RowSource):
    """The EE box of eq. (17): one row per axis with a finite bound, in DM_CARTESIAN only.

    Args:
        lower, upper: [m] the box (world frame; ±inf: free).
        dt: [s] the control period Δt.
    """

    name = "EE box"
    retry = Retry.KEEP
    rechecked = True

    def __init__(self, lower: FloatArray, upper: FloatArray, dt: float) -> None:
        self.lower, self.upper, self.dt = lower, upper, dt
        self.axes = np.flatnonzero(np.isfinite(lower) | np.isfinite(upper)).astype(np.int64)
        self._names = [f"EE box {'xyz'[a]}" for a in self.axes.tolist()]

    def compute_rows(self, tick: Tick) -> Rows | None:
        k = self.axes.shape[0]
        if tick.mode != Mode.DM_CARTESIAN or not k:
            return None
        C, l, u = np.empty((k, tick.lb.shape[0])), np.empty(k), np.empty(k)
        x = tick.kin.x
        _ee_box(tick.kin.J, x, self.lower, self.upper, self.axes, tick.lb, tick.ub, self.dt, C, l, u)
        inside = np.minimum(x[self.axes] - self.lower[self.axes], self.upper[self.axes] - x[self.axes])
        return Rows(C, l, l_brake=l, damper=l, names=self._names, distances=inside, u=u)
