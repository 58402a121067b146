"""Waiting for a started robot (sim or driver) and daemon to come up, on their own signals.

Each process says it is up with its liveliness token: ``alive/sim`` (the sim, its model built and
its step loop starting; a real robot's driver, connected) and ``alive/daemon`` (the daemon, its
controller built and its loop starting). The stack is ready when the daemon answers with a fresh,
valid state (``status.state_ok``). How long a start takes is the host's business: importing the
stack, building a MuJoCo model from the robot description and the daemon's collision rows took
from seconds to more than 25 s on a loaded 2-core machine (docs/results.md §7.4). So the wait
has no tight budget while the processes run, and a clear reason when it gives up:

- a process that exits before it is up is reported at once, with its exit status and the last
  line of its log (:meth:`~.processes.Stack.exited`);
- a start that has not finished after ``start_timeout`` (both processes still running, a token
  missing) is reported naming the missing one;
- once both are up, a daemon that has had no valid state for ``state_timeout`` is reported with
  its last fault.

Each is a :class:`NotReady` whose message is the reason, for the verdict line.
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


class NotReady(WmmQpError):
    """The stack did not come up; the message says which process and why."""


class Peer(Protocol):
    """What the wait needs of a client (:class:`~.client.Client`)."""

    def alive(self, timeout: float = 1.0) -> list[str]: ...

    def info(self, timeout: float = 2.0) -> InfoMsg | None: ...


def wait_ready(client: Peer, exited: Callable[[], str | None], *, start_timeout: float = START_TIMEOUT,
               state_timeout: float = STATE_TIMEOUT, say: Callable[[str], None] | None = None,
               clock: Callable[[], float] = time.monotonic,
               sleep: Callable[[float], None] = time.sleep) -> InfoMsg:
    """Wait until both processes are up and the daemon has a valid state.

    Args:
        client: a client of the robot's keys.
        exited: the reason a started process is gone (None: all run), e.g. ``Stack.exited``.
        start_timeout: [s] the longest wait for both liveliness tokens.
        state_timeout: [s] the longest wait for ``state_ok`` once both are up.
        say: progress (what is being waited for), at most a few times a second.
        clock, sleep: [s] monotonic time and sleeping (tests pass fakes).

    Returns:
        the daemon's info with ``state_ok``.

    Raises:
        NotReady: a process exited, did not come up, or the daemon had no valid state.
    """
    t0 = clock()
    up_at: float | None = None
    last: InfoMsg | None = None
    while True:
        if (why := exited()) is not None:
            raise NotReady(why)
        names = client.alive(0.5)
        missing = [n for n in ("sim", "daemon") if n not in names]
        now = clock()
        if missing:
            up_at = None
            who = " and the ".join(missing)
            if now - t0 > start_timeout:
                raise NotReady(f"the {who} did not come up within {start_timeout:g} s (still running)")
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
        if now - up_at > state_timeout:
            if last is None:
                detail = "it did not answer"
            else:
                detail = f"last fault: {last.status.last_fault}" if last.status.last_fault else "no fault reported"
            raise NotReady(f"the sim and the daemon are up, but the daemon had no valid state for "
                           f"{state_timeout:g} s ({detail})")
        if say is not None:
            say(f"waiting for the daemon's first valid state ({now - up_at:.0f} s)")
        sleep(0.1)
