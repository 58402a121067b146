"""A gamepad through Linux evdev (``/dev/input/event*``; ``pip install 'wmm-qp[devices]'``).

The driver reads kernel input events — (type, code, value) triples, the codes of
``linux/input-event-codes.h`` — from an event source: :func:`open_gamepad` opens a real device
with python-evdev; :class:`RecordedEvents` replays recorded ones (tests, a recorded session).
Default mapping (an Xbox-style pad, :class:`GamepadMapping`): left stick x/y → EE y/x, right
stick y → z, right stick x → yaw, d-pad → roll and pitch; A (BTN_SOUTH) holds, Y (BTN_NORTH)
resumes tracking, START quits. Sticks have a dead zone.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from .base import DeviceSample, InputDevice

# linux/input-event-codes.h (a stable kernel ABI)
EV_KEY, EV_ABS = 0x01, 0x03
ABS_X, ABS_Y, ABS_Z, ABS_RX, ABS_RY, ABS_RZ, ABS_HAT0X, ABS_HAT0Y = 0x00, 0x01, 0x02, 0x03, 0x04, 0x05, 0x10, 0x11
BTN_SOUTH, BTN_EAST, BTN_NORTH, BTN_WEST, BTN_START, BTN_SELECT = 0x130, 0x131, 0x133, 0x134, 0x13B, 0x13A


@dataclass(frozen=True)
class AxisRange:
    """An absolute axis's range (evdev's absinfo min and max)."""

    lo: float
    hi: float

    def normalise(self, value: float) -> float:
        """value in [lo, hi] → [−1, 1]."""
        mid, half = (self.hi + self.lo) / 2, (self.hi - self.lo) / 2
        return float(np.clip((value - mid) / half, -1.0, 1.0)) if half > 0 else 0.0


@dataclass(frozen=True)
class GamepadMapping:
    """Which axis and button does what.

    Attributes:
        axes: event code → (twist axis 0..5, sign).
        hold, resume, quit: button codes.
        dead_zone: |normalised value| below this is 0.
    """

    axes: dict[int, tuple[int, float]] = field(default_factory=lambda: {
        ABS_Y: (0, -1.0),      # left stick forward (negative y on a pad) → +x
        ABS_X: (1, -1.0),      # left stick left → +y
        ABS_RY: (2, -1.0),     # right stick forward → +z
        ABS_RX: (5, -1.0),     # right stick left → +yaw
        ABS_HAT0X: (3, 1.0),   # d-pad right → +roll
        ABS_HAT0Y: (4, -1.0),  # d-pad up → +pitch
    })
    hold: int = BTN_SOUTH
    resume: int = BTN_NORTH
    quit: int = BTN_START
    dead_zone: float = 0.12


class EventSource(Protocol):
    """Where the kernel's events come from."""

    def ranges(self) -> dict[int, AxisRange]:
        """Each absolute axis's range."""
        ...

    def poll(self) -> Iterable[tuple[int, int, int]]:
        """The events that arrived since the last call (never blocks)."""
        ...

    def close(self) -> None: ...


class RecordedEvents:
    """A recorded event stream, replayed: ``events`` are (t [s], type, code, value), ``t`` from
    the replay's first poll."""

    def __init__(self, events: Iterable[tuple[float, int, int, int]], ranges: dict[int, AxisRange]) -> None:
        self._events = sorted(events)
        self._ranges = ranges
        self._i = 0
        self._t0: float | None = None

    def ranges(self) -> dict[int, AxisRange]:
        return dict(self._ranges)

    def poll_at(self, t: float) -> Iterator[tuple[int, int, int]]:
        """The events up to t [s] since the replay started."""
        while self._i < len(self._events) and self._events[self._i][0] <= t:
            _, typ, code, value = self._events[self._i]
            self._i += 1
            yield typ, code, value

    def poll(self) -> Iterable[tuple[int, int, int]]:
        import time

        if self._t0 is None:
            self._t0 = time.monotonic()
        return list(self.poll_at(time.monotonic() - self._t0))

    def close(self) -> None:
        pass


class _EvdevSource:
    """A real device through python-evdev (non-blocking reads)."""

    def __init__(self, dev: Any) -> None:
        self.dev = dev

    def ranges(self) -> dict[int, AxisRange]:
        caps = self.dev.capabilities(absinfo=True).get(EV_ABS, [])
        return {int(code): AxisRange(float(info.min), float(info.max)) for code, info in caps}

    def poll(self) -> Iterable[tuple[int, int, int]]:
        try:
            return [(e.type, e.code, e.value) for e in self.dev.read()]
        except BlockingIOError:
            return []

    def close(self) -> None:
        self.dev.close()


def open_gamepad(path: str | None = None) -> _EvdevSource:
    """Open a gamepad: ``path`` (``/dev/input/eventN``) or the first device with sticks and a
    BTN_SOUTH.

    Raises:
        wmm_qp.ConfigError: evdev is not installed, no such device, or no gamepad found.
    """
    from wmm_qp import ConfigError

    try:
        import evdev
    except ImportError:
        raise ConfigError("--device", "", "python-evdev is not installed: pip install 'wmm-qp[devices]'") from None
    paths = [path] if path else [str(p) for p in sorted(Path("/dev/input").glob("event*"))]
    for p in paths:
        try:
            dev = evdev.InputDevice(p)
        except OSError as e:
            if path:
                raise ConfigError(p, "", f"cannot open: {e.strerror}") from None
            continue
        caps = dev.capabilities()
        if path or (EV_ABS in caps and BTN_SOUTH in caps.get(EV_KEY, [])):
            return _EvdevSource(dev)
        dev.close()
    raise ConfigError("/dev/input", "", "no gamepad found (give one with --device /dev/input/eventN)")


class GamepadDevice(InputDevice):
    """A gamepad as an input device.

    Args:
        source: the event source (:func:`open_gamepad`, :class:`RecordedEvents`).
        mapping: axes and buttons.
        rotations: the rotation axes are live (the pose task).
    """

    name = "gamepad"

    def __init__(self, source: EventSource, mapping: GamepadMapping | None = None, rotations: bool = False) -> None:
        self.source = source
        self.mapping = mapping or GamepadMapping()
        self.rotations = rotations
        self._ranges = source.ranges()
        self._twist = np.zeros(6)
        self._hold = self._quit = self._resume = False

    def feed(self, events: Iterable[tuple[int, int, int]]) -> None:
        """Apply events (type, code, value)."""
        m = self.mapping
        for typ, code, value in events:
            if typ == EV_ABS and code in m.axes:
                axis, sign = m.axes[code]
                rng = self._ranges.get(code, AxisRange(-1.0, 1.0))
                v = rng.normalise(value)
                v = 0.0 if abs(v) < m.dead_zone else v
                self._twist[axis] = sign * v if (axis < 3 or self.rotations) else 0.0
            elif typ == EV_KEY and value == 1:  # pressed (2: autorepeat, 0: released)
                if code == m.hold:
                    self._hold = True
                elif code == m.resume:
                    self._resume = True
                elif code == m.quit:
                    self._quit = True

    def read(self, now: float) -> DeviceSample:
        self.feed(self.source.poll())
        return self.read_state()

    def read_state(self) -> DeviceSample:
        """The sample of the events fed so far (buttons reported once)."""
        s = DeviceSample(twist=self._twist.copy(), hold=self._hold, quit=self._quit, resume=self._resume)
        self._hold = self._quit = self._resume = False
        return s

    def close(self) -> None:
        self.source.close()
