"""The simulated wheeled mobile manipulator: a pure model, no transport.

The pure model is plain objects, no I/O: :class:`SimRobot` (the robot's firmware, referees and
odometry) is stepped by commands, drives a :class:`Plant` (the hardware: write the rates,
advance, read the measurements; :class:`KinematicPlant` by default) and reports a
:class:`SimState` (odometry and ground truth, torques, the referee's violation counts). The
physics plant, ``wmm_qp_sim.mujoco_plant.MujocoPlant``, needs ``mujoco`` (:func:`make_plant`).

The firmware's shared parts — the referees, the lease gate, the command shaper — are every
robot's, in ``wmm_qp_robot``; this package adds what only a simulated robot has (plants, slip,
contact, the gripper). It imports only ``wmm_qp``, ``wmm_qp_robot`` and third-party packages
(``tools/check_layers.py``); its Zenoh node, ``wmm-qp sim``, is a driver of the service layer
(``wmm_qp_service.drivers.sim_node``).
"""

from .config import BoxConfig, PhysicsConfig, SimConfig, SlipConfig, load_sim_config
from .contact import Box, ContactResult
from .kinematic_plant import KinematicPlant
from .plant import Plant, PlantState
from .plants import PlantNotAvailable, available_plants, make_plant
from .robot import SimCommand, SimRobot, SimState
from .slip import SlipModel, integrate_pose

__all__ = [
    "Box",
    "BoxConfig",
    "ContactResult",
    "KinematicPlant",
    "PhysicsConfig",
    "Plant",
    "PlantNotAvailable",
    "PlantState",
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
