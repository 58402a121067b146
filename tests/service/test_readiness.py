"""Waiting for a started stack (``wmm_qp_service.readiness``): with a fake clock and a scripted
peer (no processes, no timing), and ``Stack.exited`` on a real process that fails at start."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import pytest
from wmm_qp_service.processes import Stack, isolated_config
from wmm_qp_service.protocol import InfoMsg, StatusMsg
from wmm_qp_service.readiness import START_TIMEOUT, STATE_TIMEOUT, NotReady, wait_ready


class Clock:
    """[s] fake monotonic time, advanced only by sleeping."""

    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t

    def sleep(self, s: float) -> None:
        self.t += s


class Peer:
    """The sim's and the daemon's tokens appear at scripted times; the daemon's state is valid from
    ``state_at`` on; every ``lose``-th info query gets no answer (a reply lost on a loaded host)."""

    def __init__(self, clock: Clock, sim_at: float, daemon_at: float, state_at: float, lose: int = 0,
                 fault: str = "") -> None:
        self.clock, self.sim_at, self.daemon_at, self.state_at = clock, sim_at, daemon_at, state_at
        self.lose, self.fault, self.queries = lose, fault, 0

    def alive(self, timeout: float = 1.0) -> list[str]:
        t = self.clock()
        return [n for n, at in (("daemon", self.daemon_at), ("robot", self.sim_at)) if t >= at]

    def info(self, timeout: float = 2.0) -> InfoMsg | None:
        self.queries += 1
        if self.lose and self.queries % self.lose == 0:
            return None
        ok = self.clock() >= self.state_at
        return InfoMsg(robot="r", status=StatusMsg(robot="r", mode="hold", state_ok=ok, safe_stop=not ok,
                                                  last_fault=self.fault))


def wait(peer: Peer, clock: Clock, exited: object = lambda: None) -> InfoMsg:
    return wait_ready(peer, exited, clock=clock, sleep=clock.sleep)  # type: ignore[arg-type]


def test_a_slow_start_is_waited_for_while_the_processes_run() -> None:
    """The daemon's first answer after 120 s (a loaded host): no fixed 90 s budget ends it."""
    clock = Clock()
    info = wait(Peer(clock, sim_at=100.0, daemon_at=120.0, state_at=125.0), clock)
    assert info.status.state_ok and 125.0 <= clock.t < 126.0


def test_a_lost_info_reply_does_not_end_the_wait() -> None:
    clock = Clock()
    peer = Peer(clock, sim_at=1.0, daemon_at=2.0, state_at=20.0, lose=2)  # every other query unanswered
    assert wait(peer, clock).status.state_ok and clock.t >= 20.0


def test_a_process_that_exits_is_named_at_once() -> None:
    clock = Clock()
    peer = Peer(clock, sim_at=1e9, daemon_at=2.0, state_at=1e9)
    exited = lambda: "the sim exited with status 1 (sim.log: boom)" if clock.t >= 5.0 else None  # noqa: E731
    with pytest.raises(NotReady, match=r"^the sim exited with status 1 \(sim.log: boom\)$"):
        wait(peer, clock, exited)
    assert clock.t < 6.0


def test_a_start_that_never_ends_names_the_missing_process() -> None:
    clock = Clock()
    with pytest.raises(NotReady, match=rf"^the robot did not come up within {START_TIMEOUT:g} s \(still running\)$"):
        wait(Peer(clock, sim_at=1e9, daemon_at=3.0, state_at=1e9), clock)
    assert START_TIMEOUT <= clock.t < START_TIMEOUT + 1.0


def test_up_without_a_valid_state_says_the_daemons_last_fault() -> None:
    clock = Clock()
    peer = Peer(clock, sim_at=1.0, daemon_at=2.0, state_at=1e9, fault="command stream broken (44 ms)")
    with pytest.raises(NotReady, match=r"no valid state for 30 s \(last fault: command stream broken \(44 ms\)\)"):
        wait(peer, clock)
    assert 2.0 + STATE_TIMEOUT <= clock.t < 2.0 + STATE_TIMEOUT + 1.0


@pytest.mark.integration
def test_stack_exited_names_the_process_its_status_and_its_last_log_line(tmp_path: Path) -> None:
    stack = Stack(isolated_config(), log_dir=tmp_path, extra_sim_args=["--physics", "bullet"])
    try:
        assert stack.exited() is None  # nothing started
        p = stack.start_sim()
        p.wait(timeout=120)
        why = stack.exited()
    finally:
        stack.stop()
    assert why is not None and why.startswith("the sim exited with status 2 (sim.log: ")
    assert "bullet" in why and "Traceback" not in why and sys.executable not in why


def test_exited_is_none_while_every_process_runs(tmp_path: Path) -> None:
    stack = Stack(isolated_config(), log_dir=tmp_path)
    stack.procs["sim"] = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    try:
        time.sleep(0.1)
        assert stack.exited() is None
    finally:
        stack.kill("sim")
