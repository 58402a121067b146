"""What the access-control tests share: a Zenoh config's value, a patient wait, a session's peers,
the viewer's attempts and the operator's drive."""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from typing import Any

import numpy as np
import zenoh

TIMEOUT = 30.0
"""[s] the default patience of :func:`until`."""


def config_value(zc: zenoh.Config, key: str) -> Any:
    """The value at ``key`` of a Zenoh config, decoded from its JSON."""
    return json.loads(zc.get_json(key))


def until(pred: Callable[[], Any], timeout: float = TIMEOUT, what: str = "condition") -> Any:
    """``pred()``'s first truthy value, polled every 20 ms; AssertionError naming ``what`` after ``timeout`` [s]."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if v := pred():
            return v
        time.sleep(0.02)
    raise AssertionError(f"{what} not met within {timeout} s")


def peers(s: zenoh.Session) -> set[str]:
    """The Zenoh ids of the session's peers."""
    return {str(z) for z in s.info.peers_zid()}


def viewer_attempts(viewer: Any, x0: np.ndarray) -> None:
    """100 mode changes (``dm_cartesian``) and setpoints 10 cm from ``x0`` [m] from a client that
    may not send them, then a second for them to arrive if they could."""
    for k in range(100):
        viewer.set_mode("dm_cartesian")
        viewer.send_setpoint(x0 + np.array([0.1, 0.0, 0.0]))
        if k % 10 == 0:
            time.sleep(0.02)
    time.sleep(1.0)


def drive_to(op: Any, target: np.ndarray, timeout: float = TIMEOUT) -> None:
    """The operator's setpoints at ``target`` [m] until the status's EE is within 5 mm of it
    (after a fault on a loaded host, resumed in ``track`` as an operator would)."""

    def there() -> bool:
        if op.resume_needed():
            op.resume("track", timeout=5.0)
        op.send_setpoint(target)
        st = op.latest_status()
        return st is not None and float(np.linalg.norm(np.array(st.x) - target)) < 0.005

    until(there, timeout, "the EE at the operator's target")
