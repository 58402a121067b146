"""The interface every input device implements."""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field

import numpy as np

from wmm_qp.config import FloatArray


@dataclass(frozen=True)
class DeviceSample:
    """What a device says at one instant.

    Attributes:
        twist: 6 numbers in [−1, 1]: the EE's velocity along world x, y, z and its angular
            velocity about world x (roll), y (pitch), z (yaw), as fractions of the set speeds.
        hold: the hold button was pressed since the last sample (hold now; latched once).
        quit: the quit button was pressed.
        resume: the resume (track) button was pressed.
        gripper: a gripper button was pressed: ``open`` or ``close`` ("" = none).
    """

    twist: FloatArray = field(default_factory=lambda: np.zeros(6))
    hold: bool = False
    quit: bool = False
    resume: bool = False
    gripper: str = ""


class InputDevice(ABC):
    """An input device: poll it at the teleop's rate (never blocks)."""

    name: str = "device"

    @abstractmethod
    def read(self, now: float) -> DeviceSample:
        """The device's state at ``now`` [s] (monotonic): the twist held at that instant and the
        buttons pressed since the previous call."""

    def close(self) -> None:  # noqa: B027 (most devices hold nothing)
        """Release the device."""
