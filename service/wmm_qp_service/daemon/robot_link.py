"""The robot link: where the cycle's states come from and where its commands go.

The cycle (:class:`~.cycle.Cycle`) reads and writes only through a :class:`RobotLink`; the
service's other traffic (setpoints, modes, status, the lease …) never goes through it. Today's
link is Zenoh (:class:`ZenohRobotLink`: ``<robot>/state`` in, ``<robot>/cmd`` out); a robot
side that hosts the core in its own process hands the state and takes the command in memory
through another implementation of the same protocol.
"""

from __future__ import annotations

import contextlib
import time
from typing import Any, Protocol

import zenoh

from ..keys import Keys
from ..protocol import CommandMsg, StateMsg, encode
from ..rate_loop import Mailbox
from ..validation import Validator


class RobotLink(Protocol):
    """The robot side of the cycle.

    Attributes:
        taken_ns: [ns] (``time.perf_counter_ns``) when the last state came off the link, before
            its validation (the breakdown's poll stage; set only when the link is timed).
    """

    taken_ns: int

    def take(self) -> tuple[float, StateMsg] | None:
        """The newest valid state since the last call and its receipt time [s] (wall clock), or
        None (nothing new, or refused by validation); never blocks."""
        ...

    def wait(self, timeout: float) -> bool:
        """Block until a state may be there or ``timeout`` [s] passed (the state trigger's sleep);
        True: one may be."""
        ...

    def send(self, msg: CommandMsg) -> None:
        """Send a command to the robot; never blocks on the robot."""
        ...

    def close(self) -> None:
        """Release the link (never raises)."""
        ...


class ZenohRobotLink:
    """The robot over Zenoh: ``state`` subscribed, ``cmd`` published (express, real-time
    priority, dropped rather than queued under congestion).

    With ``trigger_state`` a callback on Zenoh's own thread stamps each state and hands it over
    (the newest wins) and :meth:`wait` sleeps until then (no polling, no spin); else the newest
    state waits in a ring of depth 1 and is stamped when taken.

    Args:
        session: the open Zenoh session.
        keys: the robot's keys.
        validate: the state's validator (counts what it refuses).
        trigger_state: the state trigger (``loop.trigger = "state"``).
        timed: record :attr:`taken_ns` (the tick breakdown is on).
    """

    def __init__(self, session: zenoh.Session, keys: Keys, validate: Validator[StateMsg], trigger_state: bool,
                 timed: bool = False) -> None:
        self._validate = validate
        self._timed = timed
        self.taken_ns = 0
        self._inbox: Mailbox[tuple[float, zenoh.Sample]] | None = None
        self._ring: zenoh.Subscriber[zenoh.handlers.Handler[zenoh.Sample]] | None = None
        if trigger_state:
            self._inbox = Mailbox()
            self._sub: zenoh.Subscriber[Any] = session.declare_subscriber(
                keys.state, zenoh.handlers.Callback(self._on_sample, indirect=False))
        else:
            self._sub = self._ring = session.declare_subscriber(keys.state, zenoh.handlers.RingChannel(1))
        self._pub = session.declare_publisher(keys.cmd, express=True,
                                              congestion_control=zenoh.CongestionControl.DROP,
                                              priority=zenoh.Priority.REAL_TIME)

    def _on_sample(self, sample: zenoh.Sample) -> None:
        """Zenoh's thread: stamp the state's receipt (the telemetry's ``state_rx``) and hand it over."""
        assert self._inbox is not None
        self._inbox.put((time.time(), sample))

    def take(self) -> tuple[float, StateMsg] | None:
        if self._inbox is not None:
            got = self._inbox.take()
            if got is None:
                return None
            t_rx, s = got
        else:
            assert self._ring is not None
            if (r := self._ring.try_recv()) is None:
                return None
            t_rx, s = time.time(), r  # its receipt (the telemetry's state_rx)
        data = s.payload.to_bytes()
        if self._timed:
            self.taken_ns = time.perf_counter_ns()
        m = self._validate(data)
        return None if m is None else (t_rx, m)

    def wait(self, timeout: float) -> bool:
        if self._inbox is None:
            return False
        return self._inbox.wait(timeout)

    def send(self, msg: CommandMsg) -> None:
        self._pub.put(encode(msg))

    def close(self) -> None:
        for ent in (self._sub, self._pub):
            with contextlib.suppress(Exception):
                ent.undeclare()
