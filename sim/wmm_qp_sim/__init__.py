"""The simulated wheeled mobile manipulator: a pure model, no transport.

The pure model is plain objects, no I/O: :class:`SimRobot` (the robot's firmware, referees and
odometry) is stepped by commands, drives a :class:`Plant` (the hardware: write the rates,
advance, read the measurements; :class:`KinematicPlant` by default) and reports a
:class:`SimState` (odometry and ground truth, torques, the referee's violation counts). The
physics plant, ``wmm_qp_sim.mujoco_plant.MujocoPlant``, needs ``mujoco`` (:func:`make_plant`).

This package imports only ``wmm_qp`` and third-party packages (``tools/check_layers.py``); its
Zenoh node, ``wmm-qp sim``, is a driver of the service layer (``wmm_qp_service.drivers.sim_node``).
"""

from .config import BoxConfig, PhysicsConfig, RefereeConfig, SimConfig, SlipConfig, load_sim_config
from .contact import Box, ContactResult
from .kinematic_plant import KinematicPlant
from .plant import Plant, PlantState
from .plants import PlantNotAvailable, available_plants, make_plant
from .referee import VIOLATION_KINDS, Referee
from .robot import SimCommand, SimRobot, SimState
from .slip import SlipModel, integrate_pose

__all__ = [
    "VIOLATION_KINDS",
    "Box",
    "BoxConfig",
    "ContactResult",
    "KinematicPlant",
    "PhysicsConfig",
    "Plant",
    "PlantNotAvailable",
    "PlantState",
    "Referee",
    "RefereeConfig",
    "SimCommand",
    "SimConfig",
    "SimRobot",
    "SimState",
    "SlipConfig",
    "SlipModel",
    "available_plants",
    "integrate_pose",
    "load_sim_config",
    "make_plant",
]
