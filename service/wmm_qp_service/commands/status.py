"""``wmm-qp status [--json]``: show the daemon's status."""

from __future__ import annotations

import argparse
import json
import sys
from typing import TYPE_CHECKING

import msgspec

if TYPE_CHECKING:
    from ..protocol import InfoMsg

HELP = "show the daemon's status"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from ..cli_common import add_service_arguments
    from .common import add_robot_argument

    parser.add_argument("--json", action="store_true", help="print one JSON object (status + config)")
    parser.add_argument("--timeout", type=float, default=3.0, help="[s] wait for the daemon")
    add_service_arguments(parser)
    add_robot_argument(parser)


def run(args: argparse.Namespace) -> int:
    from ..client import Client
    from .common import robot_service_config

    _, svc = robot_service_config(args)
    with Client(svc, name="status-cli") as c:
        info = c.wait_for_daemon(args.timeout)
        why = c.no_daemon_reason() if info is None and not c.daemon_alive() else ""
    if info is None:
        why = why or f"the daemon of {svc.prefix}/{svc.robot} is alive but does not answer on its info key"
        print(f"wmm-qp status: error: {why}", file=sys.stderr)
        return 1
    if args.json:
        print(json.dumps(msgspec.to_builtins(info), default=str))
        return 0
    show(info, f"{svc.prefix}/{svc.robot}")
    return 0


def show(info: InfoMsg, where: str) -> None:
    """Print the status of the daemon at ``where`` (prefix/robot) as ``wmm-qp status`` does."""
    s, lp = info.status, info.status.loop
    total_viol = sum(s.robot_violations.values())
    print(f"robot      {where}   controller {info.config['controller']['kind']}"
          f"   task {info.task or '?'}")
    print(f"           {info.n_arm} joints [{', '.join(info.joints)}]   {info.base_kind or '?'} base, "
          f"{info.n_wheels} wheels [{', '.join(info.wheels)}]")
    print(f"mode       {s.mode}   state {'ok' if s.state_ok else 'NOT OK'}"
          f"{'   SAFE STOP' if s.safe_stop else ''}   robot {'alive' if s.robot_alive else 'not seen'}")
    print(f"command    {s.controller_status} {s.reason}".rstrip())
    print(f"loop       {lp.rate_hz:g} Hz (measured {lp.measured_hz:.1f})   ticks {lp.ticks}   "
          f"deadline misses {lp.deadline_misses}")
    print(f"tick time  p50 {lp.tick_p50_us:.0f} µs   p99 {lp.tick_p99_us:.0f} µs   "
          f"max {lp.tick_max_us:.0f} µs")
    rej = ", ".join(f"{k} {v}" for k, v in sorted(s.rejected.items())) or "none"
    print(f"rejected   {rej}")
    last = f"{s.last_fault_code}: {s.last_fault}" if s.last_fault_code else s.last_fault
    print(f"last fault {last or 'none'}"
          f"{'   RESUME NEEDED (send a mode)' if s.resume_needed else ''}")
    if s.faults:
        print(f"faults     {', '.join(f'{k} {v}' for k, v in sorted(s.faults.items()))}")
    lease = ("held" if s.lease_holder == s.lease else
             f"NOT HELD (the robot applies {s.lease_holder}'s commands)" if s.lease_holder else "not yet granted")
    print(f"lease      {lease}   robot instance {s.robot_instance or 'none'}   round trip {s.round_trip_ms:.1f} ms"
          f"   operator {s.operator or 'none'} (conflicts {s.operator_conflicts})")
    if s.robot_violations:  # a robot's referee: counts, 0 included
        print(f"robot      violations {total_viol} {s.robot_violations if total_viol else ''}".rstrip())
    else:  # {}: this robot publishes no truth (docs/protocol.md), nothing refereed it here
        print("robot      violations not refereed (the robot publishes no truth)")
    print(f"collision  {info.collision_summary or 'unknown (an older daemon)'}")
    if s.x:
        print(f"EE         x {[round(v, 4) for v in s.x]}   x_d {[round(v, 4) for v in s.x_d]}"
              f"   DM {s.dm:.3f}")
    if s.quat_d:
        print(f"           orientation target (x, y, z, w) {[round(v, 4) for v in s.quat_d]}")
    if s.orientation_ignored:
        print(f"           {s.orientation_ignored} setpoint orientations ignored (position task)")
