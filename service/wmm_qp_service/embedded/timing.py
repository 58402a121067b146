"""The embedded loop's timing: the status's figures of a core that ticks in a robot's cycle, and
how many robot cycles make one control tick."""

from __future__ import annotations

import wmm_qp as w

from ..rate_loop import LoopTiming


class CycleTiming(LoopTiming):
    """The status's loop figures of a core that ticks in a robot's cycle.

    The robot side paces the loop (its clock, or libfranka's ``readOnce``); this only records
    each tick's work (:meth:`record`) and the ticks whose cycle started after its deadline
    (:meth:`miss`). Its ``trigger`` is ``"embedded"``.
    """

    trigger = "embedded"

    def start(self) -> float:
        self.t0 = self.tick_start = self._clock()
        return self.t0

    def wait(self) -> float:
        raise NotImplementedError("the robot side paces an embedded core")

    def miss(self) -> None:
        """This tick's cycle started after its deadline (the previous cycle overran)."""
        self.deadline_misses += 1
        self.overruns += 1


def decimation(robot_rate_hz: float, rate_hz: float) -> int:
    """Robot cycles per control tick.

    Raises:
        wmm_qp.ConfigError: the control rate does not divide the robot's cycle rate.
    """
    ratio = robot_rate_hz / rate_hz
    d = round(ratio)
    if d < 1 or abs(ratio - d) > 1e-6:
        raise w.ConfigError("<embedded>", "loop.rate_hz",
                            f"{rate_hz:g} Hz must divide the robot's cycle rate {robot_rate_hz:g} Hz "
                            f"(e.g. {robot_rate_hz:g} or {robot_rate_hz / 2:g}): the core ticks every n-th cycle")
    return d
