"""What the access-control tests share: a Zenoh config's value, a patient wait, a session's peers."""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from typing import Any

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
