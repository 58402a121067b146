"""Hard bounds on the commands: the joint motion bounds of eq. (13) and the wheel bounds; and the
QP's rows, each from its source (:mod:`.rows`): the EE box of eq. (17) (:mod:`.ee_box`), the
collision dampers (:mod:`.collision`, their rule :mod:`.dampers`, their pairs
:mod:`.pair_search`), the fence (:mod:`.fence`) and the σ_min floor (:mod:`.singularity_floor`)."""

from .collision import CollisionRows
from .dampers import DamperRows
from .ee_box import EeBox
from .fence import FenceRows
from .interval import intersect_by_priority
from .joint_motion_bounds import MotionBounds, braking_command, braking_velocity, joint_motion_bounds
from .rows import Retry, Rows, RowSource, Tick
from .singularity_floor import SigmaMinFloor
from .wheel_bounds import wheel_bounds, wheel_braking_command

__all__ = [
    "CollisionRows",
    "DamperRows",
    "EeBox",
    "FenceRows",
    "MotionBounds",
    "Retry",
    "RowSource",
    "Rows",
    "SigmaMinFloor",
    "Tick",
    "braking_command",
    "braking_velocity",
    "intersect_by_priority",
    "joint_motion_bounds",
    "wheel_bounds",
    "wheel_braking_command",
]
