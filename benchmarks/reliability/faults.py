"""Fault timing figures: sim/daemon SIGKILL and restart, setpoint flood, state loss/delay, SIGSTOP.

    .venv/bin/python benchmarks/reliability/faults.py --rate 1000 --json --out benchmarks/reliability/faults.json

Each scenario runs against the real processes (``wmm_qp_tools.faults``); latencies come
from the publishers' wall-clock stamps. See docs/reliability.md.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

SCENARIOS = ("sim_kill", "daemon_kill", "flood", "state_loss", "state_delay", "sigstop_sim", "sigstop_daemon")


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--rate", type=float, default=1000.0, help="[Hz] daemon rate")
    p.add_argument("--only", nargs="*", choices=SCENARIOS, help="run only these")
    p.add_argument("--json", action="store_true")
    p.add_argument("--out", metavar="FILE", help="also write the JSON here")
    args = p.parse_args()
    from wmm_qp_service import faults
    from wmm_qp_service.processes import Stack, isolated_config, log_folder

    out: dict[str, Any] = {"rate_hz": args.rate}
    todo = args.only or SCENARIOS
    log_dir = log_folder(None, "faults")
    stack = Stack(isolated_config(), rate_hz=args.rate, log_dir=log_dir)
    probe = None
    try:
        stack.start()
        probe = faults.Probe(stack)
        for name in todo:
            print(f"faults: {name} ...", file=sys.stderr, flush=True)
            try:
                if name == "sim_kill":
                    r = faults.sim_kill_and_restart(probe, args.rate)
                elif name == "daemon_kill":
                    r = faults.daemon_kill_and_restart(probe)
                elif name == "flood":
                    r = faults.setpoint_flood(probe)
                elif name == "state_loss":
                    r = faults.state_faults(probe, ["--state-loss", "0.05"])
                elif name == "state_delay":
                    r = faults.state_faults(probe, ["--state-delay-ms", "20"])
                elif name == "sigstop_sim":
                    r = faults.sigstop(probe, "sim")
                else:
                    r = faults.sigstop(probe, "daemon")
            except TimeoutError as e:
                r = {"error": str(e)}
            out[name] = r
            print(f"faults: {name}: {json.dumps(r)}", file=sys.stderr, flush=True)
    finally:
        if probe is not None:
            probe.close()
        out["exit_codes"] = stack.stop()
    out["logs"] = str(log_dir)
    if args.out:
        Path(args.out).write_text(json.dumps(out, indent=1))
    if args.json:
        print(json.dumps(out))
    return 0 if all("error" not in out[n] for n in todo) else 1


if __name__ == "__main__":
    sys.exit(main())
