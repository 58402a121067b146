"""``wmm-qp bench``: per-tick controller time, one-shot vs persistent QPs, the pink race,
scaling with the number of joints, every shipped robot × task kind × solver, and the loop over
Zenoh (docs/benchmarks.md).

``--robot-config FILE`` picks the robot of every section but ``robots`` (which loops over the
shipped robot files); ``--task KIND`` overrides the controller config's task kind (not in
``e2e``, whose daemon loads ``--controller-config``; ``pink`` is position-only).

``--baseline-tree DIR`` (with ``--only tick``, or with every section) times the Gen3's track-mode
tick of this source tree and of DIR's in the same run, in ``--rounds`` alternating rounds
(:mod:`wmm_qp_tools.bench.tick_compare`).

``--only record`` (only by name) times the daemon's tick with and without ``--record`` in one run
(:mod:`wmm_qp_tools.bench.record`, docs/recording.md)."""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any

from wmm_qp_service.commands.common import add_config_arguments, add_physics_argument, load_configs, physics_plant

from wmm_qp.config import TASK_KINDS

HELP = "measure per-tick controller time and the loop over Zenoh"

_SECTIONS = ("default", "controller", "oneshot", "pink", "scaling", "robots", "e2e", "daemon", "collisions",
             "collision_default", "jitter", "sim", "tick", "ros2", "record")
_MODES = ("hold", "track", "dm_cartesian", "dm_nullspace")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    add_config_arguments(parser)
    parser.add_argument("--task", choices=TASK_KINDS, default=None,
                        help="task kind, overriding the controller config's [task] kind")
    parser.add_argument("--ticks", type=int, default=20000, help="ticks per case (default 20000)")
    parser.add_argument("--only", choices=_SECTIONS, help="run one section only")
    parser.add_argument("--skip", action="append", choices=_SECTIONS, help="a section not to run (repeatable)")
    parser.add_argument(
        "--solver",
        action="append",
        dest="solvers",
        metavar="NAME",
        help="a backend to measure (repeatable; default: every available one)",
    )
    parser.add_argument(
        "--mode",
        action="append",
        dest="modes",
        choices=_MODES,
        help="a controller mode (repeatable; default: all four)",
    )
    parser.add_argument("--no-breakdown", action="store_true", help="skip the instrumented pass")
    add_physics_argument(parser, "sim: every installed plant side by side")
    parser.add_argument(
        "--max-seconds",
        type=float,
        default=30.0,
        help="wall-clock budget per timed pass [s] (default 30)",
    )
    parser.add_argument(
        "--baseline-tree", type=Path, default=None, metavar="DIR",
        help="tick: another source tree of wmm-qp (e.g. git worktree add --detach /tmp/base main) whose track-mode "
             "tick is timed beside this tree's, alternating worker runs; the tick section runs only with it",
    )  # fmt: skip
    parser.add_argument("--rounds", type=int, default=5,
                        help="tick: rounds, each one worker run of --ticks ticks per tree (default 5)")  # fmt: skip


