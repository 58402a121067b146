"""The stream rules of every robot's firmware, once: the simulated robot (``wmm_qp_sim.robot``)
and the command shaper of a robot that needs one (:mod:`.shaper`, the FR3) both are a
:class:`StreamRules`, and differ only in how they execute what the rules let through (the sim's
plant, ramped or not; the shaper's jerk-limited tracker) and in what they check the executed
motion against.

A **stream** is the commands of one sender's stream (its key: e.g. (lease, stream id)). The rules
(docs/protocol.md, "The robot's firmware"):

- **an illegal command** (past a velocity limit, non-finite; whatever the state) is refused and
  is a protective stop, whatever stream it belongs to; the stop is its stream's (unless another
  stop is under way, the robot still moving or the command of the stream that stop ended);
- **a stop ends its stream**: a stale stop (no command within the stale timeout) or a protective
  stop; later commands of that stream (late on the way, or from a sender that froze) are not
  applied and are counted in ``ended``, not in ``refused``: the stop was the event, not each of them;
- **after a protective stop** every command is refused while the robot still moves; at rest, the
  first legal command of a **new** stream releases the stop and is followed;
- **after a stale stop** a new stream resumes at once (the jump from the braked rates is the
  executor's to ramp, or the referee's to judge).

Pure: no clock, no transport, no limits of its own — the caller says whether a command is
illegal and whether the robot is at rest.
"""

from __future__ import annotations

from collections.abc import Hashable
from enum import Enum

from wmm_qp.fault_codes import FaultCode


class Verdict(Enum):
    """What the rules made of a received command."""

    FOLLOW = "follow"  # the new target
    RESUME = "resume"  # the new target, and the protective stop it released is over
    REFUSED = "refused"  # illegal: a protective stop (counted in ``refused``)
    BRAKING = "braking"  # a new stream while a protective stop still brakes (``refused``)
    ENDED = "ended"  # a command of the stream a stop ended (``ended``)

    @property
    def followed(self) -> bool:
        return self in (Verdict.FOLLOW, Verdict.RESUME)


class StreamRules:
    """The stream rules' state and counts (module docstring).

    Attributes:
        stale: a stale stop ended the current stream.
        protective: a protective stop is under way (until a new stream at rest releases it).
        protective_stops: protective stops so far.
        protective_reason, protective_code: the last protective stop's message and its
            :class:`~wmm_qp.fault_codes.FaultCode` value ("" before the first).
        refused: commands refused (illegal, or a new stream while braking).
        ended: commands of a stream a stop ended.
        stream: the key of the last command received (the stop's, during a stop).
        stopped_stream: the key of the stream the last stop ended.
    """

    def reset_rules(self) -> None:
        """No stop, no stream, counts zeroed."""
        self.stale = False
        self.protective = False
        self.protective_stops = 0
        self.protective_reason = ""
        self.protective_code = ""
        self.refused = 0
        self.ended = 0
        self.stream: Hashable | None = None
        self.stopped_stream: Hashable | None = None

    @property
    def stopped(self) -> bool:
        """A stale or protective stop: the robot brakes to rest."""
        return self.stale or self.protective

    def go_stale(self) -> bool:
        """No command within the stale timeout: a stale stop ends the stream (True when it is
        new; False during a stale stop already)."""
        if self.stale:
            return False
        self.stale = True
        self.stopped_stream = self.stream
        return True

    def protect(self, code: FaultCode, why: str) -> None:
        """A protective stop (counted once until released), with its code and message."""
        if not self.protective:
            self.protective_stops += 1
            self.stopped_stream = self.stream
        self.protective = True
        self.protective_reason = why
        self.protective_code = code.value

    def releases(self, key: Hashable | None, at_rest: bool) -> bool:
        """Whether a legal command of stream ``key`` would release the protective stop now."""
        return self.protective and at_rest and (key is None or key != self.stopped_stream)

    def receive(self, key: Hashable | None, illegal: str | None, at_rest: bool) -> Verdict:
        """Apply the rules to a received command.

        Args:
            key: its stream's key (None: a sender without streams, never ended by a stop).
            illegal: why the command is illegal whatever the state (None: legal).
            at_rest: the robot's executed rates are all 0.
        """
        if illegal is not None:  # first: an illegal command is a fault, any stream's
            self.refused += 1
            if not self.protective or (at_rest and key != self.stopped_stream):  # the stop is now its stream's
                self.stale = False  # (else the stream the stop ended stays the stopped one)
                self.stream = self.stopped_stream = key
            self.protect(FaultCode.REFUSED_COMMAND, f"refused command: {illegal}")
            return Verdict.REFUSED
        if key is not None and (self.stale or self.protective) and key == self.stopped_stream:
            self.ended += 1  # the stop ended this stream: only a new one resumes
            return Verdict.ENDED
        self.stale = False
        self.stream = key
        if self.protective:
            if not at_rest:
                self.refused += 1  # still braking: commands wait until the robot is at rest
                return Verdict.BRAKING
            self.protective = False  # at rest, a legal command of a new stream: resume
            return Verdict.RESUME
        return Verdict.FOLLOW

    def restop(self, key: Hashable | None, code: FaultCode, why: str) -> None:
        """The protective stop under way is now stream ``key``'s, for a new reason (the FR3's
        refused recovery, asked by that stream's first command: its later commands are ended)."""
        self.protect(code, why)
        self.stream = self.stopped_stream = key
