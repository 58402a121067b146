"""The daemon's service side over Zenoh: everything but the robot's state and command.

Inputs, validated on receipt and applied to the core before each tick (:meth:`ZenohService.apply`):
mode changes (``mode``, FIFO: none lost), the latest setpoint (``setpoint``, ring of 1), the
latest live obstacle set (``obstacles``), the sim's evaluation data (``sim/truth``, optional:
telemetry only) and the robot's liveliness (``alive/robot``). Outputs: the status (``status``,
``loop.status_hz``), telemetry (``telemetry``, every ``loop.telemetry_every`` commands while
someone listens), ``info`` replies (a bounded number a tick), and the tokens ``alive/daemon``
and ``lease/<id>``. Every call is non-blocking: a slow client costs a dropped message, never a
late command.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Callable
from typing import Any

import zenoh

from ..config import ServiceConfig
from ..keys import Keys
from ..protocol import StatusMsg, TelemetryMsg, encode
from .core import ControlCore
from .cycle import Sent
from .host import HostInputs
from .reports import NAN3, target


def matching(pub: Any) -> bool:
    """Some subscriber matches the publisher (True when Zenoh cannot tell)."""
    try:
        return bool(pub.matching_status.matching)
    except Exception:
        return True


def answer_queries(queryable: Any, limit: int, key: str, reply: Callable[[], bytes],
                   failed: Callable[[str], None]) -> int:
    """Answer at most ``limit`` pending queries (the rest wait in the queryable's FIFO for the
    next ticks: a burst costs the loop ``limit`` replies a tick, not a stall).

    Args:
        queryable: has ``try_recv()`` → a query with ``reply(key, payload)``, or None.
        limit: replies at most.
        key: the reply's key.
        reply: builds the payload (once per query: each sees the state of its tick).
        failed: told why a reply failed (a vanished querier must not stop the loop).

    Returns:
        the number answered.
    """
    n = 0
    while n < limit and (q := queryable.try_recv()) is not None:
        n += 1
        try:
            q.reply(key, reply())
        except Exception as e:
            failed(f"info reply failed: {e}")
    return n


class ZenohService:
    """The subscribers, queryable, publishers and tokens of one daemon run.

    Args:
        session: the open Zenoh session.
        keys: the robot's keys.
        svc: the service config (rates of status, telemetry and replies).
        lease: this daemon's lease id (its token ``lease/<id>``).
        inputs: the host's inputs (validated on receipt, applied to the core at one point of the tick).
    """

    def __init__(self, session: zenoh.Session, keys: Keys, svc: ServiceConfig, lease: str,
                 inputs: HostInputs) -> None:
        ring, fifo = zenoh.handlers.RingChannel, zenoh.handlers.FifoChannel
        self.keys, self.robot = keys, svc.robot
        self.inputs = inputs
        self._setpoint = session.declare_subscriber(keys.setpoint, ring(1))
        self._mode = session.declare_subscriber(keys.mode, fifo(256))
        self._obstacles = session.declare_subscriber(keys.obstacles, ring(1))  # the latest set wins
        self._truth = session.declare_subscriber(keys.sim_truth, ring(1))  # optional: telemetry only
        self.queryable = session.declare_queryable(keys.info, fifo(64))
        self._alive = session.liveliness().declare_subscriber(keys.alive("robot"), fifo(64), history=True)
        self._token = session.liveliness().declare_token(keys.alive("daemon"))
        self._lease_token = session.liveliness().declare_token(keys.lease(lease))
        self._status = session.declare_publisher(keys.status)
        self._tel = session.declare_publisher(keys.telemetry, congestion_control=zenoh.CongestionControl.DROP)
        lp = svc.loop
        self.status_every = max(1, round(lp.rate_hz / lp.status_hz))
        self.tel_every = lp.telemetry_every
        self.tel_listened = bool(self.tel_every)  # re-read with every status: no telemetry built for nobody
        self.queries_per_tick = lp.queries_per_tick

    def apply(self, core: ControlCore, now: float) -> None:
        """Hand the core what arrived since the last tick: every mode change, the latest
        setpoint, obstacle set and truth (:meth:`.HostInputs.apply`)."""
        inputs = self.inputs
        while (s := self._mode.try_recv()) is not None:
            inputs.take("mode", s.payload.to_bytes())
        for kind, sub in (("setpoint", self._setpoint), ("obstacles", self._obstacles), ("truth", self._truth)):
            if (s := sub.try_recv()) is not None:
                inputs.take(kind, s.payload.to_bytes())
        inputs.apply(core, now)

    def telemetry(self, core: ControlCore, sent: Sent, tick: int, t: float, tick_us: float,
                  state_rx: float) -> None:
        """Publish tick ``tick``'s telemetry (every ``telemetry_every``-th, while someone listens).

        Args:
            t: [s] since the loop's start; tick_us: [µs] the last tick's work;
            state_rx: [s] the receipt of the state the command comes from.
        """
        if not (self.tel_listened and tick % self.tel_every == 0):
            return
        cmd = sent.cmd
        fresh = core.stream.cmd_state_seq >= 0
        ee = core.truth.ee_true if core.truth is not None else NAN3
        self._tel.put(encode(TelemetryMsg(
            robot=self.robot, seq=sent.seq, stamp=sent.stamp, t=t,
            mode=core.mode.value, x=cmd.x.tolist(), x_d=target(core.ref),
            xd_d=core.ref.xd_d.tolist(), ee_true=ee, ee_error=core.ee_error,
            wheel_speeds=cmd.wheel_speeds.tolist(), arm_rates=cmd.arm_rates.tolist(),
            status=cmd.status.value, dm=float(cmd.dm), task_error=float(cmd.task_error),
            tick_us=tick_us, step_us=core.step_ns * 1e-3,
            state_seq=core.stream.cmd_state_seq, state_rx=state_rx if fresh else math.nan,
            cmd_stamp=sent.stamp)))

    def liveliness(self, core: ControlCore) -> None:
        """Hand the core the robot's liveliness changes."""
        while (a := self._alive.try_recv()) is not None:
            core.on_robot_alive(a.kind == zenoh.SampleKind.PUT)

    def status(self, tick: int, build: Callable[[], StatusMsg]) -> None:
        """Publish the status on every ``status_every``-th tick (and re-read whether anyone
        listens to the telemetry)."""
        if tick % self.status_every == 0:
            self._status.put(encode(build()))
            self.tel_listened = bool(self.tel_every) and matching(self._tel)

    def close(self) -> None:
        """Undeclare everything (never raises)."""
        for ent in (self._token, self._lease_token, self._setpoint, self._mode, self._obstacles, self._truth,
                    self.queryable, self._alive, self._status, self._tel):
            with contextlib.suppress(Exception):
                ent.undeclare()
