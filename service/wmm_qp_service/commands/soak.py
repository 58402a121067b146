"""``wmm-qp soak``: sim + daemon (or, with ``--embedded``, the one embedded process) + a teleop client
for a long time; drift in time and memory."""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path
from typing import Any

from ..progress import ProgressLine
from ..verdict import EXIT_CODES_HELP, judge
from .common import (
    add_collision_argument,
    add_physics_argument,
    add_robot_argument,
    embedded_rate,
    load_robot,
    physics_plant,
)

HELP = "run sim + daemon + client for a long time and report drift in time and memory"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.epilog = EXIT_CODES_HELP + " A process that crashes or does not stop is a FAIL too."
    parser.add_argument("--duration", type=float, default=60.0, help="[s] how long")
    parser.add_argument("--rate", type=float, default=1000.0, help="[Hz] control rate")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--logs", metavar="DIR",
                        help="write the sim's and the daemon's logs here (default: a fresh folder under the "
                             "temporary directory, kept and named on the verdict line)")
    parser.add_argument("--trigger", choices=("rate", "state"),
                        help="the daemon's loop.trigger (default: the service config's)")
    parser.add_argument("--embedded", action="store_true",
                        help="one process instead of two: the control core in the sim's own cycle "
                             "(wmm-qp sim --embedded; --rate must divide the sim's rate)")
    add_robot_argument(parser)
    add_collision_argument(parser)
    add_physics_argument(parser)


