"""wmm-qp: QP-based kinematic control of a wheeled mobile manipulator.

Pure computation: no I/O, no transport, no threads. One entry point for every controller,
``controller.step(state, reference) → command``.
"""

from .config import (
    ControllerConfig,
    RobotConfig,
    default_config_dir,
    load_controller_config,
    load_robot_config,
)
from .controllers import Controller, PaperController, QpController, TraditionalController, make_controller
from .exceptions import ConfigError, InvalidInput, SolverFailed, SolverNotFound, WmmQpError
from .model import Kinematics, WmmModel
from .types import Command, Mode, Reference, RobotState, Status

PAPER_START_Q_ARM = (0.0, 0.5235987755982988, 0.0, 1.5707963267948966, 0.0, -0.5235987755982988, 0.0)
"""q_m of every paper experiment: [0, π/6, 0, π/2, 0, −π/6, 0] (the print lost the minus on joint 6)."""

__version__ = "0.1.0"

__all__ = [
    "PAPER_START_Q_ARM",
    "Command",
    "ConfigError",
    "Controller",
    "ControllerConfig",
    "InvalidInput",
    "Kinematics",
    "Mode",
    "PaperController",
    "QpController",
    "Reference",
    "RobotConfig",
    "RobotState",
    "SolverFailed",
    "SolverNotFound",
    "Status",
    "TraditionalController",
    "WmmModel",
    "WmmQpError",
    "default_config_dir",
    "load_controller_config",
    "load_robot_config",
    "make_controller",
]
