"""A command to the simulated robot's firmware: rates and the sender's stream bookkeeping."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wmm_qp.config import FloatArray


@dataclass(slots=True)
class SimCommand:
    """A command to the robot, held until the next one.

    Attributes:
        wheel_speeds: [rad/s] wheel speeds (the base kind's wheel order).
        arm_rates: [rad/s or m/s] joint rates (the robot description's joint order).
        period: [s] the command's own period (the Δt of its sender's bounds (13)); the referee
            judges the change from the previous command over it. None: over the time since the
            previous command.
        seq: the sender's sequence number (a gap widens the referee's window), or None.
        received: [s] monotonic time the command was received (caps the referee's window at
            the time that really passed), or None.
        stream: the sender's stream id (a new one is judged against the executed rates), or
            None (then a stale or protective stop starts a new stream).
        sent: [s] the sender's stamp (its own clock), or None.
        sender: who sent it (the lease holder): the firmware's streams are a sender's (a
            restarted daemon numbers its streams from 1 again, and its first command is a new
            stream, not one a stop ended).
    """

    wheel_speeds: FloatArray
    arm_rates: FloatArray
    period: float | None = None
    seq: int | None = None
    received: float | None = None
    stream: int | None = None
    sent: float | None = None
    sender: str = ""

    def __post_init__(self) -> None:
        self.wheel_speeds = np.asarray(self.wheel_speeds, dtype=float).reshape(-1)
        self.arm_rates = np.asarray(self.arm_rates, dtype=float).reshape(-1)

    @property
    def stream_key(self) -> tuple[str, int] | None:
        """The firmware's key of its stream: (sender, stream), or None (no stream given)."""
        return None if self.stream is None else (self.sender, self.stream)

    def is_valid(self, n_wheels: int, n_arm: int) -> bool:
        """The robot's sizes and finite values."""
        return bool(
            self.wheel_speeds.shape == (n_wheels,)
            and self.arm_rates.shape == (n_arm,)
            and np.isfinite(self.wheel_speeds).all()
            and np.isfinite(self.arm_rates).all()
        )
