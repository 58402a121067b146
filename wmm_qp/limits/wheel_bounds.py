"""Wheel speed bounds: speed and acceleration limits of the base's wheels (acceleration wins)."""

from __future__ import annotations

import numpy as np

from .._typing import FloatArray
from ..config import BaseConfig
from .interval import intersect_by_priority


def wheel_bounds(w_prev: FloatArray, base: BaseConfig, dt: float) -> tuple[FloatArray, FloatArray]:
    """Bounds on the next wheel-speed command [rad/s].

    Args:
        w_prev: [rad/s] current wheel speeds.
        base: wheel speed and acceleration limits.
        dt: [s] control period.
    """
    step = base.wheel_acceleration_max * dt
    w_max = base.wheel_speed_max
    return intersect_by_priority(w_prev - step, w_prev + step, -w_max, w_max)


def wheel_braking_command(w_prev: FloatArray, base: BaseConfig, dt: float) -> FloatArray:
    """One tick of maximal wheel braking: w_prev moved towards 0 by at most a·dt."""
    step = base.wheel_acceleration_max * dt
    return w_prev - np.clip(w_prev, -step, step)
