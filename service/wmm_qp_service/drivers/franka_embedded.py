"""``wmm-qp driver franka --embedded``: the daemon's control core in libfranka's 1 kHz cycle.

Each robot cycle (``readOnce`` … ``writeOnce``, :meth:`FrankaEmbedded.cycle`): the robot's time
advances by libfranka's duration; the measured state becomes the state message the core reads
(:meth:`~.franka.FrankaDriver.state_msg`); every ``decimation``-th cycle the core ticks and its
command goes straight to the driver's referee and shaper (:meth:`~.franka.FrankaDriver.on_command_msg`:
the referee judges it as received, then the shaper's firmware, as for a command off the wire);
the shaper gives this cycle's velocities, written at once. Then the slack
(:meth:`FrankaEmbedded.after`): the service thread publishes the state, every ``TRUTH_EVERY``-th
cycle the referee's counts, the core's telemetry and status; gripper commands reach the hand.
pylibfranka holds the GIL while ``readOnce`` waits for the robot, so no other Python thread runs
meanwhile: the Zenoh side (:class:`~..embedded.service.ServiceThread`) is pumped in this slack
every few cycles instead of on a thread.

The core's clock is the robot's: its time (the sum of libfranka's durations, the clock the
driver's stale timeout runs on) plus the wall time since this cycle's ``readOnce``. A robot whose
cycles come slower than the wall's (franky-sim on a loaded host) is not a stalled controller to
its watchdogs, while a tick that takes long within a cycle still shows. A cycle the core ticks in
whose robot time since the previous state exceeds 1.5 robot cycles (the loop was late for the
robot) is a deadline miss. The robot's control is the split driver's :class:`~.franka_link.FrankaLink`:
stopping (the arm brakes to rest, the motion is finished), a reflex of the robot
(``ControlException``: a protective stop, the control given back, the robot recovered by the first
command of a new stream at rest) and a lost connection are handled as
:meth:`~.franka.FrankaDriver.run` handles them.
"""

from __future__ import annotations

import math
import sys
import threading
import time
from collections.abc import Callable
from typing import Any

import numpy as np

import wmm_qp as w
from wmm_qp.scene import Scene

from ..embedded import EmbeddedControl
from ..embedded.service import embedded_session
from ..protocol import CommandMsg, StateMsg
from ..rate_loop import realtime_priority
from .franka import DT, TRUTH_EVERY, FrankaDriver
from .franka_link import FrankaLink, drive

LATE = 1.5
"""A cycle whose duration exceeds this many robot cycles was late for the robot (a miss)."""


