"""Wire fuzzing run: sim + daemon as processes, one client floods every key with hostile payloads.

    .venv/bin/python benchmarks/reliability/fuzz.py --n 100000 --rate 4000 --loop-rate 1000 --json

Prints (or writes as JSON) messages sent by key and kind, the daemon's rejections by reason
and accepted messages during the flood, deadline misses and ticks during the flood, crashes
(processes that died: must be 0) and the sim's referee violations. See docs/reliability.md.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--n", type=int, default=100_000, help="messages to send")
    p.add_argument("--rate", type=float, default=4000.0, help="[1/s] send rate")
    p.add_argument("--loop-rate", type=float, default=1000.0, help="[Hz] daemon rate")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--baseline", type=float, default=10.0,
                   help="[s] measure ticks and deadline misses this long without the flood first")
    p.add_argument("--json", action="store_true")
    p.add_argument("--out", metavar="FILE", help="also write the JSON here")
    args = p.parse_args()
    from wmm_qp_service.client import Client
    from wmm_qp_service.processes import Stack, isolated_config, log_folder
    from wmm_qp_tools.fuzz import fuzz_wire

    log_dir = log_folder(None, "fuzz")
    stack = Stack(isolated_config(), rate_hz=args.loop_rate, log_dir=log_dir)
    try:
        stack.start()
        with Client(stack.svc, name="fuzzer") as c:
            if c.wait_for_daemon(30.0) is None:
                print(f"fuzz: the daemon did not come up (logs {log_dir})", file=sys.stderr)
                return 1
            end = time.monotonic() + 30.0
            while time.monotonic() < end and not ((i := c.info()) and i.status.state_ok):
                time.sleep(0.1)
            c.set_mode("track")
            time.sleep(0.5)
            a = c.info()
            time.sleep(args.baseline)
            b = c.info()
            base = ({"ticks": b.status.loop.ticks - a.status.loop.ticks,
                     "deadline_misses": b.status.loop.deadline_misses - a.status.loop.deadline_misses,
                     "seconds": args.baseline} if a is not None and b is not None else {})
            rep = fuzz_wire(c, args.n, rate_hz=args.rate, seed=args.seed,
                            alive=lambda: sum(pr.poll() is None for pr in stack.procs.values()),
                            progress=lambda k: print(f"fuzz: {k} sent", file=sys.stderr, flush=True))
    finally:
        codes = stack.stop()
    out = rep.as_dict() | {"baseline_without_flood": base, "loop_rate_hz": args.loop_rate,
                           "send_rate": args.rate, "seed": args.seed,
                           "exit_codes": codes, "logs": str(log_dir)}
    out["sim_log_tail"] = (log_dir / "sim.log").read_text().strip().splitlines()[-1:]
    if args.out:
        Path(args.out).write_text(json.dumps(out, indent=1))
    if args.json:
        print(json.dumps(out))
    else:
        print(f"fuzz: sent {rep.sent} in {rep.duration_s:.1f} s; by key {dict(rep.sent_by_key)}")
        print(f"      daemon rejected {rep.rejected}, accepted {rep.accepted}")
        print(f"      during the flood: {rep.ticks} ticks, {rep.deadline_misses} deadline misses, "
              f"loop {rep.measured_hz:.1f} Hz; crashes {rep.crashes}; violations {rep.violations}")
        print(f"      baseline without the flood: {base}")
        print(f"      exit codes {codes}")
    ok = rep.crashes == 0 and rep.daemon_answering and all(v == 0 for v in codes.values())
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
