"""The daemon process (``wmm-qp serve``): the lease, the wiring, and the loop that runs the cycle.

:class:`Daemon` opens the Zenoh session, takes the lease (:mod:`.lease`), wires the cycle to
the robot (:class:`~.robot_link.ZenohRobotLink`) and the service side
(:class:`~.zenoh_service.ZenohService`), and runs :class:`ControlLoop` on the control thread at
the loop's rate (or on each state, ``loop.trigger = "state"``).
"""

from __future__ import annotations

import contextlib
import gc
import sys
import threading
import time
from collections import Counter
from pathlib import Path
from typing import TYPE_CHECKING, Any

import msgspec
import zenoh

import wmm_qp as w
from wmm_qp.scene import Scene

from ..config import ServiceConfig
from ..keys import Keys
from ..protocol import StateMsg, StatusMsg, encode
from ..rate_loop import LoopTiming, RateLoop, StateLoop, realtime_priority
from ..tick_stages import POLL, QUERIES, STATUS, TELEMETRY, TickStages
from ..transport import ROLE_DAEMON, io_priority, open_session
from . import reports
from .core import ControlCore
from .cycle import Cycle
from .host import HostInputs
from .lease import LeaseHeld, LeaseRace, acquire
from .robot_link import ZenohRobotLink
from .watchdog import FaultLog, say
from .zenoh_service import ZenohService, answer_queries

if TYPE_CHECKING:
    from ..recording.journal import TickJournal


class ControlLoop:
    """One tick of a run: the state, the service's inputs, the cycle, then the service's outputs.

    Args:
        daemon: the daemon (its core, validators' counts, lease race settings).
        cycle: state in → tick → command out.
        service: the service side.
        timing: the loop's timing (its tick count and work time).
        state_loop: the state trigger's loop (None: the fixed rate; the cycle polls the state).
        race: the start-up race for the lease.
    """

    def __init__(self, daemon: Daemon, cycle: Cycle, service: ZenohService, timing: LoopTiming,
                 state_loop: StateLoop[StateMsg] | None, race: LeaseRace) -> None:
        self.daemon, self.core, self.cycle, self.service = daemon, daemon.core, cycle, service
        self.timing, self.state_loop, self.race = timing, state_loop, race
        self.stages = daemon.stages
        self.journal = daemon.journal

    def tick(self, now: float) -> bool:
        """Run the tick that is due at ``now`` [s]; False: the lease race was lost (leave)."""
        core, cycle, service, stages, timing = self.core, self.cycle, self.service, self.stages, self.timing
        # ---- the state: the state loop's wait() polled it, the fixed-rate loop polls now
        if stages is not None:
            stages.begin(time.perf_counter_ns())
        m = self.state_loop.item if self.state_loop is not None else cycle.poll_state()
        if m is not None:
            cycle.lap_state()
            if self.race.lost_to(core, now):
                return False
        # ---- the other inputs (FIFO of modes, the latest setpoint and obstacles)
        service.apply(core, now)
        if stages is not None:
            stages.lap(POLL)
        core.check_obstacles(now)
        # ---- control (stages: watchdogs, ruckig, step, publish)
        sent = cycle.command(now)
        if self.journal is not None:  # copies into shared memory; a writer process serialises
            self.journal.tick(core, sent, timing.ticks, now - core.t0, timing.last_work * 1e6)
        if sent is not None:
            # ---- after the command: telemetry (when someone listens), status, queries
            service.telemetry(core, sent, timing.ticks, now - core.t0, timing.last_work * 1e6, cycle.state_rx)
            if stages is not None:
                stages.lap(TELEMETRY)
        service.liveliness(core)
        service.status(timing.ticks, self._status)
        if stages is not None:
            stages.lap(STATUS)
        self.daemon.answer_queries(service.queryable, service.queries_per_tick)
        if stages is not None:
            stages.lap(QUERIES)
            if sent is not None:
                stages.end()
            else:
                stages.discard()
        return True

    def _status(self) -> StatusMsg:
        d = self.daemon
        st = reports.status(self.core, self.timing, d.rejected(), d.accepted())
        if self.journal is not None:
            self.journal.status(self.timing.ticks, st)
        return st


