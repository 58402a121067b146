"""Helpers of the tests that start real processes: waiting for a condition with a generous
timeout, a daemon ready to take setpoints, and the ``wmm-qp`` CLI as a child process."""

from __future__ import annotations

import subprocess
import time
from collections.abc import Callable
from typing import Any

from wmm_qp_service.client import Client
from wmm_qp_service.processes import CLI

TIMEOUT = 30.0


def until(pred: Callable[[], Any], timeout: float = TIMEOUT, period: float = 0.05) -> Any:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        v = pred()
        if v:
            return v
        time.sleep(period)
    raise AssertionError(f"condition not met within {timeout} s")


def ready(c: Client) -> Any:
    assert c.wait_for_daemon(3 * TIMEOUT) is not None, "daemon did not answer"  # a first start compiles
    return until(lambda: (i := c.info()) is not None and i.status.state_ok and i)


def cli(*argv: str, timeout: float = 60.0) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*CLI, *argv], capture_output=True,
                          text=True, timeout=timeout, stdin=subprocess.DEVNULL)
