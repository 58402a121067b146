"""``wmm-qp driver ros2``: a robot run by ROS 2 (ros2_control) behind the daemon's protocol.

One process, two threads: rclpy's executor stores the robot's newest joint state and odometry
(:class:`~.hardware.Ros2Hardware`); the driver's cycle (the robot file's ``[ros2] rate_hz``)
reads them, takes the daemon's commands from Zenoh and writes the arm's rates and the base's
twist. Every command passes wmm-qp's robot firmware first, the same as the FR3's
(:mod:`wmm_qp_service.drivers.franka`) and the sim's:

- the lease/instance/seq gate (:class:`wmm_qp_robot.lease_gate.LeaseGate`);
- the referee (:mod:`wmm_qp_robot.referee`) judges every command as received and the measured
  positions every cycle; its counts go out on ``sim/truth`` (ground truth NaN: a real robot);
- the command shaper (:class:`wmm_qp_robot.shaper.CommandShaper`) over the arm's joints and the
  base's wheels together: a jerk-limited stream within the velocity and acceleration limits,
  stale commands braked to rest (``stale_stop``; the stop ends the stream), a command past a
  velocity limit or one from which a joint could not brake before its position limit refused
  (protective stop, until a new stream at rest) — judged from where the joints are now: the
  newest joint state carried on by the rates written since it was measured, and a cycle more
  (what is written now acts on the robot's next update);
- a lost robot: no joint state for ``[ros2] state_timeout`` (none at all, the robot's broadcaster
  stopped, or every one refused) is a protective stop coded ``robot_state_lost`` naming the topic
  and the age; the driver brakes its output to rest and refuses every command until joint states
  come back and a new stream starts at rest.

The state it publishes (``state``, docs/protocol.md) is the robot's: q_arm measured, q_base the
odometry, ``v_arm`` and ``wheel_speeds`` the rates written (exactly 0 at rest, as the sim's
executed rates and the FR3's written stream), ``tau`` the joint state's efforts. The robot's
messages refused (another robot's joint names, garbage, a partial or non-finite state) are
counted in the state's ``refused`` (``joint_states_foreign``, ``joint_states_partial``,
``joint_states_invalid``, ``odom_invalid``). The driver never imports the sim.
"""

from __future__ import annotations

import contextlib
import json
import math
import sys
import threading
import time
from collections import deque
from pathlib import Path
from typing import Any

import numpy as np
import zenoh
from wmm_qp_robot.config import RefereeConfig
from wmm_qp_robot.lease_gate import LeaseGate
from wmm_qp_robot.referee import Referee
from wmm_qp_robot.shaper import CommandShaper, StreamLimits

import wmm_qp as w
from wmm_qp.fault_codes import FaultCode

from .. import robot_side
from ..config import ServiceConfig
from ..keys import Keys
from ..protocol import CommandMsg, StateMsg, TruthMsg, encode
from ..rate_loop import RateLoop
from ..transport import ROLE_SIM, open_session
from ..validation import Validator
from .hardware import Ros2Hardware, Ros2Measured

NAN3 = [math.nan] * 3
TRUTH_EVERY = 10
"""The referee's counts go out on ``sim/truth`` every this many cycles."""
WAIT_SAY = 2.0
"""[s] between two "waiting for joint states" lines at start."""
RING = 4096
"""States whose joint state's arrival is kept, to time the command computed from each."""


def stream_limits(robot: w.RobotConfig) -> StreamLimits:
    """The shaper's limits over the arm's joints then the base's wheels (no position limit)."""
    arm, b = StreamLimits.of(robot.arm), robot.base
    m = robot.n_wheels
    wa = np.asarray(b.wheel_acceleration_max, dtype=float)
    return StreamLimits(np.concatenate([arm.q_lo, np.full(m, -np.inf)]), np.concatenate([arm.q_hi, np.full(m, np.inf)]),
                        np.concatenate([arm.v_max, np.asarray(b.wheel_speed_max, dtype=float)]),
                        np.concatenate([arm.a_max, wa]), np.concatenate([arm.j_max, 1000.0 * wa]))


