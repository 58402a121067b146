"""The embedded host's Zenoh side, off the cycle's thread: what a split daemon and sim publish
and receive, with the same keys and messages, but never the state → command path.

:class:`ServiceThread` runs on its own thread. Its inputs are Zenoh channels (Zenoh's own
threads only store the samples: no Python runs there, so no Zenoh callback takes the GIL from
the cycle): mode changes (FIFO), the latest setpoint and obstacle set (rings of 1), the robot
side's own inputs (``sim/box``, ``gripper``), ``info`` queries; it forwards their payloads
to the cycle's inbox as they are (the cycle validates and applies them in its slack). Its
outputs are what the cycle hands over: the state (for observers only here, with the split sim's
QoS), the evaluation data, telemetry, status and ``info`` replies, encoded and published here. It holds the tokens
``alive/daemon``, ``alive/robot`` and ``lease/<id>``. The cycle wakes it after the command, every
cycle (one state per pump); it wakes by itself every :data:`IDLE` at most. Where the robot's
library holds the
GIL while it waits for the robot (pylibfranka), no thread could run: the cycle then calls
:meth:`ServiceThread.pump` itself in its slack (``threaded=False``).

:func:`embedded_session` opens the session (both endpoints: clients, ``wmm-qp status`` and a
second daemon find the robot where they look for a daemon and a sim), takes the control lease
(a daemon that holds it already: :class:`~..daemon.LeaseHeld`) and runs the thread.
"""

from __future__ import annotations

import contextlib
import sys
import threading
from collections.abc import Iterator
from typing import TYPE_CHECKING, Any

import zenoh

from .. import robot_side
from ..config import ServiceConfig
from ..daemon.lease import acquire
from ..daemon.zenoh_service import matching
from ..keys import Keys
from ..protocol import encode
from ..rate_loop import realtime_priority
from ..transport import ROLE_EMBEDDED, io_priority, open_session
from .control import EmbeddedControl, telemetry_msg

if TYPE_CHECKING:
    Channel = zenoh.handlers.FifoChannel[zenoh.Sample] | zenoh.handlers.RingChannel[zenoh.Sample]

IDLE = 0.02
"""[s] the service thread's longest sleep when the cycle does not wake it (a robot side that
stopped cycling: its inputs and queries still move)."""


