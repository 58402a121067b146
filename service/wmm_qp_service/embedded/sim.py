"""``wmm-qp sim --embedded``: the simulated robot hosting the control core in its step loop.

:class:`EmbeddedSim` composes the sim's node (:class:`~..drivers.sim_node.SimNode`: the robot,
its firmware and referees, on either plant) and an :class:`~.control.EmbeddedControl`. Each
robot cycle (:meth:`EmbeddedSim.cycle`): the robot steps, receiving the command the core wrote in
the previous cycle (its referee judges it as received, before the firmware); the state it then
reports goes to the core, whose command goes straight into the robot's command inbox (stamped
on arrival, as the split sim stamps a command off the wire); then the slack. The step loop
keeps the sim's wall-clock rule (:meth:`SimNode.advance`): after a stall of the process — a
slow tick included — every step that was due runs before the next state, the robot executing
its held command and, past ``stale_timeout``, braking by itself, as a real robot's firmware
would have while its controller was late.

The robot obeys only the core in its own process: nothing is subscribed on ``cmd``, and its
state names the core's lease. A second daemon for the same robot sees that lease and refuses to
start.
"""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from wmm_qp_sim.config import SimConfig
from wmm_qp_sim.robot import SimRobot, SimState

import wmm_qp as w
from wmm_qp.scene import Scene, load_scene

from ..config import ServiceConfig
from ..daemon import FaultLog
from ..drivers.sim_node import CommandInbox, SimNode
from ..protocol import CommandMsg
from ..rate_loop import RateLoop, realtime_priority
from .control import EmbeddedControl
from .service import embedded_session

REFEREE_LINES = 50
"""The referee's events said on stderr at most (as the split sim)."""


