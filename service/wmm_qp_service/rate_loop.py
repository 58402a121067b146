"""Loop timing: the fixed-rate loop (absolute deadlines, sleep then spin) and the
state-triggered loop (a tick as soon as a new state arrives, the fixed-rate deadline as its
watchdog); overruns counted.

The clock, the sleep and the state source are injected so the timing logic is testable with a
fake clock (tests never depend on real timing).
"""

from __future__ import annotations

import math
import os
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Generic, TypeVar

import numpy as np

from .protocol import LoopStats

T = TypeVar("T")

TRIGGERS = ("rate", "state")
"""``loop.trigger``: ``rate`` = :class:`RateLoop`, ``state`` = :class:`StateLoop`."""


def realtime_priority(priority: int) -> str:
    """Put the calling thread under SCHED_FIFO at ``priority`` (Linux); say what happened.

    A real-time thread is not preempted by ordinary processes, so a loaded machine delays its
    ticks far less. The loop sleeps most of each period, so it does not starve the others. The
    daemon's control thread uses it (``loop.rt_priority``), the sim's step loop on request
    (``wmm-qp sim --rt-priority``).
    """
    if priority <= 0:
        return "normal scheduling"
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))  # 0 = this thread
    except (AttributeError, OSError) as e:  # not Linux, or not permitted
        return f"normal scheduling (SCHED_FIFO {priority} refused: {getattr(e, 'strerror', e)})"
    return f"SCHED_FIFO {priority}"


class Mailbox(Generic[T]):
    """The newest item handed over by another thread (a Zenoh callback), and a wait for it.

    :meth:`put` (the producer's thread: it only stores and signals) replaces what was not taken
    yet, as a ring of depth 1 does; :meth:`take` (the loop's thread) never blocks; :meth:`wait`
    blocks until a :meth:`put` or the timeout. The loop's thread sleeps in the kernel instead of
    polling: a state-triggered daemon costs the CPU of its ticks, not of its waiting.
    """

    def __init__(self) -> None:
        self._box: deque[T] = deque(maxlen=1)  # append and popleft are atomic under the GIL
        self._event = threading.Event()
        self.put_count = 0

    def put(self, item: T) -> None:
        """Store ``item`` (the older one, if not taken, is dropped) and wake the waiter."""
        self._box.append(item)
        self.put_count += 1
        self._event.set()

    def take(self) -> T | None:
        """The newest item not taken yet, or None (never blocks)."""
        try:
            return self._box.popleft()
        except IndexError:
            return None

    def wait(self, timeout: float) -> bool:
        """Block until a :meth:`put` since the last wait, or ``timeout`` [s]; True: signalled.

        A True return may find nothing to :meth:`take` (taken already): callers poll again.
        """
        signalled = self._event.wait(max(0.0, timeout))
        if signalled:
            self._event.clear()  # before the take: a put after it signals the next wait
        return signalled


