"""The controller's track-mode tick of two source trees, alternately, in separate processes.

Two versions of ``wmm_qp`` cannot share one process (one package name). Two ways:

**Interleaved** (``--blocks B``, the default way): per solver, one worker process per tree
(:mod:`._tick_worker`, ``PYTHONPATH`` and working directory set to that tree) stays alive, and
the two are asked in turn for the next block of ticks of the same trajectory (old, new, new, old,
…: ABBA, so neither always goes first), each block ``ticks / B`` ticks, until each did ``ticks``.
Both see the same machine within seconds of each other, which on a shared machine matters more
than anything else. Per tree: p50 and p99 over all its ticks; per block pair the new/old p50
ratio, and their median.

**Whole runs** (``--rounds R``): each round runs
``wmm-qp bench --only controller --mode track --no-breakdown --json`` once in the old tree and
once in the new one, each a fresh Python with ``PYTHONPATH`` set to that tree (and the tree as the
working directory, so it reads its own ``configs/``). Same trajectory (the paper's circle from
the default robot's start), same number of ticks, same solvers. Over the rounds: the median of
each process's p50 and p99, new/old ratios of those medians and the median of the rounds' own
new/old p50 ratios (paired: a slow drift of a shared machine cancels). The runs' stage and status counts
and their tracking error must agree (the same numerics on the same robot), which is checked too.

    python -m wmm_qp_tools.bench.compare_commits OLD_TREE [--new NEW_TREE]
        [--blocks 40 | --rounds 5] [--ticks 20000] [--solver NAME ...] [--json]

Typical use against a commit: ``git worktree add --detach /tmp/wt_old <commit>``, then
``python -m wmm_qp_tools.bench.compare_commits /tmp/wt_old`` (docs/benchmarks.md).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tomllib
from pathlib import Path
from typing import Any

import numpy as np

HERE = Path(__file__).resolve().parents[3]  # the source tree this module belongs to
DEFAULT_PACKAGE_DIRS = ("", "sim", "service")  # where wmm_qp, wmm_qp_sim and wmm_qp_service live in a tree


def package_dirs(tree: Path) -> list[Path]:
    """The folders of ``tree`` that hold its packages: its pyproject.toml's
    ``[tool.setuptools.packages.find] where`` (``.``, ``sim``, ``service`` if it says nothing)."""
    try:
        data = tomllib.loads((tree / "pyproject.toml").read_text())
        where = data["tool"]["setuptools"]["packages"]["find"]["where"]
        if isinstance(where, list) and all(isinstance(w, str) for w in where):
            return [tree / w for w in where]
    except (OSError, tomllib.TOMLDecodeError, KeyError, TypeError):
        pass
    return [tree / w for w in DEFAULT_PACKAGE_DIRS]


def tree_env(tree: Path) -> dict[str, str]:
    """This process's environment with ``PYTHONPATH`` set to ``tree``'s packages (and its configs not
    overridden), so that a child imports *that* tree's code."""
    env = dict(os.environ)
    env.pop("WMM_QP_CONFIG_DIR", None)
    env["PYTHONPATH"] = os.pathsep.join(str(p) for p in package_dirs(tree))
    return env


def run_tree(tree: Path, ticks: int, solvers: list[str], python: str = sys.executable) -> dict[str, Any]:
    """One ``wmm-qp bench`` controller run (track mode only) in ``tree``; its parsed JSON."""
    env = tree_env(tree)
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


class TickWorker:
    """A :mod:`._tick_worker` process of one tree (this tree's worker script, that tree's ``wmm_qp``)."""

    def __init__(self, tree: Path, solver: str, python: str = sys.executable) -> None:
        env = tree_env(tree)
        script = Path(__file__).with_name("_tick_worker.py")
        self.p = subprocess.Popen([python, "-P", str(script), solver], cwd=tree, env=env, text=True,
                                  stdin=subprocess.PIPE, stdout=subprocess.PIPE)  # fmt: skip
        if not self._read().get("ready"):
            raise RuntimeError(f"the worker in {tree} did not start")

    def _read(self) -> dict[str, Any]:
        assert self.p.stdout is not None
        line = self.p.stdout.readline()
        if not line:
            raise RuntimeError(f"a worker ended (exit {self.p.wait()})")
        out: dict[str, Any] = json.loads(line)
        return out

    def ask(self, line: str) -> dict[str, Any]:
        assert self.p.stdin is not None
        self.p.stdin.write(line + "\n")
        self.p.stdin.flush()
        return self._read()

    def close(self) -> None:
        if self.p.stdin is not None:
            self.p.stdin.close()
        self.p.wait(timeout=30)


