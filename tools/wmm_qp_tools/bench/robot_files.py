"""The robot files the per-robot bench sections time, each loaded once."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import wmm_qp as w


def shipped_robots() -> list[Path]:
    """The robot files shipped in ``configs/robots/``, the default robot first."""
    default = w.default_robot_file()
    files = sorted(default.parent.glob("*.toml"))
    return sorted(files, key=lambda f: f.name != default.name)


def loaded(files: list[Path], out: dict[str, Any]) -> Iterator[tuple[Path, w.RobotConfig]]:
    """(file, robot) for each file that loads; a file that does not (an optional package missing)
    is recorded in ``out`` under its stem as {"file", "available": False, "reason"}."""
    for f in files:
        try:
            robot = w.load_robot_config(f)
        except w.ConfigError as e:
            out[f.stem] = {"file": str(f), "available": False, "reason": str(e)}
            continue
        yield f, robot