class LoopTiming:
    """Work time per tick: a window for the percentiles, the maximum, the counters (what
    :class:`RateLoop` and :class:`StateLoop` share, and the status reports).

    Args:
        rate_hz: [Hz] the loop's rate (its period is the deadline budget of a tick).
        clock: monotonic clock [s].
        window: number of recent tick times kept for the percentiles.
    """

    trigger = "rate"

    def __init__(self, rate_hz: float, clock: Callable[[], float], window: int) -> None:
        if not rate_hz > 0:
            raise ValueError("rate_hz must be > 0")
        self.rate_hz = float(rate_hz)
        self.period = 1.0 / self.rate_hz
        self._clock = clock
        self._times = np.zeros(window)
        self._n = 0
        self.ticks = 0
        self.deadline_misses = 0
        self.skipped = 0
        self.tick_max = 0.0
        self.last_work = 0.0  # [s] the last recorded tick's work
        self.overruns = 0
        self.watchdog_ticks = 0
        self.t0 = clock()
        self.tick_start = self.t0

    def start(self) -> float:
        """(Re)start now; returns the first tick's start time [s]."""
        raise NotImplementedError

    def wait(self) -> float:
        """End the current tick and wait for the next one; returns its start time [s]."""
        raise NotImplementedError

    def record(self, work_s: float) -> None:
        """Record one tick's work time [s]."""
        self._times[self._n % self._times.size] = work_s
        self._n += 1
        self.ticks += 1
        self.last_work = work_s
        if work_s > self.tick_max:
            self.tick_max = work_s

    def percentiles_us(self, *q: float) -> list[float]:
        """[µs] the q-th percentiles (nearest rank) of the recent tick work times (0 before any tick).

        One partial sort of the window for all of them (``np.percentile`` costs ~0.2 ms per call
        on 2,048 samples here: twice per status, it was a tick's worth of work at 1 kHz).
        """
        n = min(self._n, self._times.size)
        if n == 0:
            return [0.0] * len(q)
        k = [min(n - 1, max(0, math.ceil(p / 100.0 * n) - 1)) for p in q]
        part = np.partition(self._times[:n], k)
        return [float(part[i]) * 1e6 for i in k]

    def percentile_us(self, q: float) -> float:
        """[µs] the q-th percentile (nearest rank) of the recent tick work times (0 before any tick)."""
        return self.percentiles_us(q)[0]

    def stats(self) -> LoopStats:
        """The figures the status reports."""
        elapsed = self._clock() - self.t0
        p50, p99 = self.percentiles_us(50.0, 99.0)
        return LoopStats(
            rate_hz=self.rate_hz,
            measured_hz=self.ticks / elapsed if elapsed > 0 else 0.0,
            ticks=self.ticks,
            deadline_misses=self.deadline_misses,
            tick_p50_us=p50,
            tick_p99_us=p99,
            tick_max_us=self.tick_max * 1e6,
            trigger=self.trigger,
            watchdog_ticks=self.watchdog_ticks,
            overruns=self.overruns,
        )


