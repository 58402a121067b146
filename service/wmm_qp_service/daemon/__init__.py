"""The control daemon (``wmm-qp serve``): one robot, one controller, one control thread.

Three parts, and the seams between them:

- **the cycle** — state in → tick → command out, with no transport: :class:`ControlCore`
  (:meth:`~ControlCore.on_state`, :meth:`~ControlCore.tick`; the instance latch and seq in
  :mod:`.state_gate`, the command stream — the sent ring, the state's age, anchoring and
  prediction, breaks — in :mod:`.command_stream`, the watchdogs and faults in :mod:`.watchdog`)
  and :class:`Cycle`, which takes the state off a robot link, runs the tick and sends the
  command with its bookkeeping (seq, stream, lease, instance, publication time). Nothing in it
  raises: failures become a safe stop and a reason in the status.
- **the robot link** — where states come from and commands go: the :class:`RobotLink`
  protocol (``take``, ``wait``, ``send``, ``close``); today :class:`ZenohRobotLink`
  (``<robot>/state`` in, ``<robot>/cmd`` out).
- **the service side** — everything else over Zenoh (:class:`ZenohService`): mode changes,
  setpoints (one operator, fence clamp: :mod:`.setpoints`), live obstacles, the sim's truth and
  liveliness go in, validated on receipt, through the core's input methods (:mod:`.inputs`);
  status, telemetry and ``info`` replies (:mod:`.reports`) and the tokens go out; the lease is
  taken at start and its start-up race watched (:mod:`.lease`).

:class:`Daemon` (:mod:`.loop`) wires the three on one thread: each tick (:class:`ControlLoop`)
takes the newest state — a ring polled at the fixed rate, or with ``loop.trigger = "state"`` a
callback on Zenoh's thread that stamps it and wakes the loop — then applies the service's
inputs (polled from Zenoh's channels, none blocking), runs the cycle, and publishes telemetry,
status and replies after the command.

A robot side that hosts the core in its own process and thread (the embedded mode,
:mod:`wmm_qp_service.embedded`: ``wmm-qp sim --embedded``, ``wmm-qp driver franka --embedded``)
replaces only the link: its cycle hands the state to :meth:`ControlCore.on_state` and takes the
command from :class:`Cycle` in memory (an in-process :class:`RobotLink`), while a service thread
carries setpoints, modes, obstacles, status, telemetry, info and the lease over Zenoh with the
same keys and messages. The core is not thread-safe: the service's inputs reach it on the
cycle's thread (as :meth:`ZenohService.apply` does here, between two cycles; the embedded host
hands them over in the cycle's slack).
"""

from .command_stream import CommandStream
from .core import ControlCore
from .cycle import Cycle, Sent
from .lease import LeaseHeld, LeaseRace
from .loop import ControlLoop, Daemon
from .robot_link import RobotLink, ZenohRobotLink
from .state_gate import SEQ_JUMP_MAX, StateGate
from .watchdog import ROUND_TRIPS, FaultLog, FaultRecord
from .watchdog import say as _say
from .zenoh_service import ZenohService

__all__ = [
    "ROUND_TRIPS",
    "SEQ_JUMP_MAX",
    "CommandStream",
    "ControlCore",
    "ControlLoop",
    "Cycle",
    "Daemon",
    "FaultLog",
    "FaultRecord",
    "LeaseHeld",
    "LeaseRace",
    "RobotLink",
    "Sent",
    "StateGate",
    "ZenohRobotLink",
    "ZenohService",
    "_say",
]
