"""The robot side of the control lease: which commands a robot (the sim, a driver) obeys.

A command is obeyed only if it is well formed (validated on receipt), comes from the lease holder
(the earliest lease token still alive), is addressed to this robot's instance, and, from that
holder, carries a seq above the last one obeyed. A new holder's stream starts from the robot's
executed rates (the referee's hard break). docs/drivers.md states the contract.
"""

from __future__ import annotations

import secrets
from collections import Counter
from collections.abc import Callable
from typing import Any

from .referee import Referee


class LeaseGate:
    """Lease, instance and seq checks shared by every robot-side process (a mixin).

    Args:
        validate: decodes and validates a command payload (None: rejected).
    """

    def __init__(self, validate: Callable[[bytes], Any]) -> None:
        self.validate: Any = validate  # a Validator (its counts are the rejected commands)
        self.instance = secrets.token_hex(8)
        self.leases: dict[str, None] = {}  # alive lease holders, in the order they appeared
        self._holder = ""  # the holder whose commands were obeyed last
        self._holder_seq = -1  # the last seq obeyed from it
        self.refused: Counter[str] = Counter()

    @property
    def holder(self) -> str:
        """The control lease holder whose commands are obeyed ("" = none)."""
        return next(iter(self.leases), "")

    def on_lease(self, holder: str, alive: bool) -> None:
        """A lease token appeared (alive) or vanished."""
        if alive:
            self.leases.setdefault(holder, None)
        else:
            self.leases.pop(holder, None)

    def admit(self, data: bytes, referee: Referee) -> Any:
        """The validated command if this robot obeys it, else None (counted in :attr:`refused` by
        reason: invalid, lease, instance, seq)."""
        msg = self.validate(data)
        if msg is None:
            self.refused["invalid"] += 1
            return None
        return self.obey(msg, referee)

    def obey(self, msg: Any, referee: Referee) -> Any:
        """A validated command (decoded here, or handed over in memory by a control core in the
        same process) if this robot obeys it, else None (counted in :attr:`refused` by reason:
        lease, instance, seq)."""
        if msg.lease != self.holder:
            self.refused["lease"] += 1
            return None
        if msg.instance != self.instance:
            self.refused["instance"] += 1
            return None
        if msg.lease != self._holder:  # a new holder: its stream starts from the robot's rates
            self._holder, self._holder_seq = msg.lease, -1
            referee.break_stream()
        elif msg.seq <= self._holder_seq:
            self.refused["seq"] += 1  # old or replayed: the holder's seq only increases
            return None
        self._holder_seq = msg.seq
        return msg
