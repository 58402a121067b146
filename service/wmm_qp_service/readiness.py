"""Waiting until a robot (sim or driver) and its daemon are ready: the one wait every caller uses
(:meth:`~.client.Reader.wait_ready` is a call into :func:`wait_ready`).

Each process says it is up with its liveliness token: ``alive/robot`` (the sim, its model built and
its step loop starting; a real robot's driver, connected) and ``alive/daemon`` (the daemon, its
controller built and its loop starting). The stack is ready when the daemon answers with a fresh,
valid state (``status.state_ok``); a reply lost on a loaded host is no verdict, the wait asks again.

Two kinds of caller wait:

- a program that started the processes (``demo``, ``soak``, the realtime experiments, the e2e
  bench) passes ``exited`` (:meth:`~.processes.Stack.exited`). It waits for both tokens, and a
  failure names the process: one that exits before it is up is reported at once, with its exit
  status and the last line of its log; a start that has not finished after ``timeout`` (the
  processes still running, a token missing) names the missing one; once both are up, a daemon
  with no valid state for ``state_timeout`` is reported with its last fault.
- a client of a daemon it did not start passes no ``exited``. It waits for the daemon's token
  (one key: a mistyped robot id costs no query time-outs), and a failure says how long it waited,
  for which robot, and what was missing: the daemon (and which daemons are seen), or a valid state
  from its robot (whether the robot is alive, the last fault).

How long a start takes is the host's business: importing the stack, building a MuJoCo model from
the robot description and the daemon's collision rows took from seconds to more than 25 s on a
loaded 2-core machine (docs/results.md §7.4). So a program that watches its processes can wait long
(:data:`START_TIMEOUT`) while they run. Every failure is a :class:`NotReady`.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Protocol

from wmm_qp.exceptions import WmmQpError

from .protocol import InfoMsg

START_TIMEOUT = 300.0
"""[s] the longest a process may take to come up while it runs (a loaded host, a first start that
compiles the kernels)."""
STATE_TIMEOUT = 30.0
"""[s] the longest the daemon may go without a valid state once both processes are up."""
NODES = ("robot", "daemon")
"""The liveliness tokens of a started stack, waited for when ``exited`` is given."""


class NotReady(WmmQpError):
    """The stack did not come up, or its daemon had no valid state in time; the message says which
    process and why (a client's also how long it waited).

    Attributes:
        reason: what was missing, or the process that exited.
        robot: ``<prefix>/<robot>`` waited for ("" when the caller did not name it).
        info: the daemon's last answer (its status's ``state_ok`` false); None: it never answered.
        waited: [s] how long the wait lasted.
    """

    def __init__(self, message: str, *, reason: str | None = None, robot: str = "", info: InfoMsg | None = None,
                 waited: float = 0.0) -> None:
        self.reason = message if reason is None else reason
        self.robot = robot
        self.info = info
        self.waited = waited
        super().__init__(message)


class Peer(Protocol):
    """What the wait needs of a client (:class:`~.client.Client`)."""

    def alive(self, timeout: float = 1.0) -> list[str]: ...

    def info(self, timeout: float = 2.0) -> InfoMsg | None: ...


def wait_ready(client: Peer, exited: Callable[[], str | None] | None = None, *, timeout: float = START_TIMEOUT,
               state_timeout: float | None = STATE_TIMEOUT, robot: str = "",
               tokens: Callable[[float], list[str]] | None = None, absent: Callable[[], str] | None = None,
               say: Callable[[str], None] | None = None, clock: Callable[[], float] = time.monotonic,
               sleep: Callable[[float], None] = time.sleep) -> InfoMsg:
    """Wait until the processes are up and the daemon has a valid state.

    Args:
        client: a client of the robot's keys.
        exited: the reason a process this program started is gone (None: all run), e.g.
            ``Stack.exited``; then both tokens (:data:`NODES`) are waited for. None: the caller
            started nothing; the daemon's token is waited for.
        timeout: [s] from the call, the longest wait for the tokens.
        state_timeout: [s] from the moment the tokens are all present, the longest wait for
            ``state_ok``; None: until ``timeout`` from the call.
        robot: ``<prefix>/<robot>``, for the messages and :attr:`NotReady.robot`.
        tokens: the names of the live nodes, asked within a timeout [s] (default ``client.alive``;
            a client that waits for its daemon only asks for that one token).
        absent: why the daemon is missing, for a caller that started nothing (e.g.
            :meth:`~.client.Reader.no_daemon_reason`; default: the token that is missing).
        say: progress (what is being waited for), at most a few times a second.
        clock, sleep: [s] monotonic time and sleeping (tests pass fakes).

    Returns:
        the daemon's info with ``state_ok``.

    Raises:
        NotReady: a process exited, did not come up, or the daemon had no valid state.
    """
    started = exited is not None
    nodes = NODES if started else ("daemon",)
    ask = client.alive if tokens is None else tokens
    t0 = clock()
    up_at: float | None = None
    last: InfoMsg | None = None

    def fail(reason: str, waited: float) -> NotReady:
        message = reason if started else f"not ready after {waited:.1f} s: {reason}"
        return NotReady(message, reason=reason, robot=robot, info=last, waited=waited)

    while True:
        if exited is not None and (why := exited()) is not None:
            raise fail(why, clock() - t0)
        names = ask(0.5)
        missing = [n for n in nodes if n not in names]
        now = clock()
        if missing:
            up_at = None
            who = " and the ".join(missing)
            if now - t0 > timeout:
                if started:
                    raise fail(f"the {who} did not come up within {timeout:g} s (still running)", now - t0)
                raise fail(absent() if absent is not None else f"no {who} for robot {robot}", now - t0)
            if say is not None:
                say(f"waiting for the {who} to start ({now - t0:.0f} s)")
            sleep(0.2)
            continue
        if up_at is None:
            up_at = now
        info = client.info(1.0)  # a reply lost on a loaded host is no verdict: ask again
        if info is not None:
            if info.status.state_ok:
                return info
            last = info
        end = t0 + timeout if state_timeout is None else up_at + state_timeout
        if now > end:
            detail = "it did not answer" if last is None else f"last fault: {last.status.last_fault or 'none'}"
            if started:
                lasted = f"{state_timeout:g}" if state_timeout is not None else f"{now - up_at:.0f}"
                raise fail(f"the {' and the '.join(nodes)} are up, but the daemon had no valid state for "
                           f"{lasted} s ({detail})", now - t0)
            alive = "" if last is None else f"robot alive: {'yes' if last.status.robot_alive else 'no'}; "
            raise fail(f"the daemon of robot {robot} has no valid state from its robot ({alive}{detail})", now - t0)
        if say is not None:
            say(f"waiting for the daemon's first valid state ({now - up_at:.0f} s)")
        sleep(0.1)
