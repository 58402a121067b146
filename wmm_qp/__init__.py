"""wmm-qp: QP-based kinematic control of a wheeled mobile manipulator.

Pure computation: no I/O, no transport, no threads. One entry point for every controller,
``controller.step(state, reference) → command``.
"""

from . import scene  # noqa: F401 (wmm_qp.scene, as wmm_qp.model)
from .config import (
    ControllerConfig,
    RobotConfig,
    TaskConfig,
    default_config_dir,
    default_robot_file,
    load_controller_config,
    load_robot_config,
)
from .controllers import Controller, PaperController, QpController, TraditionalController, make_controller
from .exceptions import ConfigError, InvalidInput, SolverFailed, SolverNotFound, WmmQpError
from .model import Kinematics, WmmModel
from .scene import Scene, load_scene
from .types import Command, Mode, Reference, RobotState, Status

__version__ = "0.1.0"

__all__ = [
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
    "Scene",
    "SolverFailed",
    "SolverNotFound",
    "Status",
    "TaskConfig",
    "TraditionalController",
    "WmmModel",
    "WmmQpError",
    "default_config_dir",
    "default_robot_file",
    "load_controller_config",
    "load_robot_config",
    "load_scene",
    "make_controller",
]
