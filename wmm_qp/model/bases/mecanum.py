"""The four-wheel Mecanum base, eqs. (3) and (20).

Convention (docs/model.md). Wheels are ordered front-left, front-right, rear-left,
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

import numpy as np

from ...config import BaseConfig
from .base import Base


class MecanumBase(Base):
    """The Mecanum base of eq. (20) (wheel_radius R, half wheelbase l1, half track l2)."""

    kind = "mecanum"
    wheel_names = ("front_left", "front_right", "rear_left", "rear_right")

    def __init__(self, config: BaseConfig) -> None:
        R, L = config.wheel_radius, config.l1 + config.l2
        M = (R / 4.0) * np.array(
            [[1.0, 1.0, 1.0, 1.0], [-1.0, 1.0, 1.0, -1.0], [-1.0 / L, 1.0 / L, -1.0 / L, 1.0 / L]]
        )  # eq. (20)
        super().__init__(config, M)
