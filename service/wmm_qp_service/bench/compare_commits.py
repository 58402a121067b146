"""The controller's track-mode tick of two source trees, alternately, in separate processes.

Two versions of ``wmm_qp`` cannot share one process (one package name), so each round runs
``wmm-qp bench --only controller --mode track --no-breakdown --json`` once in the old tree and
once in the new one, each a fresh Python with ``PYTHONPATH`` set to that tree (and the tree as the
working directory, so it reads its own ``configs/``). Same trajectory (the paper's circle from
the default robot's start), same number of ticks, same solvers. Over the rounds: the median of
each process's p50 and p99, new/old ratios of those medians and the median of the rounds' own
new/old p50 ratios (paired: a slow drift of a shared machine cancels). The runs' stage and status counts
and their tracking error must agree (the same numerics on the same robot), which is checked too.

    python -m wmm_qp_service.bench.compare_commits OLD_TREE [--new NEW_TREE] [--rounds 5]
        [--ticks 20000] [--solver NAME ...] [--json]

Typical use against a commit: ``git worktree add --detach /tmp/wt_old <commit>``, then
``python -m wmm_qp_service.bench.compare_commits /tmp/wt_old`` (docs/benchmarks.md).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parents[3]  # the source tree this module belongs to


def run_tree(tree: Path, ticks: int, solvers: list[str], python: str = sys.executable) -> dict[str, Any]:
    """One ``wmm-qp bench`` controller run (track mode only) in ``tree``; its parsed JSON."""
    env = dict(os.environ)
    env.pop("WMM_QP_CONFIG_DIR", None)
    env["PYTHONPATH"] = os.pathsep.join(str(tree / p) for p in ("", "sim", "service"))
    argv = [python, "-m", "wmm_qp_service.cli", "bench", "--only", "controller", "--mode", "track",
            "--no-breakdown", "--ticks", str(ticks), "--max-seconds", "600", "--json"]  # fmt: skip
    for s in solvers:
        argv += ["--solver", s]
    p = subprocess.run(argv, cwd=tree, env=env, capture_output=True, text=True, check=False)
    if p.returncode != 0:
        raise RuntimeError(f"bench in {tree} failed ({p.returncode}): {p.stderr.strip()[-500:]}")
    return json.loads(p.stdout)


def compare(old: Path, new: Path, rounds: int, ticks: int, solvers: list[str]) -> dict[str, Any]:
    """Alternate old, new for ``rounds`` rounds; per solver the medians, the ratios and the check."""
    runs: dict[str, list[dict[str, Any]]] = {"old": [], "new": []}
    for k in range(rounds):
        for name, tree in (("old", old), ("new", new)):
            print(f"round {k + 1}/{rounds}: {name} ({tree})", file=sys.stderr, flush=True)
            r = run_tree(tree, ticks, solvers)
            runs[name].append({"loadavg": r["machine"]["loadavg"], "controller": r["controller"]})
    out: dict[str, Any] = {"old": str(old), "new": str(new), "rounds": rounds, "ticks": ticks, "solvers": {}}
    for s in solvers:
        row: dict[str, Any] = {}
        for name in ("old", "new"):
            cases = [r["controller"][s]["track"] for r in runs[name]]
            p50 = [c["tick_us"]["p50"] for c in cases]
            p99 = [c["tick_us"]["p99"] for c in cases]
            row[name] = {"p50_median": statistics.median(p50), "p99_median": statistics.median(p99),
                         "p50_min": min(p50), "p50_rounds": p50, "p99_rounds": p99}  # fmt: skip
        row["ratio_p50"] = round(row["new"]["p50_median"] / row["old"]["p50_median"], 3)
        row["ratio_p99"] = round(row["new"]["p99_median"] / row["old"]["p99_median"], 3)
        # each round's new/old (the two runs back to back: a slow drift of the machine cancels)
        pairs = zip(row["new"]["p50_rounds"], row["old"]["p50_rounds"], strict=True)
        row["ratio_p50_paired_median"] = round(statistics.median(n / o for n, o in pairs), 3)
        row["ratio_p50_min"] = round(row["new"]["p50_min"] / row["old"]["p50_min"], 3)
        first_old, first_new = (runs[n][0]["controller"][s]["track"] for n in ("old", "new"))
        rms_old, rms_new = first_old["track_rms_m"], first_new["track_rms_m"]
        row["same_run"] = {
            "stages": first_old["stages"] == first_new["stages"],
            "status": first_old["status"] == first_new["status"],
            "track_rms_abs_diff": None if rms_old is None or rms_new is None else abs(rms_old - rms_new),
        }
        out["solvers"][s] = row
    out["loadavg"] = {n: [r["loadavg"] for r in runs[n]] for n in runs}
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m wmm_qp_service.bench.compare_commits", description=__doc__)
    ap.add_argument("old", type=Path, help="the old source tree (e.g. a git worktree of the commit before)")
    ap.add_argument("--new", type=Path, default=HERE, help=f"the new source tree (default: {HERE})")
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--ticks", type=int, default=20000)
    ap.add_argument("--solver", action="append", dest="solvers", metavar="NAME",
                    help="repeatable (default: proxsuite, osqp, daqp)")  # fmt: skip
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    solvers = args.solvers or ["proxsuite", "osqp", "daqp"]
    res = compare(args.old.resolve(), args.new.resolve(), args.rounds, args.ticks, solvers)
    if args.json:
        print(json.dumps(res, indent=1))
        return 0
    print(f"old {res['old']}  new {res['new']}  {res['rounds']} rounds x {res['ticks']} ticks, track mode")
    for s, row in res["solvers"].items():
        o, n = row["old"], row["new"]
        print(f"{s:9s} p50 old {o['p50_median']:7.1f} new {n['p50_median']:7.1f} µs (x{row['ratio_p50']}, "
              f"paired x{row['ratio_p50_paired_median']})  "
              f"p99 old {o['p99_median']:7.1f} new {n['p99_median']:7.1f} µs (x{row['ratio_p99']})  "
              f"same run {row['same_run']}")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
