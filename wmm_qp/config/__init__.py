"""Frozen, validated configuration: the robot and the controller.

Configs are TOML files (``configs/robots/*.toml``, ``configs/controller.toml``), loaded once at
start-up into frozen dataclasses. Every check names the file and the dotted key; inside the
library the types are trusted. One module per concern: the TOML reader (:mod:`.toml`), the
collision primitives (:mod:`.shapes`), the robot file's schema (:mod:`.robot`) and its
URDF-resolving loader (:mod:`.robot_file`), the controller file (:mod:`.controller`), where the
shipped configs are (:mod:`.discovery`).
"""

from .._typing import FloatArray
from ..exceptions import ConfigError
from .controller import (
    CONTROLLER_KINDS,
    TASK_KINDS,
    CollisionParams,
    ControllerConfig,
    QpConfig,
    TaskConfig,
    load_controller_config,
)
from .discovery import DEFAULT_ROBOT, default_config_dir, default_robot_file
from .robot import BASE_KINDS, ArmConfig, BaseConfig, GripperConfig, RobotCollisionConfig, RobotConfig, Ros2Config
from .robot_file import load_robot_config
from .shapes import SHAPE_KINDS, ShapeConfig, load_shape
from .toml import TomlTable, read_toml

__all__ = [
    "BASE_KINDS",
    "CONTROLLER_KINDS",
    "DEFAULT_ROBOT",
    "SHAPE_KINDS",
    "TASK_KINDS",
    "ArmConfig",
    "BaseConfig",
    "CollisionParams",
    "ConfigError",
    "ControllerConfig",
    "FloatArray",
    "GripperConfig",
    "QpConfig",
    "RobotCollisionConfig",
    "RobotConfig",
    "Ros2Config",
    "ShapeConfig",
    "TaskConfig",
    "TomlTable",
    "default_config_dir",
    "default_robot_file",
    "load_controller_config",
    "load_robot_config",
    "load_shape",
    "read_toml",
]
