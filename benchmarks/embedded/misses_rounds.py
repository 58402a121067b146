"""The embedded and the split stack's deadline misses at 1 kHz, alternating case by case over several
rounds (``wmm-qp bench --only e2e`` runs each case once: one burst of the host's noise in one case
decides its figure). Prints each case's misses per 10k ticks and state → command p50 / p99, then
the medians.

    python benchmarks/embedded/misses_rounds.py [--rounds 3] [--ticks 10000]
"""

from __future__ import annotations

import argparse
import statistics

from wmm_qp_service.bench import e2e


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=int, default=3, help="rounds (default 3)")
    ap.add_argument("--ticks", type=int, default=10000, help="ticks per case (default 10000: 10 s)")
    a = ap.parse_args()
    if a.rounds < 1 or a.ticks < 100:
        ap.error("--rounds must be at least 1 and --ticks at least 100")
    misses: dict[str, list[float]] = {"embedded": [], "rate": []}
    for r in range(a.rounds):
        for trigger in misses:
            res = e2e.run_case(trigger, 1000.0, a.ticks)
            s = res.get("state_to_cmd_us", {})
            m = res.get("misses_per_10k")
            misses[trigger].append(float(m) if m is not None else float("nan"))
            print(f"round {r + 1}/{a.rounds}, {trigger} 1000 Hz: misses per 10k {res.get('misses_per_10k')}, "
                  f"state -> command p50 {s.get('p50')} / p99 {s.get('p99')} µs, "
                  f"violations {sum((res.get('violations') or {}).values())}", flush=True)
    for trigger, m in misses.items():
        print(f"{trigger}: median misses per 10k {statistics.median(m):g} over {len(m)} rounds ({m})")


if __name__ == "__main__":
    main()
