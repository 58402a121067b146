"""``wmm-qp mode NAME``: change the daemon's mode."""

from __future__ import annotations

import argparse
import sys
import time

HELP = "change the daemon's mode"

MODES = ("hold", "track", "dm_cartesian", "dm_nullspace")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from ..cli_common import add_service_arguments
    from .common import add_robot_argument

    parser.add_argument("name", choices=MODES, help="the mode")
    parser.add_argument("--direction", type=float, nargs=3, metavar=("UX", "UY", "UZ"),
                        help="DM direction u in the base frame (default: the controller config's)")
    parser.add_argument("--timeout", type=float, default=5.0, help="[s] wait for the daemon")
    add_service_arguments(parser)
    add_robot_argument(parser)


def run(args: argparse.Namespace) -> int:
    from ..client import Client
    from .common import robot_service_config

    _, svc = robot_service_config(args)
    with Client(svc, name="mode-cli") as c:
        if c.wait_for_daemon(args.timeout) is None:
            print(f"wmm-qp mode: error: no daemon answers on {c.keys.info}", file=sys.stderr)
            return 1
        c.set_mode(args.name, args.direction)
        end = time.monotonic() + args.timeout
        while time.monotonic() < end:
            info = c.info(timeout=1.0)
            if info is not None and info.status.mode == args.name:
                print(f"mode: {args.name}")
                return 0
            time.sleep(0.05)
    print(f"wmm-qp mode: error: the daemon did not switch to {args.name}", file=sys.stderr)
    return 1
