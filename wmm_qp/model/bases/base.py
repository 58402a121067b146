"""The one interface of every base kind: its wheels and P(q_b) of eq. (3).

Each kind gives M (3 × n_wheels), the map from wheel speeds [rad/s] to the body twist
(v_x, v_y, ω) in the base frame; then P(ψ) = blkdiag(Rz2(ψ), 1)·M maps them to the world-frame
base velocity [ẋ_b, ẏ_b, ψ̇] (eq. (3)). A positive wheel speed drives its wheel forward.
"""

from __future__ import annotations

import math

import numpy as np

from ..._typing import FloatArray
from ...config import BaseConfig


class Base:
    """A mobile base: wheel names and order, M, P(ψ) of eq. (3), wheel limits.

    Subclasses set ``kind``, ``wheel_names`` and build ``M`` from the config.

    Attributes:
        config: the base's config (geometry and wheel limits).
        M: 3 × n_wheels, wheel speeds → body twist (read only).
        M_pinv: its pseudoinverse, body twist → wheel speeds (least squares where M has rank < 3).
        holonomic: M has rank 3 (the base can move in any direction of the floor).
    """

    kind = "base"
    wheel_names: tuple[str, ...] = ()

    def __init__(self, config: BaseConfig, M: FloatArray) -> None:
        self.config = config
        self.M: FloatArray = np.array(M, dtype=np.float64).reshape(3, -1)
        self.M.setflags(write=False)
        self.M_pinv: FloatArray = np.asarray(np.linalg.pinv(self.M), dtype=np.float64).reshape(-1, 3)
        self.M_pinv.setflags(write=False)
        self.holonomic = bool(self.M.shape[1] and np.linalg.matrix_rank(self.M) == 3)
        if len(self.wheel_names) != self.M.shape[1]:
            raise ValueError(f"{type(self).__name__}: {len(self.wheel_names)} wheel names for {self.M.shape[1]} wheels")

    @property
    def n_wheels(self) -> int:
        return int(self.M.shape[1])

    def P(self, yaw: float) -> FloatArray:
        """P(q_b) of eq. (3): wheel speeds → world-frame base velocity [ẋ_b, ẏ_b, ψ̇].

        Args:
            yaw: [rad] base heading ψ.
        """
        c, s = math.cos(yaw), math.sin(yaw)
        return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ self.M  # blkdiag(Rz2(ψ), 1)·M

    def body_twist(self, wheel_speeds: FloatArray) -> FloatArray:
        """[v_x, v_y, ω] in the base frame [m/s, m/s, rad/s] for wheel speeds [rad/s]."""
        return self.M @ wheel_speeds

    def wheel_speeds(self, body_twist: FloatArray) -> FloatArray:
        """Wheel speeds [rad/s] that realise a base-frame twist [v_x, v_y, ω] (no slip; the least-
        squares one where the twist is not realisable, e.g. sideways on a differential drive)."""
        return self.M_pinv @ body_twist