class RateLoop(LoopTiming):
    """Paces a loop at a fixed period with absolute deadlines.

    Tick k is due at ``t0 + k·period``. :meth:`wait` sleeps until ``spin`` before the next
    deadline, then spins on the clock. A tick that starts after its deadline (the previous
    tick's work overran) is a deadline miss; when the loop has fallen more than a whole
    period behind, the missed deadlines are skipped (counted, never run in a burst).

    With ``rephase`` a late tick starts a new schedule instead (the next deadline a whole period
    after it): a late tick is not followed by an early one (on the absolute grid the tick after a
    late one could come a fraction of a period later). The ROS 2 driver's shaper, which changes its
    rates by the time elapsed, then keeps its full rate of change after a busy moment.

    Args:
        rate_hz: [Hz] loop rate.
        spin_s: [s] spin this long before each deadline instead of sleeping.
        clock: monotonic clock [s].
        sleep: sleep function [s].
        window: number of recent tick times kept for the percentiles.
        rephase: a late tick moves the schedule (see above) instead of keeping the absolute grid.
    """

    def __init__(self, rate_hz: float, spin_s: float = 200e-6,
                 clock: Callable[[], float] = time.perf_counter,
                 sleep: Callable[[float], None] = time.sleep, window: int = 2048, rephase: bool = False) -> None:
        super().__init__(rate_hz, clock, window)
        self.spin_s = spin_s
        self._sleep = sleep
        self.rephase = rephase
        self.deadline = self.t0

    def start(self) -> float:
        """(Re)start the schedule now; returns the first tick's start time [s]."""
        self.t0 = self._clock()
        self.deadline = self.t0
        self.tick_start = self.t0
        return self.t0

    def wait(self) -> float:
        """End the current tick (record its work time) and wait for the next deadline.

        Returns:
            [s] the start time of the next tick.
        """
        now = self._clock()
        self.record(now - self.tick_start)
        self.deadline += self.period
        if now > self.deadline:
            self.deadline_misses += 1
            self.overruns += 1
            behind = int((now - self.deadline) // self.period)
            if behind > 0:  # more than a whole period late: skip, do not burst
                self.skipped += behind
                self.deadline += behind * self.period
            if self.rephase:  # the next tick a whole period after this one
                self.deadline = now
            self.tick_start = now
            return now
        remaining = self.deadline - now
        if remaining > self.spin_s:
            self._sleep(remaining - self.spin_s)
        while (now := self._clock()) < self.deadline:
            pass
        self.tick_start = now
        return now


class StateLoop(LoopTiming, Generic[T]):
    """Ticks as soon as a new state arrives (the robot's cycle is the clock); the fixed-rate
    deadline remains as the watchdog.

    :meth:`wait` ends the current tick and returns when the next one starts: either a new state
    arrived (:attr:`item` holds it, :attr:`fresh` is True), or no state came for ``wait_periods``
    periods since the last tick (a *watchdog tick*: :attr:`fresh` is False, the daemon takes the
    prediction path; after ``state_timeout`` without a state its watchdog stops the robot).

    Waiting, with ``block`` (the daemon's: :meth:`Mailbox.wait`, its Zenoh callback's signal),
    sleeps in the kernel until the source signals a state or the watchdog is due: no CPU spent
    waiting, and the wake-up is the source's. Without ``block`` the loop
    sleeps until ``lead`` before the next state is due (the last arrival plus a period), then polls
    the source in a tight loop (``spin_max`` at most, then in naps of ``nap``: a lost state
    costs no spinning). ``lead`` adapts: a state that was already waiting at the first poll
    (it came while the loop slept) widens it by ``lead_up``; every state caught while polling
    narrows it by ``lead_down`` (within [``lead_min``, ``lead_max``]).

    A state that arrives less than ``min_gap_periods`` periods after the previous tick's start
    is held until then (a robot faster than the loop's rate cannot make two commands land within
    one of its bounds' (13) Δt).

    Deadline misses: a tick whose work ends more than one period after its trigger (its command
    is late for the robot's next cycle), and every watchdog tick (a robot cycle without a state);
    :attr:`watchdog_ticks` counts the latter apart.

    Args:
        rate_hz: [Hz] the robot's cycle rate (the commands' Δt).
        poll: returns the newest state if one arrived since the last call, else None (never
            blocks: the daemon's :meth:`Mailbox.take` and its decoding).
        block: wait up to the given time [s] for the source to signal a new state (may return
            early, signalled or not: the loop polls again); None = sleep, then poll (``lead``).
        wait_periods: a watchdog tick after this many periods without a state (> 1, so that a
            state arriving with jitter does not race the watchdog: two commands within one
            robot cycle, one overwritten).
        min_gap_periods: the shortest time between two tick starts, in periods.
        clock: monotonic clock [s].
        sleep: sleep function [s].
        lead_min, lead_max: [s] range of the adaptive lead (poll this long before a state is due).
        spin_max: [s] poll in a tight loop at most this long, then in naps.
        nap: [s] sleep between polls once ``spin_max`` has passed.
        window: number of recent tick times kept for the percentiles.
    """

    trigger = "state"

    def __init__(self, rate_hz: float, poll: Callable[[], T | None], wait_periods: float = 1.5,
                 min_gap_periods: float = 0.5, block: Callable[[float], object] | None = None,
                 clock: Callable[[], float] = time.perf_counter,
                 sleep: Callable[[float], None] = time.sleep, lead_min: float = 50e-6,
                 lead_max: float | None = None, spin_max: float | None = None, nap: float = 50e-6,
                 window: int = 2048) -> None:
        super().__init__(rate_hz, clock, window)
        if not wait_periods > 1.0:
            raise ValueError("wait_periods must be > 1 (a late state would race the watchdog)")
        if not 0.0 <= min_gap_periods < 1.0:
            raise ValueError("min_gap_periods must be in [0, 1)")
        self._poll = poll
        self._sleep = sleep
        self._block = block
        self.wait_s = wait_periods * self.period
        self.min_gap = min_gap_periods * self.period
        self.lead_min = lead_min
        self.lead_max = 0.5 * self.period if lead_max is None else lead_max
        self.lead = min(self.lead_max, max(self.lead_min, 0.2 * self.period))
        self.lead_up = 0.1 * self.period
        self.lead_down = 0.002 * self.period
        self.spin_max = 0.5 * self.period if spin_max is None else spin_max
        self.nap = nap
        self.item: T | None = None
        self.fresh = False
        self.trigger_time = self.t0
        self.last_arrival = -math.inf
        self.early = 0  # states already waiting at the first poll (the lead was too short)

    def start(self) -> float:
        """(Re)start now: the first tick starts at once, without a state (its watchdog tick).

        Returns:
            [s] the first tick's start time.
        """
        self.t0 = self._clock()
        self.tick_start = self.trigger_time = self.t0
        self.item, self.fresh = None, False
        return self.t0

    def due(self, now: float) -> float:
        """[s] when the next state is expected: the last arrival plus the first whole number of
        periods that is not before ``now`` minus the lead (a lost state skips a cycle)."""
        if not math.isfinite(self.last_arrival):
            return now
        n = max(1, math.ceil((now + self.lead - self.last_arrival) / self.period))
        return self.last_arrival + n * self.period

    def wait(self) -> float:
        """End the current tick (record its work time) and wait for a new state or the watchdog.

        Returns:
            [s] the start time of the next tick (:attr:`fresh`, :attr:`item` say which). A
            state's tick starts at the poll that returned it, so its receipt (decoding,
            validation) counts in the tick's work.
        """
        clock = self._clock
        now = clock()
        self.record(now - self.tick_start)
        if now - self.trigger_time > self.period:  # its command came too late for the next cycle
            self.overruns += 1
            self.deadline_misses += 1
        self.item, self.fresh = None, False
        watchdog = self.trigger_time + self.wait_s
        if self._block is not None:
            return self._wait_blocking(watchdog)
        poll_from = min(self.due(now) - self.lead, watchdog)
        slept = poll_from > now
        if slept:
            self._sleep(poll_from - now)
        first = True
        t_poll = clock()
        spin_until = t_poll + self.spin_max
        while (item := self._poll()) is None:
            now = clock()
            if now >= watchdog:
                break
            first = False
            if now > spin_until:  # a late or lost state: nap, do not burn the core
                self._sleep(min(self.nap, watchdog - now))
            t_poll = clock()
        if item is None:
            return self._watchdog_tick(now)
        if first and slept:  # it was already waiting: it came while the loop slept
            self.early += 1
            self.lead = min(self.lead_max, self.lead + self.lead_up)
        elif not first:  # caught while polling: its arrival is known to a poll's time
            self.lead = max(self.lead_min, self.lead - self.lead_down)
        self.last_arrival = t_poll  # (when it was already waiting: an upper bound)
        return self._triggered(item, t_poll)

    def _wait_blocking(self, watchdog: float) -> float:
        """:meth:`wait` with ``block``: poll, block until signalled or the watchdog, poll again."""
        clock, block = self._clock, self._block
        assert block is not None
        t_poll = clock()
        while (item := self._poll()) is None:
            now = clock()
            if now >= watchdog:
                return self._watchdog_tick(now)
            block(watchdog - now)
            t_poll = clock()
        self.last_arrival = t_poll
        return self._triggered(item, t_poll)

    def _watchdog_tick(self, now: float) -> float:
        """No state for ``wait_periods``: the watchdog tick (the prediction path) starts ``now``."""
        self.watchdog_ticks += 1
        self.deadline_misses += 1
        self.trigger_time = self.tick_start = now
        return now

    def _triggered(self, item: T, t_poll: float) -> float:
        """A state's tick: it starts at ``t_poll`` (the poll that returned ``item``), or once
        ``min_gap`` has passed since the previous tick's start (held; the newest state kept)."""
        clock = self._clock
        self.trigger_time = t_poll
        earliest = self.tick_start + self.min_gap
        while (now := clock()) < earliest:  # faster than the loop's rate: held, the newest kept
            if self._block is not None:
                self._block(earliest - now)
            if (newer := self._poll()) is not None:
                item = newer
        self.item, self.fresh = item, True
        self.tick_start = t_poll if t_poll >= earliest else now
        return self.tick_start
