"""``wmm-qp driver franka``: drive a real robot through its own interface, speaking the daemon's protocol."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

HELP = ("drive a real robot behind the daemon's protocol (driver franka --robot-ip IP: a Franka FR3 via libfranka; "
        "driver ros2 --robot-config FILE: a ros2_control robot)")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from ..cli_common import add_service_arguments
    from .common import add_embedded_arguments, add_robot_argument

    sub = parser.add_subparsers(dest="driver", metavar="ROBOT", required=True)
    p = sub.add_parser("franka", help="a Franka FR3 through libfranka's joint velocity interface (1 kHz)",
                       description="a Franka FR3 through libfranka's joint velocity interface (1 kHz); "
                                   "pip install 'wmm-qp[franka]'")
    p.add_argument("--robot-ip", required=True, metavar="IP", help="the robot's (or franky-sim's) address")
    add_service_arguments(p)
    add_robot_argument(p, default="fr3.toml")  # None: configs/robots/fr3.toml, set in run()
    p.add_argument("--stale-timeout", type=float, default=None, metavar="S",
                   help="[s] commands older than this brake the arm to rest (default: configs/sim.toml's "
                        "stale_timeout, 0.025)")
    p.add_argument("--rt-priority", type=int, default=None, metavar="N",
                   help="SCHED_FIFO priority of libfranka's cycle (its Zenoh threads one below), 0 = normal "
                        "scheduling (default: configs/sim.toml's rt_priority, 50: libfranka sets none with "
                        "RealtimeConfig.kIgnore; without root or CAP_SYS_NICE the driver says so and runs normally)")
    e = add_embedded_arguments(
        p, "embedded mode: the control core in libfranka's cycle (no wmm-qp serve)",
        "host the control daemon's core in libfranka's 1 kHz cycle: each cycle reads the state, ticks and writes "
        "the velocities in one thread; Zenoh still carries setpoints, modes, obstacles, status, telemetry, info "
        "and the lease (clients talk to this process)",
        "with --embedded: [Hz] the core's rate, dividing 1000 (default: 1000)")
    e.add_argument("--scene", type=Path, default=None, metavar="FILE",
                   help="with --embedded: the controller's obstacles and fence (default: configs/scenes/default.toml)")

    r = sub.add_parser("ros2", help="a robot run by ROS 2 (ros2_control): joint states and odometry in, the arm's "
                                    "forward velocity commands and the base's cmd_vel out (docs/ros2.md)",
                       description="a robot run by ROS 2 through ros2_control, on the topics of its robot file's "
                                   "[ros2] table; every command passes wmm-qp's robot firmware first (docs/ros2.md); "
                                   "pip install 'wmm-qp[ros2]'")
    add_service_arguments(r)
    r.add_argument("--robot-config", type=Path, required=True, metavar="FILE",
                   help="the robot file (configs/robots/*.toml; its [ros2] table names the topics)")
    r.add_argument("--stale-timeout", type=float, default=None, metavar="S",
                   help="[s] commands older than this brake the robot to rest (default: configs/sim.toml's "
                        "stale_timeout, 0.025)")
    r.add_argument("--rate", type=float, default=None, metavar="HZ",
                   help="[Hz] the driver's cycle: joint states read, commands written (default: the robot file's "
                        "[ros2] rate_hz, 250)")
    r.add_argument("--report", type=Path, default=None, metavar="JSON",
                   help="write the driver's timing at exit: state → command latency (a joint state's arrival → "
                        "the rates computed from it written), the joint states' transit, its loop's misses")


def run(args: argparse.Namespace) -> int:
    if args.driver == "ros2":
        return _run_ros2(args)
    from wmm_qp_sim import load_sim_config

    from ..cli_common import stop_on_signals
    from ..drivers.franka import FrankaDriver
    from .common import embedded_only_given, robot_service_config

    if args.robot_config is None:
        from wmm_qp.config import default_config_dir

        args.robot_config = default_config_dir() / "robots" / "fr3.toml"
    robot, svc = robot_service_config(args)
    if robot.base.kind != "fixed" or robot.n_arm != 7:
        print(f"wmm-qp driver franka: error: --robot-config {robot.path}: a Franka arm has 7 joints on a "
              f"fixed base; this file has {robot.n_arm} joints on a {robot.base.kind!r} base", file=sys.stderr)
        return 2
    sim_cfg = load_sim_config(None)
    stale = sim_cfg.stale_timeout if args.stale_timeout is None else args.stale_timeout
    if not 0.0 < stale <= 1.0:
        print("wmm-qp driver franka: error: --stale-timeout must be in (0, 1] s", file=sys.stderr)
        return 2
    if args.embedded and args.control_rate is not None and not 0 < args.control_rate <= 1000.0:
        print("wmm-qp driver franka: error: --control-rate must be in (0, 1000] Hz (the robot's cycle)",
              file=sys.stderr)
        return 2
    prio = sim_cfg.rt_priority if args.rt_priority is None else args.rt_priority
    if not 0 <= prio <= 99:
        print("wmm-qp driver franka: error: --rt-priority must be in [0, 99]", file=sys.stderr)
        return 2
    driver = FrankaDriver(svc, robot, stale_timeout=stale, referee=sim_cfg.referee, rt_priority=prio)
    if args.embedded:
        code = _run_embedded(args, driver)
        if code is None:
            return 3
    else:
        if (flag := embedded_only_given(args)) is not None:
            print(f"wmm-qp driver franka: error: {flag} needs --embedded (without it the driver hosts no "
                  f"controller: give it to wmm-qp serve)", file=sys.stderr)
            return 2
        code = driver.run(args.robot_ip, stop_on_signals())
    sh = driver.shaper
    violations = {k: n for k, n in driver.referee.counts.items() if n}
    last = f" (last: {sh.protective_reason})" if sh.protective_reason else ""
    print(f"wmm-qp driver franka: stopped at t = {driver.t:.3f} s (exit {code}){_clock(driver.t, driver.started_at)}, "
          f"violations {violations}, protective stops {sh.protective_stops}{last}, refused {dict(driver.refused)}",
          file=sys.stderr, flush=True)
    return code


def _run_embedded(args: argparse.Namespace, driver: Any) -> int | None:
    """``driver franka --embedded``: the control core in libfranka's cycle; None: another daemon
    holds the robot's lease (said on stderr; exit 3)."""
    from ..cli_common import stop_on_signals
    from ..daemon import LeaseHeld
    from ..drivers.franka_embedded import FrankaEmbedded
    from .common import load_scene_arg
    from .serve import controller_config

    emb = FrankaEmbedded(driver, controller_config(args), control_rate=args.control_rate, kind=args.controller,
                         scene=load_scene_arg(args))
    try:
        code = emb.run(args.robot_ip, stop_on_signals(), wait_lease=args.wait_lease)
    except LeaseHeld as e:
        print(f"wmm-qp driver franka: error: {e}", file=sys.stderr, flush=True)
        return None
    t = emb.control.timing
    print(f"wmm-qp driver franka: the embedded core ticked {t.ticks} times, {t.deadline_misses} deadline misses, "
          f"faults {dict(emb.control.core.fault_record.counts) or 'none'}", file=sys.stderr, flush=True)
    return code


