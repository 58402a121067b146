"""The daemon's watchdogs and its faults: the conditions that force a safe stop now
(:func:`hazard`), the record of the faults seen (:class:`FaultRecord`: the status's ``last_fault``
and ``faults``), and the stderr writer that keeps a slow terminal out of the control thread
(:class:`FaultLog`)."""

from __future__ import annotations

import contextlib
import math
import sys
import threading
from collections import Counter, deque
from typing import NamedTuple

from wmm_qp.fault_codes import FaultCode

from ..config import WatchdogConfig
from .state_gate import StateGate


class Fault(NamedTuple):
    """A fault: its stable code (the status's ``faults`` key) and its message (``last_fault``)."""

    code: FaultCode
    message: str


ROUND_TRIPS = 50
"""States in the state-age window (each bounded by the time since the command it applied)."""


def say(line: str) -> None:
    """Write a line to stderr; never raises (a closed pipe, a full terminal)."""
    with contextlib.suppress(Exception):
        print(line, file=sys.stderr, flush=True)


class FaultLog:
    """Fault lines written by a thread of their own, so that a slow or closed stderr can neither
    block nor stop the control thread; at most ``depth`` lines wait, the rest are counted.

    Args:
        depth: lines kept while the writer is behind.
    """

    def __init__(self, depth: int = 256) -> None:
        self._q: deque[str] = deque()
        self._depth = depth
        self.dropped = 0
        self._wake = threading.Event()
        self._stop = False
        self._thread = threading.Thread(target=self._run, name="fault-log", daemon=True)
        self._thread.start()

    def __call__(self, line: str) -> None:
        if len(self._q) >= self._depth:
            self.dropped += 1
            return
        self._q.append(line)
        self._wake.set()

    def _run(self) -> None:
        while True:
            self._wake.wait(0.5)
            self._wake.clear()
            while self._q:
                say(self._q.popleft())
            if self._stop:
                return

    def close(self) -> None:
        """Write what is left and end the thread."""
        self._stop = True
        self._wake.set()
        self._thread.join(timeout=2.0)
        if self.dropped:
            say(f"wmm-qp serve: {self.dropped} fault lines dropped (stderr was too slow)")


class FaultRecord:
    """The faults the daemon saw, as its status reports them.

    Attributes:
        last: the last fault's message, as the status shows it ("" before any).
        last_code: its code ("" before any; a note that is not a fault leaves it).
        last_time: [s] clock value when ``last`` was recorded (-inf: none).
        counts: faults by code (the status's ``faults``).
        event: a fault that happened once (not a condition): it holds the safe stop until
            ``event_until`` [s].
    """

    def __init__(self) -> None:
        self.last = ""
        self.last_code = ""
        self.last_time = -math.inf
        self.counts: Counter[str] = Counter()
        self.event: Fault | None = None
        self.event_until = -math.inf

    def record(self, code: FaultCode, what: str, now: float) -> bool:
        """Count fault ``what`` under ``code`` at ``now`` [s].

        Returns:
            True when it differs from the last one (to be said once on stderr).
        """
        new = what != self.last
        self.last = what
        self.last_code = code.value
        self.last_time = now
        self.counts[code.value] += 1
        return new

    def hold(self, fault: Fault, until: float) -> None:
        """Event ``fault`` holds the safe stop until ``until`` [s]."""
        self.event = fault
        self.event_until = until


def second_source(gate: StateGate) -> Fault:
    """The fault of a second robot's states on the key (the gate's last foreign instance)."""
    return Fault(FaultCode.SECOND_STATE_SOURCE, f"second state source (robot instance {gate.foreign} on the key "
                 f"besides the latched {gate.instance}: two robots under one id)")


def hazard(wd: WatchdogConfig, now: float, state_time: float, gate: StateGate, protective: str,
           round_trip: float, faults: FaultRecord) -> Fault | None:
    """The fault that forces a safe stop now, or None.

    Conditions, the first that holds named: a second sim instance on the key within
    ``state_timeout``; no valid state for ``state_timeout`` (or the sim's token vanished); the
    sim's firmware in a protective stop; the state older than ``state_age_max`` (round trip); and, for ``state_timeout``
    after it happened, a rise of the sim's violation counts.

    Args:
        wd: the watchdog's limits.
        now: [s] the tick's clock value.
        state_time: [s] when the last valid state arrived (-inf: none, or the sim vanished).
        gate: the instance latch (the second source).
        protective: the robot's protective stop reason ("" when none).
        round_trip: [s] the median state-age bound over :data:`ROUND_TRIPS` states (NaN: not yet).
        faults: the record (its event fault).
    """
    # the second source first: a flood of another robot's states on the key also starves the
    # latched one, and "state stale" would hide the cause the operator must remove
    if now - gate.foreign_time <= wd.state_timeout:
        return second_source(gate)
    if now - state_time > wd.state_timeout:
        return Fault(FaultCode.STATE_STALE, f"state stale (none valid for > {wd.state_timeout * 1e3:.0f} ms)")
    if protective:
        return Fault(FaultCode.ROBOT_PROTECTIVE_STOP, f"robot protective stop ({protective})")
    if round_trip > wd.state_age_max:
        return Fault(FaultCode.STATE_TOO_OLD, f"state too old (median age bound {round_trip * 1e3:.1f} ms over "
                     f"{ROUND_TRIPS} states; bounds (13) allow {wd.state_age_max * 1e3:.1f} ms)")
    if now < faults.event_until and faults.event is not None:
        return faults.event
    return None
