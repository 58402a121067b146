"""A device's twist → an EE target that moves at a set speed."""

from __future__ import annotations

import math

import numpy as np

from wmm_qp.config import FloatArray

from .base import DeviceSample


def _axis_angle(w: FloatArray) -> FloatArray:
    """The rotation matrix of the rotation vector w [rad]."""
    a = float(np.linalg.norm(w))
    if a < 1e-12:
        return np.eye(3)
    k = w / a
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(a) * K + (1.0 - math.cos(a)) * (K @ K)


class TargetIntegrator:
    """The EE target a device moves: position at ``speed`` [m/s] and orientation at
    ``angular_speed`` [rad/s] for a full deflection (twist entries ±1).

    Args:
        x: [m] the starting target (world).
        R: its orientation (3×3, world), or None (position only).
        speed: [m/s] along each axis at full deflection.
        angular_speed: [rad/s] about each axis at full deflection.
        dt_max: [s] the longest step integrated at once (a stalled loop does not jump the target).
    """

    def __init__(self, x: FloatArray, R: FloatArray | None = None, speed: float = 0.05,
                 angular_speed: float = 0.3, dt_max: float = 0.1) -> None:
        if not (speed > 0 and angular_speed > 0 and dt_max > 0):
            raise ValueError("speed, angular_speed and dt_max must be > 0")
        self.x = np.array(x, dtype=float)
        self.R = None if R is None else np.array(R, dtype=float)
        self.speed, self.angular_speed, self.dt_max = speed, angular_speed, dt_max

    def reset(self, x: FloatArray, R: FloatArray | None = None) -> None:
        """Start again from x (and R): where the daemon latched its target (after hold)."""
        self.x = np.array(x, dtype=float)
        self.R = None if R is None else np.array(R, dtype=float)

    def step(self, sample: DeviceSample, dt: float) -> bool:
        """Integrate one sample over dt [s]; returns whether the target moved."""
        dt = min(max(dt, 0.0), self.dt_max)
        tw = np.clip(np.asarray(sample.twist, dtype=float), -1.0, 1.0)
        if dt == 0.0 or not np.any(tw):
            return False
        self.x = self.x + self.speed * dt * tw[:3]
        if self.R is not None and np.any(tw[3:]):
            self.R = _axis_angle(self.angular_speed * dt * tw[3:]) @ self.R  # world-frame turn
        return True

    def quaternion(self) -> list[float] | None:
        """The orientation target as the protocol's [x, y, z, w] (None: position only)."""
        if self.R is None:
            return None
        from ..console.geometry import matrix_to_quat

        w, x, y, z = matrix_to_quat(self.R)
        return [float(x), float(y), float(z), float(w)]
