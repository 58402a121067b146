"""Kinematic model of the WMM: Mecanum base, Pinocchio arm, and their composition."""

from .arm import ArmModel
from .mecanum import MecanumBase
from .wmm import Kinematics, WmmModel, rot_z

__all__ = ["ArmModel", "Kinematics", "MecanumBase", "WmmModel", "rot_z"]