def rss_kib(pid: int) -> int | None:
    """Resident set size [KiB] of a process (Linux /proc), None if unknown."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
    except OSError:
        return None
    return None


def run(args: argparse.Namespace) -> int:
    if not 5.0 <= args.duration <= 7 * 86400:
        print("wmm-qp soak: error: --duration must be in [5 s, 7 days]", file=sys.stderr)
        return 2
    if not 10.0 <= args.rate <= 2000.0:
        print("wmm-qp soak: error: --rate must be in [10, 2000] Hz", file=sys.stderr)
        return 2
    if args.embedded and args.trigger is not None:
        print("wmm-qp soak: error: --trigger is the split daemon's; with --embedded the robot's cycle is the clock",
              file=sys.stderr)
        return 2
    import numpy as np

    from wmm_qp_service.machine import CPU_HOW, CpuMeter

    from ..client import Client
    from ..processes import Stack, isolated_config, log_folder
    from ..readiness import START_TIMEOUT, STATE_TIMEOUT, NotReady
    from ..teleop import stream_circle, stream_haptic

    robot = load_robot(args)  # a bad file: one line, exit 2, before anything starts
    plant = physics_plant(args)
    if args.embedded:
        embedded_rate(args.rate)  # one that does not divide the sim's rate: one line, exit 2
    svc = isolated_config(robot=robot)
    log_dir = log_folder(args.logs, "soak")
    daemon_args = [] if args.trigger is None else ["--trigger", args.trigger]
    daemon_args += ["--no-collision"] if args.no_collision else []  # else the daemon's default: rows on
    stack = Stack(svc, rate_hz=args.rate, log_dir=log_dir, robot_file=robot.path, extra_daemon_args=daemon_args,
                  extra_sim_args=["--physics", plant], embedded=args.embedded)
    out: dict[str, Any] = {"physics": plant, "embedded": args.embedded}
    bar = ProgressLine("soak")
    up = False
    try:
        bar.update(f"starting the {'embedded sim' if args.embedded else 'sim and the daemon'} (logs: {log_dir})")
        stack.start()
        with Client(svc, name="soak") as c:
            try:
                info = c.wait_ready(START_TIMEOUT, STATE_TIMEOUT, exited=stack.exited, say=bar.update)
            except NotReady as e:
                return _no_stack(out, stack, log_dir, args.json, f"the stack did not come up: {e}")
            up = True

            def tick() -> None:
                def text() -> str:
                    tr = c.latest_truth()
                    v = sum(tr.violations.values()) if tr is not None else "?"
                    return f"{time.monotonic() - t0:.0f}/{args.duration:g} s, {v} violations so far"
                bar.update(text)
            c.set_mode("track")
            time.sleep(0.2)
            x0 = np.array(info.status.x)
            pids = {n: p.pid for n, p in stack.procs.items()}
            rss0 = {n: rss_kib(pid) for n, pid in pids.items()}
            loop0 = info.status.loop
            meter = CpuMeter(pids)
            samples: list[dict[str, Any]] = []  # every segment: time, load average, RSS
            t0 = time.monotonic()
            k = 0
            while (left := args.duration - (time.monotonic() - t0)) > 0:
                samples.append({"t_s": round(time.monotonic() - t0, 1), "load1": round(os.getloadavg()[0], 2),
                                "rss_kib": {n: rss_kib(pid) for n, pid in pids.items()}})
                seg = min(20.0, left)
                if k % 2 == 0:
                    stream_haptic(c, x0, seg, seed=k, on_tick=tick)
                else:
                    stream_circle(c, x0, seg, on_tick=tick)
                k += 1
                c.set_mode("hold")
                time.sleep(0.5)
                c.set_mode("track")
            cpu = meter.shares()
            final = c.info()
            st = c.latest_state() or c.wait_state(2.0)
            tr = c.latest_truth() or c.wait_truth(2.0)
            rss1 = {n: rss_kib(pid) for n, pid in pids.items()}
        if final is None:
            return _no_stack(out, stack, log_dir, args.json, "the daemon stopped answering")
        lp = final.status.loop
        n = lp.ticks - loop0.ticks
        misses = lp.deadline_misses - loop0.deadline_misses
        loads = [x["load1"] for x in samples]
        out = {"robot": robot.name, "physics": plant, "embedded": args.embedded, "duration_s": args.duration,
               "rate_hz": args.rate,
               "trigger": lp.trigger,
               "collision": final.status.collision, "collision_summary": final.status.collision_summary,
               "window_ticks": n, "window_misses": misses,
               "misses_per_10k": round(1e4 * misses / n, 2) if n else None,
               "watchdog_ticks": lp.watchdog_ticks - loop0.watchdog_ticks,
               "cpu_pct": cpu, "cpu_how": CPU_HOW,
               "load1_during": {"min": min(loads, default=None), "max": max(loads, default=None),
                                "median": sorted(loads)[len(loads) // 2] if loads else None},
               "samples": samples, "ticks": lp.ticks,
               "deadline_misses": lp.deadline_misses, "tick_p50_us": lp.tick_p50_us,
               "tick_p99_us": lp.tick_p99_us, "tick_max_us": lp.tick_max_us,
               "measured_hz": lp.measured_hz, "rss_kib_start": rss0, "rss_kib_end": rss1,
               "violations": dict(tr.violations) if tr else final.status.robot_violations,
               "rejected": final.status.rejected, "last_fault": final.status.last_fault,
               "faults": final.status.faults,
               "protective_stops": st.protective_stops if st else None,
               "load_average": list(os.getloadavg())}
    finally:
        bar.update("stopping the sim and the daemon")
        codes = stack.stop()  # again after _no_stack: a no-op
        bar.close()
        if up:
            out["exit_codes"] = codes
    out["logs"] = str(log_dir)
    verdict = judge(out["violations"], failures=_process_failures(out["exit_codes"]),
                    deadline_misses=int(out["window_misses"]), faults=out["faults"] or {},
                    protective_stops=int(out["protective_stops"] or 0), logs=log_dir)
    out |= verdict.json_fields()
    if args.json:
        print(json.dumps(out))
        print(verdict.line(), file=sys.stderr, flush=True)
    else:
        print(f"soak: {out['duration_s']:g} s at {out['rate_hz']:g} Hz ({out['trigger']} trigger) — ticks "
              f"{out['ticks']}, deadline misses {out['deadline_misses']} ({out['misses_per_10k']} per 10k in the "
              f"window), tick p50 {out['tick_p50_us']:.0f} µs, p99 {out['tick_p99_us']:.0f} µs, max "
              f"{out['tick_max_us']:.0f} µs")
        print(f"      CPU % of one core {out['cpu_pct']}; load average (1 min) {out['load1_during']}")
        print(f"      RSS [KiB] start {out['rss_kib_start']} end {out['rss_kib_end']}")
        print(f"      violations {out['violations']}; faults {out['faults'] or 'none'}; "
              f"protective stops {out['protective_stops']}; exit codes {out['exit_codes']}")
        print(verdict.line(), flush=True)
    return verdict.exit_code


def _process_failures(codes: dict[str, int | None]) -> list[str]:
    """A crashed process, or one that did not stop: each a FAIL."""
    return [f"the {name} did not stop on SIGINT (killed)" if code is None else f"the {name} exited with status {code}"
            for name, code in codes.items() if code != 0]


def _no_stack(out: dict[str, Any], stack: Any, log_dir: Path, as_json: bool,
              why: str = "the stack did not come up") -> int:
    """FAIL: nothing to judge (the processes stopped, the verdict line names the logs)."""
    codes = stack.stop()
    verdict = judge({}, failures=[why, *_process_failures(codes)], logs=log_dir)
    out |= {"logs": str(log_dir), "exit_codes": codes, **verdict.json_fields()}
    if as_json:
        print(json.dumps(out))
        print(verdict.line(), file=sys.stderr, flush=True)
    else:
        print(verdict.line(), flush=True)
    return verdict.exit_code
