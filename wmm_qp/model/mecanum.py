"""Kinematics of the four-wheel Mecanum base, eqs. (3) and (20).

Convention (DESIGN.md §1). Wheels are ordered front-left, front-right, rear-left,
rear-right; a positive wheel speed drives its wheel forward. With rollers at 45° in the
usual X arrangement, the base twist in the base frame is

    [v_x, v_y, ω]ᵀ = M v_b,   M = (R/4)·[[ 1,    1,   1,    1  ],
                                       [−1,    1,   1,   −1  ],
                                       [−1/L, 1/L, −1/L, 1/L ]],   L = l1 + l2,

so all wheels forward drive the base forward, (−, +, +, −) drives it to the left and
(−, +, −, +) spins it counter-clockwise. The paper's printed J_l J_v (eq. (20)) lost the
signs and the R/4 factor; this is what it must mean.
"""

from __future__ import annotations

import math

import numpy as np

from ..config import BaseConfig, FloatArray


class MecanumBase:
    """The Mecanum base of eq. (20).

    Args:
        config: wheel radius and geometry.
    """

    def __init__(self, config: BaseConfig) -> None:
        self.config = config
        R, L = config.wheel_radius, config.l1 + config.l2
        self.M: FloatArray = (R / 4.0) * np.array(
            [[1.0, 1.0, 1.0, 1.0], [-1.0, 1.0, 1.0, -1.0], [-1.0 / L, 1.0 / L, -1.0 / L, 1.0 / L]]
        )
        self.M.setflags(write=False)
        # Right inverse (M has full row rank): the wheel speeds of a body twist.
        self.M_pinv: FloatArray = np.asarray(np.linalg.pinv(self.M), dtype=np.float64)
        self.M_pinv.setflags(write=False)

    def P(self, yaw: float) -> FloatArray:
        """P(q_b) of eqs. (3), (20): wheel speeds → world-frame base velocity [ẋ_b, ẏ_b, ψ̇].

        Args:
            yaw: [rad] base heading ψ.
        """
        c, s = math.cos(yaw), math.sin(yaw)
        return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ self.M  # blkdiag(Rz2(ψ), 1)·M

    def body_twist(self, wheel_speeds: FloatArray) -> FloatArray:
        """[v_x, v_y, ω] in the base frame [m/s, m/s, rad/s] for wheel speeds [rad/s]."""
        return self.M @ wheel_speeds

    def wheel_speeds(self, body_twist: FloatArray) -> FloatArray:
        """Wheel speeds [rad/s] that realise a base-frame twist [v_x, v_y, ω] (no slip)."""
        return self.M_pinv @ body_twist
