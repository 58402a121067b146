"""The simulated wheeled mobile manipulator: a pure model (this package) and its Zenoh adapter.

The pure model is plain objects, no I/O: :class:`SimRobot` is stepped by commands and reports
a :class:`SimState` (odometry and ground truth, torques, the referee's violation counts).
"""

from .config import BoxConfig, RefereeConfig, SimConfig, SlipConfig, load_sim_config
from .contact import Box, ContactResult
from .referee import VIOLATION_KINDS, Referee
from .robot import SimCommand, SimRobot, SimState
from .slip import SlipModel, integrate_pose

__all__ = [
    "VIOLATION_KINDS",
    "Box",
    "BoxConfig",
    "ContactResult",
    "Referee",
    "RefereeConfig",
    "SimCommand",
    "SimConfig",
    "SimRobot",
    "SimState",
    "SlipConfig",
    "SlipModel",
    "integrate_pose",
    "load_sim_config",
]