def _clean(x: Any) -> Any:
    """NaN → None so that the JSON is standard."""
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, dict):
        return {k: _clean(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_clean(v) for v in x]
    return x


def _fmt(s: dict[str, Any]) -> str:
    return f"p50 {s['p50']:8.1f}  p99 {s['p99']:8.1f}  max {s['max']:8.1f} µs  (n={s['n']})"


def _print_report(r: dict[str, Any]) -> None:
    m = r["machine"]
    print(f"machine: {m['nproc']} cores, {m['cpu']}, Python {m['python']}, load {m['loadavg']}")
    print(f"robot: {r['robot']} ({r['robot_file']}), task {r['task']}")
    for solver, modes in r.get("controller", {}).items():
        for mode, c in modes.items():
            print(f"controller {solver:9s} {mode:12s} {_fmt(c['tick_us'])}  stages {c['stages']}")
            if "pieces_us" in c:
                parts = "  ".join(f"{k} {v['p50']:.1f}" for k, v in c["pieces_us"].items())
                print(f"    breakdown p50 µs: {parts}")
    one = r.get("oneshot", {})
    for solver, o in one.items():
        if isinstance(o, dict) and "oneshot_us" in o:
            print(
                f"oneshot    {solver:9s} qpsolvers {o['oneshot_us']['p50']:8.1f}  persistent "
                f"{o['persistent_us']['p50']:8.1f} µs p50  ×{o['speedup_p50']}"
            )
    race = r.get("pink")
    if race:
        if race.get("available"):
            for k in ("ours", "pink", "pink_accel"):
                print(f"race       {k:10s} {_fmt(race[k]['tick_us'])}  valid {race[k]['valid']}")
            print(f"race       pink/ours p50 ×{race['ratio_p50']}  p99 ×{race['ratio_p99']}  fair {race['fair']}")
        else:
            print(f"race       {race['reason']}")
    for name, row in r.get("robots", {}).items():
        if not row.get("available"):
            print(f"robots     {name}: {row.get('reason')}")
            continue
        for kind in ("position", "pose"):
            for solver, c in row.get(kind, {}).items():
                print(f"robots     {name:16s} {kind:8s} {solver:9s} track {_fmt(c['tick_us'])}")
    sc = r.get("scaling", {})
    for solver, rows in sc.items():
        if isinstance(rows, dict):
            for n, row in rows.items():
                print(f"scaling    {solver:9s} {n:>2s} arm joints ({row['n_vars']} vars) {_fmt(row['tick_us'])}")
    e2e = r.get("e2e", {})
    cases = [(k, v) for k, v in e2e.items() if k not in ("embedded", "embedded_plain", "floor")]
    cases += [(f"embedded {k}", v) for k, v in (e2e.get("embedded") or {}).items()]
    cases += [(f"plain {k}", v) for k, v in (e2e.get("embedded_plain") or {}).items()]
    for case, e in cases:
        if not isinstance(e, dict):
            continue
        if not e.get("available"):
            print(f"e2e        {case} Hz: {e.get('reason')}")
            continue
        print(
            f"e2e        {case:>13s} Hz: achieved {e['achieved_hz']} Hz, {e['ticks']} ticks, "
            f"misses {e['deadline_misses']} ({e['misses_per_10k']} / 10k, watchdog {e['watchdog_ticks']}), "
            f"tick/step p50 ×{e['tick_over_step_p50']}, applied at k+1 {e['applied_next_step']}, "
            f"overwritten {e['cmds_not_applied']}/{e['cmds_in_window']}, CPU % {e.get('cpu_pct')}"
        )
        for k in ("tick_us", "step_us", "state_to_cmd_us", "state_transport_us", "daemon_us", "cmd_to_applied_us"):
            print(f"           {k:18s} {_fmt(e[k])}")
    for rate, f in (e2e.get("floor") or {}).items():
        print(f"e2e        floor {rate:>7s} Hz: an empty loop, {f['scheduling']}: {f['deadline_misses']} deadline "
              f"misses in {f['ticks']} ticks ({f['misses_per_10k']} per 10k), late {f['late_us']} µs")
    for case, e in r.get("daemon", {}).items():
        if not isinstance(e, dict):
            continue
        b = e.get("breakdown", {})
        if not b.get("stages"):
            print(f"daemon     {case} Hz: {e.get('reason') or b.get('reason')}")
            continue
        print(f"daemon     {case:>10s} Hz: tick {_fmt(b['tick'])}, tick/step p50 ×{b.get('tick_over_step_p50')}")
        for name, st in b["stages"].items():
            print(f"           {name:18s} {_fmt(st)}")
    for name, c in r.get("collision_default", {}).items():
        if not c.get("available"):
            print(f"rows       {name}: {c.get('reason')}")
            continue
        print(f"rows       {name:16s} with {_fmt(c['with_rows'])}")
        print(f"           {'':16s} w/o  {_fmt(c['without_rows'])}  ×{c['ratio_p50']} p50, "
              f"rows p50 {c['rows']['p50']:g} max {c['rows']['max']}")
    for rate, j in r.get("jitter", {}).items():
        print(f"jitter     {rate:>5s} Hz, no work, {j['scheduling']}: {j['deadline_misses']} deadline misses in "
              f"{j['ticks']} ticks ({j['misses_per_10k']} per 10k), late {j['late_us']} µs, "
              f"steal {j['steal_percent']} %")
    if (a := r.get("step_after_idle")) is not None:
        print(f"step idle  ctl.step p50/p99 µs: back to back {a['none']['p50']}/{a['none']['p99']}, after a "
              f"{a['idle_us']:g} µs sleep {a['sleep']['p50']}/{a['sleep']['p99']} (×{a['sleep_over_none_p50']}), "
              f"after a spin {a['spin']['p50']}/{a['spin']['p99']} (×{a['spin_over_none_p50']})")
    for name, row in r.get("sim", {}).items():
        for plant in r.get("physics", []):
            if plant in row:
                c = row[plant]
                print(f"sim {name:16s} {plant:9s} step {_fmt(c['step_us'])}  realtime x{c['realtime_factor']}")
    if (t := r.get("tick_compare")) is not None:
        if not t.get("available"):
            print(f"tick       {t['reason']}")
        else:
            print(f"tick       {t['solver']} track p50: this {t['this_us_p50']:.1f} µs, "
                  f"baseline {t['baseline_us_p50']:.1f} µs ({t['baseline_tree']}): "
                  f"ratio this/baseline {t['ratio']:.3f} over {t['rounds']} rounds "
                  f"(rounds' median {t['ratio_rounds_median']:.3f}); same numerics {t['same_run']}")  # fmt: skip
    if (ros := r.get("ros2")) is not None:
        if not ros.get("available"):
            print(f"ros2       not run: {ros.get('why')}")
        for rate, x in ros.get("rates", {}).items():
            s2c = x["state_to_command"]
            print(f"ros2 {rate:>4} Hz state → command p50 {s2c['p50_ms']} ms, p99 {s2c['p99_ms']} ms; driver misses "
                  f"{x['deadline_misses']}/{x['cycles']}, daemon misses {x['daemon_deadline_misses']}/"
                  f"{x['daemon_ticks']}, violations {x['violations'] or 0}")
    if (rc := r.get("record")) is not None:
        if not rc.get("available"):
            print(f"record     {rc.get('reason')}")
        else:
            j, d = rc["journal"], rc["daemon"]
            print(f"record     hook in process: core.tick p50 {j['tick_us']['p50']} µs, TickJournal.tick p50 "
                  f"{j['journal_us']['p50']} µs (×{j['journal_over_tick_p50']}); {j['recorded']}/{j['ticks']} ticks "
                  f"in the file; the writer process {j['writer_cpu_us_per_tick']} µs of CPU a tick")
            print(f"           daemon 1 kHz tick p50: without {d['without']['tick_us'].get('p50')} µs, with "
                  f"{d['with']['tick_us'].get('p50')} µs (×{d['ratio_p50']})")
    print(f"targets    {r['targets']}")


def run(args: argparse.Namespace) -> int:
    from wmm_qp.solvers import SOLVER_NAMES, available_solvers

    if args.ticks < 1:
        print("wmm-qp bench: error: --ticks must be at least 1", file=sys.stderr)
        return 2
    if args.max_seconds <= 0:
        print("wmm-qp bench: error: --max-seconds must be positive", file=sys.stderr)
        return 2
    for s in args.solvers or []:
        if s not in SOLVER_NAMES:
            print(
                f"wmm-qp bench: error: unknown solver {s!r}; choose from {', '.join(SOLVER_NAMES)}",
                file=sys.stderr,
            )
            return 2
        if s not in available_solvers():
            print(f"wmm-qp bench: error: solver {s!r} is not installed", file=sys.stderr)
            return 2
    if args.rounds < 1:
        print("wmm-qp bench: error: --rounds must be at least 1", file=sys.stderr)
        return 2
    if args.baseline_tree is not None:
        from wmm_qp_tools.bench.compare_commits import HERE
        from wmm_qp_tools.bench.tick_compare import tree_problem

        if args.only not in (None, "tick"):
            print(f"wmm-qp bench: error: --baseline-tree applies to the tick section (--only tick, or no --only), "
                  f"not to --only {args.only}", file=sys.stderr)  # fmt: skip
            return 2
        if (why := tree_problem(args.baseline_tree)) is not None:
            print(f"wmm-qp bench: error: --baseline-tree {args.baseline_tree}: {why}; give a checkout of wmm-qp, "
                  "e.g. git worktree add --detach /tmp/base main", file=sys.stderr)  # fmt: skip
            return 2
        if tree_problem(HERE) is not None:
            print(f"wmm-qp bench: error: --baseline-tree needs this wmm-qp to run from a source tree (an editable "
                  f"install), not from {HERE}", file=sys.stderr)  # fmt: skip
            return 2
    elif args.only == "tick":
        print("wmm-qp bench: error: --only tick needs --baseline-tree DIR (the tree to time beside this one)",
              file=sys.stderr)  # fmt: skip
        return 2
    robot, cfg = load_configs(args)
    if args.physics is not None:
        physics_plant(args)  # not installed: one line, exit 2, before anything runs
    if args.task is not None:
        cfg = cfg.with_(task={"kind": args.task})
    cfg.weights_for(robot)  # a W of another length than the robot's: one line, exit 2
    from wmm_qp_tools.bench import run_bench

    result = run_bench(
        ticks=args.ticks,
        only=args.only,
        solvers=args.solvers,
        modes=args.modes,
        breakdown=not args.no_breakdown,
        max_seconds=args.max_seconds,
        skip=args.skip,
        robot=robot,
        cfg=cfg,
        controller_file=args.controller_config,
        physics=None if args.physics is None else [args.physics],
        baseline_tree=None if args.baseline_tree is None else args.baseline_tree.resolve(),
        rounds=args.rounds,
    )
    if args.json:
        json.dump(_clean(result), sys.stdout, indent=1)
        print()
    else:
        _print_report(result)
    return 0
