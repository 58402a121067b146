"""The processes of one real-time run: ``wmm-qp sim`` and ``wmm-qp serve`` on loopback (unique key
prefix and ports, :class:`~..processes.Stack`), a client that waits until they are ready, and the
service-side figures of the run (loop, state age, rejections, faults, exit codes)."""

from __future__ import annotations

import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from wmm_qp_service.client import Client, NotReady
from wmm_qp_service.processes import Stack, isolated_config

from wmm_qp.config import RobotConfig
from wmm_qp.exceptions import WmmQpError
from wmm_qp_tools.experiments.recorder import Recorder
from wmm_qp_tools.experiments.setup import Setup

STARTUP_TIMEOUT = 60.0  # [s] for the sim and the daemon to come up and the daemon to have a valid state


class RealtimeError(WmmQpError):
    """The real-time stack did not come up or did not produce a trace."""


@dataclass
class StackOptions:
    """How to start the sim and the daemon for one run.

    Attributes:
        controller: the daemon's controller kind.
        solver: the daemon's QP backend (None: the config's).
        rate_hz: [Hz] control rate.
        slip: the sim's base slip on or off.
        seed: the sim's slip seed (None: the sim config's).
        log_dir: the processes' logs go here.
        robot: the robot; both processes load its file and run under its name (None: their default).
        controller_file: the daemon's controller config (None: its default).
        scene_file: the scene both processes load (``--scene``: the daemon's collision rows on;
            None: their default scene and, the paper's setting, no collision rows).
        physics: the sim's plant (``wmm-qp sim --physics``), "kinematic" or "mujoco".
    """

    controller: str
    solver: str | None
    rate_hz: float
    slip: bool
    seed: int | None
    log_dir: Path
    robot: RobotConfig | None = None
    controller_file: Path | None = None
    scene_file: Path | None = None
    physics: str = "kinematic"


def options(name: str, setup: Setup, controller: str, solver: str | None, slip: bool, seed: int | None,
            rate_hz: float | None, log_dir: Path | None, controller_file: Path | None = None) -> StackOptions:
    """The options of a run named ``name`` for ``setup``'s robot, scene and plant (``rate_hz``
    None: the controller config's; ``log_dir`` None: a fresh temporary folder)."""
    log_dir = log_dir or Path(tempfile.mkdtemp(prefix=f"wmm-qp-rt-{name}-"))
    log_dir.mkdir(parents=True, exist_ok=True)
    return StackOptions(controller, solver, float(rate_hz or setup.ctl_cfg.rate_hz), slip, seed, log_dir,
                        setup.robot, controller_file, setup.scene.path if setup.scene is not None else None,
                        setup.sim_cfg.physics.plant)


def _sim_config_file(slip: bool, tmp: Path) -> list[str]:
    """Extra ``wmm-qp sim`` arguments for the slip switch (a minimal TOML when off)."""
    if slip:
        return []
    p = tmp / "sim_no_slip.toml"
    p.write_text("[slip]\nenabled = false\n")
    return ["--sim-config", str(p)]


def on_stack(opts: StackOptions, drive: Callable[[Client, Recorder], Any]) -> tuple[Any, Recorder, dict[str, Any]]:
    """Start sim and daemon, wait until they are ready, run ``drive(client, recorder)``, stop them.

    Returns:
        (what ``drive`` returned, the closed recorder, the service-side figures).

    Raises:
        RealtimeError: they did not come up within ``STARTUP_TIMEOUT``, or one exited first (the
            message names the process, why, and the logs).
    """
    svc = isolated_config(robot=opts.robot)
    daemon_args = ["--controller", opts.controller, *(["--solver", opts.solver] if opts.solver else []),
                   *([] if opts.controller_file is None else ["--controller-config", str(opts.controller_file)]),
                   *(["--no-collision"] if opts.scene_file is None else [])]  # the paper's setting: no rows
    sim_args = (_sim_config_file(opts.slip, opts.log_dir) + ([] if opts.seed is None else ["--seed", str(opts.seed)])
                + ["--physics", opts.physics])
    stack = Stack(svc, rate_hz=opts.rate_hz, log_dir=opts.log_dir, extra_daemon_args=daemon_args,
                  extra_sim_args=sim_args, robot_file=None if opts.robot is None else opts.robot.path,
                  scene_file=opts.scene_file)  # fmt: skip
    svc = stack.svc
    try:
        stack.start()
        with Client(svc, name="experiment", telemetry=True) as c:
            try:
                c.wait_ready(STARTUP_TIMEOUT, exited=stack.exited)
            except NotReady as e:
                raise RealtimeError(f"the stack did not come up: {e} (logs: {opts.log_dir})") from e
            rec = Recorder(c).open()
            c.telemetry()  # start from here
            info0 = c.info()
            wall0 = time.perf_counter()
            out = drive(c, rec)
            time.sleep(0.05)
            rec.drain()
            c.set_mode("hold")
            info1 = c.info()
            rec.drain()
            rec.close()
            wall = time.perf_counter() - wall0
    finally:
        codes = stack.stop()
    service: dict[str, Any] = {
        "rate_hz": opts.rate_hz,
        "transport": "zenoh, loopback",
        "exit_codes": codes,
        "logs": str(opts.log_dir),
        "wall_time": wall,
    }
    if info0 is not None and info1 is not None:
        l0, l1 = info0.status.loop, info1.status.loop
        ticks = l1.ticks - l0.ticks
        misses = l1.deadline_misses - l0.deadline_misses
        service |= {
            "ticks": ticks,
            "deadline_misses": misses,
            "misses_per_10k": round(1e4 * misses / ticks, 2) if ticks else None,
            "tick_p50_us": round(l1.tick_p50_us, 1),
            "tick_p99_us": round(l1.tick_p99_us, 1),
            "rejected": dict(info1.status.rejected),
            "last_fault": info1.status.last_fault,
            "collision": info1.status.collision,
        }
    return out, rec, service
