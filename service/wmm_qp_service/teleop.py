"""Client-side streaming of setpoints (used by ``wmm-qp teleop`` and ``wmm-qp demo``)."""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from .client import Client
from .streams import HapticStream, circle


def stream_haptic(client: Client, x0: np.ndarray, duration: float, rate_hz: float = 100.0,
                  seed: int = 0, on_tick: Callable[[], None] | None = None) -> int:
    """Stream a haptic-like target (jitter in value and in send time, jumps) for ``duration`` [s].

    The daemon estimates the target's velocity from the stream. Returns the number sent.
    """
    hs = HapticStream(x0, seed=seed)
    rng = np.random.default_rng(seed + 1)
    t0 = time.monotonic()
    n = 0
    while (t := time.monotonic() - t0) < duration:
        client.send_setpoint(hs.sample(t))
        n += 1
        if on_tick is not None:
            on_tick()
        time.sleep(max(0.0, rng.normal(1.0 / rate_hz, 0.25 / rate_hz)))
    return n


def stream_circle(client: Client, x0: np.ndarray, duration: float, rate_hz: float = 100.0,
                  on_tick: Callable[[], None] | None = None) -> int:
    """Stream the paper's circle from x0 with its feed-forward velocity. Returns the number sent."""
    t0 = time.monotonic()
    n = 0
    next_t = t0
    while (t := time.monotonic() - t0) < duration:
        x, xd = circle(x0, t)
        client.send_setpoint(x, xd)
        n += 1
        if on_tick is not None:
            on_tick()
        next_t += 1.0 / rate_hz
        time.sleep(max(0.0, next_t - time.monotonic()))
    return n


def hold_stream(client: Client, x: np.ndarray, duration: float, rate_hz: float = 50.0,
                on_tick: Callable[[], None] | None = None) -> None:
    """Stream a standing target x [m] for ``duration`` [s]."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < duration:
        client.send_setpoint(x, [0.0, 0.0, 0.0])
        if on_tick is not None:
            on_tick()
        time.sleep(1.0 / rate_hz)


def wait(duration: float, on_tick: Callable[[], None] | None = None, period: float = 0.02) -> None:
    """Sleep ``duration`` [s], calling on_tick every ``period``."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < duration:
        if on_tick is not None:
            on_tick()
        time.sleep(period)
