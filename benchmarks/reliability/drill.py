"""The stress drill: the demo (sim + daemon as processes on loopback) run over and over under load.

Conditions (``wmm_qp_tools.stress.CONDITIONS``): ``cpu`` (a spinning process per core), ``disk``
(a writer that writes and fsyncs 64 MiB files without a pause), ``freeze_sim`` / ``freeze_daemon``
(SIGSTOP for uniform 5-500 ms, SIGCONT, every 0.3-1.5 s), ``all`` (all of them at once). Each
condition runs demos back to back for ``--minutes``; every demo's JSON and its processes' logs are
kept under ``--out``. What the drill asserts: the sim's referee counts 0 (no command past the
bounds (13), no collision); faults, deadline misses, resumes and protective stops are the system
doing its job and are reported.

    python benchmarks/reliability/drill.py --minutes 2 --out /tmp/drill     # every condition
    python benchmarks/reliability/drill.py --conditions freeze_daemon --minutes 5
    python benchmarks/reliability/drill.py --embedded --minutes 1   # the demo as one embedded process

With ``--embedded`` each demo runs ``wmm-qp demo --embedded``: one process hosts the sim and the
control core in one cycle; ``freeze_sim`` freezes that process (the robot and its controller
together: when it is continued the robot runs every step it missed, its firmware braking past its
command timeout), and ``freeze_daemon`` has no daemon to freeze (its freezes are counted: 0).

Exit status: 0 when every demo counted 0 referee violations and exited, 1 otherwise.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

from wmm_qp_service.processes import CLI
from wmm_qp_tools.stress import CONDITIONS, stressed


def one_demo(out: Path, condition: str, i: int, args: argparse.Namespace) -> dict:
    logs = out / f"{condition}_{i:02d}"
    logs.mkdir(parents=True, exist_ok=True)
    argv = [*CLI, "demo", "--json", "--logs", str(logs),
            "--duration", str(args.demo_duration), "--rate", str(args.rate)]
    if args.robot_config:
        argv += ["--robot-config", args.robot_config]
    if args.embedded:
        argv += ["--embedded"]
    t0 = time.monotonic()
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=open(logs / "demo.log", "wb"),  # noqa: SIM115
                            stdin=subprocess.DEVNULL)
    with stressed(condition, parent=lambda: proc.pid, seed=args.seed + i) as applied:
        stdout, _ = proc.communicate(timeout=args.demo_duration * 4 + 180)
    wall = time.monotonic() - t0
    try:
        summary = json.loads(stdout.decode() or "null")
    except json.JSONDecodeError:
        summary = None
    (logs / "demo.json").write_bytes(stdout)
    log = logs / ("embedded.log" if args.embedded else "sim.log")
    referee = [ln for ln in log.read_text(errors="replace").splitlines() if "sim: referee:" in ln] \
        if log.exists() else []
    row = {"condition": condition, "run": i, "exit": proc.returncode, "wall_s": round(wall, 1),
           "freezes_sim": len(applied.get("freezes_sim", [])),
           "freezes_daemon": len(applied.get("freezes_daemon", [])),
           "disk_mb": applied.get("disk_mb", 0), "logs": str(logs), "referee_lines": referee[:5]}
    if summary is None:
        row["error"] = "no JSON from the demo"
        return row
    loop = summary.get("loop") or {}
    row.update(ticks=loop.get("ticks"), deadline_misses=loop.get("deadline_misses"),
               violations=summary.get("violations_total"), violations_by_kind=summary.get("violations"),
               faults=sum((summary.get("faults") or {}).values()), faults_by_kind=summary.get("faults"),
               resumes=sum(p.get("resumes", 0) for p in summary.get("phases", [])),
               protective_stops=summary.get("protective_stops"))
    return row


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--conditions", default=",".join(CONDITIONS), help="comma-separated, of " + ", ".join(CONDITIONS))
    ap.add_argument("--minutes", type=float, default=2.0, help="[min] per condition (demos run back to back)")
    ap.add_argument("--demo-duration", type=float, default=30.0, help="[s] each demo's scenario")
    ap.add_argument("--rate", type=float, default=500.0, help="[Hz] the daemon's rate")
    ap.add_argument("--robot-config", default=None, help="robot file (default: the Gen3)")
    ap.add_argument("--embedded", action="store_true", help="each demo with --embedded (one process)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=Path("drill-out"), help="logs and results.json go here")
    args = ap.parse_args()
    conditions = [c.strip() for c in args.conditions.split(",") if c.strip()]
    bad = [c for c in conditions if c not in CONDITIONS]
    if bad:
        print(f"drill: error: unknown condition(s) {bad}; choose from {', '.join(CONDITIONS)}", file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    rows: list[dict] = []
    for cond in conditions:
        end = time.monotonic() + args.minutes * 60.0
        i = 0
        while time.monotonic() < end:
            row = one_demo(args.out, cond, i, args)
            rows.append(row)
            print(f"drill: {cond} #{i}: exit {row['exit']}, {row.get('ticks')} ticks, violations "
                  f"{row.get('violations')} {row.get('violations_by_kind') or ''}, faults {row.get('faults')}, "
                  f"misses {row.get('deadline_misses')}, freezes sim/daemon {row['freezes_sim']}/"
                  f"{row['freezes_daemon']} ({row['wall_s']} s)", file=sys.stderr, flush=True)
            i += 1
            (args.out / "results.json").write_text(json.dumps(rows, indent=1))
    table = summarize(rows)
    (args.out / "table.md").write_text(table)
    print(table)
    bad_runs = [r for r in rows if r.get("violations") != 0]
    return 1 if bad_runs else 0


def summarize(rows: list[dict]) -> str:
    """The docs' table: one line per condition."""
    lines = ["| condition | demos | minutes | ticks | deadline misses | faults | resumes | protective stops "
             "| freezes sim/daemon | referee counts |", "|---|---|---|---|---|---|---|---|---|---|"]
    for cond in dict.fromkeys(r["condition"] for r in rows):
        rs = [r for r in rows if r["condition"] == cond]

        def tot(key: str, rs: list[dict] = rs) -> int:
            return sum(int(r.get(key) or 0) for r in rs)

        bad = [r for r in rs if r.get("violations") is None]
        lines.append(f"| {cond} | {len(rs)} | {sum(r['wall_s'] for r in rs) / 60:.1f} | {tot('ticks')} | "
                     f"{tot('deadline_misses')} | {tot('faults')} | {tot('resumes')} | {tot('protective_stops')} | "
                     f"{tot('freezes_sim')}/{tot('freezes_daemon')} | {tot('violations')}"
                     + (f" ({len(bad)} without JSON)" if bad else "") + " |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    sys.exit(main())
