"""End-to-end over Zenoh: daemon + sim at 500 Hz and 1 kHz.

Runs the service helper's real processes (``wmm-qp sim``, ``wmm-qp serve``) on loopback and
reads the daemon's own loop statistics (``wmm-qp status --json``). Until those commands exist
in this install, the section reports ``available: False`` with the reason.
"""

from __future__ import annotations

import importlib.util
from typing import Any

REQUIRED = ("serve", "sim", "status")


def missing_commands() -> list[str]:
    return [c for c in REQUIRED if importlib.util.find_spec(f"wmm_qp_service.commands.{c}") is None]


def run(ticks: int, rates: tuple[float, ...] = (500.0, 1000.0)) -> dict[str, Any]:
    """{"available": False, "reason": ...} until the daemon and the sim exist."""
    missing = missing_commands()
    if missing:
        return {
            "available": False,
            "reason": f"not available: wmm-qp {', '.join(missing)} not implemented in this install",
        }
    return {
        "available": False,
        "reason": "not available: the daemon exists but the bench's end-to-end driver "
        "(start sim + serve, read status --json) is not written yet",
    }