def _clock(robot_s: float, started_at: float) -> str:
    """The robot's clock against the wall's since the motion started: a robot time well behind
    (franky-sim steps its physics slower than real time on a busy host) is said, not hidden."""
    import math
    import time

    wall = time.monotonic() - started_at
    if not math.isfinite(wall) or wall <= 0.5:
        return ""
    ratio = robot_s / wall
    slow = "; the robot's clock ran slower than the wall's (a simulator behind real time?)" if ratio < 0.9 else ""
    return f" in {wall:.1f} s of wall time ({ratio:.2f}× real time{slow})"


def _run_ros2(args: argparse.Namespace) -> int:
    """``driver ros2``: a ros2_control robot (docs/ros2.md)."""
    from wmm_qp_sim import load_sim_config

    from ..cli_common import stop_on_signals
    from ..ros2.driver import Ros2Driver
    from .common import robot_service_config

    robot, svc = robot_service_config(args)
    sim_cfg = load_sim_config(None)  # the firmware's defaults: the same stale timeout and referee as the sim's
    referee = sim_cfg.referee
    stale = sim_cfg.stale_timeout if args.stale_timeout is None else args.stale_timeout
    if not 0.0 < stale <= 1.0:
        print("wmm-qp driver ros2: error: --stale-timeout must be in (0, 1] s", file=sys.stderr)
        return 2
    if args.rate is not None and not 1.0 <= args.rate <= 2000.0:
        print("wmm-qp driver ros2: error: --rate must be in [1, 2000] Hz", file=sys.stderr)
        return 2
    driver = Ros2Driver(svc, robot, stale_timeout=stale, referee=referee, rate_hz=args.rate)
    code = driver.run(stop_on_signals(), report=args.report)
    sh = driver.shaper
    violations = {k: n for k, n in driver.referee.counts.items() if n}
    last = f" (last: {sh.protective_reason})" if sh.protective_reason else ""
    lat = driver.report(driver.ros_in)["state_to_command"]
    timing = (f"; state → command p50 {lat['p50_ms']:.2f} ms, p99 {lat['p99_ms']:.2f} ms over {lat['n']} commands"
              if lat["n"] else "")
    print(f"wmm-qp driver ros2: stopped at t = {driver.t:.3f} s (exit {code}), violations {violations}, "
          f"protective stops {sh.protective_stops}{last}, refused {dict(driver.refused)}, {driver.cycles} cycles, "
          f"{driver.misses} deadline misses{timing}", file=sys.stderr, flush=True)
    return code
