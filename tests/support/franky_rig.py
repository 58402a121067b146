"""franky-sim for the Franka driver's tests: a MuJoCo FR3 that speaks libfranka's protocol, in a
child process of the test (libfranka's connect holds the GIL while it waits for the server, so
the two cannot share one interpreter), watched through shared memory.

franky-sim enforces none of the robot's limits and models none of its reflexes. A post-step
callback watches its physics state and counts every step with a joint past the FR3's position or
velocity limits. :class:`ReflexModel` gives it the one thing it lacks for an error path: a reflex
of the robot's controller, tripped by the test, as the robot reports one over libfranka's
protocol — libfranka then raises its own ``ControlException`` in the driver.
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import os
import signal
import subprocess
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from wmm_qp_service.processes import CLI

import wmm_qp as w
from wmm_qp.config import default_config_dir

FR3 = default_config_dir() / "robots" / "fr3.toml"
# shared with the sim process: q (7), dq (7), steps, steps with a joint past its position limit,
# steps with a joint past its velocity limit, reflexes tripped, automatic error recoveries received,
# the gripper's width [m] (the fingers' joints, summed)
N_SHARED = 20
REFLEXES, RECOVERIES, GRIPPER = 17, 18, 19
RT_PRIORITY = 50
"""franky-sim's SCHED_FIFO priority in the rig: the driver's and the daemon's (configs/sim.toml
``rt_priority``, configs/service.toml)."""
CARTESIAN_REFLEX = 7
"""The index of ``cartesian_reflex`` in the robot state's 41 error flags (libfranka's ``Errors``)."""


class ReflexModel:
    """A reflex of the FR3's controller, which franky-sim does not model, tripped by the test.

    When ``trip`` is set, at the next physics step franky-sim's server aborts the running motion as
    the FCI does on a Cartesian collision reflex: the motion stops (franky-sim holds the joints
    where they were commanded), the robot state reports the ``Reflex`` mode with
    ``cartesian_reflex`` in its current and last motion errors, and the Move command is answered
    ``ReflexAborted``. libfranka reads those and raises its own ``ControlException`` ("motion
    aborted by reflex! ["cartesian_reflex"]"). The ``AutomaticErrorRecovery`` command clears it.

    Args:
        server: franky-sim's robot server (``SimulationServer.robot_servers[0]``).
        trip: set by the test; cleared when the reflex trips.
        shared: the shared counters (:data:`REFLEXES`, :data:`RECOVERIES`).
    """

    def __init__(self, server: Any, trip: Any, shared: Any) -> None:
        from franky_sim.franka_robot_protocol import (
            AutomaticErrorRecoveryCommand,
            AutomaticErrorRecoveryStatus,
            RobotCommand,
        )

        self.server, self.trip, self.shared = server, trip, shared
        self.active = False
        model = self

        class Recovery(AutomaticErrorRecoveryCommand):  # type: ignore[misc]
            def handle(self, _server: Any) -> None:
                model.active = False
                shared[RECOVERIES] += 1
                self.reply(AutomaticErrorRecoveryStatus.kSuccess)

        # franky-sim's own handler acknowledges without a state to clear; its command table is private
        commands = server._FrankaServer__command_class_map
        commands[RobotCommand.kAutomaticErrorRecovery] = Recovery
        server._get_state_bytes = self._state_bytes

    def _state_bytes(self) -> bytes:
        from franky_sim.franka_robot_protocol import RobotMode

        st = self.server.robot_state
        if self.active:
            errors = tuple(i == CARTESIAN_REFLEX for i in range(41))
            st = st.replace(robot_mode=RobotMode.kReflex, errors=errors, reflex_reason=errors)
        return bytes(st.pack_state())

    def step(self) -> None:
        """Trip the reflex if the test asked for it (called after each physics step)."""
        if not self.trip.is_set():
            return
        self.trip.clear()
        from franky_sim.franka_robot_protocol import MoveStatus, RobotCommand
        from franky_sim.franka_server import BaseCommand

        rs = self.server
        motion = rs.current_motion_id
        rs.stop_motion(send_preemption_signal=False)  # the motion stops, the joints held
        rs.reset_current_motion_id()
        self.active = True
        self.shared[REFLEXES] += 1
        if motion:
            BaseCommand.send_response(rs._tcp_socket, RobotCommand.kMove, motion, MoveStatus.kReflexAborted)


def serve(shared: Any, hostname: Any, stop: Any, q_lo: list[float], q_hi: list[float], v_max: list[float],
          trip: Any = None) -> None:
    """The child process: franky-sim with one FR3 (and its hand), watched; a reflex model when
    ``trip`` (an event) is given."""
    from franky_sim import SimulationServer
    from franky_sim.mujoco_simulator import MujocoSimulator

    lo, hi, vm = np.array(q_lo), np.array(q_hi), np.array(v_max)
    with MujocoSimulator(enable_visualization=False) as sim:
        rm = sim.add_robot()
        reflex: list[ReflexModel] = []

        def watch(s: Any) -> None:
            st = s.robots[0].inner_state
            q, dq = np.asarray(st.q, dtype=float), np.asarray(st.dq, dtype=float)
            shared[0:7], shared[7:14] = q.tolist(), dq.tolist()
            shared[14] += 1
            shared[15] += bool(np.any((q < lo - 1e-6) | (q > hi + 1e-6)))
            shared[16] += bool(np.any(np.abs(dq) > vm * 1.01))  # 1 %: the physics' own tracking
            shared[GRIPPER] = float(s.robots[0].hand_width)
            for r in reflex:
                r.step()

        sim.register_post_step_callback(watch)
        with SimulationServer(sim) as server:
            if trip is not None:
                reflex.append(ReflexModel(server.robot_servers[0], trip, shared))
            hostname.value = rm.hostname.encode()
            if os.environ.get("WMM_QP_FRANKY_OWN_LOOP"):  # franky-sim's own loop, to compare
                server.run_async()
                stop.wait()
            else:
                pace(server, stop)


def pace(server: Any, stop: Any, period: float = 1e-3, behind_max: float = 0.05) -> None:
    """franky-sim's ticks on absolute deadlines, one per ``period`` [s] of wall time, until ``stop``.

    franky-sim's own loop (``run_async``) sleeps ``period`` minus each tick's work, relative to
    the tick's start: every sleep's overshoot (timer slack, wake-up latency) is lost for good, and
    on a busy 2-core host its robot clock ran at about half real time (the driver stopped at robot
    time 46 s after 92 s of wall time). Here a late tick is made up by the next ones; a backlog
    over ``behind_max`` [s] is dropped, not burst through. The loop runs at the sim's real-time
    priority where the host allows it: the driver and the daemon spin at SCHED_FIFO, and on a
    2-core host a simulator at ordinary priority is the one starved (its state gaps then read as
    the daemon's stale states and stalls)."""
    with contextlib.suppress(AttributeError, OSError):  # as the robot side's processes: SCHED_FIFO when allowed
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(RT_PRIORITY))
    next_t = time.perf_counter()
    while not stop.is_set():
        server.run_once(realtime=False)
        next_t += period
        delay = next_t - time.perf_counter()
        if delay > 0:
            time.sleep(delay)
        elif delay < -behind_max:
            next_t = time.perf_counter()


@dataclass
class FrankySim:
    """A running franky-sim child process and its shared state."""

    proc: Any
    shared: Any
    stop: Any
    host: str
    trip: Any  # the reflex model's trip event (None: no reflex model)

    def q(self) -> np.ndarray:
        """[rad] the physics' joint positions now."""
        return np.array(self.shared[0:7])

    def close(self) -> None:
        self.stop.set()
        self.proc.join(10)
        if self.proc.is_alive():
            self.proc.kill()


def start_franky_sim(robot: w.RobotConfig, reflex: bool = False, timeout: float = 60.0) -> FrankySim:
    """Start franky-sim in a spawned child process; returns once it listens."""
    ctx = mp.get_context("spawn")
    a = robot.arm
    shared, hostname, stop = ctx.Array("d", N_SHARED), ctx.Array("c", 64), ctx.Event()
    trip = ctx.Event() if reflex else None
    proc = ctx.Process(target=serve, args=(shared, hostname, stop, a.position_lower.tolist(),
                                           a.position_upper.tolist(), a.velocity_max.tolist(), trip), daemon=True)
    proc.start()
    t0 = time.monotonic()
    while not hostname.value and time.monotonic() - t0 < timeout and proc.is_alive():
        time.sleep(0.1)
    sim = FrankySim(proc, shared, stop, hostname.value.decode(), trip)
    if not sim.host:
        sim.close()
        raise AssertionError("franky-sim did not start")
    return sim


@contextmanager
def driver_stack(sim: FrankySim, logs: Path, serve: bool = True,
                 driver_args: Sequence[str] = ()) -> Iterator[tuple[Any, dict[str, Any]]]:
    """``wmm-qp driver franka`` on franky-sim (with ``driver_args``, e.g. ``--embedded``; and
    ``wmm-qp serve``) on an isolated prefix, their stderr in ``logs/driver.log`` and
    ``logs/serve.log``; yields (service config, {name: process}); on exit each gets SIGINT (a
    clean stop), then is killed after 20 s."""
    from wmm_qp_service.processes import isolated_config

    robot = w.load_robot_config(FR3)
    svc = isolated_config(robot=robot)
    common = ["--robot-config", str(FR3), "--prefix", svc.prefix, "--daemon-endpoint", svc.zenoh.daemon_endpoint,
              "--sim-endpoint", svc.zenoh.sim_endpoint]
    procs: dict[str, Any] = {}
    try:
        driver = ["driver", "franka", "--robot-ip", sim.host, *driver_args]
        for name, argv in (("driver", driver), ("serve", ["serve"])):
            if name == "serve" and not serve:
                continue
            with open(logs / f"{name}.log", "w") as err:
                procs[name] = subprocess.Popen([*CLI, *argv, *common],
                                               stderr=err, stdin=subprocess.DEVNULL)
        yield svc, procs
    finally:
        for p in reversed(list(procs.values())):
            if p.poll() is None:
                p.send_signal(signal.SIGINT)
        for p in reversed(list(procs.values())):
            try:
                p.wait(20)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait(5)
