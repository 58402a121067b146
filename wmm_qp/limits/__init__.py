"""Hard bounds on the commands: the joint motion bounds of eq. (13) and the wheel bounds."""

from .interval import intersect_by_priority
from .joint_motion_bounds import MotionBounds, braking_command, braking_velocity, joint_motion_bounds
from .wheel_bounds import wheel_bounds, wheel_braking_command

__all__ = [
    "MotionBounds",
    "braking_command",
    "braking_velocity",
    "intersect_by_priority",
    "joint_motion_bounds",
    "wheel_bounds",
    "wheel_braking_command",
]
