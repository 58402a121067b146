"""The state-triggered loop (``loop.trigger = "state"``): its logic with a fake clock and a
scripted state source (no real timing), polling (``lead``) and blocking (``block``, the
daemon's: a Zenoh callback's :class:`Mailbox`); the mailbox itself."""

from __future__ import annotations

import itertools
import threading

import pytest
from support.clocks import FakeClock
from wmm_qp_service.rate_loop import Mailbox, StateLoop

PERIOD = 1e-3


class Source:
    """States that arrive at scripted times; polling returns the newest arrived one (a ring of
    depth 1: an older one not polled in time is overwritten)."""

    def __init__(self, clock: FakeClock, arrivals: list[float]) -> None:
        self.clock = clock
        self.arrivals = sorted(arrivals)
        self.i = 0  # next arrival not yet taken
        self.polls = 0
        self.blocked = 0.0  # [s] fake time spent in block()
        self.blocks = 0

    def block(self, timeout: float) -> bool:
        """The mailbox's wait: the clock jumps to the next arrival, or by ``timeout``."""
        assert timeout >= 0.0
        self.blocks += 1
        t0 = self.clock.t
        nxt = self.arrivals[self.i] if self.i < len(self.arrivals) else float("inf")
        signalled = nxt <= t0 + timeout
        self.clock.t = max(t0, nxt) if signalled else t0 + timeout
        self.blocked += self.clock.t - t0
        return signalled

    def poll(self) -> int | None:
        self.polls += 1
        newest = None
        while self.i < len(self.arrivals) and self.arrivals[self.i] <= self.clock.t:
            newest = self.i
            self.i += 1
        return newest


def make(arrivals: list[float], blocking: bool = False, **kw: float) -> tuple[StateLoop[int], FakeClock, Source]:
    c = FakeClock()
    src = Source(c, [c.t + a for a in arrivals])
    loop: StateLoop[int] = StateLoop(1.0 / PERIOD, src.poll, clock=c, sleep=c.sleep,
                                     block=src.block if blocking else None, **kw)
    loop.start()
    return loop, c, src


def run(loop: StateLoop[int], clock: FakeClock, n: int, work: float = 100e-6) -> list[tuple[float, int | None]]:
    """n ticks of ``work`` each; (tick start, item) per tick."""
    out = []
    for _ in range(n):
        clock.t += work
        start = loop.wait()
        out.append((start, loop.item if loop.fresh else None))
    return out


@pytest.mark.parametrize("blocking", [False, True], ids=["polling", "blocking"])
def test_a_tick_per_state_soon_after_it_arrives(blocking: bool) -> None:
    arrivals = [0.3e-3 + k * PERIOD + (20e-6 if k % 3 else 0.0) for k in range(200)]  # jitter
    loop, c, src = make(arrivals, blocking)
    ticks = run(loop, c, 200)
    assert [item for _, item in ticks] == list(range(200))  # each state once, in order, none lost
    late = [start - src.arrivals[item] for start, item in ticks[20:] if item is not None]
    assert max(late) < 10e-6  # caught while polling: within a few fake reads of its arrival
    assert loop.watchdog_ticks == 0 and loop.deadline_misses == 0
    if blocking:  # it waited in block() most of the time, neither slept nor spun
        assert c.slept == 0.0 and src.blocked > 0.5 * (c.t - loop.t0)
        assert src.polls <= 2 * 200 + 1  # a poll before the wait and one after each wake
    else:
        assert c.slept > 0.5 * (c.t - loop.t0)  # it slept most of the time (polls only near arrivals)


@pytest.mark.parametrize("blocking", [False, True], ids=["polling", "blocking"])
def test_a_lost_state_gives_one_watchdog_tick_at_wait_periods(blocking: bool) -> None:
    arrivals = [k * PERIOD + 0.2e-3 for k in range(10) if k != 5]
    loop, c, src = make(arrivals, blocking=blocking)
    ticks = run(loop, c, 11)
    items = [item for _, item in ticks]
    assert items == [0, 1, 2, 3, 4, None, 5, 6, 7, 8, None]  # (the last: the states ended)
    wd_start = ticks[5][0]
    assert wd_start - src.arrivals[4] == pytest.approx(1.5 * PERIOD, abs=10e-6)
    assert loop.watchdog_ticks == 2 and loop.deadline_misses == 2  # a watchdog tick is a miss


@pytest.mark.parametrize("blocking", [False, True], ids=["polling", "blocking"])
def test_no_state_at_all_ticks_at_the_watchdog_rate(blocking: bool) -> None:
    loop, c, _ = make([], blocking=blocking)
    ticks = run(loop, c, 20)
    assert all(item is None for _, item in ticks)
    gaps = [b[0] - a[0] for a, b in itertools.pairwise(ticks)]
    assert all(g == pytest.approx(1.5 * PERIOD, abs=10e-6) for g in gaps)
    assert loop.watchdog_ticks == 20


