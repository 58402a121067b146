"""The driver contract's test kit (docs/drivers.md): checks a running driver from the outside.

A :class:`Controller` plays the daemon's part on the wire — it holds a control lease, reads
the driver's states and sends commands — so the checks see the driver exactly as the daemon
does, whatever it drives (the sim, a Franka FR3, your robot). ``wmm-qp contract``
(:mod:`wmm_qp_tools.commands.contract`) runs :data:`CHECKS` in order with :func:`run_checks`;
each check returns a line of what it did and saw, or raises :class:`ContractError` naming what
the driver did against what the contract asks. Every verdict is derived from what the driver
put on the wire (its states: ``cmd_seq``, the executed rates, the positions, the stops, the
refusal counts, all on the robot's own time ``t``), never from what it claims about itself.

The checks run on one driver one after the other (each starts a new command stream) and leave
the robot at rest; they move joints slowly near their start, command one past its velocity limit
(the firmware must refuse it), and drive one joint towards its nearest position limit (the
firmware must stop it before the limit); at the end the arm goes back to where it started.

Timing slack: the checks run on shared machines, so wall-clock waits are generous (``SLACK``);
the durations that are part of the contract (the stale stop's delay, the acceleration of the
executed rates) are measured on the states' own time ``t``.
"""

from __future__ import annotations

import contextlib
import math
import os
import secrets
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import msgspec
import numpy as np
import zenoh
from wmm_qp_service.config import ServiceConfig
from wmm_qp_service.keys import Keys
from wmm_qp_service.protocol import CommandMsg, StateMsg, encode
from wmm_qp_service.rate_loop import realtime_priority
from wmm_qp_service.transport import ROLE_DAEMON, open_session

import wmm_qp as w

SLACK = 0.3
"""[s] what a loaded host may add to any wall-clock wait of the contract."""
COUNTED_MIN = 0.8
"""[-] the share of a reason's refused commands its count must show (the kit's commands may be
dropped in transit on a loaded host, as the daemon's are)."""
COUNT_WAIT = 2.0
"""[s] how long the kit waits for a driver to count the refusals it provoked (a loaded driver counts
late; one that does not count at all costs each refusing check this long)."""
MAX_RATE = 1.0
"""[rad/s] the fastest the kit moves a joint (its step and its run to a limit: half the joint's
velocity limit, at most this)."""
GOTO_GAIN = 6.0
"""[1/s] the gain of the P law that brings the arm back to where the kit found it (:func:`goto`)."""
ACCEL_WINDOW = 0.01
"""[s] the executed rates' acceleration is judged over windows of at least this much robot time
(a real robot's measured rates are noisy from one cycle to the next)."""
ACCEL_RTOL = 0.05
"""[-] the acceleration a driver may exceed its limits by (measurement, discretisation)."""


def _scheduling() -> tuple[int, os.sched_param] | None:
    """This thread's scheduling policy and parameter (None: not Linux)."""
    try:
        return os.sched_getscheduler(0), os.sched_getparam(0)
    except (AttributeError, OSError):
        return None


class ContractError(AssertionError):
    """The driver broke the contract (the message says how)."""


class NoDriver(ContractError):
    """No driver answers on the robot's keys (the message names what was seen instead)."""


class DaemonRunning(ContractError):
    """A daemon (or another controller) holds the robot: the kit takes the daemon's place."""


