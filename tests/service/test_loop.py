"""Fixed-rate loop: deadline arithmetic and miss counting with a fake clock (no real timing)."""

from __future__ import annotations

import pytest
from wmm_qp_service.rate_loop import RateLoop


class FakeClock:
    def __init__(self) -> None:
        self.t = 100.0
        self.sleeps: list[float] = []

    def __call__(self) -> float:
        self.t += 1e-6  # each read advances a microsecond (so spinning terminates)
        return self.t

    def sleep(self, s: float) -> None:
        self.sleeps.append(s)
        self.t += s


def make(rate: float = 1000.0, spin: float = 200e-6) -> tuple[RateLoop, FakeClock]:
    c = FakeClock()
    loop = RateLoop(rate, spin, clock=c, sleep=c.sleep)
    loop.start()
    return loop, c


def test_ticks_start_on_absolute_deadlines_without_drift() -> None:
    loop, c = make()
    t0 = loop.t0
    for k in range(1, 1001):
        c.t += 300e-6  # work
        start = loop.wait()
        assert start >= t0 + k * 1e-3
        assert start - (t0 + k * 1e-3) < 5e-6  # woke within a few fake µs of the deadline
    assert loop.deadline_misses == 0 and loop.ticks == 1000


def test_sleeps_until_spin_window_then_spins() -> None:
    loop, c = make(rate=500.0, spin=200e-6)
    c.t += 100e-6
    loop.wait()
    assert len(c.sleeps) == 1
    assert c.sleeps[0] == pytest.approx(2e-3 - 100e-6 - 200e-6, abs=5e-6)


def test_overrun_counts_a_miss_and_skips_whole_periods() -> None:
    loop, c = make(rate=1000.0)
    c.t += 3.5e-3  # the work of this tick took 3.5 periods
    loop.wait()
    assert loop.deadline_misses == 1
    assert loop.skipped == 2  # of the ticks due at 1, 2, 3 ms one ran (late), two were skipped
    c.t += 100e-6
    start = loop.wait()
    assert start == pytest.approx(loop.t0 + 4e-3, abs=5e-6)  # back on the absolute grid
    assert loop.deadline_misses == 1


def test_small_overrun_is_one_miss_and_keeps_grid() -> None:
    loop, c = make(rate=1000.0)
    c.t += 1.2e-3
    loop.wait()
    c.t += 100e-6
    start = loop.wait()
    assert loop.deadline_misses == 1 and loop.skipped == 0
    assert start == pytest.approx(loop.t0 + 2e-3, abs=5e-6)


def test_a_rephased_loop_never_starts_two_ticks_closer_than_a_period() -> None:
    """After late ticks (a fraction of a period late, and periods late), a ``rephase`` loop's next
    tick comes a whole period after the late one; the absolute grid's came sooner (0.5 ms and
    0.2 ms after it here), and a command stepped by a period's worth each tick changed faster."""
    for rephase in (True, False):
        c = FakeClock()
        loop = RateLoop(1000.0, 200e-6, clock=c, sleep=c.sleep, rephase=rephase)
        start = loop.start()
        gaps = []
        for work in (300e-6, 1.5e-3, 100e-6, 3.8e-3, 100e-6, 100e-6, 1.05e-3, 100e-6):
            c.t += work
            nxt = loop.wait()
            gaps.append(nxt - start)
            start = nxt
        if rephase:
            assert min(gaps) >= 1e-3 - 5e-6, gaps
            assert loop.deadline_misses == 3 and loop.skipped == 2
        else:
            assert min(gaps) < 0.6e-3, gaps  # the attack: on the grid, ticks bunch after a late one


def test_stats_percentiles_and_max() -> None:
    loop, c = make(rate=100.0)
    for k in range(100):
        c.t += (k + 1) * 1e-5  # 10 µs ... 1000 µs
        loop.wait()
    s = loop.stats()
    assert s.ticks == 100 and s.deadline_misses == 0
    assert s.tick_p50_us == pytest.approx(505, abs=10)
    assert s.tick_max_us == pytest.approx(1000, abs=5)
    assert s.tick_p99_us <= s.tick_max_us


def test_rate_must_be_positive() -> None:
    with pytest.raises(ValueError):
        RateLoop(0.0)
