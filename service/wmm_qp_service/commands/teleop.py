"""``wmm-qp teleop``: stream setpoints to the daemon (haptic-like stream or the paper's circle)."""

from __future__ import annotations

import argparse
import sys

HELP = "stream setpoints to the daemon: a haptic-like stream or the paper's circle"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from ..cli_common import add_service_arguments
    from .common import add_robot_argument

    parser.add_argument("stream", choices=("haptic", "circle"), nargs="?", default="haptic",
                        help="haptic: jittery, jumpy stream; circle: the paper's circle with "
                             "feed-forward velocity")
    parser.add_argument("--duration", type=float, default=20.0, help="[s] how long to stream")
    parser.add_argument("--rate", type=float, default=100.0, help="[Hz] send rate")
    parser.add_argument("--seed", type=int, default=0, help="jitter/jump seed (haptic)")
    parser.add_argument("--no-mode", action="store_true",
                        help="do not switch the daemon to track mode first")
    add_service_arguments(parser)
    add_robot_argument(parser)


def run(args: argparse.Namespace) -> int:
    import time

    import numpy as np

    from ..client import Client
    from ..teleop import stream_circle, stream_haptic
    from .common import robot_service_config

    if not (args.duration > 0 and args.rate > 0):
        print("wmm-qp teleop: error: --duration and --rate must be > 0", file=sys.stderr)
        return 2
    _, svc = robot_service_config(args)
    with Client(svc, name="teleop") as c:
        info = c.wait_for_daemon(5.0)
        if info is None or not info.status.x:
            print("wmm-qp teleop: error: no daemon with a live robot answers", file=sys.stderr)
            return 1
        if not args.no_mode:
            c.set_mode("track")
            time.sleep(0.1)
            info = c.info() or info
        x0 = np.array(info.status.x)
        if args.stream == "circle":
            n = stream_circle(c, x0, args.duration, args.rate)
        else:
            n = stream_haptic(c, x0, args.duration, args.rate, seed=args.seed)
    print(f"teleop: sent {n} setpoints ({args.stream}) in {args.duration:g} s")
    return 0
