"""``wmm-qp driver franka``: drive a real robot through its own interface, speaking the daemon's protocol."""

from __future__ import annotations

import argparse
import sys

HELP = "drive a real robot behind the daemon's protocol (driver franka --robot-ip IP: a Franka FR3 via libfranka)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from ..cli_common import add_service_arguments
    from .common import add_robot_argument

    sub = parser.add_subparsers(dest="driver", metavar="ROBOT", required=True)
    p = sub.add_parser("franka", help="a Franka FR3 through libfranka's joint velocity interface (1 kHz)",
                       description="a Franka FR3 through libfranka's joint velocity interface (1 kHz); "
                                   "pip install 'wmm-qp[franka]'")
    p.add_argument("--robot-ip", required=True, metavar="IP", help="the robot's (or franky-sim's) address")
    add_service_arguments(p)
    add_robot_argument(p)
    p.set_defaults(robot_config=None)  # None: configs/robots/fr3.toml
    p.add_argument("--stale-timeout", type=float, default=None, metavar="S",
                   help="[s] commands older than this brake the arm to rest (default: configs/sim.toml's "
                        "stale_timeout, 0.025)")


def run(args: argparse.Namespace) -> int:
    from wmm_qp_sim import load_sim_config

    from ..cli_common import stop_on_signals
    from ..drivers.franka import FrankaDriver
    from .common import robot_service_config

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
    driver = FrankaDriver(svc, robot, stale_timeout=stale, referee=sim_cfg.referee)
    code = driver.run(args.robot_ip, stop_on_signals())
    sh = driver.shaper
    violations = {k: n for k, n in driver.referee.counts.items() if n}
    last = f" (last: {sh.reason})" if sh.reason else ""
    print(f"wmm-qp driver franka: stopped at t = {driver.t:.3f} s (exit {code}), violations {violations}, "
          f"protective stops {sh.protective_stops}{last}, refused {dict(driver.refused)}", file=sys.stderr, flush=True)
    return code