class Ros2Driver(LeaseGate):
    """The firmware side of the driver: commands in, the shaper and the referee, states out.

    Pure of rclpy and Zenoh: :meth:`on_command` takes a command's payload, :meth:`cycle` one
    measurement (or None) and returns the rates to write; :meth:`run` binds them to ROS 2 and
    Zenoh.

    Args:
        svc: service config (keys, validation ranges).
        robot: the robot file (its ``[ros2]`` table: topics, rate, state timeout).
        stale_timeout: [s] commands older than this brake the robot to rest.
        referee: the referee's tolerances.
        rate_hz: [Hz] the cycle (None: the robot file's ``[ros2] rate_hz``).
    """

    def __init__(self, svc: ServiceConfig, robot: w.RobotConfig, stale_timeout: float = 0.025,
                 referee: RefereeConfig | None = None, rate_hz: float | None = None) -> None:
        svc = svc.with_robot(robot)
        self.svc = svc
        self.robot = robot
        self.cfg = robot.ros2
        self.rate_hz = float(rate_hz if rate_hz is not None else self.cfg.rate_hz)
        self.dt = 1.0 / self.rate_hz
        self.keys = Keys.of(svc.prefix, svc.robot)
        LeaseGate.__init__(self, Validator(CommandMsg, svc.robot, svc.validation, n_arm=robot.n_arm,
                                           n_wheels=robot.n_wheels))
        self.n = robot.n_arm
        self.shaper = CommandShaper(stream_limits(robot), self.dt, stale_timeout)
        self.referee = Referee(robot, referee if referee is not None else RefereeConfig(), period_max=stale_timeout)
        self.cmd_seq = -1
        self.t = 0.0  # [s] the driver's time (monotonic, from its start)
        self.seq = 0
        self.lost = True  # no fresh joint state: commands are refused (a protective stop once started)
        self._stopped = False
        self.meas: Ros2Measured | None = None  # the newest measurement used
        self.q_now = np.zeros(self.n)  # [rad] the joints' positions now: measured, carried on by the rates written
        self._rx_seq = np.full(RING, -1, dtype=np.int64)  # state seq → its joint state's arrival [s, monotonic]
        self._rx_t = np.zeros(RING)
        self._pending = -1  # the state seq of the last command accepted, until written
        self.latency: deque[float] = deque(maxlen=500_000)  # [s] joint state in → the command from it out
        self.misses = 0  # cycles started after their deadline (the driver's loop)
        self.cycles = 0
        self.ros_in: list[float] = []  # [s] the joint states' publication → arrival, at the end of run()

    def _q(self) -> np.ndarray:
        """Where the arm's joints are now (:meth:`cycle`'s estimate) with the wheels' (unbounded:
        zeros) appended: what the firmware's cannot-stop checks judge."""
        return np.concatenate([self.q_now, np.zeros(self.robot.n_wheels)])

    def on_command(self, data: bytes, received: float) -> bool:
        """Validate a command, check its sender, judge it, hand it to the shaper.

        Args:
            data: the payload.
            received: [s] monotonic time of receipt.

        Returns:
            True when the shaper took it as its target.
        """
        msg = self.admit(data, self.referee)
        if msg is None:
            return False
        n, sh = self.n, self.shaper
        arm, wheels = np.array(msg.arm_rates, dtype=float), np.array(msg.wheel_speeds, dtype=float)
        self.referee.on_command(self.t, arm, wheels, sh.v[:n], sh.v[n:], period=msg.period, seq=msg.seq,
                                received=received, step=self.dt, stream=msg.stream, sent=msg.stamp)
        if self.lost:
            self.refused["state_lost"] += 1  # nothing measured to judge it against: the robot brakes
            return False
        ended = sh.ended
        if not sh.command(self.t, np.concatenate([arm, wheels]), (msg.lease, msg.stream), self._q()):
            self.refused["ended" if sh.ended > ended else "firmware"] += 1
            return False
        self.cmd_seq = msg.seq
        self._pending = msg.state_seq
        return True

    def written(self, now: float) -> None:
        """The rates were written at ``now`` [s, monotonic]: time the command accepted since the
        last write from its state's joint state (the state it names in ``state_seq``)."""
        k = self._pending
        if k >= 0 and self._rx_seq[k % RING] == k:
            self.latency.append(now - float(self._rx_t[k % RING]))
        self._pending = -1

    def report(self, ros_in: Any = ()) -> dict[str, Any]:
        """The driver's timing: state → command latency [ms] (a joint state's arrival → the rates
        computed from it written to the robot: the state out over Zenoh, the daemon's tick, the
        command back, the wait for this driver's next cycle), its loop's misses; ``ros_in``:
        [s] joint states' publication → arrival (their header stamp, one machine's clock)."""

        def pct(xs: Any) -> dict[str, float | int | None]:
            a = np.asarray(list(xs), dtype=float) * 1e3
            if not a.size:
                return {"n": 0, "p50_ms": None, "p99_ms": None, "max_ms": None}
            return {"n": int(a.size), "p50_ms": float(np.percentile(a, 50)), "p99_ms": float(np.percentile(a, 99)),
                    "max_ms": float(a.max())}

        return {"rate_hz": self.rate_hz, "cycles": self.cycles, "deadline_misses": self.misses,
                "state_to_command": pct(self.latency), "joint_states_in": pct(ros_in),
                "protective_stops": self.shaper.protective_stops, "refused": dict(self.refused),
                "violations": {k: n for k, n in self.referee.counts.items() if n}}

    def cycle(self, t: float, meas: Ros2Measured | None, now: float) -> np.ndarray:
        """One cycle: judge the measurement's age and positions, shape the next rates.

        Args:
            t: [s] the driver's time of this cycle.
            meas: the newest measurement (None: none yet).
            now: [s] monotonic time (the clock that stamped ``meas.received``).

        Returns:
            [rad/s] the arm's rates then the wheels' speeds to write.
        """
        self.t = t
        age = now - meas.received if meas is not None else math.inf
        if age > self.cfg.state_timeout:
            if not self.lost or not self.shaper.protective:
                topic = self.cfg.joint_states
                why = (f"no joint states on {topic!r} for {age:.3f} s (state_timeout {self.cfg.state_timeout:g} s)"
                       if meas is not None else f"no joint states on {topic!r} yet")
                self.shaper.protect(FaultCode.ROBOT_STATE_LOST, f"robot state lost: {why}")
            self.lost = True
        else:
            self.lost = False
            self.meas = meas
            self.referee.check_positions(meas.q_arm)  # type: ignore[union-attr]
        n, v_out = self.n, self.shaper.v  # (the rates written last cycle: the robot executes them)
        if not self.lost and meas is not None:
            # the joint state is `age` old and what is written now acts a cycle later: carry it on
            self.q_now = meas.q_arm + v_out[:n] * (age + self.dt)
        elif self.meas is not None:
            self.q_now = self.q_now + v_out[:n] * self.dt
        v = self.shaper.step(t, self._q())
        stopped = self.shaper.stale or self.shaper.protective
        if stopped and not self._stopped:
            self.referee.break_stream(hard=False)  # the robot stopped following the stream
        self._stopped = stopped
        return v

    def refused_counts(self, hw_counts: dict[str, int]) -> dict[str, int]:
        """The state's ``refused``: the gate's, the firmware's and the robot's refused messages."""
        return {**self.refused, **{k: n for k, n in hw_counts.items() if n}}

    def state_msg(self, hw_counts: dict[str, int]) -> StateMsg:
        """The wire message of this cycle's state (the newest measurement)."""
        self.seq += 1
        sh, n, m = self.shaper, self.n, self.meas
        assert m is not None
        self._rx_seq[self.seq % RING], self._rx_t[self.seq % RING] = self.seq, m.received
        return StateMsg(
            robot=self.svc.robot, seq=self.seq, stamp=time.time(), t=self.t,
            q_base=m.q_base.tolist(), q_arm=m.q_arm.tolist(), v_arm=sh.v[:n].tolist(),
            wheel_speeds=sh.v[n:].tolist(), tau=m.tau.tolist(), gripper_width=math.nan,
            stale_stop=sh.stale, cmd_seq=self.cmd_seq, instance=self.instance, lease=self.holder,
            protective_stop=sh.protective, protective_stops=sh.protective_stops,
            protective_reason=sh.protective_reason, protective_code=sh.protective_code,
            refused=self.refused_counts(hw_counts))

    def truth_msg(self) -> TruthMsg:
        """The referee's counts as ``sim/truth`` (no ground truth: NaN)."""
        return TruthMsg(
            robot=self.svc.robot, seq=self.seq, stamp=time.time(), t=self.t, instance=self.instance,
            state_seq=self.seq, base_true=NAN3, ee_true=NAN3, contact_force=[0.0, 0.0, 0.0],
            violations={k: n for k, n in self.referee.counts.items() if n})

    def run(self, stop: threading.Event, max_cycles: int | None = None, report: Path | None = None) -> int:
        """Drive the robot until ``stop`` (or ``max_cycles``): brake to rest, then exit; with
        ``report``, write :meth:`report` there as JSON.

        Returns:
            0 after a clean stop; 2 when ROS 2 is not installed (said on stderr).
        """
        from .node import Ros2Missing, RosNode

        def log(s: str) -> None:
            print(f"wmm-qp driver ros2: {s}", file=sys.stderr, flush=True)

        try:
            ros = RosNode("wmm_qp_driver")
        except Ros2Missing as e:
            log(f"error: {e}")
            return 2
        with ros, open_session(self.svc, ROLE_SIM) as session:
            hw = Ros2Hardware(ros.node, self.robot)
            k = self.keys
            sub = robot_side.command_subscriber(session, k, zenoh.handlers.FifoChannel(1024))
            pub, pub_truth = robot_side.state_publisher(session, k), robot_side.truth_publisher(session, k)
            lease_sub = robot_side.lease_watch(session, k)
            token = None
            try:
                said = -math.inf
                while hw.read() is None:  # nothing to report before the robot's first joint state
                    if stop.is_set():
                        return 0
                    if time.monotonic() - said > WAIT_SAY:
                        said = time.monotonic()
                        log(f"waiting for joint states on {self.cfg.joint_states!r} (sensor_msgs/JointState "
                            f"naming {', '.join(self.robot.arm.joints)}); refused so far {dict(hw.counts)}")
                    time.sleep(0.01)
                token = robot_side.alive_token(session, k)
                log(f"{k.state.rsplit('/', 1)[0]} driving the ROS 2 robot: joint states {self.cfg.joint_states!r}, "
                    f"odometry {self.cfg.odom!r}, arm {self.cfg.arm_command!r}, base {self.cfg.cmd_vel!r} "
                    f"({self.cfg.cmd_vel_type}), {self.rate_hz:g} Hz (instance {self.instance})")
                return self._loop(hw, sub, lease_sub, pub, pub_truth, stop, max_cycles)
            finally:
                self.ros_in = list(hw.ros_in)
                if report is not None:
                    report.write_text(json.dumps(self.report(self.ros_in), indent=1) + "\n")
                for ent in (token, lease_sub, sub, pub, pub_truth):
                    if ent is not None:
                        with contextlib.suppress(Exception):
                            ent.undeclare()

    def _loop(self, hw: Ros2Hardware, sub: Any, lease_sub: Any, pub: Any, pub_truth: Any, stop: threading.Event,
              max_cycles: int | None) -> int:
        # after a late tick the next one a whole period later (the absolute grid's next comes early,
        # and the shaper, which moves by the time elapsed, would move by less)
        loop = RateLoop(self.rate_hz, 0.0, clock=time.monotonic, rephase=True)
        now = t0 = loop.start()
        finishing = False
        n = 0
        errors = 0
        while True:
            while (a := lease_sub.try_recv()) is not None:
                self.on_lease(str(a.key_expr).rsplit("/", 1)[-1], a.kind == zenoh.SampleKind.PUT)
            while (c := sub.try_recv()) is not None:
                if finishing:
                    continue
                try:
                    self.on_command(c.payload.to_bytes(), time.monotonic())
                except Exception as e:  # never out of the control loop: the command is dropped
                    self.refused["error"] += 1
                    errors += 1
                    if errors <= 10:
                        print(f"wmm-qp driver ros2: a command dropped: {type(e).__name__}: {e}",
                              file=sys.stderr, flush=True)
            v = self.cycle(now - t0, hw.read(), time.monotonic())
            n += 1
            if not finishing and (stop.is_set() or (max_cycles is not None and n >= max_cycles)):
                finishing = True  # brake to rest, then exit
                self.shaper.halt()
            hw.write(v[self.n:], v[:self.n])
            self.written(time.monotonic())
            counts = dict(hw.counts)
            pub.put(encode(self.state_msg(counts)))
            done = finishing and self.shaper.at_rest
            if n % TRUTH_EVERY == 1 or done:
                pub_truth.put(encode(self.truth_msg()))
            if done:
                return 0
            now = loop.wait()
            self.cycles, self.misses = loop.ticks, loop.deadline_misses