class FrankaEmbedded:
    """The Franka driver with the control core in its cycle.

    Args:
        driver: the driver (its shaper, referee, lease gate and hand).
        ctl_cfg: controller config.
        control_rate: [Hz] the core's rate (None: the robot's 1 kHz); it divides 1 kHz.
        kind: controller kind (None: the controller config's).
        scene: the fence and obstacles of the controller (None: the default scene).
        clock: [s] monotonic clock (the time within a cycle); wall: [s] wall clock (stamps).
        cuts: the cycle's cost cuts (:class:`~..embedded.EmbeddedControl`).
    """

    def __init__(self, driver: FrankaDriver, ctl_cfg: w.ControllerConfig, *, control_rate: float | None = None,
                 kind: str | None = None, scene: Scene | None = None, clock: Callable[[], float] = time.monotonic,
                 wall: Callable[[], float] = time.time, cuts: bool = True) -> None:
        self.driver = driver
        self.mono = clock
        self._t_read = clock()
        rate = 1.0 / DT if control_rate is None else control_rate
        self.control = EmbeddedControl(driver.svc.with_(loop={"rate_hz": rate}), ctl_cfg, driver.robot,
                                       self._deliver, 1.0 / DT, kind=kind, scene=scene, on_input=self._on_input,
                                       clock=self.clock, wall=wall, cuts=cuts)
        self.cycles = 0
        self._q = np.zeros(driver.robot.n_arm)
        self._link: FrankaLink | None = None  # the robot's control, while the loop runs
        self._state: StateMsg | None = None
        self._ticked = False
        self._force = np.zeros(3)

    def clock(self) -> float:
        """[s] the core's clock: the robot's time, plus the wall time since this cycle's read."""
        return self.driver.t + (self.mono() - self._t_read)

    def _deliver(self, msg: CommandMsg) -> None:
        """The core's command, in memory: the referee, then the shaper, at this cycle's time."""
        # after libfranka ended the motion, the first command of a new stream at rest recovers the
        # robot, as on the split driver
        self.driver.on_command_msg(msg, self._q, self.mono(), recover=self._recover)

    def _recover(self) -> str | None:
        return "no robot to recover" if self._link is None else self.driver.recover(self._link)

    def _on_input(self, kind: str, data: bytes) -> None:
        if kind == "gripper":
            self.driver.on_gripper(data)

    def start(self) -> float:
        """Before the first cycle: the robot obeys this process's core; returns the start [s]."""
        self.driver.on_lease(self.control.core.lease, True)
        return self.control.start()

    def cycle(self, elapsed: float, q: np.ndarray, tau: np.ndarray, force: np.ndarray, now: float,
              tick: bool = True) -> np.ndarray:
        """Read → update → write's first two: the state in, the core's tick, this cycle's velocities.

        Args:
            elapsed: [s] libfranka's duration since the last cycle.
            q: [rad] measured joint positions.
            tau: [N·m] the external torque estimate.
            force: [N] the external force estimate at the EE (for the truth).
            now: [s] the monotonic clock at this cycle's read.
            tick: the core may tick (False while the driver is stopping).

        Returns:
            [rad/s] the velocities to write now.
        """
        d, c = self.driver, self.control
        d.t += elapsed
        self._t_read = now
        now = d.t  # the core's clock at the read
        self._q, self._force = q, force
        width = d.hand.width if d.hand is not None else math.nan
        state = d.state_msg(q, tau, width)
        self._ticked = tick and c.ticks_now(self.cycles)
        self.cycles += 1
        if self._ticked:
            if elapsed > LATE * DT:
                c.timing.miss()
            c.update(state, now)
        self._state = state
        return d.shape(q)

    def after(self) -> None:
        """The slack, after ``writeOnce``: hand-overs, inputs, the collector."""
        d = self.driver
        truth = d.truth_msg(self._force) if d.seq % TRUTH_EVERY == 1 else None
        self.control.after(d.t, self._state, truth, self._ticked)

    def loop(self, fr: Any, link: FrankaLink, stop: threading.Event, max_cycles: int | None,
             robot_ip: str) -> int:
        """libfranka's cycle until ``stop`` (or ``max_cycles``), then brake and finish.

        Returns:
            0 after a clean stop; 1 when the connection was lost or the robot did not recover.
        """
        d = self.driver
        self._link = link

        def step(finishing: bool) -> tuple[np.ndarray, int]:
            st, elapsed = link.read()
            v = self.cycle(elapsed, np.array(st.q, dtype=float), np.array(st.tau_ext_hat_filtered, dtype=float),
                           np.array(st.O_F_ext_hat_K, dtype=float)[:3], self.mono(), tick=not finishing)
            return v, self.cycles

        return drive(fr, link, d, stop, max_cycles, robot_ip, step, lambda done: self.after())

    def run(self, robot_ip: str, stop: threading.Event, max_cycles: int | None = None,
            wait_lease: bool = False) -> int:
        """Open the session, take the lease, connect to the robot and run its cycle.

        Returns:
            0 after a clean stop; 1 when the robot is unreachable or the connection was lost; 2
            without pylibfranka.

        Raises:
            LeaseHeld: another daemon controls this robot.
        """
        try:
            import pylibfranka as fr
        except ImportError:
            print("wmm-qp driver franka: error: needs pylibfranka (pip install 'wmm-qp[franka]')",
                  file=sys.stderr, flush=True)
            return 2
        d = self.driver
        # pylibfranka's readOnce holds the GIL while it waits for the robot: the service side
        # runs in the cycle's slack, not on a thread that would starve
        with embedded_session(d.svc, self.control, stop, wait_lease=wait_lease, robot_inputs=("gripper",),
                              rt_priority=d.rt_priority, threaded=False) as svc:
            if svc is None:
                return 0
            try:
                link = FrankaLink(fr, fr.Robot(robot_ip, fr.RealtimeConfig.kIgnore))
                link.start()
            except (fr.NetworkException, fr.FrankaException, RuntimeError) as e:
                print(f"wmm-qp driver franka: error: cannot connect to the robot at {robot_ip}: {e}",
                      file=sys.stderr, flush=True)
                return 1
            if d.hand is not None:
                d.hand.start(robot_ip)
            d.scheduling = realtime_priority(d.rt_priority)  # after the hand's child started
            print(f"wmm-qp driver franka: {d.keys.root} driving the robot at {robot_ip} (instance {d.instance}), "
                  f"the control core in its cycle at {self.control.timing.rate_hz:g} Hz ({d.scheduling}), lease "
                  f"{self.control.core.lease}", file=sys.stderr, flush=True)
            self.start()
            try:
                return self.loop(fr, link, stop, max_cycles, robot_ip)
            finally:
                self.control.stop()
                if d.hand is not None:
                    d.hand.close()
