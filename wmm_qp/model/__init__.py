"""Kinematic model of the WMM: the base kinds, the Pinocchio arm, and their composition."""

from .arm import ArmModel
from .bases import BASES, Base, DiffDriveBase, FixedBase, MecanumBase, OmniBase, make_base
from .wmm import Kinematics, WmmModel, rot_z

__all__ = [
    "BASES",
    "ArmModel",
    "Base",
    "DiffDriveBase",
    "FixedBase",
    "Kinematics",
    "MecanumBase",
    "OmniBase",
    "WmmModel",
    "make_base",
    "rot_z",
]
