"""The driver contract's test kit (docs/drivers.md): checks a running driver from the outside.

A :class:`Controller` plays the daemon's part on the wire — it holds a control lease, reads
the driver's states and sends commands — so the checks see the driver exactly as the daemon
does, whatever it drives (the sim, a Franka FR3, your robot). Each ``check_*`` function raises
:class:`ContractError` naming what the driver did against what the contract asks. The checks
run on one driver one after the other (each starts a new command stream) and leave the robot at
rest; they move one joint (the last one) slowly and near its start, and command it past its
velocity limit only where the firmware must refuse it.

Timing slack: the checks run on shared test machines, so rates and delays are judged with a
generous margin (``SLACK``); they test what a driver does, not how fast the host is.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable
from typing import Any

import msgspec
import numpy as np
import zenoh
from wmm_qp_service.config import ServiceConfig
from wmm_qp_service.keys import Keys
from wmm_qp_service.protocol import CommandMsg, StateMsg, encode
from wmm_qp_service.transport import ROLE_DAEMON, open_session

import wmm_qp as w

SLACK = 0.3
"""[s] what a loaded host may add to any deadline of the contract."""


class ContractError(AssertionError):
    """The driver broke the contract (the message says how)."""


class Controller:
    """The daemon's side of the wire: a lease, the states, commands.

    Args:
        svc: the driver's service config (prefix, robot id, endpoints).
        robot: the robot description the driver was started with.
        lease: this controller's lease id.
        period: [s] the commands' period (the daemon's control period).
    """

    def __init__(self, svc: ServiceConfig, robot: w.RobotConfig, lease: str = "contract", period: float = 0.002):
        self.svc, self.robot, self.lease, self.period = svc, robot, lease, period
        self.keys = Keys.of(svc.prefix, svc.robot)
        self._stack = contextlib.ExitStack()
        self.session: zenoh.Session = self._stack.enter_context(open_session(svc, ROLE_DAEMON))
        self._token: Any = None
        self._sub = self.session.declare_subscriber(self.keys.state, zenoh.handlers.FifoChannel(100_000))
        self._pub = self.session.declare_publisher(self.keys.cmd, express=True)
        self._dec = msgspec.msgpack.Decoder(StateMsg)
        self.states: list[StateMsg] = []
        self.seq = 0
        self.stream = 0

    def close(self) -> None:
        """Undeclare everything and close the session."""
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

    def drain(self) -> StateMsg | None:
        """Collect the states that arrived; the newest (None: none ever)."""
        while (s := self._sub.try_recv()) is not None:
            with contextlib.suppress(msgspec.DecodeError):
                self.states.append(self._dec.decode(s.payload.to_bytes()))
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
        raise ContractError(f"{what} within {timeout:g} s; last state: {self._brief(self.drain())}")

    def new_stream(self) -> None:
        """The next command starts a new stream."""
        self.stream = self.seq + 1

    def send(self, arm_rates: list[float], lease: str | None = None, instance: str | None = None) -> int:
        """Send one command (this controller's lease and the driver's instance by default); its seq."""
        st = self.drain()
        self.seq += 1
        self._pub.put(encode(CommandMsg(
            robot=self.svc.robot, seq=self.seq, stamp=time.time(), wheel_speeds=[0.0] * self.robot.n_wheels,
            arm_rates=[float(v) for v in arm_rates], lease=self.lease if lease is None else lease,
            instance=(st.instance if st is not None else "") if instance is None else instance,
            period=self.period, stream=self.stream)))
        return self.seq

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


def _moving(c: Controller, joint: int | None, rate: float, ramp: float = 0.3) -> int:
    """With the lease, a new stream that ramps ``joint`` (None: the last) from rest to ``rate``
    [rad/s] over ``ramp`` [s] and holds it. Returns the joint."""
    c.hold_lease()
    joint = c.robot.n_arm - 1 if joint is None else joint
    for _ in range(5):  # this process starved past the robot's command timeout: its stop ended the stream
        c.new_stream()
        t0 = time.monotonic()
        while (t := time.monotonic() - t0) < ramp + 0.1:
            v = c.zeros()
            v[joint] = rate * min(1.0, t / ramp)
            c.send(v)
            st = c.drain()
            if st is not None and st.stale_stop and st.cmd_seq >= c.stream:
                break  # the robot stopped this stream by its own timeout: a new one, from rest
            time.sleep(c.period)
        else:
            return joint
        c.until(_at_rest, 2.0, "the robot braked to rest")
    return joint


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


def check_states(c: Controller, min_rate_hz: float, seconds: float = 1.0) -> dict[str, Any]:
    """States at the robot's rate, seq increasing by 1, one instance; the liveliness token.

    Args:
        min_rate_hz: [Hz] the robot's rate, judged on the states' own time ``t`` (a simulated
            robot on a loaded host runs slower than the wall clock); at least half of it is
            demanded (a loaded host delays a wake-up, not the driver's count).
    """
    c.until(lambda st: True, 10.0, "a first state")
    c.states.clear()
    time.sleep(seconds)
    c.drain()
    sts = c.states
    seqs = np.array([s.seq for s in sts])
    span = sts[-1].t - sts[0].t if len(sts) > 1 else 0.0  # [s] robot time: a simulated robot may run slow
    if len(sts) < 10 or not span > 0 or (len(sts) - 1) / span < 0.5 * min_rate_hz:
        raise ContractError(f"{len(sts)} states over {span:.3f} s of robot time ({seconds:g} s of wall time), "
                            f"the robot's rate is {min_rate_hz:g} Hz")
    if np.any(np.diff(seqs) <= 0):
        raise ContractError("state seq does not increase")
    gaps = int(np.sum(np.diff(seqs) != 1))
    if seqs[-1] - seqs[0] + 1 - len(sts) > 0.5 * len(sts):
        raise ContractError(f"state seq is not consecutive: {gaps} gaps in {len(sts)} states")
    instances = {s.instance for s in sts}
    if len(instances) != 1 or "" in instances:
        raise ContractError(f"states of {len(instances)} instances {sorted(instances)} from one driver")
    names = [str(r.ok.key_expr) for r in c.session.liveliness().get(c.keys.alive("robot"), timeout=2.0)
             if r.ok is not None]
    if not names:
        raise ContractError(f"no liveliness token {c.keys.alive('robot')}")
    return {"states": len(sts), "rate_hz": (len(sts) - 1) / span, "seq_gaps": gaps, "instance": sts[-1].instance}


def check_lease(c: Controller) -> dict[str, Any]:
    """The lease holder's commands are applied; a forged lease's and another instance's refused."""
    c.hold_lease()
    c.until(lambda st: st.lease == c.lease, 5.0, f"state.lease naming the holder {c.lease!r}")
    c.new_stream()
    first = c.send(c.zeros())
    c.until(lambda st: st.cmd_seq >= first, 2.0, "the holder's command applied (cmd_seq)", lambda: c.send(c.zeros()))
    st0 = _resting(c, 0.05)
    lease0, inst0 = st0.refused.get("lease", 0), st0.refused.get("instance", 0)
    for _ in range(20):
        c.send(c.zeros(), lease="intruder")
        time.sleep(c.period)
    c.until(lambda st: st.refused.get("lease", 0) > lease0, 2.0, "a forged lease's commands refused (refused.lease)")
    for _ in range(20):
        c.send(c.zeros(), instance="another-instance")
        time.sleep(c.period)
    st = c.until(lambda st: st.refused.get("instance", 0) > inst0, 2.0,
                 "commands for another instance refused (refused.instance)")
    return {"refused": dict(st.refused)}


def check_refuses_past_limits(c: Controller, joint: int | None = None) -> dict[str, Any]:
    """A command past a joint's velocity limit: refused, a protective stop naming the joint,
    ``refused.firmware`` counted, the joint not moving."""
    c.hold_lease()
    j = c.robot.n_arm - 1 if joint is None else joint
    st0 = _resting(c, 0.1)
    fw0, stops0 = st0.refused.get("firmware", 0), st0.protective_stops
    q0 = np.array(st0.q_arm)
    c.new_stream()
    v = c.zeros()
    v[j] = 1.2 * float(c.robot.arm.velocity_max[j])
    st = c.until(lambda st: st.protective_stop and st.protective_stops > stops0, 2.0,
                 f"a protective stop for joint {j + 1} at 1.2 x its velocity limit", lambda: c.send(v))
    if f"joint {j + 1}" not in st.protective_reason:
        raise ContractError(f"protective_reason {st.protective_reason!r} does not name joint {j + 1}")
    if st.refused.get("firmware", 0) <= fw0:
        raise ContractError("the refused command is not counted in refused.firmware")
    moved = float(np.max(np.abs(np.array(st.q_arm) - q0)))
    if moved > 0.01:
        raise ContractError(f"the arm moved {moved:.4f} rad on a refused command")
    return {"protective_reason": st.protective_reason, "moved": moved}


def check_stops_the_stopped_stream(c: Controller) -> dict[str, Any]:
    """After a protective stop (:func:`check_refuses_past_limits` just ran) the stopped stream's
    commands stay refused (``refused.ended``), and a new stream resumes."""
    st0 = c.until(lambda st: st.protective_stop and _at_rest(st), 2.0 + SLACK, "the robot at rest in its stop")
    st = _ended(c, st0, lambda st: st.protective_stop, "stopped")
    c.new_stream()
    st = c.until(lambda st: not st.protective_stop and not st.stale_stop, 2.0, "a new stream resuming",
                 lambda: c.send(c.zeros()))
    return {"refused_ended": st.refused.get("ended", 0)}


def _ended(c: Controller, st0: Any, stopped: Callable[[Any], bool], which: str) -> Any:
    """Legal commands of the stream the robot's stop ended, for 0.1 s: refused and counted in
    ``refused.ended`` (not ``refused.firmware``), the robot still in its stop; the last state."""
    time.sleep(0.1)  # what the check before sent (a stream of illegal commands: firmware) has landed
    st0 = c.drain() or st0
    fw0, end0 = st0.refused.get("firmware", 0), st0.refused.get("ended", 0)
    st = _resting(c, 0.1)  # legal commands, the stopped stream
    if not stopped(st) or st.refused.get("ended", 0) <= end0:
        raise ContractError(f"the {which} stream's commands were not refused as ended (refused.ended): "
                            f"{Controller._brief(st)}")
    if st.refused.get("firmware", 0) > fw0:
        raise ContractError(f"the {which} stream's commands counted as firmware faults (refused.firmware "
                            f"{fw0} -> {st.refused['firmware']}): each would hold the daemon in a safe stop")
    return st


def check_brakes_when_stale(c: Controller, stale_timeout: float, joint: int | None = None,
                            rate: float = 0.3) -> dict[str, Any]:
    """A moving joint, then no command: ``stale_stop`` within the command timeout and the
    executed rates at 0 soon after.

    Args:
        stale_timeout: [s] the driver's command timeout.
        rate: [rad/s] the joint's speed before the commands stop.
    """
    j = _moving(c, joint, rate)
    st = c.drain()
    if st is None or abs(st.v_arm[j]) < 0.5 * rate:
        raise ContractError(f"joint {j + 1} did not follow {rate} rad/s: {Controller._brief(st)}")
    t_last = time.monotonic()
    st = c.until(lambda st: st.stale_stop, stale_timeout + SLACK, "stale_stop after the commands stopped")
    detect = time.monotonic() - t_last
    brake = rate / float(c.robot.arm.acceleration_max[j])
    st = c.until(_at_rest, brake + stale_timeout + SLACK, "the robot braked to rest")
    c.new_stream()  # leave it ready for the next check
    c.until(lambda st: not st.stale_stop, 2.0, "a new stream after the stale stop", lambda: c.send(c.zeros()))
    return {"detect_s": detect, "stale_stop": True}


def check_stale_ends_the_stream(c: Controller, stale_timeout: float, joint: int | None = None,
                                rate: float = 0.3) -> dict[str, Any]:
    """After a stale stop the stopped stream's commands (late on the way, or from a sender that
    froze) are refused and counted in ``refused.ended``, not ``refused.firmware`` (the daemon faults on
    each firmware refusal: the stop is one event); the robot stays in its stop; a new stream resumes.

    Args:
        stale_timeout: [s] the driver's command timeout.
        rate: [rad/s] the joint's speed before the commands stop.
    """
    j = _moving(c, joint, rate)
    brake = rate / float(c.robot.arm.acceleration_max[j])
    st0 = c.until(lambda st: st.stale_stop and _at_rest(st), stale_timeout + brake + 2 * SLACK,
                  "the robot at rest in its stale stop")
    st = _ended(c, st0, lambda st: st.stale_stop, "stale")
    c.new_stream()
    st = c.until(lambda st: not st.stale_stop, 2.0, "a new stream resuming", lambda: c.send(c.zeros()))
    return {"refused_ended": st.refused.get("ended", 0)}


def check_all(c: Controller, min_rate_hz: float, stale_timeout: float) -> dict[str, Any]:
    """Every check, in an order that leaves each one's robot as the next expects it."""
    return {"states": check_states(c, min_rate_hz), "lease": check_lease(c),
            "stale": check_brakes_when_stale(c, stale_timeout),
            "stale_stream": check_stale_ends_the_stream(c, stale_timeout),
            "limits": check_refuses_past_limits(c), "stopped_stream": check_stops_the_stopped_stream(c)}