class Controller:
    """The daemon's side of the wire: a lease, the states, commands.

    Args:
        svc: the driver's service config (prefix, robot id, endpoints).
        robot: the robot description the driver was started with.
        lease: this controller's lease id (None: ``contract-`` and a random suffix).
        period: [s] the commands' period (the daemon's control period).
    """

    def __init__(self, svc: ServiceConfig, robot: w.RobotConfig, lease: str | None = None, period: float = 0.002):
        # a fresh lease per run, as each daemon start has its own: the driver keeps the seq of a
        # holder it saw, and a later run's seqs start again from 1
        lease = lease or f"contract-{secrets.token_hex(4)}"
        self.svc, self.robot, self.lease, self.period = svc, robot, lease, period
        self.keys = Keys.of(svc.prefix, svc.robot)
        self._stack = contextlib.ExitStack()
        self.session: zenoh.Session = self._stack.enter_context(open_session(svc, ROLE_DAEMON))
        self._token: Any = None
        self._sub = self.session.declare_subscriber(self.keys.state, zenoh.handlers.FifoChannel(100_000))
        # blocking, not dropping, under congestion: the refusal counts are judged command by
        # command, so every command the kit sends reaches the driver
        self._pub = self.session.declare_publisher(self.keys.cmd, express=True,
                                                   congestion_control=zenoh.CongestionControl.BLOCK)
        self._dec = msgspec.msgpack.Decoder(StateMsg)
        self.states: list[StateMsg] = []
        self.log: list[StateMsg] = []  # every state since :meth:`record` (None: not recording)
        self._recording = False
        self.seq = 0
        self.stream = 0
        # the daemon's scheduling for the thread that sends (Zenoh's threads, started with the
        # session, keep theirs): a loaded host then delays its commands as little as the daemon's
        # (restored by close(): left at SCHED_FIFO, the caller's later children inherit it, and a
        # test process's CPU hogs at FIFO starved a demo at the same priority for good)
        self._sched_before = _scheduling()
        self.scheduling = realtime_priority(svc.loop.rt_priority)

    def close(self) -> None:
        """Undeclare everything, close the session, give the thread its scheduling back."""
        if (before := getattr(self, "_sched_before", None)) is not None:
            with contextlib.suppress(AttributeError, OSError):
                os.sched_setscheduler(0, *before)
        for ent in (self._token, self._sub, self._pub):
            if ent is not None:
                with contextlib.suppress(Exception):
                    ent.undeclare()
        self._stack.close()

    def __enter__(self) -> Controller:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def hold_lease(self) -> None:
        """Declare this controller's lease token."""
        if self._token is None:
            self._token = self.session.liveliness().declare_token(self.keys.lease(self.lease))

    def record(self) -> list[StateMsg]:
        """From now on keep every state in :attr:`log` (a fresh list, returned)."""
        self.drain()
        self.log = []
        self._recording = True
        return self.log

    def drain(self) -> StateMsg | None:
        """Collect the states that arrived; the newest (None: none ever)."""
        while (s := self._sub.try_recv()) is not None:
            with contextlib.suppress(msgspec.DecodeError):
                st = self._dec.decode(s.payload.to_bytes())
                self.states.append(st)
                if self._recording:
                    self.log.append(st)
        if len(self.states) > 20_000:
            del self.states[:-1000]
        return self.states[-1] if self.states else None

    def until(self, pred: Callable[[StateMsg], bool], timeout: float, what: str,
              send: Callable[[], object] | None = None) -> StateMsg:
        """Drain (calling ``send`` every period) until the newest state satisfies ``pred``."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if send is not None:
                send()
            st = self.drain()
            if st is not None and pred(st):
                return st
            time.sleep(self.period)
        raise ContractError(f"no {what} within {timeout:g} s; last state: {self._brief(self.drain())}")

    def new_stream(self) -> None:
        """The next command starts a new stream."""
        self.stream = self.seq + 1

    def send(self, arm_rates: Sequence[float], lease: str | None = None, instance: str | None = None,
             seq: int | None = None, wheels: Sequence[float] | None = None) -> int:
        """Send one command (this controller's lease, the driver's instance and the next seq by
        default); its seq."""
        st = self.drain()
        if seq is None:
            self.seq += 1
            seq = self.seq
        self._pub.put(encode(CommandMsg(
            robot=self.svc.robot, seq=seq, stamp=time.time(),
            wheel_speeds=[0.0] * self.robot.n_wheels if wheels is None else [float(v) for v in wheels],
            arm_rates=[float(v) for v in arm_rates], lease=self.lease if lease is None else lease,
            instance=(st.instance if st is not None else "") if instance is None else instance,
            period=self.period, stream=self.stream)))
        return seq

    def drive(self, arm_rates: Sequence[float]) -> StateMsg | None:
        """Send one command of a motion that must go on: when the robot stopped this stream by its
        command timeout (this process stalled past it on a loaded host), a new stream goes on from
        where the robot is. The newest state (None: none yet)."""
        st = self.drain()
        if st is not None and st.stale_stop and st.cmd_seq >= self.stream:
            self.new_stream()
        self.send(arm_rates)
        return st

    def zeros(self) -> list[float]:
        return [0.0] * self.robot.n_arm

    @staticmethod
    def _brief(st: StateMsg | None) -> str:
        if st is None:
            return "none"
        return (f"seq {st.seq}, lease {st.lease!r}, cmd_seq {st.cmd_seq}, stale_stop {st.stale_stop}, "
                f"protective_stop {st.protective_stop} ({st.protective_reason!r}), refused {dict(st.refused)}, "
                f"v_arm {np.round(st.v_arm, 3).tolist()}")


def _at_rest(st: StateMsg) -> bool:
    return not np.any(st.v_arm) and not np.any(st.wheel_speeds)


def _rest_tol(c: Controller) -> float:
    """[rad/s] below this a measured joint rate is rest (a real robot's are never exactly 0)."""
    return 0.01 * float(np.min(c.robot.arm.velocity_max))


def _near_rest(c: Controller) -> Callable[[StateMsg], bool]:
    tol = _rest_tol(c)
    return lambda st: bool(np.all(np.abs(st.v_arm) <= tol) and np.all(np.abs(st.wheel_speeds) <= tol))


def _moving(c: Controller, joint: int | None, rate: float, ramp: float = 0.3, timeout: float = 5.0) -> int:
    """With the lease, a new stream that ramps ``joint`` (None: the last) from rest to ``rate``
    [rad/s] over about ``ramp`` [s] and holds it until the robot executes it. Returns the joint."""
    c.hold_lease()
    joint = c.robot.n_arm - 1 if joint is None else joint
    c.new_stream()
    step = rate * c.period / ramp
    v = 0.0
    end = time.monotonic() + ramp + timeout
    while time.monotonic() < end:
        st = c.drain()
        if st is not None and st.stale_stop and st.cmd_seq >= c.stream:
            v = abs(st.v_arm[joint])  # this process stalled past the command timeout: on from there
        if v >= rate and st is not None and st.cmd_seq >= c.seq and abs(st.v_arm[joint] - rate) < 0.05 * rate:
            return joint
        v = min(rate, v + step)
        cmd = c.zeros()
        cmd[joint] = v
        c.drive(cmd)
        time.sleep(c.period)
    raise ContractError(f"joint {joint + 1} did not reach {rate} rad/s within {ramp + timeout:g} s: "
                        f"{Controller._brief(c.drain())}")


def _resting(c: Controller, seconds: float) -> StateMsg:
    """Commands of zero rates for ``seconds`` in the current stream; the newest state."""
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        c.send(c.zeros())
        c.drain()
        time.sleep(c.period)
    st = c.drain()
    if st is None:
        raise ContractError("no state at all")
    return st


def settle(c: Controller, timeout: float = 10.0) -> StateMsg:
    """With the lease, a new stream of zero rates until the robot applies it, out of any stop
    and at rest (a robot in a protective stop resumes once at rest: docs/drivers.md)."""
    c.hold_lease()
    c.new_stream()
    first = c.seq + 1
    return c.until(lambda st: st.cmd_seq >= first and not st.stale_stop and not st.protective_stop
                   and _near_rest(c)(st), timeout, "robot applying a new stream of zero rates, out of its stops, "
                   "at rest", lambda: c.drive(c.zeros()))


@dataclass
class Kit:
    """One run of the contract against one driver: the controller and what the checks learn.

    Attributes:
        c: the daemon's side of the wire.
        rate_hz: [Hz] the robot's cycle rate (states at least half of it).
        stale_timeout: [s] the command timeout the daemon's bounds (13) assume
            (``watchdog.command_hold − watchdog.state_age_max``).
        refusals: per reason, (the state's count before, the commands the driver refused for it),
            for :func:`check_refusal_counts`.
        start_q: [rad] where the arm was when the kit began (it returns there at the end).
    """

    c: Controller
    rate_hz: float
    stale_timeout: float
    refusals: dict[str, tuple[int, int]] = field(default_factory=dict)
    not_refused: dict[str, str] = field(default_factory=dict)
    start_q: np.ndarray | None = None


def _cycles(k: Kit, n: float) -> float:
    """[s] n of the robot's cycles."""
    return n / k.rate_hz


# ---------------------------------------------------------------------------------------- checks
def check_states(k: Kit, seconds: float = 1.0) -> str:
    """States at the robot's rate (at least half of it, counted on the states' own time ``t``:
    a simulated robot may run slower than the wall clock on a loaded host), seq increasing by 1,
    one instance."""
    c = k.c
    c.states.clear()
    time.sleep(seconds)
    c.drain()
    sts = c.states
    if len(sts) < 2:
        raise ContractError(f"{len(sts)} states in {seconds:g} s")
    seqs = np.array([s.seq for s in sts])
    span = sts[-1].t - sts[0].t  # [s] robot time: a simulated robot may run slow
    # the driver's cycles by its seqs (states lost in transit are not the driver's doing)
    rate = float(seqs[-1] - seqs[0]) / span if span > 0 else math.inf
    if len(sts) < 10 or not span > 0 or rate < 0.5 * k.rate_hz:
        raise ContractError(f"{len(sts)} states, seq {seqs[0]} to {seqs[-1]}, over {span:.3f} s of robot time "
                            f"({seconds:g} s of wall time): {rate:.0f} Hz; the robot's rate is {k.rate_hz:g} Hz")
    if np.any(np.diff(seqs) <= 0):
        i = int(np.flatnonzero(np.diff(seqs) <= 0)[0])
        raise ContractError(f"state seq does not increase: {seqs[i]} then {seqs[i + 1]}")
    gaps = int(np.sum(np.diff(seqs) != 1))
    missing = int(seqs[-1] - seqs[0] + 1 - len(sts))
    if np.median(np.diff(seqs)) != 1:  # states lost in transit leave gaps; a driver that counts so has no 1s
        raise ContractError(f"state seq is not consecutive: {gaps} gaps ({missing} seqs skipped) in {len(sts)} "
                            f"states, the usual step {np.median(np.diff(seqs)):g}")
    instances = {s.instance for s in sts}
    if len(instances) != 1 or "" in instances:
        raise ContractError(f"states of {len(instances)} instances {sorted(instances)} from one driver")
    return (f"{len(sts)} states in {seconds:g} s: {rate:.0f} Hz on the robot's time (>= {0.5 * k.rate_hz:g}), "
            f"seq consecutive ({missing} lost in transit in {gaps} gaps), one instance {sts[-1].instance}")


def check_liveliness(k: Kit) -> str:
    """The driver holds its liveliness token ``alive/robot`` (its disappearance is the daemon's
    safe stop)."""
    key = k.c.keys.alive("robot")
    names = [str(r.ok.key_expr) for r in k.c.session.liveliness().get(key, timeout=2.0) if r.ok is not None]
    if not names:
        raise ContractError(f"no liveliness token {key} (the daemon would see no robot)")
    return f"token {names[0]} present"


def _burst(k: Kit, n: int, reason: str, arm: Sequence[float] | None = None,
           **kw: Any) -> tuple[list[int], StateMsg]:
    """After :func:`settle`, ``n`` commands (zero rates, or ``arm``) with the keyword arguments
    of :meth:`Controller.send` (a forged lease, another instance, an old seq, …), one per period
    and nothing else; verdict: none of them applied (no state's ``cmd_seq`` names one), judged
    once the driver counted them all under ``reason`` or applied one, or after ``COUNT_WAIT`` (a
    loaded driver answers late). The refusals are booked under ``reason`` for
    :func:`check_refusal_counts`."""
    c = k.c
    st0 = settle(c)
    applied, count0 = st0.cmd_seq, st0.refused.get(reason, 0)
    log = c.record()
    sent = []
    for _ in range(n):
        sent.append(c.send(c.zeros() if arm is None else arm, **kw))
        if "seq" in kw:
            kw["seq"] += 1
        time.sleep(c.period)
    end = time.monotonic() + COUNT_WAIT
    while time.monotonic() < end:
        st = c.drain() or st0
        if st.refused.get(reason, 0) - count0 >= n or any(s.cmd_seq != applied and s.cmd_seq in sent for s in log):
            break
        time.sleep(c.period)
    time.sleep(0.05)  # a state applying one after the count would have come by now
    st = c.drain() or st0
    c._recording = False
    hit = [s for s in log if s.cmd_seq != applied and s.cmd_seq in sent]
    bad = [s for s in log if not np.all(np.isfinite(s.v_arm))]
    if hit or bad:
        k.not_refused[reason] = "applied"
        raise ContractError(f"applied {reason} command seq {hit[0].cmd_seq if hit else '?'}"
                            + (f" (state seq {hit[0].seq})" if hit else "")
                            + (", executed rates not finite" if bad else ""))
    base, booked = k.refusals.get(reason, (count0, 0))
    k.refusals[reason] = (base, booked + n)
    return sent, st


def check_lease(k: Kit) -> str:
    """Commands are applied only from the lease holder, the earliest lease token alive: a sender
    with a forged lease (no token) and one whose token appeared after the holder's are refused;
    ``state.lease`` names the holder."""
    c = k.c
    c.hold_lease()
    c.until(lambda st: st.lease == c.lease, 5.0, f"state.lease naming the holder {c.lease!r}")
    _burst(k, 10, "lease", lease="intruder")
    later = f"{c.lease}-later"
    late = c.session.liveliness().declare_token(c.keys.lease(later))
    try:
        time.sleep(0.2)  # the driver has seen the later token
        _, st = _burst(k, 10, "lease", lease=later)
        if st.lease != c.lease:
            raise ContractError(f"state.lease {st.lease!r} after a later lease token appeared; the holder is "
                                f"{c.lease!r}, the earliest alive")
    finally:
        late.undeclare()
    return (f"holder {c.lease!r} reported in state.lease; 10 commands with a forged lease and 10 from a later "
            f"token's holder: none applied (cmd_seq)")


def check_instance(k: Kit) -> str:
    """Commands addressed to another instance are refused."""
    _burst(k, 10, "instance", instance="another-instance")
    return "10 commands of the holder for instance 'another-instance': none applied (cmd_seq)"


def check_seq(k: Kit) -> str:
    """A holder's seq increases: commands replayed with seqs it already used are refused."""
    st0 = settle(k.c)
    _burst(k, 10, "seq", seq=max(0, st0.cmd_seq - 20))
    return "10 commands replayed with seqs the holder had used: none applied (cmd_seq)"


def check_invalid(k: Kit) -> str:
    """A malformed command (a NaN rate) is refused on receipt (``Validator``)."""
    arm = k.c.zeros()
    arm[-1] = math.nan
    _burst(k, 10, "invalid", arm=arm)
    return "10 commands with a NaN rate for the last joint: none applied (cmd_seq), rates finite"


def check_refusal_counts(k: Kit) -> str:
    """Every refused command is counted in ``state.refused`` under its reason (the daemon and the
    operator read them): each refusal the checks before provoked, one count."""
    c = k.c
    if not k.refusals:
        raise ContractError("no refusal to count (the checks that provoke them did not run or failed)")

    def counted(st: StateMsg) -> bool:
        return all(st.refused.get(r, 0) - b >= n for r, (b, n) in k.refusals.items())

    try:
        st = c.until(counted, COUNT_WAIT, "state.refused counting every refusal")  # a loaded driver counts late
    except ContractError:
        st = c.drain()  # type: ignore[assignment]
    assert st is not None
    rows = [f"{r} +{st.refused.get(r, 0) - b} of {n}" for r, (b, n) in sorted(k.refusals.items())]
    # a command lost in transit on a loaded host is neither refused nor counted: at least
    # COUNTED_MIN of each reason's refusals, never more than were sent
    wrong = [f"{r}: +{st.refused.get(r, 0) - b} for {n} refused" for r, (b, n) in sorted(k.refusals.items())
             if not COUNTED_MIN * n <= st.refused.get(r, 0) - b <= n]
    if wrong:
        raise ContractError(f"state.refused does not count the refusals: {'; '.join(wrong)} (refused "
                            f"{dict(st.refused)})")
    skipped = f"; not judged: {', '.join(sorted(k.not_refused))} (not refused)" if k.not_refused else ""
    return f"counted: {', '.join(rows)}{skipped}"


def _accel(k: Kit, log: list[StateMsg]) -> tuple[float, int, float, float]:
    """The largest ratio of an executed rate's change to its limit's, over windows of at least
    :data:`ACCEL_WINDOW` of robot time: (ratio, joint (-1 a wheel), its change, the window)."""
    a = np.array(k.c.robot.arm.acceleration_max, dtype=float)
    nw = k.c.robot.n_wheels
    t = np.array([s.t for s in log])
    v = np.array([list(s.v_arm) + list(s.wheel_speeds) for s in log])
    lim = np.concatenate([a, np.broadcast_to(np.asarray(k.c.robot.base.wheel_acceleration_max, dtype=float), nw)])
    tol = 0.01 * np.concatenate([np.array(k.c.robot.arm.velocity_max, dtype=float),
                                 np.broadcast_to(np.asarray(k.c.robot.base.wheel_speed_max, dtype=float), nw)])
    worst = (0.0, 0, 0.0, 0.0)
    j = 0
    for i in range(len(t)):
        while j < len(t) and t[j] < t[i] + ACCEL_WINDOW:
            j += 1
        if j >= len(t):
            break
        dt = t[j] - t[i]
        dv = np.abs(v[j] - v[i])
        ratio = (dv - tol) / (lim * dt)
        m = int(np.argmax(ratio))
        if ratio[m] > worst[0]:
            worst = (float(ratio[m]), m if m < k.c.robot.n_arm else -1, float(dv[m]), float(dt))
    return worst


def check_ramp(k: Kit) -> str:
    """The drives ramp the executed rates towards the command at the acceleration limits: a
    step of the commanded rate (0 → half the velocity limit → 0, each at once) is executed
    ramped, the acceleration measured from the states' rates and times."""
    c = k.c
    settle(c)
    j = c.robot.n_arm - 1
    step = min(0.5 * float(c.robot.arm.velocity_max[j]), MAX_RATE)
    a = float(c.robot.arm.acceleration_max[j])
    log = c.record()
    hold = step / a + 0.05
    for target in (step, 0.0):
        v = c.zeros()
        v[j] = target
        reached = math.inf  # [s] monotonic time the robot executed the target
        end = time.monotonic() + hold + 2.0 + SLACK
        while time.monotonic() < min(end, reached + hold):
            st = c.drive(v)
            if st is not None and math.isinf(reached) and abs(st.v_arm[j] - target) < 0.02 * step:
                reached = time.monotonic()
            time.sleep(c.period)
    c.until(_near_rest(c), 1.0 + SLACK, "rest after the step down", lambda: c.drive(c.zeros()))
    c._recording = False
    peak = max((abs(s.v_arm[j]) for s in log), default=0.0)
    if peak < 0.9 * step:
        raise ContractError(f"joint {j + 1} reached {peak:.3f} rad/s of a commanded {step:.3f} rad/s step "
                            f"(it does not follow)")
    ratio, jj, dv, dt = _accel(k, log)
    what = f"joint {jj + 1}" if jj >= 0 else "a wheel"
    lim = float(c.robot.arm.acceleration_max[jj]) if jj >= 0 else float(np.max(c.robot.base.wheel_acceleration_max))
    if ratio > 1.0 + ACCEL_RTOL:
        raise ContractError(f"{what}'s executed rate changed by {dv:.3f} in {dt * 1e3:.1f} ms of robot time: "
                            f"{dv / dt:.1f}/s², its limit {lim:g} (no ramp at the acceleration limit)")
    return (f"commanded joint {j + 1} 0 -> {step:.3f} -> 0 rad/s in steps: executed up to {peak:.3f}, "
            f"acceleration at most {ratio:.2f} x the limits ({len(log)} states)")


def check_stale(k: Kit, rate: float = 0.3) -> str:
    """A moving joint, then no command: ``stale_stop`` within the command timeout (on the robot's
    time, from the first state that applied the last command) and the executed rates at rest."""
    c = k.c
    settle(c)
    j = _moving(c, None, rate)
    last = c.seq
    log = c.record()
    brake = rate / float(c.robot.arm.acceleration_max[j])
    c.until(lambda st: st.stale_stop and _near_rest(c)(st), 10 * k.stale_timeout + brake + 2 * SLACK,
            "stale_stop and rest after the commands stopped")
    c._recording = False
    applied = next((i for i, s in enumerate(log) if s.cmd_seq >= last), None)
    stop = next((i for i, s in enumerate(log) if s.stale_stop), None)
    rest = next((i for i, s in enumerate(log) if s.stale_stop and _near_rest(c)(s)), None)
    if applied is None or stop is None or rest is None or stop < applied:
        raise ContractError("the states do not show the last command applied, then the stale stop")
    # the stop happened after the last state without it: only that much lateness is proven
    late = log[stop - 1].t - log[applied].t if stop > applied else 0.0
    allowed = k.stale_timeout + _cycles(k, 2)
    if late > allowed:
        raise ContractError(f"stale_stop {late * 1e3:.1f} ms (robot time) or later after the last command was "
                            f"applied; the contract's command timeout is {k.stale_timeout * 1e3:g} ms")
    braking = log[rest].t - log[stop].t
    if braking > brake * (1 + ACCEL_RTOL) + _cycles(k, 3):
        raise ContractError(f"{braking * 1e3:.0f} ms (robot time) from the stale stop to rest from {rate} rad/s; "
                            f"braking at the acceleration limit takes {brake * 1e3:.0f} ms")
    return (f"joint {j + 1} at {rate} rad/s, commands stopped: stale_stop "
            f"{log[stop].t - log[applied].t:.4f} s after the last command applied (robot time; allowed "
            f"{allowed:.4f}), at rest {braking:.3f} s later")


def _ended(k: Kit, stopped: Callable[[StateMsg], bool], which: str) -> str:
    """Legal commands of the stream the robot's stop ended, for 0.1 s: refused and counted in
    ``refused.ended`` (not ``refused.firmware``), the robot still in its stop, its ``cmd_seq``
    naming a command of that stream (the daemon's rule: a stop that names one of its stream's
    commands ended that stream); then a new stream resumes."""
    c = k.c
    stream = c.stream  # the stopped stream's first seq
    _resting(c, 0.1)  # what the check before sent has landed; the stream goes on (no stale stop on top)
    st0 = c.drain()
    assert st0 is not None
    fw0, end0 = st0.refused.get("firmware", 0), st0.refused.get("ended", 0)
    log = c.record()
    st = _resting(c, 0.15)  # legal commands, the stopped stream (sent on: no stale stop on top)
    c._recording = False
    moved = [s for s in log if not stopped(s)]
    if moved or st.refused.get("ended", 0) <= end0:
        raise ContractError(f"the {which} stream's commands were not refused as ended (refused.ended), the stop "
                            f"{'left' if moved else 'kept'}: {Controller._brief(st)}")
    if st.refused.get("firmware", 0) > fw0:
        raise ContractError(f"the {which} stream's commands counted as firmware faults (refused.firmware "
                            f"{fw0} -> {st.refused['firmware']}): each would hold the daemon in a safe stop")
    if st.cmd_seq < stream:
        raise ContractError(f"cmd_seq {st.cmd_seq} in the stop names no command of the {which} stream (seq >= "
                            f"{stream}): the daemon would not learn its stream stopped")
    n = st.refused.get("ended", 0) - end0
    settle(c)
    return (f"refused.ended +{n}, refused.firmware +0, cmd_seq {st.cmd_seq} names the stream (from {stream}); a new "
            f"stream resumed")


def check_stale_stream(k: Kit, rate: float = 0.3) -> str:
    """After a stale stop the stopped stream's commands (late on the way, or from a sender that
    froze) are refused and counted in ``refused.ended``, not ``refused.firmware`` (the daemon
    faults on each firmware refusal: the stop is one event); a new stream resumes."""
    c = k.c
    settle(c)
    j = _moving(c, None, rate)
    brake = rate / float(c.robot.arm.acceleration_max[j])
    c.until(lambda st: st.stale_stop and _near_rest(c)(st), 10 * k.stale_timeout + brake + 2 * SLACK,
            "stale stop at rest")
    return "stale stop at rest; its stream's commands: " + _ended(k, lambda st: st.stale_stop, "stale")


def check_velocity_limit(k: Kit) -> str:
    """A command past a joint's velocity limit is refused: a protective stop naming the joint,
    ``refused.firmware`` counted, the joint not moving, no executed rate past its limit."""
    c = k.c
    st0 = settle(c)
    j = c.robot.n_arm - 1
    fw0, stops0 = st0.refused.get("firmware", 0), st0.protective_stops
    q0 = np.array(st0.q_arm)
    c.new_stream()
    v = c.zeros()
    v[j] = 1.2 * float(c.robot.arm.velocity_max[j])
    log = c.record()
    try:
        st = c.until(lambda st: st.protective_stop and st.protective_stops > stops0, 1.0 + SLACK,
                     f"protective stop for joint {j + 1} commanded at 1.2 x its velocity limit", lambda: c.send(v))
    finally:
        c._recording = False
    vmax = np.array(c.robot.arm.velocity_max, dtype=float)
    over = [s for s in log if np.any(np.abs(s.v_arm) > vmax * (1 + 1e-6) + _rest_tol(c))]
    if over:
        raise ContractError(f"executed rates past the velocity limits: {np.round(over[0].v_arm, 3).tolist()}")
    if f"joint {j + 1}" not in st.protective_reason:
        raise ContractError(f"protective_reason {st.protective_reason!r} does not name joint {j + 1}")
    if st.refused.get("firmware", 0) <= fw0:
        raise ContractError("the refused command is not counted in refused.firmware")
    moved = float(np.max(np.abs(np.array(st.q_arm) - q0)))
    if moved > 0.01:
        raise ContractError(f"the arm moved {moved:.4f} rad on a refused command")
    return (f"joint {j + 1} commanded at {v[j]:.3f} rad/s: protective stop ({st.protective_code or 'no code'}: "
            f"{st.protective_reason}), refused.firmware +{st.refused.get('firmware', 0) - fw0}, moved {moved:.4f} rad")


def _limit_joint(c: Controller, q: np.ndarray) -> tuple[int, float] | None:
    """The joint with a finite position limit nearest in time at its velocity limit, and the
    direction (+1: its upper limit) — None: no joint has one."""
    lo = np.array(c.robot.arm.position_lower, dtype=float)
    hi = np.array(c.robot.arm.position_upper, dtype=float)
    vmax = np.array(c.robot.arm.velocity_max, dtype=float)
    best: tuple[float, int, float] | None = None
    for j in range(c.robot.n_arm):
        for d, lim in ((1.0, hi[j]), (-1.0, lo[j])):
            if math.isfinite(lim):
                cost = abs(lim - q[j]) / vmax[j]
                if best is None or cost < best[0]:
                    best = (cost, j, d)
    return None if best is None else (best[1], best[2])


def goto(c: Controller, q_target: Sequence[float] | np.ndarray, speed: float = 0.5, timeout: float = 20.0,
         tol: float = 0.01) -> StateMsg:
    """Drive the arm to ``q_target`` [rad] (a P law of gain :data:`GOTO_GAIN` capped by the rate
    that stops within the error at half the acceleration limits, rates at most ``speed`` x the
    velocity limits and :data:`MAX_RATE`, changed by at most the acceleration limits per period),
    then rest; the last state."""
    vmax = np.minimum(speed * np.array(c.robot.arm.velocity_max, dtype=float), MAX_RATE)
    a = np.broadcast_to(np.array(c.robot.arm.acceleration_max, dtype=float), vmax.shape)
    amax = a * c.period
    target = np.array(q_target, dtype=float)
    settle(c)
    v = np.zeros(c.robot.n_arm)
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        st = c.drain()
        assert st is not None
        err = target - np.array(st.q_arm)
        if np.all(np.abs(err) < tol):
            break
        want = np.sign(err) * np.minimum(np.minimum(GOTO_GAIN * np.abs(err), np.sqrt(a * np.abs(err))), vmax)
        if st.stale_stop and st.cmd_seq >= c.stream:  # this process stalled: go on from the rates there
            v = np.array(st.v_arm)
        v = v + np.clip(want - v, -amax, amax)
        c.drive(v)
        time.sleep(c.period)
    return settle(c)


def check_position_limit(k: Kit, speed: float = 0.5) -> str:
    """A joint driven towards its position limit is stopped before it: the firmware refuses the
    motion from which the joint could not brake to rest at its acceleration limit before the
    limit (a protective stop naming the joint), and the joint never passes the limit.

    The kit drives the joint nearest to a limit at ``speed`` x its velocity limit and stops
    commanding as soon as a state shows the joint can no longer brake before the limit
    (q + v|v|/(2A) past it) without a protective stop: a faulty driver's joint then overruns
    by little more than a few cycles of motion."""
    c = k.c
    st0 = settle(c)
    pick = _limit_joint(c, np.array(st0.q_arm))
    if pick is None:
        return "no joint has a finite position limit: nothing to check"
    j, d = pick
    lim = float(c.robot.arm.position_upper[j] if d > 0 else c.robot.arm.position_lower[j])
    a = float(c.robot.arm.acceleration_max[j])
    rate = min(speed * float(c.robot.arm.velocity_max[j]), MAX_RATE)
    stops0 = st0.protective_stops
    tol = 0.005 + rate * _cycles(k, 3)
    c.new_stream()
    log = c.record()
    duration = abs(lim - st0.q_arm[j]) / rate + rate / a + 1.0
    end = time.monotonic() + duration * 3 + 10.0  # a loaded host: this process stalls, the robot waits
    verdict = ""
    v = 0.0
    try:
        while time.monotonic() < end:
            st = c.drain()
            assert st is not None
            if st.protective_stop and st.protective_stops > stops0:
                break
            q, vj = st.q_arm[j], st.v_arm[j]
            reach = q + vj * abs(vj) / (2 * a)
            if d * (reach - lim) > tol:
                verdict = (f"joint {j + 1} at {q:.4f} rad moving {vj:.3f} rad/s can no longer brake before its "
                           f"{'upper' if d > 0 else 'lower'} limit {lim:.4f} (it would reach {reach:.4f}), "
                           f"and no protective stop")
                break
            if st.stale_stop and st.cmd_seq >= c.stream:  # this process stalled: go on from the rate there
                v = abs(vj)
            v = min(rate, v + a * c.period)
            cmd = c.zeros()
            cmd[j] = d * v
            c.drive(cmd)
            time.sleep(c.period)
        else:
            verdict = f"joint {j + 1} never stopped: {Controller._brief(c.drain())}"
        if verdict:
            with contextlib.suppress(ContractError):
                c.new_stream()
                c.until(_near_rest(c), 2.0, "rest", lambda: c.send(c.zeros()))
            raise ContractError(verdict)
        # the stream goes on (zero rates, legal) while the robot brakes: its stop, not a stale one, ends it
        st = c.until(lambda st: st.protective_stop and _near_rest(c)(st), 2.0 + SLACK, "rest in the protective stop",
                     lambda: c.send(c.zeros()))
    finally:
        c._recording = False
    past = max(d * (s.q_arm[j] - lim) for s in log)
    if past > 0.005:
        raise ContractError(f"joint {j + 1} passed its limit {lim:.4f} by {past:.4f} rad")
    if f"joint {j + 1}" not in st.protective_reason:
        raise ContractError(f"protective_reason {st.protective_reason!r} does not name joint {j + 1}")
    return (f"joint {j + 1} driven at {rate:.3f} rad/s towards its limit {lim:.4f}: protective stop "
            f"({st.protective_code or 'no code'}: {st.protective_reason}), at rest {abs(lim - st.q_arm[j]):.4f} rad "
            f"before the limit")


def _velocity_stop(c: Controller) -> StateMsg:
    """From rest, a new stream commanding the last joint past its velocity limit until the
    robot is in a protective stop."""
    stops0 = settle(c).protective_stops
    c.new_stream()
    v = c.zeros()
    v[-1] = 1.2 * float(c.robot.arm.velocity_max[-1])
    return c.until(lambda st: st.protective_stop and st.protective_stops > stops0, 1.0 + SLACK,
                   "protective stop for a command past the velocity limit", lambda: c.send(v))


def check_stopped_stream(k: Kit, attempts: int = 6) -> str:
    """After a protective stop the stopped stream's commands stay refused (``refused.ended``, not
    ``refused.firmware``) and a new stream resumes. The stop is the one the robot is in
    (:func:`check_position_limit`'s), else one provoked here with a command past the last joint's
    velocity limit. The stream goes on (legal commands) from the stop on; an attempt in which the
    robot also went stale (this process stalled past the command timeout: then the stale stop
    ends the stream too) proves nothing and is made again."""
    c = k.c
    for attempt in range(attempts):
        st = c.drain()
        how = "the position limit's stop"
        if attempt or st is None or not st.protective_stop or st.stale_stop:
            try:
                _velocity_stop(c)
                how = "a velocity limit's stop"
            except ContractError:  # a driver that does not refuse that: the position limit's stop again
                recover(k)
                check_position_limit(k)
        log = c.record()
        c.until(lambda st: st.protective_stop and _near_rest(c)(st), 2.0 + SLACK, "rest in the protective stop",
                lambda: c.send(c.zeros()))  # the stream goes on: its stop, not a stale one, ends it
        before = list(log)
        out = _ended(k, lambda st: st.protective_stop, "stopped")
        if not any(s.stale_stop for s in before + c.log):
            return f"{how}, at rest; its stream's commands: {out}"
    raise ContractError(f"no verdict: in {attempts} attempts this process stalled past the command timeout after "
                        f"the protective stop (a stale stop on top ends the stream too): a loaded host")


@dataclass(frozen=True)
class Check:
    """One duty of docs/drivers.md and its check."""

    name: str
    duty: str
    run: Callable[[Kit], str]


CHECKS: tuple[Check, ...] = (
    Check("states", "states at the robot's rate, seq consecutive, one instance", check_states),
    Check("liveliness", "the liveliness token alive/robot", check_liveliness),
    Check("lease", "obeys only the lease holder (the earliest token alive)", check_lease),
    Check("instance", "refuses commands for another instance", check_instance),
    Check("seq", "refuses a holder's old or replayed seq", check_seq),
    Check("invalid", "refuses malformed commands", check_invalid),
    Check("refusal_counts", "counts each refused command in state.refused by reason", check_refusal_counts),
    Check("ramp", "ramps the executed rates within the acceleration limits", check_ramp),
    Check("stale", "brakes to rest (stale_stop) within the command timeout", check_stale),
    Check("stale_stream", "a stale stop ends its stream (refused.ended); a new stream resumes", check_stale_stream),
    Check("velocity_limit", "refuses a command past a velocity limit with a protective stop", check_velocity_limit),
    Check("position_limit", "refuses a motion that could not brake before a position limit", check_position_limit),
    Check("stopped_stream", "a protective stop ends its stream (refused.ended); a new stream resumes",
          check_stopped_stream),
)
NAMES = tuple(ch.name for ch in CHECKS)


def wait_for_driver(c: Controller, timeout: float) -> StateMsg:
    """The driver's first state; else :class:`NoDriver` naming the robots' keys that do carry
    states or liveliness tokens (a wrong robot id or prefix)."""
    seen: set[str] = set()

    def note(sample: zenoh.Sample) -> None:
        seen.add(str(sample.key_expr))

    spy = c.session.declare_subscriber("**/state", zenoh.handlers.Callback(note, indirect=False))
    try:
        return c.until(lambda st: True, timeout, "")
    except ContractError:
        tokens = sorted({str(r.ok.key_expr) for r in c.session.liveliness().get("**/alive/robot", timeout=1.0)
                         if r.ok is not None})
        where = f"states seen on {', '.join(sorted(seen)[:5])}" if seen else "no robot state seen on any key"
        if tokens:
            where += f"; robot tokens: {', '.join(tokens[:5])}"
        hint = ("wrong --robot-config, --robot or --prefix?" if seen or tokens else
                f"is the driver running and listening on {c.svc.zenoh.sim_endpoint} (--sim-endpoint)?")
        raise NoDriver(f"no state on {c.keys.state} within {timeout:g} s; {where}: {hint}") from None
    finally:
        with contextlib.suppress(Exception):
            spy.undeclare()


def check_no_daemon(c: Controller) -> None:
    """Raise :class:`DaemonRunning` when a daemon or another lease holder controls the robot."""
    found = [str(r.ok.key_expr) for key in (c.keys.alive("daemon"), c.keys.lease_all)
             for r in c.session.liveliness().get(key, timeout=1.0) if r.ok is not None]
    if found:
        raise DaemonRunning(f"{', '.join(sorted(found))} alive: a daemon (or another controller) holds "
                            f"{c.keys.root}; stop it first, the contract takes the daemon's place")


@dataclass(frozen=True)
class Result:
    """One check's verdict."""

    name: str
    passed: bool
    detail: str
    seconds: float


def recover(k: Kit) -> None:
    """After a failed check: a new stream of zero rates until the robot rests (never raises)."""
    with contextlib.suppress(Exception):
        k.c._recording = False
        settle(k.c)


def run_checks(k: Kit, skip: Sequence[str] = (), on_result: Callable[[Result], None] | None = None,
               on_start: Callable[[Check], None] | None = None) -> list[Result]:
    """Every check of :data:`CHECKS` not in ``skip``, in order; a failed one is followed by
    :func:`recover` and the next. At the end the arm goes back to where it started."""
    out: list[Result] = []
    st = k.c.drain()
    k.start_q = np.array(st.q_arm) if st is not None else None
    try:
        for ch in CHECKS:
            if ch.name in skip:
                continue
            if on_start is not None:
                on_start(ch)
            t0 = time.monotonic()
            try:
                res = Result(ch.name, True, ch.run(k), time.monotonic() - t0)
            except ContractError as e:
                res = Result(ch.name, False, str(e), time.monotonic() - t0)
                recover(k)
            except Exception as e:  # the kit's own fault: no verdict on the driver, but never a pass
                res = Result(ch.name, False, f"the check itself failed ({type(e).__name__}: {e}): no verdict",
                             time.monotonic() - t0)
                recover(k)
            out.append(res)
            if on_result is not None:
                on_result(res)
    finally:
        if k.start_q is not None:
            with contextlib.suppress(Exception):
                goto(k.c, k.start_q)
    return out


def check_all(c: Controller, min_rate_hz: float, stale_timeout: float,
              skip: Sequence[str] = ()) -> dict[str, Result]:
    """Every check (see :func:`run_checks`), by name."""
    return {r.name: r for r in run_checks(Kit(c, min_rate_hz, stale_timeout), skip)}

