"""The installed ``wmm-qp`` command: the runtime's commands (:mod:`wmm_qp_service.cli`) and the tools'.

The tools' commands sit in the same table, so ``wmm-qp --help`` lists one command line; a robot
process started by another command runs ``python -m wmm_qp_service.cli`` and loads no tool.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence

from wmm_qp_service import cli as runtime

_TOOLS = {
    "experiment": ("wmm_qp_tools.commands.experiment", "reproduce one of the paper's experiments (circle, dm, push)"),
    "bench": ("wmm_qp_tools.commands.bench", "measure per-tick controller time and the loop over Zenoh"),
    "contract": ("wmm_qp_tools.commands.contract", "check a running driver against the driver contract "
                 "(docs/drivers.md)"),
    "record": ("wmm_qp_tools.commands.record", "record a robot's keys to MCAP (ROS 2 message types) as a client"),
    "replay": ("wmm_qp_tools.commands.replay", "re-run the controller on a recording and report the first "
                                               "command that differs"),
    "plot": ("wmm_qp_tools.commands.plot", "plot a recording: joints against their limits, wheels, EE, DM, "
                                           "tick time, modes and faults"),
}


def _tables() -> tuple[dict[str, str], dict[str, str]]:
    """The runtime's commands with the tools after ``demo``, in ``wmm-qp --help``'s order."""
    commands: dict[str, str] = {}
    helps: dict[str, str] = {}
    for name, module in runtime.COMMANDS.items():
        commands[name], helps[name] = module, runtime.HELP[name]
        if name == "demo":
            for tool, (mod, text) in _TOOLS.items():
                commands[tool], helps[tool] = mod, text
    return commands, helps


COMMANDS, HELP = _tables()


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The parser of every ``wmm-qp`` command (``only``: load just that command's module)."""
    return runtime.build_parser(only, COMMANDS, HELP)


def main(argv: Sequence[str] | None = None) -> int:
    """The ``wmm-qp`` entry point: run one command; its exit code."""
    return runtime.main(argv, COMMANDS, HELP)


if __name__ == "__main__":
    raise SystemExit(main())