def test_a_state_that_came_while_sleeping_widens_the_lead() -> None:
    # states on a 1 ms grid, then the grid jumps 0.4 ms earlier: the next one is already there
    arrivals = [k * PERIOD + 0.5e-3 for k in range(10)] + [k * PERIOD + 0.1e-3 for k in range(10, 30)]
    loop, c, _ = make(arrivals)
    run(loop, c, 10)
    lead0, early0 = loop.lead, loop.early
    ticks = run(loop, c, 20)
    assert [item for _, item in ticks] == list(range(10, 30))  # none lost
    assert loop.early > early0
    assert loop.lead > lead0


def test_the_lead_narrows_while_states_come_on_time() -> None:
    loop, c, _ = make([k * PERIOD + 0.3e-3 for k in range(300)])
    lead0 = loop.lead
    run(loop, c, 300)
    assert loop.lead < lead0 and loop.lead >= loop.lead_min


@pytest.mark.parametrize("blocking", [False, True], ids=["polling", "blocking"])
def test_states_faster_than_the_rate_are_held_to_the_minimum_gap(blocking: bool) -> None:
    # states every 0.2 ms against a 1 kHz loop: ticks no closer than min_gap, the newest taken
    loop, c, _ = make([k * 0.2e-3 for k in range(100)], min_gap_periods=0.5, blocking=blocking)
    ticks = run(loop, c, 30, work=20e-6)
    starts = [s for s, _ in ticks]
    assert all(b - a >= 0.5 * PERIOD - 1e-9 for a, b in itertools.pairwise(starts))
    items = [i for _, i in ticks]
    assert all(i is not None for i in items) and items == sorted(items)
    assert len(set(items)) == len(items)


@pytest.mark.parametrize("blocking", [False, True], ids=["polling", "blocking"])
def test_a_tick_whose_work_overruns_the_period_is_a_miss(blocking: bool) -> None:
    loop, c, _ = make([k * PERIOD + 0.1e-3 for k in range(10)], blocking=blocking)
    run(loop, c, 3)
    c.t += 1.3 * PERIOD  # this tick's work: its command misses the robot's next cycle
    loop.wait()
    assert loop.overruns == 1 and loop.deadline_misses >= 1
    assert loop.fresh  # the newest state is taken at once (the one in between was overwritten)


def test_a_long_wait_naps_instead_of_spinning() -> None:
    loop, c, src = make([0.1e-3], spin_max=50e-6)
    run(loop, c, 1)
    polls = src.polls
    run(loop, c, 1)  # no state: the watchdog after 1.5 periods
    assert src.polls - polls < 150  # polling the whole 1.5 ms (2 fake µs a poll) would be ~700


@pytest.mark.parametrize("kw", [{"wait_periods": 1.0}, {"min_gap_periods": 1.0}, {"min_gap_periods": -0.1}])
def test_bad_parameters_are_refused(kw: dict[str, float]) -> None:
    with pytest.raises(ValueError):
        StateLoop(1000.0, lambda: None, **kw)


@pytest.mark.parametrize("blocking", [False, True], ids=["polling", "blocking"])
def test_stats_report_the_trigger_figures(blocking: bool) -> None:
    loop, c, _ = make([k * PERIOD + 0.2e-3 for k in range(5)], blocking=blocking)
    run(loop, c, 7)
    s = loop.stats()
    assert s.ticks == 7 and s.deadline_misses == loop.watchdog_ticks == 2
    assert 0.0 < s.tick_p50_us <= s.tick_p99_us <= s.tick_max_us


def test_a_blocking_wait_for_a_lost_state_wakes_only_at_the_watchdog() -> None:
    loop, c, src = make([0.1e-3], blocking=True)
    run(loop, c, 1)
    polls, blocks = src.polls, src.blocks
    run(loop, c, 1)  # no state: one wait until the watchdog, nothing in between
    assert not loop.fresh and loop.watchdog_ticks == 1
    assert src.blocks - blocks == 1 and src.polls - polls == 2


def test_the_mailbox_keeps_the_newest_and_signals_each_put() -> None:
    box: Mailbox[int] = Mailbox()
    assert box.take() is None and not box.wait(0.0)  # nothing yet: no signal
    box.put(1)
    box.put(2)  # the older one, not taken, is dropped (a ring of depth 1)
    assert box.wait(0.0) and box.take() == 2 and box.take() is None
    assert not box.wait(0.0)  # the signal was consumed by the wait
    assert box.put_count == 2


def test_a_put_from_another_thread_wakes_the_waiter() -> None:
    box: Mailbox[str] = Mailbox()
    started = threading.Event()

    def producer() -> None:
        started.wait()
        box.put("state")

    t = threading.Thread(target=producer)
    t.start()
    started.set()
    assert box.wait(30.0)  # returns at the put (30 s: only a guard against a hang)
    t.join()
    assert box.take() == "state"
