"""Manipulability measures: directional (eqs. (8)–(10)) and Yoshikawa's."""

from .directional import directional_manipulability, dm_cartesian_gradient, dm_gradient, torque_norm_per_newton
from .preference import dm_preference, dm_preference_gain
from .yoshikawa import yoshikawa_manipulability

__all__ = [
    "directional_manipulability",
    "dm_cartesian_gradient",
    "dm_gradient",
    "dm_preference",
    "dm_preference_gain",
    "torque_norm_per_newton",
    "yoshikawa_manipulability",
]
