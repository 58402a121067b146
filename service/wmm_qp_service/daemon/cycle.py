"""The cycle: state in → tick → command out, over a robot link and nothing else.

Each cycle takes the newest state off the :class:`~.robot_link.RobotLink` and hands it to
:meth:`.ControlCore.on_state`, runs :meth:`.ControlCore.tick`, and sends the command it returns
with its bookkeeping: the next seq, the stream it belongs to, the lease and the robot instance
it is for, and its publication time (the state-age window's reference). A command the tick
itself made late (longer than the robot's command timeout since the last one) is not sent: the
stream is braked from the last command sent instead (:meth:`.ControlCore.withdraw`).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import NamedTuple

import wmm_qp as w

from ..protocol import CommandMsg, StateMsg
from ..tick_stages import POLL, PUBLISH, VALIDATION, TickStages
from .core import ControlCore
from .robot_link import RobotLink


class Sent(NamedTuple):
    """A command that went out.

    Attributes:
        cmd: the controller's command.
        seq: its seq.
        stamp: [s] wall-clock time just after it was handed to the link (telemetry's ``cmd_stamp``).
    """

    cmd: w.Command
    seq: int
    stamp: float


class Cycle:
    """State in, tick, command out.

    Args:
        core: the control core.
        link: the robot link.
        robot: the robot's id (the command's ``robot``).
        period: [s] the control period (the command's ``period``).
        stages: the breakdown's stopwatch (None: off).
        clock: [s] the loop's monotonic clock.
        wall: [s] the wall clock (stamps).

    Attributes:
        state_rx: [s] wall-clock receipt of the last accepted state (NaN before one).
    """

    def __init__(self, core: ControlCore, link: RobotLink, robot: str, period: float,
                 stages: TickStages | None = None, clock: Callable[[], float] = time.perf_counter,
                 wall: Callable[[], float] = time.time) -> None:
        self.core, self.link, self.robot, self.period = core, link, robot, period
        self.stages = stages
        self.clock, self.wall = clock, wall
        self.state_rx = math.nan
        self._rx = [0, 0, 0]  # [ns] a state's poll start, off the link, accepted (the breakdown's stages)

    def poll_state(self) -> StateMsg | None:
        """The newest state if one arrived, valid and accepted by the core (``on_state``)."""
        stages = self.stages
        t0 = time.perf_counter_ns() if stages is not None else 0
        got = self.link.take()
        if got is None:
            return None
        t_rx, m = got
        if not self.core.on_state(m, self.clock()):
            return None
        self.state_rx = t_rx
        if stages is not None:
            self._rx[:] = t0, self.link.taken_ns, time.perf_counter_ns()
        return m

    def lap_state(self) -> None:
        """The breakdown: this tick began when the accepted state was polled (poll, validation)."""
        if self.stages is not None:
            t_poll, t_taken, t_accepted = self._rx
            self.stages.begin(t_poll)
            self.stages.lap_at(POLL, t_taken)
            self.stages.lap_at(VALIDATION, t_accepted)

    def command(self, now: float) -> Sent | None:
        """Tick at ``now`` [s] and send the command, if any (None: nothing went out)."""
        core = self.core
        cmd = core.tick(now)
        if cmd is None:
            return None
        if core.stream.late(t_pub := self.clock()):  # this tick itself stalled
            core.withdraw(f"braking stream after a stall (the tick took {(t_pub - now) * 1e3:.0f} ms: "
                          f"its command is too late)")
            return None
        stream = core.stream
        seq = stream.numbered()
        self.link.send(CommandMsg(
            robot=self.robot, seq=seq, stamp=self.wall(),
            wheel_speeds=cmd.wheel_speeds.tolist(), arm_rates=cmd.arm_rates.tolist(),
            status=cmd.status.value, lease=core.lease, instance=core.gate.instance,
            period=self.period, state_seq=stream.cmd_state_seq, stream=stream.start))
        stamp = self.wall()
        stream.sent(seq, t_pub)
        if self.stages is not None:
            self.stages.lap(PUBLISH)
        return Sent(cmd, seq, stamp)
