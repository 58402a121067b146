"""``wmm-qp bench --only tick --baseline-tree DIR``: the track-mode tick of this tree and of another, in one run.

Two versions of ``wmm_qp`` cannot share one process, so each tree's tick is timed by a
:mod:`._tick_worker` process (this tree's worker script, ``PYTHONPATH`` set to that tree's packages,
its own ``configs/``: the default robot, the paper's Gen3, and the default controller config without
collision rows; :mod:`.compare_commits`). A round starts one fresh worker per tree, one after the
other, and each times ``ticks`` ticks of the paper's circle from the robot's start; the first of a
round alternates (this, baseline; baseline, this; …), so that a slow spell of a shared machine and
a slow drift fall on both trees alike. Over all rounds: each tree's p50 over all its ticks and the
ratio this / baseline; per round the ratio of the two p50s.

The workers also report their stage and status counts and tracking RMS: the same numerics give the
same counts and an RMS equal to rounding (``same_run``).
"""

from __future__ import annotations

import os
import statistics
import sys
from pathlib import Path
from typing import Any

import numpy as np

from wmm_qp_tools.bench.compare_commits import HERE, TickWorker, package_dirs

TREES = ("this", "baseline")


def tree_problem(tree: Path) -> str | None:
    """Why ``tree`` cannot be timed (not a wmm-qp source tree), or None if it can."""
    if not tree.is_dir():
        return "not a directory"
    if not any((d / "wmm_qp" / "__init__.py").is_file() for d in package_dirs(tree)):
        return "not a wmm-qp source tree (no wmm_qp/__init__.py)"
    if not (tree / "configs" / "controller.toml").is_file():
        return "not a wmm-qp source tree (no configs/controller.toml)"
    return None


def round_order(k: int) -> tuple[str, str]:
    """The trees in round ``k`` (0-based): this tree first in even rounds, the baseline in odd ones."""
    return TREES if k % 2 == 0 else TREES[::-1]


def _p(ns: list[int], q: float) -> float:
    """[µs] the q-th percentile of tick durations given in [ns]."""
    return round(float(np.percentile(np.asarray(ns, dtype=float) / 1e3, q)), 2)


def run(baseline: Path, solver: str, ticks: int, rounds: int, this: Path = HERE) -> dict[str, Any]:
    """Time both trees' track-mode tick in ``rounds`` alternating rounds (module docstring).

    Args:
        baseline: the other source tree (e.g. ``git worktree add --detach /tmp/base main``).
        solver: the QP backend both trees use.
        ticks: ticks per worker run.
        rounds: rounds (each one worker run per tree).
        this: this process's source tree.

    Returns:
        {"available": True, "this_tree", "baseline_tree", "solver", "ticks", "rounds",
        "this_us_p50", "baseline_us_p50", "ratio" (this / baseline p50), "this_us_p99",
        "baseline_us_p99", "ratio_rounds" (each round's this / baseline p50),
        "ratio_rounds_median", "same_run" {"stages", "status", "track_rms_abs_diff"},
        "loadavg_before", "loadavg_after"}; a worker that fails gives {"available": False,
        "reason"}.
    """
    trees = {"this": this, "baseline": baseline}
    out: dict[str, Any] = {"available": True, "this_tree": str(this), "baseline_tree": str(baseline),
                           "solver": solver, "ticks": ticks, "rounds": rounds,
                           "loadavg_before": [round(x, 2) for x in os.getloadavg()]}  # fmt: skip
    ns: dict[str, list[int]] = {name: [] for name in TREES}
    stats: dict[str, dict[str, Any]] = {}
    ratios: list[float] = []
    try:
        for k in range(rounds):
            got: dict[str, list[int]] = {}
            for name in round_order(k):
                print(f"  tick: round {k + 1}/{rounds}, {name} ({trees[name]})", file=sys.stderr, flush=True)
                worker = TickWorker(trees[name], solver)
                try:
                    got[name] = worker.ask(str(ticks))["ns"]
                    stats[name] = worker.ask("stats")
                finally:
                    worker.close()
                ns[name] += got[name]
            ratios.append(round(_p(got["this"], 50) / _p(got["baseline"], 50), 3))
    except (RuntimeError, OSError, ValueError) as e:  # a tree whose wmm_qp cannot run the worker
        return {"available": False, "reason": f"a tick worker failed: {e}", "this_tree": str(this),
                "baseline_tree": str(baseline)}  # fmt: skip
    out |= {"this_us_p50": _p(ns["this"], 50), "baseline_us_p50": _p(ns["baseline"], 50),
            "this_us_p99": _p(ns["this"], 99), "baseline_us_p99": _p(ns["baseline"], 99)}  # fmt: skip
    out["ratio"] = round(out["this_us_p50"] / out["baseline_us_p50"], 3)
    out["ratio_rounds"] = ratios
    out["ratio_rounds_median"] = round(statistics.median(ratios), 3)
    rms = [stats[name]["track_rms_m"] for name in TREES]
    out["same_run"] = {
        "stages": stats["this"]["stages"] == stats["baseline"]["stages"],
        "status": stats["this"]["status"] == stats["baseline"]["status"],
        "track_rms_abs_diff": None if None in rms else abs(rms[0] - rms[1]),
    }
    out["loadavg_after"] = [round(x, 2) for x in os.getloadavg()]
    return out
