"""The terminal keyboard as an input device.

A terminal reports key presses, not releases: a key held down repeats (typically every
30–50 ms after a first delay of 250–500 ms). So a press drives its axis at full speed for
``latch`` [s]; the repeats of a held key keep it moving, and it stops ``latch`` after the key is
let go. Keys (:data:`KEYMAP`): w/s ±x, a/d ±y, r/f ±z; with the pose task u/o ±yaw, i/k ±pitch,
j/l ±roll; space holds, t resumes tracking, c closes and v opens the gripper, q quits.
"""

from __future__ import annotations

import numpy as np

from .base import DeviceSample, InputDevice

KEYMAP: dict[str, tuple[int, float]] = {
    "w": (0, +1.0), "s": (0, -1.0),
    "a": (1, +1.0), "d": (1, -1.0),
    "r": (2, +1.0), "f": (2, -1.0),
    "j": (3, +1.0), "l": (3, -1.0),   # roll: about world x
    "i": (4, +1.0), "k": (4, -1.0),   # pitch: about world y
    "u": (5, +1.0), "o": (5, -1.0),   # yaw: about world z
}
"""key → (twist axis, sign): x, y, z, roll, pitch, yaw."""
HOLD_KEYS = (" ",)
RESUME_KEYS = ("t",)
QUIT_KEYS = ("q", "\x1b")  # q or Esc
GRIPPER_KEYS = {"c": "close", "v": "open"}
"""key → gripper action."""


class KeyboardDevice(InputDevice):
    """Keys pressed (fed by the terminal UI with :meth:`press`) as a twist.

    Args:
        latch: [s] how long one press drives its axis.
        rotations: the yaw/pitch/roll keys are live (the pose task); else they are ignored.
    """

    name = "keyboard"

    def __init__(self, latch: float = 0.15, rotations: bool = False) -> None:
        self.latch = latch
        self.rotations = rotations
        self._until = np.full(6, -np.inf)
        self._sign = np.zeros(6)
        self._hold = self._quit = self._resume = False
        self._gripper = ""

    def press(self, key: str, now: float) -> bool:
        """One key press at ``now`` [s]; returns whether the key means something."""
        if key in KEYMAP:
            axis, sign = KEYMAP[key]
            if axis >= 3 and not self.rotations:
                return False
            if self._sign[axis] != sign:  # the opposite key stops the other direction at once
                self._sign[axis] = sign
            self._until[axis] = now + self.latch
            return True
        if key in HOLD_KEYS:
            self._hold = True
            self._until[:] = -np.inf
            return True
        if key in RESUME_KEYS:
            self._resume = True
            return True
        if key in GRIPPER_KEYS:
            self._gripper = GRIPPER_KEYS[key]
            return True
        if key in QUIT_KEYS:
            self._quit = True
            return True
        return False

    def read(self, now: float) -> DeviceSample:
        twist = np.where(self._until > now, self._sign, 0.0)
        s = DeviceSample(twist=twist, hold=self._hold, quit=self._quit, resume=self._resume, gripper=self._gripper)
        self._hold = self._quit = self._resume = False
        self._gripper = ""
        return s
