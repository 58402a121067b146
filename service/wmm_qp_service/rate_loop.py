"""Fixed-rate loop timing: absolute deadlines, sleep then spin, overruns counted.

The clock and the sleep are injected so the deadline arithmetic is testable with a fake
clock (tests never depend on real timing).
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable

import numpy as np

from .protocol import LoopStats


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


class RateLoop:
    """Paces a loop at a fixed period with absolute deadlines.

    Tick k is due at ``t0 + k·period``. :meth:`wait` sleeps until ``spin`` before the next
    deadline, then spins on the clock. A tick that starts after its deadline (the previous
    tick's work overran) is a deadline miss; when the loop has fallen more than a whole
    period behind, the missed deadlines are skipped (counted, never run in a burst).

    Args:
        rate_hz: [Hz] loop rate.
        spin_s: [s] spin this long before each deadline instead of sleeping.
        clock: monotonic clock [s].
        sleep: sleep function [s].
        window: number of recent tick times kept for the percentiles.
    """

    def __init__(self, rate_hz: float, spin_s: float = 200e-6,
                 clock: Callable[[], float] = time.perf_counter,
                 sleep: Callable[[float], None] = time.sleep, window: int = 2048) -> None:
        if not rate_hz > 0:
            raise ValueError("rate_hz must be > 0")
        self.rate_hz = float(rate_hz)
        self.period = 1.0 / self.rate_hz
        self.spin_s = spin_s
        self._clock = clock
        self._sleep = sleep
        self._times = np.zeros(window)
        self._n = 0
        self.ticks = 0
        self.deadline_misses = 0
        self.skipped = 0
        self.tick_max = 0.0
        self.t0 = clock()
        self.deadline = self.t0
        self.tick_start = self.t0

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
            behind = int((now - self.deadline) // self.period)
            if behind > 0:  # more than a whole period late: skip, do not burst
                self.skipped += behind
                self.deadline += behind * self.period
            self.tick_start = now
            return now
        remaining = self.deadline - now
        if remaining > self.spin_s:
            self._sleep(remaining - self.spin_s)
        while (now := self._clock()) < self.deadline:
            pass
        self.tick_start = now
        return now

    def record(self, work_s: float) -> None:
        """Record one tick's work time [s]."""
        self._times[self._n % self._times.size] = work_s
        self._n += 1
        self.ticks += 1
        self.tick_max = max(self.tick_max, work_s)

    def percentile_us(self, q: float) -> float:
        """[µs] the q-th percentile of the recent tick work times (0 before any tick)."""
        n = min(self._n, self._times.size)
        if n == 0:
            return 0.0
        return float(np.percentile(self._times[:n], q) * 1e6)

    def stats(self) -> LoopStats:
        """The figures the status reports."""
        elapsed = self._clock() - self.t0
        return LoopStats(
            rate_hz=self.rate_hz,
            measured_hz=self.ticks / elapsed if elapsed > 0 else 0.0,
            ticks=self.ticks,
            deadline_misses=self.deadline_misses,
            tick_p50_us=self.percentile_us(50),
            tick_p99_us=self.percentile_us(99),
            tick_max_us=self.tick_max * 1e6,
        )