def _pct(ns: list[int], q: float) -> float:
    return round(float(np.percentile(np.asarray(ns, dtype=float) / 1e3, q)), 2)


def interleave(old: Path, new: Path, blocks: int, ticks: int, solvers: list[str]) -> dict[str, Any]:
    """The interleaved comparison (module docstring)."""
    size = max(1, ticks // blocks)
    out: dict[str, Any] = {"old": str(old), "new": str(new), "method": "interleaved", "blocks": blocks,
                           "ticks": size * blocks, "block_ticks": size, "solvers": {},
                           "loadavg_before": [round(x, 2) for x in os.getloadavg()]}  # fmt: skip
    for s in solvers:
        print(f"interleaved: {s}, {blocks} blocks of {size} ticks per tree", file=sys.stderr, flush=True)
        workers = {"old": TickWorker(old, s), "new": TickWorker(new, s)}
        ns: dict[str, list[int]] = {"old": [], "new": []}
        pairs: list[float] = []
        try:
            for b in range(blocks):
                order = ("old", "new") if b % 2 == 0 else ("new", "old")
                got = {name: workers[name].ask(str(size))["ns"] for name in order}
                for name in order:
                    ns[name] += got[name]
                pairs.append(_pct(got["new"], 50) / _pct(got["old"], 50))
            stats = {name: workers[name].ask("stats") for name in ("old", "new")}
        finally:
            for wk in workers.values():
                wk.close()
        row: dict[str, Any] = {name: {"p50": _pct(ns[name], 50), "p99": _pct(ns[name], 99), "n": len(ns[name])}
                               for name in ("old", "new")}  # fmt: skip
        row["ratio_p50"] = round(row["new"]["p50"] / row["old"]["p50"], 3)
        row["ratio_p99"] = round(row["new"]["p99"] / row["old"]["p99"], 3)
        row["ratio_p50_blocks_median"] = round(statistics.median(pairs), 3)
        row["ratio_p50_blocks_quartiles"] = [round(float(v), 3) for v in np.percentile(pairs, [25, 75])]
        rms_old, rms_new = stats["old"]["track_rms_m"], stats["new"]["track_rms_m"]
        row["same_run"] = {
            "stages": stats["old"]["stages"] == stats["new"]["stages"],
            "status": stats["old"]["status"] == stats["new"]["status"],
            "track_rms_abs_diff": None if rms_old is None or rms_new is None else abs(rms_old - rms_new),
        }
        out["solvers"][s] = row
    out["loadavg_after"] = [round(x, 2) for x in os.getloadavg()]
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m wmm_qp_tools.bench.compare_commits", description=__doc__)
    ap.add_argument("old", type=Path, help="the old source tree (e.g. a git worktree of the commit before)")
    ap.add_argument("--new", type=Path, default=HERE, help=f"the new source tree (default: {HERE})")
    ap.add_argument("--blocks", type=int, default=40, help="interleaved blocks per tree (default 40)")
    ap.add_argument("--rounds", type=int, default=None, help="whole runs per tree instead of interleaved blocks")
    ap.add_argument("--ticks", type=int, default=20000)
    ap.add_argument("--solver", action="append", dest="solvers", metavar="NAME",
                    help="repeatable (default: proxsuite, osqp, daqp)")  # fmt: skip
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    solvers = args.solvers or ["proxsuite", "osqp", "daqp"]
    if args.rounds is None:
        res = interleave(args.old.resolve(), args.new.resolve(), args.blocks, args.ticks, solvers)
        if args.json:
            print(json.dumps(res, indent=1))
            return 0
        print(f"old {res['old']}  new {res['new']}  interleaved, {res['blocks']} x {res['block_ticks']} ticks per tree")
        for s, row in res["solvers"].items():
            o, n = row["old"], row["new"]
            print(f"{s:9s} p50 old {o['p50']:7.1f} new {n['p50']:7.1f} µs (x{row['ratio_p50']}, blocks' median "
                  f"x{row['ratio_p50_blocks_median']})  p99 old {o['p99']:7.1f} new {n['p99']:7.1f} µs "
                  f"(x{row['ratio_p99']})  same run {row['same_run']}")  # fmt: skip
        return 0
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
