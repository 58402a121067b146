"""The command stream: what the daemon sent, and what the robot's states say of it.

Commands are numbered (``seq``) and their publication times kept in a ring; a state names the
last command the robot applied (``cmd_seq``), so its age is bounded by the time since that
command was sent, without shared clocks. The median bound over :data:`~.watchdog.ROUND_TRIPS`
states is the round trip the watchdog checks; with the state trigger the worst one sets bounds
(13)'s latency margin (``follow_state_age``).

A stream is the commands since the robot last followed them from rest: it breaks when the robot
stops by itself (:meth:`CommandStream.left`) or when the lease is lost. This daemon's own stall
past the robot's command timeout (:meth:`CommandStream.late`) does not break it: the stream is
kept and braked to rest (:meth:`CommandStream.stall`, :meth:`CommandStream.braked`), since its
commands may still be on the way and every braking command is a legal continuation of them,
whatever the robot did meanwhile. While it holds, the controller's acceleration bounds start from
the last command (:meth:`CommandStream.anchored`: what the robot executes next), and a tick
without a new state predicts one (:func:`predicted`).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

import wmm_qp as w

from ..config import WatchdogConfig
from ..protocol import StateMsg
from .watchdog import ROUND_TRIPS

SENT = 1024
"""Publication times kept per command seq (a ring)."""


class CommandStream:
    """The sent ring, the state-age window and the stream's state: a state machine that owns its
    seq and its states, changed only through its methods.

    States: **following** (the robot applies the stream's commands: ``anchor_on_command``, the
    bounds start from the last command), **unconfirmed** (a stream began, no state named one of
    its commands yet: ``not confirmed``), **braking** (this daemon stalled: ``stalled``, braked to
    rest in the same stream), **broken** (the robot stopped following it: ``broken``, nothing is
    sent until it rests). The daemon's core asks it (:meth:`late`, :meth:`left`, :meth:`braked`)
    and tells it what happened (:meth:`begin`, :meth:`numbered`, :meth:`sent`, :meth:`stall`,
    :meth:`break_off`, :meth:`rejoin`, :meth:`braked_to_rest`, :meth:`safe_stop_sent`, …).

    Args:
        wd: the watchdog's limits (the robot's command timeout is ``command_hold − state_age_max``).
        base_latency: [s] bounds (13)'s latency margin when no age is measured: the worst the
            watchdog allows.
        set_latency: hands a new margin to the controller (``Controller.set_latency``).

    Attributes:
        seq: the last command's seq (0: none yet); the sender numbers each command ``seq + 1``.
        round_trip: [s] the median state-age bound (NaN until the window is full).
        latency: [s] the margin the controller uses now.
        follow_state_age: the margin follows the measured age (the state trigger).
        broken: the robot no longer follows this stream (nothing is sent until it rests).
        start: the seq of the current stream's first command.
        confirmed: a state showed the robot applied a command of the current stream (until then
            the daemon sends the stream's first command again: :meth:`begin`).
        began: [s] when the current stream's first command was computed.
        anchor_on_command: the robot follows the stream: the bounds start from the last command.
        cmd_state_seq: seq of the state this tick's command comes from (-1: predicted).
        inherited_cmd_seq: the last command the robot applied before this daemon drove it (a
            restarted daemon): not of this daemon's stream, until the robot applies one of
            this daemon's (-1: none).
        stalled: why the stream is being braked after this daemon's own stall ("": it is not).
        rest_seq: the seq of the braked stream's first command at rest (0: not sent yet).
    """

    def __init__(self, wd: WatchdogConfig, base_latency: float, set_latency: Callable[[float], None]) -> None:
        self.seq = 0
        self._sent_t = np.full(SENT, -math.inf)
        self._sent_seq = np.full(SENT, -1, dtype=np.int64)
        self._age = [math.nan] * ROUND_TRIPS  # per-state upper bounds of the age [s]
        self._n_age = 0
        self.round_trip = math.nan
        # bounds (13)'s latency margin: the robot's own command timeout plus the state's age
        # (command_hold = timeout + state_age_max, the worst the watchdog allows)
        self.follow_state_age = False
        self.state_age_max = wd.state_age_max
        self.command_timeout = wd.command_hold - wd.state_age_max
        self.base_latency = base_latency
        self.latency = base_latency
        self._set_latency = set_latency
        # [s] a gap in the commands this long counts as a break: inside the robot's command
        # timeout (command_hold − state_age_max). A stop the robot makes on its own (a gap that
        # jitter stretched past its timeout) shows in its state and breaks the stream too.
        self.stream_break = 0.8 * (wd.command_hold - wd.state_age_max)
        self.last_sent_t = -math.inf
        self.broken = False
        self.start = 0
        self.confirmed = False
        self.began = -math.inf
        self.unconfirmed_said = False  # the fault of a stream left unconfirmed was said
        self.anchor_on_command = False
        self.cmd_state_seq = -1
        self.inherited_cmd_seq = -1
        self.stalled = ""
        self.rest_seq = 0
        self._anchor: w.RobotState | None = None  # the anchored state handed to the controller

    def numbered(self) -> int:
        """The seq of the command about to go out (the stream numbers its commands)."""
        self.seq += 1
        return self.seq

    def follow(self) -> None:
        """A command computed from the robot's state (or a safe stop) went out: the robot follows
        the stream, the next bounds start from that command."""
        self.anchor_on_command = True

    def withdraw(self, anchored: bool) -> None:
        """The command just computed was not sent: the anchoring is the last sent one's."""
        self.anchor_on_command = anchored

    def safe_stop_sent(self, now: float, at_rest: bool) -> None:
        """A safe-stop command goes out at ``now`` [s] (``at_rest``: all its rates are zero): an
        unconfirmed stream's wait counts from the stop's end; a braked stream's first command at
        rest is the one whose application ends the braking (:meth:`braked`)."""
        if not self.confirmed:
            self.began = now
        if self.stalled and not self.rest_seq and at_rest:
            self.rest_seq = self.seq + 1

    def unconfirmed_too_long(self, now: float, wait: float, fresh: bool) -> bool:
        """No state named one of this stream's commands for ``wait`` [s] (``fresh``: a new state
        came): True once per stream, to say it."""
        if now - self.began > wait and fresh and not self.unconfirmed_said:
            self.unconfirmed_said = True
            return True
        return False

    def computed_from(self, state_seq: int) -> None:
        """This tick's command comes from state ``state_seq`` (-1: a predicted or repeated one)."""
        self.cmd_state_seq = state_seq

    def rejoin(self) -> None:
        """The robot rests in its own stop after a break: a new stream may start, from its
        measured rates."""
        self.broken = False
        self.anchor_on_command = False

    def braked_to_rest(self) -> None:
        """The braked stream reached the robot at rest (:meth:`braked`): it goes on."""
        self.stalled = ""

    def sent(self, seq: int, now: float) -> None:
        """Command ``seq`` was published at ``now`` [s] (for the round trip and the stream)."""
        self._sent_t[seq % SENT] = now
        self._sent_seq[seq % SENT] = seq
        self.last_sent_t = now

    def late(self, now: float) -> bool:
        """More than the robot's command timeout since the last command was published."""
        return math.isfinite(self.last_sent_t) and now - self.last_sent_t > self.stream_break

    def new_robot(self, cmd_seq: int) -> None:
        """A new robot instance was latched; ``cmd_seq``: the last command it applied (another
        daemon's, or -1): its rates are what it executes, its ages start anew."""
        self.inherited_cmd_seq = cmd_seq
        self.anchor_on_command = False
        self.stalled = ""  # the braked stream's commands name the old instance: it refuses them
        self.reset_age()

    def begin(self, now: float) -> None:
        """The next command starts a stream (the referee's baseline: the robot's executed rates).

        Until a state shows the robot applied one of its commands (:attr:`confirmed`), the
        daemon sends this first command again instead of going on from it. Commands can be lost
        on the way (a starved transmit thread drops them): a stream that went on, A·Δt per
        command, would reach a robot that received none of the first ones as a jump from its
        rates. Every repeat is a legal first command, and a legal successor of itself.
        """
        self.start = self.seq + 1  # the seq the sender gives it
        self.confirmed = False
        self.began = now
        self.unconfirmed_said = False

    def applied(self, msg: StateMsg) -> None:
        """An accepted state: once it names another command than the inherited one, the robot
        applied one of this daemon's; once it names one of the current stream's, the stream
        is :attr:`confirmed`."""
        if msg.cmd_seq != self.inherited_cmd_seq:
            self.inherited_cmd_seq = -1
        cs = msg.cmd_seq
        if (not self.confirmed and 0 < self.start <= cs <= self.seq and cs != self.inherited_cmd_seq
                and self._sent_seq[cs % SENT] == cs):  # one this daemon sent (not a restarted one's)
            self.confirmed = True

    def observe(self, msg: StateMsg, now: float) -> None:
        """An accepted state arrived at ``now`` [s]: if it applied a command of this stream, its
        age is at most the time since that command was published. Not while the stream is broken:
        the robot brakes by itself meanwhile, still naming the last command it applied, and the
        time since that one says nothing of the link (it would fill the window with the stop's
        length and fault the next stream as "state too old")."""
        if self.broken:
            return
        cs = msg.cmd_seq
        if cs >= max(0, self.start) and self._sent_seq[cs % SENT] == cs:  # this stream's only
            self._age[self._n_age % ROUND_TRIPS] = now - float(self._sent_t[cs % SENT])
            self._n_age += 1
            if self._n_age >= ROUND_TRIPS and self._n_age % 8 == 0:
                ages = sorted(self._age)  # (np.median of 50 floats: ~15 µs; this: ~2 µs)
                self.round_trip = 0.5 * (ages[(ROUND_TRIPS - 1) // 2] + ages[ROUND_TRIPS // 2])
                if self.follow_state_age:
                    self.set_latency(self.command_timeout + min(ages[-1], self.state_age_max))

    def set_latency(self, latency: float) -> None:
        """Bounds (13)'s latency margin [s] (and the collision rows', which share it): the
        state's age when the command acts, plus the robot's own command timeout."""
        self.latency = latency
        self._set_latency(latency)

    def reset_age(self) -> None:
        """Empty the state-age window (a new robot, or a new stream); bounds (13) go back to the
        worst age the watchdog allows."""
        self._age = [math.nan] * ROUND_TRIPS
        self._n_age = 0
        self.round_trip = math.nan
        if self.latency != self.base_latency:
            self.set_latency(self.base_latency)

    def left(self, msg: StateMsg) -> bool:
        """The state applied a command of the current stream and shows the robot's own stale or
        protective stop: the robot stopped following this stream. A robot that another daemon
        drove before this one (a restarted daemon) reports that daemon's last command, in its
        stale stop, until it applies one of this daemon's: that is no stop of this stream."""
        return ((msg.stale_stop or msg.protective_stop) and 0 < self.start <= msg.cmd_seq
                and msg.cmd_seq != self.inherited_cmd_seq)

    def stall(self, why: str) -> None:
        """This daemon stalled past the robot's command timeout: the stream is kept and braked.

        Its commands may still be on the way (a congested link, a starved transmit thread), so
        no new stream may start: the robot could still follow this one when the new one's first
        command, computed from rest, reaches it. Each braking command (the controller's safe
        stop, anchored on the last command sent) is a legal continuation of the stream whatever
        the robot did: if it stopped the stream meanwhile, it refuses the rest and a state shows
        its stop (:meth:`left`: the stream breaks); if it still follows, it brakes to rest with
        the stream; if none of the stream's commands has reached it yet, they make a sequence
        from rest to rest whenever they do. The states' ages measured across the stall say
        nothing about the link: the window starts anew, and the stall is not counted again.

        Args:
            why: the fault, as the status and the braking commands say it.
        """
        self.stalled = why
        self.rest_seq = 0
        self.last_sent_t = -math.inf  # acted on: the next command is not late by this stall
        self.reset_age()

    def braked(self, msg: StateMsg) -> bool:
        """The braked stream reached the robot: the state applied its first command at rest (or
        a later one of this daemon's) and shows the robot at rest, not in a stop. Every command
        sent before it has reached the robot or is lost, so the stream goes on from rest."""
        return (0 < self.rest_seq <= msg.cmd_seq <= self.seq and msg.cmd_seq != self.inherited_cmd_seq
                and not (msg.stale_stop or msg.protective_stop) and not any(msg.v_arm)
                and not any(msg.wheel_speeds))

    def break_off(self) -> None:
        """The robot no longer follows the stream: nothing goes out until it rests, and the
        next stream starts from its measured rates and its own clock."""
        self.broken = True
        self.stalled = ""
        self.reset_age()  # silent meanwhile: the states' ages say nothing about the link
        self.anchor_on_command = False
        self.last_sent_t = -math.inf

    def anchored(self, st: w.RobotState, cmd: w.Command | None, msg: StateMsg | None) -> w.RobotState:
        """The state handed to the controller: its rates replaced by the last command while
        the robot follows the command stream.

        The acceleration bounds of (13) are q̇_prev ± A·Δt around what the robot will execute
        next: the last command (its drives ramp towards it, and the referee judges each
        command against the previous one). The measured rates lag it by the state's age, and
        a late state would pull the bounds back and let two consecutive commands differ by
        more than A·Δt. The measured rates are used for the first command of a stream (to a
        new sim instance, or after a break) and when the robot stopped following the stream (a
        state that applied one of its commands shows a stale or a protective stop); a state
        from before the stream began does not count.
        """
        if not self.anchor_on_command or cmd is None or (msg is not None and self.left(msg)):
            return st
        a = self._anchor  # one object, refilled: a new RobotState re-validates its arrays (~10 µs)
        if a is None:
            a = self._anchor = w.RobotState(q_base=st.q_base, q_arm=st.q_arm)
        a.q_base, a.q_arm, a.v_arm, a.wheel_speeds = st.q_base, st.q_arm, cmd.arm_rates, cmd.wheel_speeds
        return a


def predicted(model: w.WmmModel, dt: float, st: w.RobotState, cmd: w.Command) -> w.RobotState:
    """No new state this tick: the last one, as if the last command executed for ``dt`` [s].

    The controller's acceleration bounds start from the state's rates; starting them again
    from an old state would let two consecutive commands differ by 2·A·dt.
    """
    twist = model.base.P(float(st.q_base[2])) @ cmd.wheel_speeds
    return w.RobotState(q_base=st.q_base + dt * twist, q_arm=st.q_arm + dt * cmd.arm_rates,
                        v_arm=cmd.arm_rates.copy(), wheel_speeds=cmd.wheel_speeds.copy())
