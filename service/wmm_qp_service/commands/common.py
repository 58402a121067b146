"""Helpers shared by the command modules: config loading and number-list arguments."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from wmm_qp import ControllerConfig, RobotConfig, load_controller_config, load_robot_config


def floats(n: int, name: str):
    """An argparse type: a comma-separated list of exactly n finite floats."""

    def parse(text: str) -> np.ndarray:
        parts = [p.strip() for p in text.split(",")]
        if len(parts) != n:
            raise argparse.ArgumentTypeError(f"{name} needs {n} comma-separated numbers, got {len(parts)}")
        try:
            values = np.array([float(p) for p in parts])
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name}: not a number in {text!r}") from None
        if not np.isfinite(values).all():
            raise argparse.ArgumentTypeError(f"{name}: values must be finite")
        return values

    parse.__name__ = name
    return parse


def add_config_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--robot-config", type=Path, default=None, metavar="FILE", help="robot.toml (default: configs/robot.toml)"
    )
    parser.add_argument(
        "--controller-config",
        type=Path,
        default=None,
        metavar="FILE",
        help="controller.toml (default: configs/controller.toml)",
    )


def load_configs(args: argparse.Namespace) -> tuple[RobotConfig, ControllerConfig]:
    return load_robot_config(args.robot_config), load_controller_config(args.controller_config)
