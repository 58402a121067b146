"""The "traditional" baseline: v = J⁺ ẋ with the plain pseudoinverse of the full J.

No weighting between base and arm, no α switch, no bounds: the comparison point of the
paper's Table I. In the DM modes it uses the same task velocities and null-space term as
the paper's controller, with J⁺ in place of J#.

J⁺ minimises the norm of v, so it depends on the units of v's wheel entries:

- ``wheel_units = "rad"`` (ours, the default): v_b are wheel speeds in rad/s, as everywhere in
  wmm-qp. A wheel then costs J⁺ as much as a joint while moving the EE only ~R/4 per rad/s
  (eq. (20)), so J⁺ barely uses the base.
- ``wheel_units = "rim"``: v_b are the wheels' rim speeds R·ω in m/s, which the printed (20)'s
  unit entries suggest is the paper's v_b. J⁺ is taken of J D, D = diag(1/R·I_wheels, I_joints)
  (J v = (J D)(D⁻¹ v), D⁻¹ v = [R ω; v_m]), then v = D (J D)⁺ ẋ: the base is cheap for J⁺.

Either way the command sent is wheel speeds in rad/s.
"""

from __future__ import annotations

import numpy as np

from ..config import ControllerConfig
from ..model.wmm import WmmModel
from ..types import Command, Mode, Reference, RobotState
from .base import Controller

WHEEL_UNITS = ("rad", "rim")


class TraditionalController(Controller):
    """v = J⁺ ẋ_ref (+ (I − J⁺J) v_n in the null-space DM mode), J⁺ in the chosen wheel units.

    Args:
        model: the robot.
        config: gains.
        wheel_units: "rad" (wheel speeds in rad/s) or "rim" (rim speeds in m/s) for J⁺.

    Raises:
        ValueError: unknown wheel units, or "rim" on a base with wheels but no wheel radius.
    """

    name = "traditional"

    def __init__(self, model: WmmModel, config: ControllerConfig, wheel_units: str = "rad") -> None:
        super().__init__(model, config)
        if wheel_units not in WHEEL_UNITS:
            raise ValueError(f"unknown wheel units {wheel_units!r}; choose one of {', '.join(WHEEL_UNITS)}")
        R = float(self.robot.base.wheel_radius)
        if wheel_units == "rim" and self.n_wheels and not R > 0.0:
            raise ValueError(f"wheel_units 'rim' needs the base's wheel_radius, got {R}")
        self.wheel_units = wheel_units
        # v = D v', v' the J⁺ coordinates: D = 1 (rad) or diag(1/R I_wheels, I_joints) (rim)
        self._D = np.ones(self.n_v)
        if wheel_units == "rim":
            self._D[: self.n_wheels] = 1.0 / R

    def _step(self, state: RobotState, reference: Reference) -> Command:
        mode = reference.mode
        ctx = self.context(state, reference, need_gradient=self.needs_gradient(mode))
        xdot = self.task_velocity(ctx, reference)
        JD = ctx.kin.J * self._D  # J D (D = I in rad units)
        Jp = np.linalg.pinv(JD, rcond=1e-10)
        v = Jp @ xdot
        if mode == Mode.DM_NULLSPACE:
            assert ctx.grad_q is not None
            v_n = self.config.k_N * np.concatenate([np.zeros(self.n_wheels), ctx.grad_q])  # eq. (19)
            v = v + (np.eye(self.n_v) - Jp @ JD) @ v_n
        return self.finish(ctx, self._D * v, xdot, alpha=float("nan"))
