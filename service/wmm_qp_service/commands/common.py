"""Helpers shared by the command modules: config loading and number-list arguments."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from wmm_qp import ControllerConfig, RobotConfig, load_controller_config, load_robot_config
from wmm_qp.scene import Scene, load_scene

from ..config import ServiceConfig


def floats(n: int | None, name: str):
    """An argparse type: a comma-separated list of exactly n finite floats (any number: None)."""

    def parse(text: str) -> np.ndarray:
        parts = [p.strip() for p in text.split(",")]
        if n is not None and len(parts) != n:
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


def add_robot_argument(parser: argparse.ArgumentParser, default: str = "gen3_mecanum.toml") -> None:
    """``--robot-config FILE``: the robot description (default: ``wmm_qp.default_robot_file()``,
    or ``configs/robots/<default>`` for a command whose robot is another)."""
    parser.add_argument(
        "--robot-config", type=Path, default=None, metavar="FILE",
        help=f"robot description (configs/robots/*.toml, docs/robots.md; default: configs/robots/{default})",
    )


def add_scene_argument(parser: argparse.ArgumentParser, default: str | None = None) -> None:
    """``--scene FILE``: obstacles and the workspace fence (default: configs/scenes/default.toml,
    or what ``default`` says)."""
    parser.add_argument(
        "--scene", type=Path, default=None, metavar="FILE",
        help="scene file: static obstacles and the workspace fence (wmm_qp/scene.py, docs/model.md "
             "\"Collisions\"; default: "
             + (default or "configs/scenes/default.toml, a fence 3 m around the start") + ")",
    )


def add_collision_argument(parser: argparse.ArgumentParser) -> None:
    """``--no-collision``: drive the robot without the qp controller's collision rows (on by
    default: self, floor, the scene's fence and obstacles)."""
    parser.add_argument(
        "--no-collision", action="store_true",
        help="no collision rows in the qp controller (default: on — the robot's self and floor pairs, "
             "the scene's fence and obstacles; also off with [collision] enabled = false in the controller file)",
    )


def collision_config(args: argparse.Namespace, cfg: ControllerConfig) -> ControllerConfig:
    """The controller config with the command line's collision choice: ``--no-collision`` turns the
    rows off; else ``--scene FILE`` turns them on; else the controller file decides (on unless it
    says ``[collision] enabled = false``)."""
    if getattr(args, "no_collision", False):
        return cfg.with_(collision={"enabled": False})
    if getattr(args, "scene", None) is not None:
        return cfg.with_(collision={"enabled": True})
    return cfg


PHYSICS_HELP = ("the plant the simulated robot drives: kinematic (rates executed exactly) or mujoco (rigid-body "
                "physics, torque-limited servos, traction-limited wheels; pip install 'wmm-qp[physics]')")


def add_physics_argument(parser: argparse.ArgumentParser, default: str = "the sim config's [physics] plant") -> None:
    """``--physics kinematic|mujoco``: the sim's plant (None: the sim config's)."""
    parser.add_argument("--physics", choices=("kinematic", "mujoco"), default=None,
                        help=f"{PHYSICS_HELP} (default: {default})")


def physics_plant(args: argparse.Namespace) -> str:
    """The plant ``--physics`` names, else the default sim config's; one that is not installed
    raises :class:`wmm_qp_sim.plants.PlantNotAvailable` (one line, exit 2) before anything starts."""
    from wmm_qp_sim import load_sim_config
    from wmm_qp_sim.plants import HINTS, PlantNotAvailable, available_plants

    name = getattr(args, "physics", None) or load_sim_config().physics.plant
    if name not in available_plants():
        raise PlantNotAvailable(name, available_plants(), HINTS.get(name, "unknown plant"))
    return name


def load_scene_arg(args: argparse.Namespace) -> Scene:
    """The scene of ``--scene`` (a bad file raises :class:`wmm_qp.ConfigError`: one line, exit 2)."""
    return load_scene(getattr(args, "scene", None))


