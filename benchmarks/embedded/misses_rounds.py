"""The embedded and the split stack's deadline misses at 1 kHz, alternating case by case over several
rounds (``wmm-qp bench --only e2e`` runs each case once: one burst of the host's noise in one case
decides its figure). Prints each case's misses per 10k ticks and state → command p50 / p99, then
the medians.

    python benchmarks/embedded/misses_rounds.py [--rounds 3] [--ticks 10000] [--hogs N]
"""

from __future__ import annotations

import argparse
import contextlib
import statistics

from wmm_qp_tools.bench import e2e
from wmm_qp_tools.stress import CpuHogs


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=int, default=3, help="rounds (default 3)")
    ap.add_argument("--ticks", type=int, default=10000, help="ticks per case (default 10000: 10 s)")
    ap.add_argument("--hogs", type=int, default=0, help="CPU hogs (ordinary scheduling) beside every case (default 0)")
    a = ap.parse_args()
    if a.rounds < 1 or a.ticks < 100 or a.hogs < 0:
        ap.error("--rounds must be at least 1, --ticks at least 100, --hogs at least 0")
    misses: dict[str, list[float]] = {"embedded": [], "rate": []}
    with CpuHogs(a.hogs) if a.hogs else contextlib.nullcontext():
        rounds(a, misses)
    for trigger, m in misses.items():
        print(f"{trigger}: median misses per 10k {statistics.median(m):g} over {len(m)} rounds ({m})")


def rounds(a: argparse.Namespace, misses: dict[str, list[float]]) -> None:
    """Each round: each case once, in turn."""
    for r in range(a.rounds):
        for trigger in misses:
            res = e2e.run_case(trigger, 1000.0, a.ticks)
            s = res.get("state_to_cmd_us", {})
            m = res.get("misses_per_10k")
            misses[trigger].append(float(m) if m is not None else float("nan"))
            print(f"round {r + 1}/{a.rounds}, {trigger} 1000 Hz: misses per 10k {res.get('misses_per_10k')}, "
                  f"state -> command p50 {s.get('p50')} / p99 {s.get('p99')} µs, "
                  f"violations {sum((res.get('violations') or {}).values())}", flush=True)


if __name__ == "__main__":
    main()
