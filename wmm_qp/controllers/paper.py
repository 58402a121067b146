"""The paper's controller: weighted pseudoinverse with the α switch, eqs. (11)–(19).

Our reading of the α switch, eq. (14) (garbled in the print): every tick, first try the
arm alone (α = 0). If that command lies inside the joint motion bounds (13), keep α = 0 —
the base does not move. If it leaves (13), the base takes a share: α = ``gains.alpha``
(0.2 in the paper's experiments). If the arm cannot move at all (every joint's interval
(13) has zero width), α = 1: the base does all. The paper's controller does not clip its
command to (13); that is what the QP controller adds.

Modes: TRACK / HOLD, eq. (15) with v_0 = 0 and ẋ_d + K_x(x_d − x); DM_CARTESIAN, eqs.
(16)–(17); DM_NULLSPACE, eqs. (18)–(19) with the configured α (0.2) — the paper's
null-space experiments use a moving base (docs/model.md). Below σ_min(J_m) = threshold,
damped least squares replaces J#.
"""

from __future__ import annotations

import numpy as np

from .._typing import FloatArray
from ..pseudoinverse import weight_matrix_diag, weighted_pinv
from ..types import Command, Mode, Reference, RobotState
from .base import Controller, TickContext


class PaperController(Controller):
    """Weighted pseudoinverse + α switch (the paper's method, as a baseline)."""

    name = "paper"

    def alpha_switch(self, ctx: TickContext, xdot: FloatArray) -> float:
        """α of eq. (14) (our reading, see the module docstring)."""
        if (ctx.arm_hi - ctx.arm_lo <= 1e-12).all():
            return 1.0
        arm_only = weight_matrix_diag(0.0, self.n_wheels, self.n_arm)  # α = 0
        v0 = weighted_pinv(ctx.kin.J, arm_only, ctx.damping) @ xdot
        inside = (ctx.arm_lo - 1e-12 <= v0[self.n_wheels :]).all() and (v0[self.n_wheels :] <= ctx.arm_hi + 1e-12).all()
        return 0.0 if inside else self.config.alpha

    def pinv(self, ctx: TickContext, alpha: float) -> FloatArray:
        """J# of eq. (11) with W_x of eq. (12); damped near singularities."""
        return weighted_pinv(ctx.kin.J, weight_matrix_diag(alpha, self.n_wheels, self.n_arm), ctx.damping)

    def _step(self, state: RobotState, reference: Reference) -> Command:
        mode = reference.mode
        ctx = self.context(state, reference, need_gradient=self.needs_gradient(mode))
        xdot = self.task_velocity(ctx, reference)
        if mode == Mode.DM_NULLSPACE:
            alpha = self.config.alpha
            Jp = self.pinv(ctx, alpha)
            assert ctx.grad_q is not None
            v_n = self.config.k_N * np.concatenate([np.zeros(self.n_wheels), ctx.grad_q])  # eq. (19)
            v = Jp @ xdot + (np.eye(self.n_v) - Jp @ ctx.kin.J) @ v_n  # eq. (18)
        else:
            alpha = self.alpha_switch(ctx, xdot)  # eq. (14)
            v = self.pinv(ctx, alpha) @ xdot  # eqs. (15), (16)
        return self.finish(ctx, v, xdot, alpha=alpha)
