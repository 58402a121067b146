"""The "traditional" baseline: v = J⁺ ẋ with the plain pseudoinverse of the full J.

No weighting between base and arm, no α switch, no bounds: the comparison point of the
paper's Table I. In the DM modes it uses the same task velocities and null-space term as
the paper's controller, with J⁺ in place of J#.
"""

from __future__ import annotations

import numpy as np

from ..types import Command, Mode, Reference, RobotState
from .base import Controller


class TraditionalController(Controller):
    """v = J⁺ ẋ_ref (+ (I − J⁺J) v_n in the null-space DM mode)."""

    name = "traditional"

    def _step(self, state: RobotState, reference: Reference) -> Command:
        mode = reference.mode
        ctx = self.context(state, reference, need_gradient=self.needs_gradient(mode))
        xdot = self.task_velocity(ctx, reference)
        Jp = np.linalg.pinv(ctx.kin.J, rcond=1e-10)
        v = Jp @ xdot
        if mode == Mode.DM_NULLSPACE:
            assert ctx.grad_q is not None
            v_n = self.config.k_N * np.concatenate([np.zeros(self.n_wheels), ctx.grad_q])  # eq. (19)
            v = v + (np.eye(self.n_v) - Jp @ ctx.kin.J) @ v_n
        return self.finish(ctx, v, xdot, alpha=float("nan"))
