"""The robot link in memory: the robot side hands its state over, the command comes back as an
object; nothing is encoded, nothing crosses a transport (:class:`~..daemon.RobotLink`)."""

from __future__ import annotations

import time
from collections.abc import Callable

from ..protocol import CommandMsg, StateMsg
from ..validation import Validator


class InProcessLink:
    """A :class:`~..daemon.RobotLink` between a robot side and the control core in one thread.

    The robot side :meth:`hand`\\ s each state over (with its receipt time); the cycle's
    :meth:`take` checks it as a received one would be checked (:meth:`Validator.checked`: the
    robot id, sizes, finite values, ranges) and :meth:`send` hands the command to the robot
    side's ``deliver`` at once.

    Args:
        validate: the state's validator (counts what it refuses).
        deliver: the robot side's command input (e.g. its command inbox's ``put``).
        timed: record :attr:`taken_ns` (a tick breakdown is on).
    """

    def __init__(self, validate: Validator[StateMsg], deliver: Callable[[CommandMsg], None],
                 timed: bool = False) -> None:
        self._validate = validate
        self._deliver = deliver
        self._timed = timed
        self._state: tuple[float, StateMsg] | None = None
        self.taken_ns = 0
        self.sent = 0  # commands handed to the robot side

    def hand(self, msg: StateMsg, received: float) -> None:
        """The robot side's state of this cycle, received at ``received`` [s] (wall clock)."""
        self._state = (received, msg)

    def take(self) -> tuple[float, StateMsg] | None:
        got, self._state = self._state, None
        if got is None:
            return None
        if self._timed:
            self.taken_ns = time.perf_counter_ns()
        m = self._validate.checked(got[1])
        return None if m is None else (got[0], m)

    def wait(self, timeout: float) -> bool:
        return self._state is not None

    def send(self, msg: CommandMsg) -> None:
        self.sent += 1
        self._deliver(msg)

    def close(self) -> None:
        self._state = None
