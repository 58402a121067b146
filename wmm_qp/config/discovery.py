"""Where the shipped configs are: the folder of controller.toml, robots/ and scenes/."""

from __future__ import annotations

import os
import sys
from pathlib import Path

from ..exceptions import ConfigError

_SOURCE_TREE = Path(__file__).resolve().parents[2]  # wmm_qp/config/discovery.py → the repository

DEFAULT_ROBOT = "gen3_mecanum.toml"
"""The paper's robot, the default of every command (``configs/robots/``)."""


def default_config_dir() -> Path:
    """The folder holding controller.toml and robots/ (the shipped robot files).

    Looked up in order: ``$WMM_QP_CONFIG_DIR``; ``./configs``; the source tree's
    ``configs/`` (editable installs); ``<prefix>/share/wmm-qp/configs`` (wheel installs).

    Raises:
        ConfigError: none of them holds a controller.toml (naming every place looked in).
    """
    candidates = []
    if env := os.environ.get("WMM_QP_CONFIG_DIR"):
        candidates.append(Path(env))
    candidates += [
        Path.cwd() / "configs",
        _SOURCE_TREE / "configs",
        Path(sys.prefix) / "share" / "wmm-qp" / "configs",
    ]
    for c in candidates:
        if (c / "controller.toml").is_file():
            return c
    raise ConfigError(candidates[0], "", "no controller.toml found in any of: " + ", ".join(map(str, candidates)))


def default_robot_file() -> Path:
    """``<default_config_dir()>/robots/gen3_mecanum.toml``."""
    return default_config_dir() / "robots" / DEFAULT_ROBOT