class ServiceThread:
    """The subscribers, queryable, publishers and tokens of an embedded host, on one thread.

    Args:
        session: the open Zenoh session.
        keys: the robot's keys.
        control: the hosted core (its inbox, queries and outbox).
        truth: publish the evaluation data on ``sim/truth``.
        robot_inputs: the robot side's own input keys to forward (``box``, ``gripper``).
        threaded: run on a thread of its own; False: the cycle runs :meth:`pump` itself, in its
            slack, every few cycles (a robot library that holds the GIL while it waits for the
            robot, as pylibfranka's ``readOnce`` does, would starve a thread).
        rt_priority: the cycle's SCHED_FIFO priority (0: normal scheduling); this thread takes
            one below it. It holds the GIL while it publishes: at normal priority on a loaded host
            the scheduler could take the CPU from it mid-call, and the cycle, real-time but
            waiting for the GIL, would wait for it (a priority inversion); one level below the
            cycle it finishes its pump and sleeps again.
    """

    def __init__(self, session: zenoh.Session, keys: Keys, control: EmbeddedControl, truth: bool = True,
                 robot_inputs: tuple[str, ...] = ("box", "gripper"), rt_priority: int = 0,
                 threaded: bool = True) -> None:
        ring, fifo = zenoh.handlers.RingChannel, zenoh.handlers.FifoChannel
        self.keys, self.control, self.robot = keys, control, control.svc.robot
        inputs: dict[str, tuple[str, Channel]] = {
            "mode": (keys.mode, fifo(256)), "setpoint": (keys.setpoint, ring(1)),
            "obstacles": (keys.obstacles, ring(1))}
        self._inputs = [(kind, session.declare_subscriber(key, handler)) for kind, (key, handler) in inputs.items()]
        self._inputs += [(kind, robot_side.input_subscriber(session, keys, kind)) for kind in ("box", "gripper")
                         if kind in robot_inputs]
        self._queryable = session.declare_queryable(keys.info, fifo(64))
        # the state's QoS as the split sim's (express, drop, real-time priority), one state per
        # pump: bursts of four express states lost ~6 % of them to the congestion drop; batched,
        # a recorder once received a state on the truth's key under a load of 17
        self._state = robot_side.state_publisher(session, keys)
        self._truth = robot_side.truth_publisher(session, keys) if truth else None
        self._status = session.declare_publisher(keys.status)
        self._tel = session.declare_publisher(keys.telemetry, congestion_control=zenoh.CongestionControl.DROP)
        live = session.liveliness()
        self._tokens = [live.declare_token(keys.alive("daemon")), robot_side.alive_token(session, keys),
                        live.declare_token(keys.lease(control.core.lease))]
        self._wake = threading.Event()
        self._stop = False
        self.errors = 0  # publications that failed (said on stderr, the first 10)
        self.pumps = 0
        self.rt_priority = max(0, rt_priority - 1) if rt_priority > 0 else 0
        self.scheduling = "not started" if threaded else "the cycle's slack"
        self.threaded = threaded
        self._thread = threading.Thread(target=self._run, name="embedded-service", daemon=True)

    def start(self) -> ServiceThread:
        if self.threaded:
            self.control.kick = self._wake.set
            self._thread.start()
        else:
            self.control.kick = self.pump
        return self

    def _run(self) -> None:
        self.scheduling = realtime_priority(self.rt_priority)
        while not self._stop:
            self._wake.wait(IDLE)
            self._wake.clear()
            self.pump()

    def pump(self) -> None:
        """Forward what arrived to the cycle, publish what the cycle handed over (never raises)."""
        self.pumps += 1
        c = self.control
        try:
            for kind, sub in self._inputs:
                while (s := sub.try_recv()) is not None:
                    c.inbox.append((kind, s.payload.to_bytes()))
            while (q := self._queryable.try_recv()) is not None:
                c.queries.append(q)
        except Exception as e:
            self._error(f"input: {type(e).__name__}: {e}")
        out = c.outbox
        while out:
            try:
                item = out.popleft()
            except IndexError:
                break
            try:
                self._publish(item)
            except Exception as e:  # a vanished querier, a closed session: never the end of the thread
                self._error(f"{item[0]}: {type(e).__name__}: {e}")

    def _publish(self, item: tuple[Any, ...]) -> None:
        tag = item[0]
        if tag == "state":
            self._state.put(encode(item[1]))
        elif tag == "truth":
            if self._truth is not None:
                self._truth.put(encode(item[1]))
        elif tag == "tel":
            self._tel.put(encode(telemetry_msg(self.robot, item[1])))
        elif tag == "status":
            self._status.put(encode(item[1]))
            self.control.tel_listened = bool(self.control.tel_every) and matching(self._tel)
        elif tag == "reply":
            try:
                item[1].reply(self.keys.info, encode(item[2]))
            except Exception as e:
                self.control.notes.append(f"info reply failed: {e}")

    def _error(self, what: str) -> None:
        self.errors += 1
        if self.errors <= 10:
            with contextlib.suppress(Exception):
                print(f"wmm-qp embedded: service: {what}", file=sys.stderr, flush=True)

    def close(self) -> None:
        """Stop the thread, publish what is left, undeclare everything (never raises)."""
        self._stop = True
        self._wake.set()
        if self.threaded:
            self._thread.join(timeout=2.0)
        self.pump()
        self.control.kick = lambda: None
        for ent in (*self._tokens, *(s for _, s in self._inputs), self._queryable, self._state, self._truth,
                    self._status, self._tel):
            if ent is not None:
                with contextlib.suppress(Exception):
                    ent.undeclare()


@contextlib.contextmanager
def embedded_session(svc: ServiceConfig, control: EmbeddedControl, stop: threading.Event, *,
                     wait_lease: bool = False, truth: bool = True, robot_inputs: tuple[str, ...] = ("box", "gripper"),
                     rt_priority: int = 0, threaded: bool = True) -> Iterator[ServiceThread | None]:
    """Open the embedded host's session, take the control lease and run its service thread.

    Args:
        svc: the service config (keys, endpoints).
        control: the hosted core (its lease id becomes the session's id).
        stop: set while waiting for the lease: yields None.
        wait_lease: wait while another daemon holds the lease (else :class:`~..daemon.LeaseHeld`).
        truth: publish the evaluation data.
        robot_inputs: the robot side's input keys.
        rt_priority: the cycle's SCHED_FIFO priority (the service thread takes one below).
        threaded: the service side on its own thread (False: in the cycle's slack).

    Yields:
        the running service thread, or None (stopped while waiting for the lease).

    Raises:
        LeaseHeld: another daemon holds the robot's lease.
    """
    keys = Keys.of(svc.prefix, svc.robot)
    with open_session(svc, ROLE_EMBEDDED, io_priority(rt_priority)) as session:
        control.core.lease = str(session.info.zid())
        if not acquire(session, keys, control.core.lease, wait_lease, stop):
            yield None
            return
        service = ServiceThread(session, keys, control, truth, robot_inputs, rt_priority, threaded).start()
        try:
            yield service
        finally:
            service.close()
