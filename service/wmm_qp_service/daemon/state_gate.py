"""The state gate: one robot under one id, its states in order.

The first state latches the robot's instance (the sim draws one at start, a driver its own). A
state of another instance while the latched one is alive is a second robot on the key: refused,
counted (``refused.instance``) and reported (:func:`~.watchdog.hazard`: a safe stop while it
lasts); once the latched instance has been silent for ``state_timeout`` a new instance is a
restarted robot and is latched instead, unless a twin was ever seen. A state whose seq does not
increase (a replay, or reordering), or jumps further than :data:`SEQ_JUMP_MAX`, is refused
(``refused.state_seq``).
"""

from __future__ import annotations

import math
from collections import Counter
from enum import Enum

SEQ_JUMP_MAX = 100_000
"""A state seq further ahead of the last one than this is refused (a sim steps at ~1 kHz)."""


class Latch(Enum):
    """What :meth:`StateGate.latch` made of a state's instance."""

    SAME = "same"  # the latched instance
    NEW = "new"  # latched now: the first robot, or a restarted one (``StateGate.previous`` names the old one)
    REFUSED = "refused"  # a second robot on the key


class StateGate:
    """The latched instance and the last accepted seq.

    Args:
        state_timeout: [s] how long the latched instance must be silent before another one is
            taken for a restarted robot.
        refused: where refusals are counted (shared with the daemon's other checks).

    Attributes:
        instance: the latched instance ("" before the first state).
        previous: the instance latched before the current one ("" when none).
        foreign: the last second instance seen, at ``foreign_time`` [s] (-inf: never).
        twin_seen: a second instance was seen: never latch another one by itself.
        last_seq: the last accepted state's seq (-1: none from this instance yet).
    """

    def __init__(self, state_timeout: float, refused: Counter[str]) -> None:
        self.state_timeout = state_timeout
        self.refused = refused
        self.instance = ""
        self.previous = ""
        self.foreign = ""
        self.foreign_time = -math.inf
        self.twin_seen = False
        self.last_seq = -1

    def latch(self, instance: str, now: float, state_time: float) -> Latch:
        """The state of ``instance`` arrived at ``now`` [s]; the latched one's last valid state
        arrived at ``state_time`` [s]."""
        if instance == self.instance:
            return Latch.SAME
        if self.instance and (self.twin_seen or now - state_time <= self.state_timeout):
            self.refused["instance"] += 1
            self.foreign, self.foreign_time = instance, now
            self.twin_seen = True
            return Latch.REFUSED
        self.previous, self.instance = self.instance, instance
        self.last_seq = -1
        return Latch.NEW

    def next_seq(self, seq: int) -> bool:
        """Accept ``seq`` when it follows the last one (counted as refused when it does not)."""
        if seq <= self.last_seq or (self.last_seq >= 0 and seq > self.last_seq + SEQ_JUMP_MAX):
            self.refused["state_seq"] += 1  # old (replayed, reordered), or a forged jump ahead
            return False
        self.last_seq = seq
        return True
