"""The differential-drive base (docs/model.md "Any robot"): two wheels, nonholonomic.

Wheels (left, right) on one axle through the base's origin, ``track_width`` b apart, radius R:

    v_x = R (ω_l + ω_r)/2,   v_y = 0,   ω = R (ω_r − ω_l)/b,

so M = [[R/2, R/2], [0, 0], [−R/b, R/b]] has rank 2: no combination of wheel speeds moves the
base sideways, the QP's J_b P (eq. (5)) has no sideways column, and the sim integrates the base
so (a sideways EE motion is done by the arm and by the base's yaw and forward motion).
"""

from __future__ import annotations

import numpy as np

from ...config import BaseConfig
from .base import Base


class DiffDriveBase(Base):
    """Two wheels on one axle (wheel_radius R, track_width b)."""

    kind = "diff_drive"
    wheel_names = ("left", "right")

    def __init__(self, config: BaseConfig) -> None:
        R, b = config.wheel_radius, config.track_width
        super().__init__(config, np.array([[R / 2, R / 2], [0.0, 0.0], [-R / b, R / b]]))
