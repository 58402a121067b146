"""Arguments and helpers shared by the service's subcommands."""

from __future__ import annotations

import argparse
import signal
import threading
from pathlib import Path
from types import FrameType

from wmm_qp import ConfigError

from .config import ServiceConfig, check_name, load_service_config, resolve_robot_id


def add_service_arguments(p: argparse.ArgumentParser) -> None:
    """--service-config, --robot, --prefix, --daemon-endpoint, --sim-endpoint, --zenoh-config."""
    g = p.add_argument_group("service")
    g.add_argument("--service-config", metavar="TOML", help="service config (default: configs/service.toml)")
    g.add_argument("--robot", help="robot id (default: the robot file's name, else the service config's robot)")
    g.add_argument("--prefix", help="key-expression prefix (default: from the service config)")
    g.add_argument("--daemon-endpoint", metavar="EP", help="e.g. tcp/127.0.0.1:7448")
    g.add_argument("--sim-endpoint", metavar="EP", help="e.g. tcp/127.0.0.1:7447")
    g.add_argument("--zenoh-config", metavar="JSON5",
                   help="base Zenoh session config of this process, e.g. configs/zenoh/acl_sim.json5 "
                        "(default: the service config's)")


def service_config(args: argparse.Namespace) -> ServiceConfig:
    """The service config with the command line's overrides applied; its robot id is
    :func:`~wmm_qp_service.config.resolve_robot_id`'s (``--robot``, else the ``name`` of
    ``--robot-config`` or of the default robot file, else the service config's)."""
    cfg = load_service_config(getattr(args, "service_config", None))
    changes: dict[str, object] = {
        "robot": resolve_robot_id(cfg, getattr(args, "robot", None), getattr(args, "robot_config", None))}
    if getattr(args, "prefix", None):
        changes["prefix"] = check_name(args.prefix, "--prefix")
    z: dict[str, object] = {}
    if getattr(args, "zenoh_config", None):
        zp = Path(args.zenoh_config)
        if not zp.is_file():
            raise ConfigError("<command line>", "--zenoh-config", f"no such file: {zp}")
        z["config"] = zp.resolve()
    if getattr(args, "daemon_endpoint", None):
        z["daemon_endpoint"] = args.daemon_endpoint
    if getattr(args, "sim_endpoint", None):
        z["sim_endpoint"] = args.sim_endpoint
    if z:
        changes["zenoh"] = z
    return cfg.with_(**changes)


def stop_on_signals() -> threading.Event:
    """An event set by SIGINT or SIGTERM (so sessions are closed cleanly)."""
    stop = threading.Event()

    def handler(signum: int, frame: FrameType | None) -> None:
        stop.set()

    signal.signal(signal.SIGINT, handler)
    signal.signal(signal.SIGTERM, handler)
    return stop