def add_config_arguments(parser: argparse.ArgumentParser) -> None:
    """``--robot-config`` and ``--controller-config``."""
    add_robot_argument(parser)
    parser.add_argument(
        "--controller-config",
        type=Path,
        default=None,
        metavar="FILE",
        help="controller.toml (default: configs/controller.toml)",
    )


def load_robot(args: argparse.Namespace) -> RobotConfig:
    """The robot description of ``--robot-config`` (a bad file raises :class:`wmm_qp.ConfigError`,
    which the CLI prints as one line and exit status 2)."""
    return load_robot_config(getattr(args, "robot_config", None))


def load_configs(args: argparse.Namespace) -> tuple[RobotConfig, ControllerConfig]:
    return load_robot(args), load_controller_config(args.controller_config)


def robot_service_config(args: argparse.Namespace) -> tuple[RobotConfig, ServiceConfig]:
    """The robot description and the service config with the command line's overrides; the robot
    id is ``--robot``, else the robot file's ``name``, else the service config's (the same for
    every command: :func:`wmm_qp_service.config.resolve_robot_id`)."""
    from ..cli_common import service_config

    robot = load_robot(args)  # a bad file: its one-line error first
    return robot, service_config(args)


def embedded_rate(rate_hz: float) -> int:
    """Robot cycles per control tick of an embedded core at ``rate_hz`` [Hz] in the default sim
    config's cycle (``--embedded``).

    Raises:
        wmm_qp.ConfigError: the rate does not divide the sim's (one line, exit 2).
    """
    from wmm_qp_sim import load_sim_config

    from ..embedded import decimation

    return decimation(load_sim_config().rate_hz, rate_hz)


EMBEDDED_ONLY = (("--controller-config", "controller_config"), ("--control-rate", "control_rate"),
                 ("--controller", "controller"), ("--task", "task"), ("--scene", "scene"),
                 ("--no-collision", "no_collision"), ("--wait-lease", "wait_lease"),
                 ("--cycle-report", "cycle_report"), ("--plain-cycle", "plain_cycle"))
"""The flags of a robot process's embedded group (dest names): they mean something only with ``--embedded``."""


def add_embedded_arguments(parser: argparse.ArgumentParser, title: str, embedded_help: str,
                           rate_help: str) -> argparse._ArgumentGroup:
    """The embedded group of a robot process (``wmm-qp sim``, ``wmm-qp driver``): ``--embedded`` and
    the control core's own settings. Returns the group, for the caller's own additions."""
    e = parser.add_argument_group(title)
    e.add_argument("--embedded", action="store_true", help=embedded_help)
    e.add_argument("--controller-config", metavar="TOML", help="with --embedded: default configs/controller.toml")
    e.add_argument("--control-rate", type=float, default=None, metavar="HZ", help=rate_help)
    e.add_argument("--controller", choices=("qp", "paper", "traditional"),
                   help="with --embedded: controller kind (default: controller.toml's)")
    e.add_argument("--task", choices=("position", "pose"),
                   help="with --embedded: the EE task (default: controller.toml's task.kind)")
    e.add_argument("--no-collision", action="store_true",
                   help="with --embedded: no collision rows in the qp controller (default: on)")
    e.add_argument("--wait-lease", action="store_true",
                   help="with --embedded: when a daemon controls this robot, wait for its lease instead of "
                        "refusing to start")
    return e


def embedded_only_given(args: argparse.Namespace, shared: tuple[str, ...] = ()) -> str | None:
    """The first embedded-only flag given without ``--embedded`` (None: none); ``shared``: flags the
    command also takes without it (e.g. the sim's ``--scene``)."""
    for flag, dest in EMBEDDED_ONLY:
        if flag not in shared and getattr(args, dest, None) not in (None, False):
            return flag
    return None
