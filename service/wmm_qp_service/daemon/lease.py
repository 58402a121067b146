"""The control lease: one daemon per robot.

The daemon holds the robot's lease as a liveliness token ``<robot>/lease/<id>``. At start it
refuses (:class:`LeaseHeld`) or waits (``--wait-lease``) while another daemon's token is alive
(:func:`acquire`); two daemons that started together both find none, and the robot applies
the commands of one of them (its ``state.lease``): the other sees that for
:attr:`~.loop.Daemon.LEASE_GRACE` and leaves (:class:`LeaseRace`).
"""

from __future__ import annotations

import math
import sys
import threading

import zenoh

from ..keys import Keys
from .core import ControlCore


class LeaseHeld(Exception):
    """Another daemon holds the robot's control lease.

    Attributes:
        robot: ``<prefix>/<robot>``.
        holder: the holder's id.
    """

    def __init__(self, robot: str, holder: str) -> None:
        self.robot = robot
        self.holder = holder
        super().__init__(f"robot {robot} is already controlled by daemon {holder} "
                         f"(its lease token {robot}/lease/{holder} is alive); stop that daemon first, "
                         f"or start this one with --wait-lease to take over when it ends")


def holders(session: zenoh.Session, keys: Keys, own: str) -> list[str]:
    """The lease holders alive now other than ``own`` (liveliness query)."""
    out = []
    for reply in session.liveliness().get(keys.lease_all, timeout=0.5):
        if reply.ok is not None:
            out.append(str(reply.ok.key_expr).rsplit("/", 1)[-1])
    return [h for h in out if h != own]


def acquire(session: zenoh.Session, keys: Keys, own: str, wait: bool, stop: threading.Event) -> bool:
    """Refuse (or, with ``wait``, wait) while another daemon holds the lease.

    Returns:
        False: stopped while waiting.

    Raises:
        LeaseHeld: another daemon holds it and ``wait`` is off.
    """
    said = False
    while (held := holders(session, keys, own)):
        if not wait:
            raise LeaseHeld(keys.root, held[0])
        if not said:
            print(f"wmm-qp serve: waiting: robot {keys.root} is controlled by daemon {held[0]}",
                  file=sys.stderr, flush=True)
            said = True
        if stop.wait(0.2):
            return False
    return True


class LeaseRace:
    """A start-up race for the lease, watched on each accepted state.

    Args:
        grace: [s] the robot may name another holder this long (tokens propagate) before this
            daemon concludes that it lost.
        wait: the daemon waits for the lease (``--wait-lease``): it never leaves.

    Attributes:
        lost: the winner's id once the race is lost ("" until then).
    """

    def __init__(self, grace: float, wait: bool) -> None:
        self.grace = grace
        self.wait = wait
        self.since = math.inf  # [s] since when the robot names another holder
        self.lost = ""

    def lost_to(self, core: ControlCore, now: float) -> bool:
        """After an accepted state at ``now`` [s]: True when the race is lost (leave the loop)."""
        if core.lease_taken:
            self.since = min(self.since, now)
            if now - self.since > self.grace and not self.wait:
                self.lost = core.lease_holder  # a start-up race, lost
                return True
        else:
            self.since = math.inf
        return False
