"""Input devices for teleoperation, behind one small interface (:class:`InputDevice`).

A device reports a normalised twist (each axis in [−1, 1]) and two buttons, hold and quit;
:class:`TargetIntegrator` turns that into an EE target moving at a set speed. Drivers: the
terminal keyboard (:class:`KeyboardDevice`) and a gamepad through Linux evdev
(:class:`GamepadDevice`, ``pip install 'wmm-qp[devices]'``), both fed by an event source that a
test replaces with a recorded one.
"""

from .base import DeviceSample, InputDevice
from .gamepad import GamepadDevice, GamepadMapping, RecordedEvents, open_gamepad
from .integrator import TargetIntegrator
from .keyboard import KEYMAP, KeyboardDevice

__all__ = [
    "KEYMAP",
    "DeviceSample",
    "GamepadDevice",
    "GamepadMapping",
    "InputDevice",
    "KeyboardDevice",
    "RecordedEvents",
    "TargetIntegrator",
    "open_gamepad",
]
