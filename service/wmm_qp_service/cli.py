"""The ``wmm-qp`` command line.

Each subcommand lives in its own module and exposes ``add_arguments(parser)`` and
``run(args) -> int``. Modules are imported only when their subcommand runs, so ``wmm-qp inspect``
never loads Zenoh. This module holds the runtime's commands (the ones a robot process runs: ``sim``,
``serve``, ``driver``, …); the installed ``wmm-qp`` is :mod:`wmm_qp_tools.cli`, which adds the
tools (``bench``, ``experiment``, ``contract``) to the same table.

Errors a user can cause (bad arguments, a bad config, a missing solver) print one line on
stderr and exit with status 2 — never a traceback.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence
from typing import Any

# name → module (under wmm_qp_service.commands), in the order `wmm-qp --help` lists them.
COMMANDS: dict[str, str] = {
    "inspect": "wmm_qp_service.commands.inspect",
    "verify": "wmm_qp_service.commands.verify",
    "sim": "wmm_qp_service.commands.sim",
    "serve": "wmm_qp_service.commands.serve",
    "teleop": "wmm_qp_service.commands.teleop",
    "mode": "wmm_qp_service.commands.mode",
    "status": "wmm_qp_service.commands.status",
    "console": "wmm_qp_service.commands.console",
    "demo": "wmm_qp_service.commands.demo",
    "soak": "wmm_qp_service.commands.soak",
    "acl": "wmm_qp_service.commands.acl",
    "driver": "wmm_qp_service.commands.driver",
}

HELP = {
    "inspect": "kinematics and directional manipulability at one configuration",
    "verify": "sample random states and check every command against every hard bound",
    "sim": "run the simulated robot (Zenoh)",
    "serve": "run the control daemon (Zenoh)",
    "teleop": "stream setpoints to the daemon: a haptic-like stream, the paper's circle, the keyboard or a gamepad",
    "mode": "change the daemon's mode",
    "status": "show the daemon's status",
    "console": "a web console: the robot live in 3D, drag its EE target, modes, status, plots (viser)",
    "demo": "start sim and daemon on loopback, drive every mode, print a summary",
    "soak": "run sim + daemon + client for a long time and report drift in time and memory",
    "acl": "write per-role Zenoh credentials with fresh secrets and their ACL configs (acl init DIR)",
    "driver": "drive a real robot behind the daemon's protocol (driver franka --robot-ip IP: a Franka FR3)",
}


class _Parser(argparse.ArgumentParser):
    """argparse that prints a one-line error and exits 2 (its default), without usage noise."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {message}\n")


def _load(name: str, commands: dict[str, str]) -> Any:
    try:
        return importlib.import_module(commands[name])
    except ModuleNotFoundError as e:
        if e.name and e.name == commands[name]:
            return None
        raise


def build_parser(only: str | None = None, commands: dict[str, str] = COMMANDS,
                 helps: dict[str, str] = HELP) -> argparse.ArgumentParser:
    """The parser of ``commands`` (name → module); ``only``: load just that command's module."""
    parser = _Parser(prog="wmm-qp", description="QP control of a wheeled mobile manipulator.")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    for name in commands:
        if only is not None and name != only:
            sub.add_parser(name, help=helps[name], add_help=False)
            continue
        mod = _load(name, commands)
        if mod is None:
            continue
        p = sub.add_parser(name, help=helps[name], description=helps[name])
        mod.add_arguments(p)
    return parser


def main(argv: Sequence[str] | None = None, commands: dict[str, str] = COMMANDS,
         helps: dict[str, str] = HELP) -> int:
    """Run one command of ``commands``; the exit code (2: a user's error, one line on stderr)."""
    from wmm_qp.exceptions import WmmQpError

    argv = list(sys.argv[1:] if argv is None else argv)
    only = argv[0] if argv and argv[0] in commands else None
    parser = build_parser(only, commands, helps)
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 2
    mod = _load(args.command, commands)
    if mod is None:
        print(f"wmm-qp: error: {args.command} is not available in this install", file=sys.stderr)
        return 2
    try:
        return int(mod.run(args))
    except WmmQpError as e:
        print(f"wmm-qp {args.command}: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"wmm-qp {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    raise SystemExit(main())