class Daemon:
    """The control daemon over Zenoh (``wmm-qp serve``).

    Args:
        svc: service config (an open robot id is the robot's name).
        ctl_cfg: controller config.
        robot: robot config.
        kind: controller kind; None = the controller config's.
        wait_lease: when another daemon holds the robot's lease, wait until it is free
            instead of refusing to start (:class:`~.lease.LeaseHeld`).
        scene: obstacles and the workspace fence (None: ``configs/scenes/default.toml``).
        breakdown: time each stage of every tick that publishes a command
            (:class:`~wmm_qp_service.tick_stages.TickStages`) and write the summary to this JSON
            file at exit (``wmm-qp serve --breakdown``; ``wmm-qp bench --only daemon``). None: off.
        record: record every tick to this MCAP file (``wmm-qp serve --record``,
            :mod:`wmm_qp_service.recording`); None: off.
        split_size, split_time: [MB], [s] start a new recording file past this size or time.
    """

    LEASE_GRACE = 1.0
    """[s] the sim may name another holder this long (tokens propagate) before this daemon
    concludes that it lost a start-up race for the lease."""

    def __init__(self, svc: ServiceConfig, ctl_cfg: w.ControllerConfig, robot: w.RobotConfig,
                 kind: str | None = None, wait_lease: bool = False, scene: Scene | None = None,
                 breakdown: str | Path | None = None, record: str | Path | None = None,
                 split_size: float | None = None, split_time: float | None = None) -> None:
        self.wait_lease = wait_lease
        self.breakdown = breakdown
        self.stages = TickStages() if breakdown is not None else None
        svc = svc.with_robot(robot)
        self.svc = svc
        self.core = ControlCore(svc, ctl_cfg, robot, kind, scene)
        self.keys = Keys.of(svc.prefix, svc.robot)
        self.inputs = HostInputs(svc, robot.n_arm, robot.n_wheels)
        self.loop: LoopTiming = RateLoop(svc.loop.rate_hz, svc.loop.spin_us * 1e-6)  # run() sets the trigger's
        self.scheduling = "not started"  # set by run(): the control thread's scheduling policy
        self.record = (record, split_size, split_time)
        self.journal: TickJournal | None = None  # the recording's hook (run() starts it)
        self.recorded: dict[str, Any] = {}  # the recording's summary (files, ticks, dropped) after run()

    def rejected(self) -> Counter[str]:
        """Rejected and refused messages by reason, all keys together."""
        return self.inputs.rejected(self.core)

    def accepted(self) -> dict[str, int]:
        """Accepted messages by key."""
        return self.inputs.accepted()

    def run(self, stop: threading.Event, max_ticks: int | None = None) -> StatusMsg:
        """Run until ``stop`` is set (or ``max_ticks``); returns the final status.

        Raises:
            LeaseHeld: another daemon holds the robot's lease (and ``wait_lease`` is off), at
                start or — after a start-up race the other one won — within ``LEASE_GRACE``.
        """
        with open_session(self.svc, ROLE_DAEMON, io_priority(self.svc.loop.rt_priority)) as session:
            self.core.lease = str(session.info.zid())
            if not acquire(session, self.keys, self.core.lease, self.wait_lease, stop):
                return reports.status(self.core, self.loop, self.rejected(), self.accepted())
            return self._run(session, stop, max_ticks)

    def answer_queries(self, queryable: Any, limit: int) -> int:
        """Answer at most ``limit`` pending ``info`` queries (:func:`~.zenoh_service.answer_queries`).

        Returns:
            the number answered.
        """
        return answer_queries(queryable, limit, self.keys.info, self._info, self._reply_failed)

    def _info(self) -> bytes:
        return encode(reports.info(self.core, self.loop, self.rejected(), self.accepted()))

    def _reply_failed(self, why: str) -> None:
        self.core.fault_record.last = why  # shown by the status; not a fault of the robot (not counted)

    def _run(self, session: zenoh.Session, stop: threading.Event, max_ticks: int | None) -> StatusMsg:
        core, svc, stages = self.core, self.svc, self.stages
        if self.record[0] is not None:  # its writer process starts before this thread's priority is raised
            from ..recording.journal import TickJournal, recording_meta

            self.journal = TickJournal(self.record[0], recording_meta(core, "serve", svc.loop.trigger),
                                       core.robot.n_arm, core.robot.n_wheels, self.record[1], self.record[2],
                                       svc.loop.rate_hz)
        # Zenoh's threads run one priority below (opened so: io_priority), this one at the loop's.
        self.scheduling = realtime_priority(svc.loop.rt_priority)
        print(f"wmm-qp serve: control thread: {self.scheduling}; trigger {svc.loop.trigger}",
              file=sys.stderr, flush=True)
        state_trigger = svc.loop.trigger == "state"
        link = ZenohRobotLink(session, self.keys, self.inputs.v_state, state_trigger, timed=stages is not None)
        service = ZenohService(session, self.keys, svc, core.lease, self.inputs)
        core.stages = stages
        cycle = Cycle(core, link, svc.robot, 1.0 / svc.loop.rate_hz, stages)
        state_loop = StateLoop(svc.loop.rate_hz, cycle.poll_state, block=link.wait) if state_trigger else None
        timing: LoopTiming = state_loop or RateLoop(svc.loop.rate_hz, svc.loop.spin_us * 1e-6)
        self.loop = timing
        core.stream.follow_state_age = state_loop is not None
        core.say = fault_log = FaultLog()
        race = LeaseRace(self.LEASE_GRACE, self.wait_lease)
        control = ControlLoop(self, cycle, service, timing, state_loop, race)
        gc.collect()
        gc.freeze()
        core.t0 = now = timing.start()
        try:
            while not stop.is_set() and (max_ticks is None or timing.ticks < max_ticks):
                if not control.tick(now):
                    break
                now = timing.wait()
        finally:
            fault_log.close()
            core.say = say
            gc.unfreeze()
            final = reports.status(core, timing, self.rejected(), self.accepted())
            service.close()
            link.close()
            if self.journal is not None:
                self.recorded = self.journal.close(timing.ticks)
            if stages is not None and self.breakdown is not None:
                with contextlib.suppress(Exception):
                    stages.write(self.breakdown, {"trigger": svc.loop.trigger, "rate_hz": svc.loop.rate_hz,
                                                  "loop": msgspec.to_builtins(final.loop)})
        if race.lost:
            raise LeaseHeld(self.keys.root, race.lost)
        return final
