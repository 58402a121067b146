"""The three-wheel omni base (docs/model.md "Any robot").

Three omni wheels at θ_i = 90°, 210°, 330° (counter-clockwise from the base's x axis), at
distance L = ``base_radius`` from the centre, each driving tangentially (a positive speed pushes
the base counter-clockwise about its centre). Wheel i's rim speed is

    R ω_i = −sin θ_i v_x + cos θ_i v_y + L ω,

so with K's rows (−sin θ_i, cos θ_i, L), the body twist is [v_x, v_y, ω]ᵀ = M ω, M = R·K⁻¹ (eq. (3)).
Wheel order: the wheel at 90° (on the base's left), then 210° (rear right), then 330° (front right).
"""

from __future__ import annotations

import math

import numpy as np

from ...config import BaseConfig
from .base import Base

ANGLES = (math.pi / 2, 7 * math.pi / 6, 11 * math.pi / 6)
"""[rad] θ_i of the three wheels."""


class OmniBase(Base):
    """Three omni wheels at 120° (wheel_radius R, base_radius L)."""

    kind = "omni"
    wheel_names = ("wheel_90", "wheel_210", "wheel_330")

    def __init__(self, config: BaseConfig) -> None:
        L = config.base_radius
        K = np.array([[-math.sin(t), math.cos(t), L] for t in ANGLES])
        super().__init__(config, config.wheel_radius * np.linalg.inv(K))
