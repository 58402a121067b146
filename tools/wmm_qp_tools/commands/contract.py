"""``wmm-qp contract``: check a running driver against the driver contract (docs/drivers.md).

It takes the daemon's place on the wire (the daemon must not run): it holds the control lease,
reads the driver's states and sends it commands, then prints one line per check (what it did and
what the driver did) — exit 0 when every check passes, 1 when one fails or no driver answers,
2 for bad arguments (:mod:`wmm_qp_tools.contract`)."""

from __future__ import annotations

import argparse
import json
import sys

HELP = "check a running driver against the driver contract (docs/drivers.md): one line per duty"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from wmm_qp_service.cli_common import add_service_arguments
    from wmm_qp_service.commands.common import add_robot_argument

    from ..contract import NAMES

    add_robot_argument(parser)
    add_service_arguments(parser)
    parser.add_argument("--json", action="store_true",
                        help='print one JSON object: {"robot", "passed", "checks": {name: {"passed", "detail", '
                             '"seconds"}}}')
    parser.add_argument("--rate", type=float, default=1000.0, metavar="HZ",
                        help="[Hz] the driver's cycle rate; its states must come at least at half of it, on its "
                             "own time (default 1000: the sim's and the FR3's)")
    parser.add_argument("--stale-timeout", type=float, default=None, metavar="S",
                        help="[s] the command timeout the driver must brake within (default: the service config's "
                             "watchdog.command_hold - watchdog.state_age_max, 0.025: what the daemon's bounds assume)")
    parser.add_argument("--wait", type=float, default=10.0, metavar="S",
                        help="[s] wait this long for the driver's first state (default 10)")
    parser.add_argument("--skip", action="append", default=[], choices=NAMES, metavar="CHECK",
                        help=f"a check not to run (repeatable): {', '.join(NAMES)}")


def run(args: argparse.Namespace) -> int:
    from wmm_qp_service.commands.common import robot_service_config

    from ..contract import (
        CHECKS,
        Check,
        ContractError,
        Controller,
        Kit,
        Result,
        check_no_daemon,
        run_checks,
        wait_for_driver,
    )

    for flag, value in (("--rate", args.rate), ("--wait", args.wait)):
        if not value > 0:
            print(f"wmm-qp contract: error: {flag} must be > 0", file=sys.stderr)
            return 2
    robot, svc = robot_service_config(args)  # a bad file or id: one line, exit 2
    stale = (svc.watchdog.command_hold - svc.watchdog.state_age_max if args.stale_timeout is None
             else args.stale_timeout)
    if not stale > 0:
        print("wmm-qp contract: error: --stale-timeout must be > 0", file=sys.stderr)
        return 2
    out = sys.stderr if args.json else sys.stdout
    root = f"{svc.prefix}/{svc.robot}"

    def fail(why: str) -> int:
        if args.json:
            print(json.dumps({"robot": root, "passed": False, "error": why, "checks": {}}))
        print(f"wmm-qp contract: error: {why}", file=sys.stderr)
        return 1

    try:
        ctl = Controller(svc, robot)
    except Exception as e:  # zenoh's error: the daemon's endpoint is taken
        first = str(e).splitlines()[0][:200] if str(e) else type(e).__name__
        return fail(f"cannot open a session listening on {svc.zenoh.daemon_endpoint} ({first}): is a daemon running "
                    f"there? The contract takes the daemon's place: stop it first")
    results: list[Result] = []
    with ctl:
        print(f"contract: {root} ({robot.n_arm} joints, {robot.n_wheels} wheels), rate {args.rate:g} Hz, command "
              f"timeout {stale * 1e3:g} ms, {ctl.scheduling}: waiting for the driver's state on {ctl.keys.state}",
              file=out, flush=True)
        try:
            check_no_daemon(ctl)
            state = wait_for_driver(ctl, args.wait)
        except ContractError as e:
            return fail(str(e))
        print(f"contract: driver instance {state.instance}; {len(CHECKS) - len(set(args.skip))} checks (they move "
              f"the arm: one joint to near its position limit, then back)", file=out, flush=True)
        width = max(len(ch.name) for ch in CHECKS)

        def started(ch: Check) -> None:
            print(f"  ....  {ch.name:<{width}}  {ch.duty}", end="\r", file=out, flush=True)

        def done(r: Result) -> None:
            print(f"  {'PASS' if r.passed else 'FAIL'}  {r.name:<{width}}  {r.detail}", file=out, flush=True)

        results = run_checks(Kit(ctl, args.rate, stale), args.skip, done, started if out.isatty() else None)
    failed = [r.name for r in results if not r.passed]
    print(f"contract: {len(results) - len(failed)} of {len(results)} checks passed"
          + (f"; FAILED: {', '.join(failed)}" if failed else ""), file=out, flush=True)
    if args.json:
        print(json.dumps({"robot": root, "passed": not failed,
                          "checks": {r.name: {"passed": r.passed, "detail": r.detail, "seconds": round(r.seconds, 3)}
                                     for r in results}}))
    return 1 if failed else 0