class EmbeddedSim:
    """The simulated robot and the control core in one thread.

    Args:
        svc: service config (keys, endpoints, validation ranges, watchdogs).
        sim_cfg: the sim's config (its rate is the robot's cycle).
        robot: robot config.
        ctl_cfg: controller config.
        control_rate: [Hz] the core's rate (None: the sim's); it must divide the sim's rate.
        kind: controller kind (None: the controller config's).
        scene: the obstacles and the fence of the controller and of the referee (None: the
            default scene).
        seed, ramp, truth, sim: as :class:`~..drivers.sim_node.SimNode`.
        rt_priority: SCHED_FIFO priority of the cycle's thread (0: normal scheduling).
        clock: [s] monotonic clock of the loop, the inbox and the core.
        sleep: the loop's sleep [s].
        wall: [s] wall clock (stamps).
        spin_s: [s] spin this long before each cycle's deadline instead of sleeping (the
            daemon's ``loop.spin_us``: a core that slept a whole period runs the next tick from
            cold caches; with ``cuts`` only).
        cuts: the cycle's cost cuts (:class:`~.control.EmbeddedControl`'s collector, the spin,
            and the service thread one SCHED_FIFO level below the cycle); False: the
            interpreter's and the sim's defaults (``--plain-cycle``).
    """

    def __init__(self, svc: ServiceConfig, sim_cfg: SimConfig, robot: w.RobotConfig, ctl_cfg: w.ControllerConfig,
                 *, control_rate: float | None = None, kind: str | None = None, scene: Scene | None = None,
                 seed: int | None = None, ramp: bool = True, truth: bool = True, sim: SimRobot | None = None,
                 rt_priority: int = 0, clock: Callable[[], float] = time.monotonic,
                 sleep: Callable[[float], None] = time.sleep, wall: Callable[[], float] = time.time,
                 spin_s: float = 0.0, cuts: bool = True) -> None:
        scene = scene if scene is not None else load_scene()
        self.node = SimNode(svc, sim_cfg, robot, seed=seed, ramp=ramp, scene=scene, sim=sim, truth=truth)
        self.svc = self.node.svc
        self.rt_priority = rt_priority
        self.inbox: CommandInbox[CommandMsg] = CommandInbox(clock=clock)
        rate = sim_cfg.rate_hz if control_rate is None else control_rate
        self.control = EmbeddedControl(self.svc.with_(loop={"rate_hz": rate}), ctl_cfg, robot, self.inbox.put,
                                       sim_cfg.rate_hz, kind=kind, scene=scene, on_input=self._on_input,
                                       clock=clock, wall=wall, cuts=cuts)
        self.cuts = cuts
        self.loop = RateLoop(sim_cfg.rate_hz, spin_s if cuts else 0.0, clock=clock, sleep=sleep)
        self.cycles = 0
        self.scheduling = "not started"
        self.say: Callable[[str], None] = lambda line: print(line, file=sys.stderr, flush=True)
        self._counted = 0
        self._said = 0

    def _on_input(self, kind: str, data: bytes) -> None:
        """The robot's own inputs (validated by the node, counted when refused)."""
        if kind == "box":
            self.node.place_box(data)
        elif kind == "gripper":
            self.node.command_gripper(data)
        elif kind == "obstacles":
            self.node.set_obstacles(data)

    def start(self) -> float:
        """Step 0 now; returns the first cycle's start [s]."""
        self.node.on_lease(self.control.core.lease, True)  # the robot obeys this process's core
        self.control.start()
        now = self.node.t0 = self.loop.start()
        self.node.steps = 0
        return now

    def cycle(self, now: float) -> SimState:
        """One robot cycle at ``now`` [s]: step(s), state, tick (every ``decimation``-th), slack."""
        node, control = self.node, self.control
        st = node.advance(now, self.inbox, node.accept_msg)
        node.publications += 1
        msg = node.state_msg(st, node.publications)
        ticked = control.ticks_now(self.cycles)
        self.cycles += 1
        if ticked:
            control.update(msg, now)
        truth = node.truth_msg(st, node.publications) if node.truth else None
        control.after(now, msg, truth, ticked)
        if (total := sum(st.violations.values())) != self._counted and self._said < REFEREE_LINES:
            self._counted, self._said = total, self._said + 1
            self.say(f"wmm-qp sim: referee: {st.violations} at t = {st.t:.3f} s; last: "
                     f"{node.sim.referee.last_event}; stale {st.stale_stop}, protective {st.protective_stop}")
        return st

    def wait(self) -> float:
        """Until the next cycle; a cycle the core ticks in that starts after its deadline is a
        miss. Returns its start [s]."""
        before = self.loop.deadline_misses
        now = self.loop.wait()
        if self.loop.deadline_misses > before and self.control.ticks_now(self.cycles):
            self.control.timing.miss()
        return now

    def run_cycles(self, n: int, now: float | None = None) -> SimState:
        """``n`` cycles without transport (tests: a fake clock); starts the loop if ``now`` is None."""
        if now is None:
            now = self.start()
        st = self.node.sim.state()
        for _ in range(n):
            st = self.cycle(now)
            now = self.wait()
        return st

    def run(self, stop: threading.Event, max_cycles: int | None = None, wait_lease: bool = False,
            report: str | Path | None = None) -> SimState:
        """Open the session, take the lease, run until ``stop`` (or ``max_cycles``).

        Args:
            stop: ends the loop.
            max_cycles: robot cycles at most.
            wait_lease: wait for another daemon's lease instead of refusing to start.
            report: write the cycle's figures (:meth:`EmbeddedControl.report`) to this JSON file
                at exit.

        Raises:
            LeaseHeld: another daemon controls this robot.
        """
        st = self.node.sim.state()
        with embedded_session(self.svc, self.control, stop, wait_lease=wait_lease, truth=self.node.truth,
                              rt_priority=self.rt_priority if self.cuts else 0) as svc:
            if svc is None:
                return st
            self.scheduling = realtime_priority(self.rt_priority)
            log = FaultLog()
            self.say = log
            print(f"wmm-qp sim: embedded cycle: {self.scheduling}, spin {self.loop.spin_s * 1e6:g} µs, "
                  f"{'cuts on' if self.cuts else 'plain (no cuts)'}; service thread: "
                  f"{f'SCHED_FIFO {svc.rt_priority} asked' if svc.rt_priority else 'normal scheduling'}; "
                  f"control at {self.control.timing.rate_hz:g} Hz "
                  f"(every {self.control.decimation} robot cycle(s)); lease {self.control.core.lease}",
                  file=sys.stderr, flush=True)
            now = self.start()
            try:
                while not stop.is_set() and (max_cycles is None or self.cycles < max_cycles):
                    st = self.cycle(now)
                    now = self.wait()
            finally:
                self.control.stop()
                log.close()
                self.say = lambda line: print(line, file=sys.stderr, flush=True)
                if report is not None:
                    write_report(report, self.report(svc.pumps, svc.errors))
        return st

    def report(self, pumps: int = 0, errors: int = 0) -> dict[str, Any]:
        """The cycle's figures and the service thread's."""
        return self.control.report() | {"cycles": self.cycles, "skipped": self.loop.skipped,
                                        "caught_up": self.node.caught_up,
                                        "service": {"pumps": pumps, "errors": errors}}


def write_report(path: str | Path, data: dict[str, Any]) -> None:
    """Write a cycle report as JSON (never raises: said on stderr)."""
    import json

    try:
        Path(path).write_text(json.dumps(data, indent=1), encoding="utf-8")
    except OSError as e:
        print(f"wmm-qp sim: cannot write the cycle report {path}: {e}", file=sys.stderr, flush=True)
