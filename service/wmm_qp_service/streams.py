"""Setpoint streams a client sends: a haptic-like teleop stream and the paper's circle."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

CIRCLE_RADIUS = 0.25
"""[m] radius of the paper's circle experiment."""
CIRCLE_OMEGA = math.pi / 20
"""[rad/s] angular rate of the paper's circle (40 s per turn)."""


def circle(x0: FloatArray, t: float, radius: float = CIRCLE_RADIUS,
           omega: float = CIRCLE_OMEGA) -> tuple[FloatArray, FloatArray]:
    """The paper's circle: x_d(t) = x0 + [r(cos ωt − 1), r sin ωt, 0] and its velocity.

    Args:
        x0: [m] start (and a point of the circle).
        t: [s] time since the start.
        radius: [m] r.
        omega: [rad/s] ω.

    Returns:
        (x_d [m], ẋ_d [m/s]).
    """
    c, s = math.cos(omega * t), math.sin(omega * t)
    x = np.asarray(x0, dtype=float) + np.array([radius * (c - 1.0), radius * s, 0.0])
    xd = np.array([-radius * omega * s, radius * omega * c, 0.0])
    return x, xd


class HapticStream:
    """A scripted stand-in for a haptic device: smooth hand motion, sensor jitter, jumps.

    The hand moves on a slow Lissajous figure around x0; every sample carries Gaussian
    jitter; every ``jump_every`` seconds the operator's hand "jumps" (a clutch re-grab) by
    ``jump`` metres along a random horizontal direction, and stays offset.

    Args:
        x0: [m] centre.
        seed: jitter and jump seed.
        amplitude: [m] Lissajous amplitude.
        jitter: [m] standard deviation of the per-sample jitter.
        jump: [m] size of a jump.
        jump_every: [s] period of the jumps (0: none).
    """

    def __init__(self, x0: FloatArray, seed: int = 0, amplitude: float = 0.06,
                 jitter: float = 3e-4, jump: float = 0.03, jump_every: float = 2.5) -> None:
        self.x0 = np.asarray(x0, dtype=float)
        self.rng = np.random.default_rng(seed)
        self.amplitude = amplitude
        self.jitter = jitter
        self.jump = jump
        self.jump_every = jump_every
        self.offset = np.zeros(3)
        self._jumps = 0

    def sample(self, t: float) -> FloatArray:
        """[m] the device's position at t [s] since the start."""
        if self.jump_every > 0 and int(t / self.jump_every) > self._jumps:
            self._jumps = int(t / self.jump_every)
            a = self.rng.uniform(0, 2 * math.pi)
            # jumps alternate away and back so the stream stays near x0
            sign = 1.0 if self._jumps % 2 else -1.0
            self.offset = self.offset + sign * self.jump * np.array([math.cos(a), math.sin(a), 0.0])
        a = self.amplitude
        hand = np.array([a * math.sin(0.8 * t), a * math.sin(1.1 * t + 0.5) * 0.8,
                         0.3 * a * math.sin(0.6 * t)])
        hand -= np.array([0.0, a * math.sin(0.5) * 0.8, 0.0])  # start at x0
        return self.x0 + hand + self.offset + self.rng.normal(0.0, self.jitter, 3)
