"""``wmm-qp demo``: sim and daemon on loopback, every mode driven, a summary printed.

Scenario (phase lengths scale with --duration; 30 s by default), from the robot's start
configuration (the paper's for the Gen3): hold → Cartesian DM enhancement → null-space DM
enhancement (the paper's Fig. 9 sequence, DM along x) → track a haptic-like stream (jitter,
jumps) → hold → track the paper's circle (feed-forward velocity) → hold. The sim and the daemon
both get ``--robot-config``; a robot whose EE starts outside the DM box of the controller config
(``dm.ee_box_lower/upper``) holds during the Cartesian DM phase. When a fault ends, the daemon
holds until a mode message (``watchdog.resume = "manual"``): the demo then resends the phase's
mode, as an operator would, and counts it (``phases[].resumes``).

With ``--driver franka --robot-ip IP`` the scenario runs through a real robot's driver
(``wmm-qp driver franka``, started by the demo) against a robot already running at that address
(a Franka FR3, or franky-sim) instead of a sim; ``violations`` are then the driver's referee
(its ``sim/truth``), and the EE error is n/a (no ground truth).

With ``--driver ros2`` the scenario runs through ``wmm-qp driver ros2`` (started by the demo)
against a ROS 2 robot already running on the topics of the robot file's ``[ros2]`` table (``wmm-qp
sim --ros2``, or a ros2_control robot; docs/ros2.md); ``violations`` are the driver's referee,
the EE error n/a (no ground truth), ``exit_codes`` name ``driver`` and ``daemon``.

With ``--embedded`` the same scenario runs through one process, ``wmm-qp sim --embedded``: the
control core in the sim's own cycle (``--rate`` is its control rate, dividing the sim's 1 kHz);
``exit_codes`` and ``cpu_pct`` name ``embedded``. With ``--driver franka --embedded`` the one
process is ``wmm-qp driver franka --embedded`` (the core in libfranka's cycle; ``driver``).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections import Counter
from pathlib import Path
from typing import Any

from ..progress import ProgressLine
from ..verdict import EXIT_CODES_HELP, Verdict, judge
from .common import (
    add_collision_argument,
    add_physics_argument,
    add_robot_argument,
    add_scene_argument,
    embedded_rate,
    load_robot,
    load_scene_arg,
    physics_plant,
)

HELP = "start sim and daemon on loopback, drive every mode, print a summary"

PHASES = (("hold", 1.0), ("dm_cartesian", 4.0), ("dm_nullspace", 9.0), ("track_haptic", 6.0),
          ("hold", 1.0), ("track_circle", 8.0), ("hold", 1.0))


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.epilog = EXIT_CODES_HELP + " A process that crashes or does not stop is a FAIL too."
    parser.add_argument("--duration", type=float, default=30.0, help="[s] scenario length")
    parser.add_argument("--rate", type=float, default=500.0, help="[Hz] control rate")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--logs", metavar="DIR",
                        help="write the sim's and the daemon's logs here (default: a fresh folder under the "
                             "temporary directory, kept and named on the verdict line)")
    parser.add_argument("--controller-config", type=Path, default=None, metavar="FILE",
                        help="the daemon's controller.toml (default: configs/controller.toml)")
    parser.add_argument("--driver", choices=("franka", "ros2"), default=None,
                        help="run the scenario through this real robot's driver instead of a sim "
                             "(franka needs --robot-ip, docs/drivers.md; ros2 drives the ROS 2 robot already "
                             "running on the topics of --robot-config's [ros2] table, docs/ros2.md)")
    parser.add_argument("--embedded", action="store_true",
                        help="one process instead of two: the control core in the sim's own cycle "
                             "(wmm-qp sim --embedded; --rate must divide the sim's rate), or with --driver "
                             "in the driver's (wmm-qp driver franka --embedded)")
    parser.add_argument("--robot-ip", metavar="IP", default=None,
                        help="the address of the running robot the --driver drives (e.g. franky-sim's)")
    add_robot_argument(parser)
    add_scene_argument(parser)
    add_collision_argument(parser)
    add_physics_argument(parser)


def run(args: argparse.Namespace) -> int:
    if not 5.0 <= args.duration <= 3600.0:
        print("wmm-qp demo: error: --duration must be in [5, 3600] s", file=sys.stderr)
        return 2
    if not 10.0 <= args.rate <= 2000.0:
        print("wmm-qp demo: error: --rate must be in [10, 2000] Hz", file=sys.stderr)
        return 2
    if args.driver == "ros2":
        if args.robot_ip is not None or args.embedded:
            print("wmm-qp demo: error: --driver ros2 takes no --robot-ip and no --embedded (the robot is the ROS 2 "
                  "graph's, on the topics of --robot-config's [ros2] table)", file=sys.stderr)
            return 2
    elif (args.driver is None) != (args.robot_ip is None):
        print("wmm-qp demo: error: --driver and --robot-ip go together (--driver franka --robot-ip IP)",
              file=sys.stderr)
        return 2
    import wmm_qp as w

    from ..processes import Stack, isolated_config, log_folder

    robot = load_robot(args)  # a bad file: one line, exit 2, before anything starts
    scene = load_scene_arg(args)
    plant = physics_plant(args)
    ctl = w.load_controller_config(args.controller_config)
    ctl.weights_for(robot)
    if args.embedded:
        embedded_rate(args.rate)  # one that does not divide the sim's rate: one line, exit 2
    svc = isolated_config(robot=robot)
    log_dir = log_folder(args.logs, "demo")
    daemon_args = [] if args.controller_config is None else ["--controller-config",
                                                             str(Path(args.controller_config).resolve())]
    daemon_args += ["--no-collision"] if args.no_collision else []  # else the rows are the daemon's default: on
    stack = Stack(svc, rate_hz=args.rate, log_dir=log_dir, robot_file=robot.path,
                  scene_file=scene.path if args.scene is not None else None,
                  extra_daemon_args=daemon_args, extra_sim_args=["--physics", plant], embedded=args.embedded)
    from wmm_qp_service.machine import CPU_HOW, CpuMeter

    from ..readiness import NotReady

    meters: list[CpuMeter] = []  # started when the stack is up (start-up is not the loop's CPU)
    cpu: dict[str, float | None] = {}
    bar = ProgressLine("demo")
    summary: dict[str, Any] | None = None
    not_up = ""
    try:
        if args.driver is not None:
            bar.update(f"starting the {args.driver} driver for {args.robot_ip or robot.name}"
                       f"{' with the control core in its cycle' if args.embedded else ' and the daemon'} "
                       f"(logs: {log_dir})")
            stack.start_driver(args.driver, args.robot_ip)
            if not args.embedded:
                stack.start_daemon()
        else:
            bar.update(f"starting the {'embedded sim' if args.embedded else 'sim and the daemon'} (logs: {log_dir})")
            stack.start()
        try:
            summary = _drive(svc, args.duration, bar, exited=stack.exited,
                             on_ready=lambda: meters.append(CpuMeter({n: p.pid for n, p in stack.procs.items()})))
        except NotReady as err:
            not_up = str(err)
        if meters:
            cpu = meters[0].shares()
    finally:
        bar.update("stopping the sim and the daemon")
        codes = stack.stop()
    bar.close()
    failures = [f for f in _process_failures(codes) if f not in not_up]  # said once
    if summary is None:
        why = f"the stack did not come up: {not_up}" if not_up else "the daemon stopped answering"
        verdict = judge({}, failures=[why, *failures], logs=log_dir)
        _say_verdict(verdict, args.json, {"logs": str(log_dir), "exit_codes": codes})
        return verdict.exit_code
    verdict = judge(summary["violations"], failures=failures,
                    deadline_misses=int(summary["loop"].get("deadline_misses") or 0),
                    faults=summary["faults"] or {}, protective_stops=int(summary["protective_stops"] or 0),
                    logs=log_dir)
    summary["exit_codes"] = codes
    summary["cpu_pct"], summary["cpu_how"] = cpu, CPU_HOW
    summary["logs"] = str(log_dir)
    # a driver's robot is its own physics (franky-sim's MuJoCo, a real arm): no plant of ours ran
    summary["physics"] = plant if args.driver is None else f"the robot's own (driver {args.driver})"
    summary["embedded"] = args.embedded
    summary["robot"] = {"name": robot.name, "file": str(robot.path), "n_arm": robot.n_arm,
                        "n_wheels": robot.n_wheels, "base_kind": robot.base.kind, "task": ctl.task.kind}
    summary |= verdict.json_fields()
    if args.json:
        print(json.dumps(_finite_or_none(summary), allow_nan=False))
    else:
        lp = summary["loop"]
        print(f"demo: {robot.name} ({robot.n_arm} joints, {robot.base.kind} base, {ctl.task.kind} task), "
              f"{summary['duration_s']:.1f} s at {lp['rate_hz']:g} Hz — {summary['scenario_ticks']} ticks "
              f"({lp['ticks']} since the daemon started, its start-up included), "
              f"deadline misses {lp['deadline_misses']}, tick p50 {lp['tick_p50_us']:.0f} µs, "
              f"p99 {lp['tick_p99_us']:.0f} µs, max {lp['tick_max_us']:.0f} µs")
        print(f"      violations {summary['violations_total']} {summary['violations']}; {summary['collision_summary']}")
        print(f"      CPU % of one core (the scenario's wall time) {cpu}")
        e = summary["ee_error_max"]
        print(f"      EE error max (ground truth) {'n/a' if e is None else f'{e * 100:.2f} cm'}; "
              f"DM along x {summary['dm_start']:.3f} → {summary['dm_end']:.3f}")
        print(f"      rejected {summary['rejected']}; faults {summary['faults'] or 'none'}; "
              f"protective stops {summary['protective_stops']}; processes exited {codes}")
    _say_verdict(verdict, args.json)
    return verdict.exit_code


def _process_failures(codes: dict[str, int | None]) -> list[str]:
    """What went wrong with the processes themselves (a crash, a hang at the end): each a FAIL."""
    out = []
    for name, code in codes.items():
        if code is None:
            out.append(f"the {name} did not stop on SIGINT (killed)")
        elif code != 0:
            out.append(f"the {name} exited with status {code}")
    return out


def _say_verdict(verdict: Verdict, as_json: bool, fields: dict[str, Any] | None = None) -> None:
    """The verdict line: last on stdout; with --json on stderr (the JSON alone on stdout)."""
    if as_json:
        if fields is not None:  # no summary: the verdict is the JSON
            print(json.dumps({**fields, **verdict.json_fields()}))
        print(verdict.line(), file=sys.stderr, flush=True)
    else:
        print(verdict.line(), flush=True)


def _delta(a: dict[str, int], b: dict[str, int]) -> dict[str, int]:
    return {k: b[k] - a.get(k, 0) for k in b if b[k] != a.get(k, 0)}


def _finite_or_none(v: Any) -> Any:
    """The summary with NaN/inf replaced by None (strict JSON)."""
    if isinstance(v, dict):
        return {k: _finite_or_none(x) for k, x in v.items()}
    if isinstance(v, list | tuple):
        return [_finite_or_none(x) for x in v]
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


class _Operator:
    """The demo's operator: the phase's mode, resumed after each fault (manual resume)."""

    mode = "hold"
    resumes = 0
    quiet_until = 0.0  # [s, wall] statuses stamped before this predate the last mode message


def _drive(svc: Any, duration: float, bar: ProgressLine, exited: Any = lambda: None,
           on_ready: Any = None) -> dict[str, Any] | None:
    """The scenario against a started stack (None: the daemon stopped answering at the end).

    Raises:
        NotReady: the stack did not come up (:meth:`~..client.Reader.wait_ready`; ``exited`` names a
            started process that ended).
    """
    import numpy as np

    from ..client import Client
    from ..readiness import START_TIMEOUT, STATE_TIMEOUT
    from ..teleop import hold_stream, stream_circle, stream_haptic, wait

    scale = duration / sum(d for _, d in PHASES)
    with Client(svc, name="demo", telemetry=True) as c:
        info = c.wait_ready(START_TIMEOUT, STATE_TIMEOUT, exited=exited, say=bar.update)
        if on_ready is not None:
            on_ready()
        ee_err: list[float] = []
        per_phase: list[dict[str, Any]] = []
        statuses: Counter[str] = Counter()  # controller statuses of the current phase
        op = _Operator()
        phase = ""

        def violations_now() -> str:
            s = c.latest_truth()
            return f"phase {phase}, {sum(s.violations.values()) if s is not None else '?'} violations so far"

        def drain() -> None:
            bar.update(violations_now)
            for m in c.telemetry():
                statuses[m.status] += 1
                if math.isfinite(m.ee_error):
                    ee_err.append(m.ee_error)
            s = c.latest_status()  # the operator's part: resume after a fault cleared (manual resume)
            if s is not None and s.resume_needed and s.stamp > op.quiet_until:
                op.quiet_until = time.time() + 0.2  # one mode message per fault
                op.resumes += 1
                c.set_mode(op.mode)

        def x_now() -> np.ndarray:
            i = c.info()
            assert i is not None and i.status.x
            return np.array(i.status.x)

        dm_start = info.status.dm
        ticks0 = (c.info() or info).status.loop.ticks  # the daemon ticked while the stack came up
        t_start = time.monotonic()
        faults0 = dict(info.status.faults)
        st0 = c.latest_truth() or c.wait_truth(2.0)
        viol0 = dict(st0.violations) if st0 is not None else {}
        for k, (name, d) in enumerate(PHASES):
            d *= scale
            mode = name.split("_track")[0] if not name.startswith("track") else "track"
            phase = f"{k + 1}/{len(PHASES)} {name} ({d:.1f} s)"
            c.set_mode(mode)
            op.mode, op.resumes, op.quiet_until = mode, 0, time.time() + 0.2
            statuses.clear()
            wait(0.05, drain)
            n0 = len(ee_err)
            if name == "track_haptic":
                stream_haptic(c, x_now(), d, on_tick=drain)
            elif name == "track_circle":
                stream_circle(c, x_now(), d, on_tick=drain)
            elif name == "dm_nullspace":
                hold_stream(c, x_now(), d, on_tick=drain)
            else:
                wait(d, drain)
            drain()
            i = c.info()
            tp = c.latest_truth()
            faults = dict(i.status.faults) if i else faults0
            viol = dict(tp.violations) if tp is not None else viol0
            per_phase.append({"phase": name, "duration_s": round(d, 2),
                              "ee_error_max": max(ee_err[n0:], default=None),  # None: untracked
                              "dm": i.status.dm if i else None,
                              "statuses": dict(statuses), "resumes": op.resumes,
                              "reason": i.status.reason if i else None,
                              "new_faults": _delta(faults0, faults),
                              "new_violations": _delta(viol0, viol)})
            faults0, viol0 = faults, viol
        final = c.info()
        st, tr = c.latest_state(), c.latest_truth()
        if final is None:
            return None
        elapsed = time.monotonic() - t_start
        violations = dict(tr.violations) if tr is not None else dict(final.status.robot_violations)
    import msgspec

    return {
        "duration_s": elapsed,
        "loop": msgspec.to_builtins(final.status.loop),
        "scenario_ticks": final.status.loop.ticks - ticks0,
        "violations": violations,
        "violations_total": int(sum(violations.values())),
        "ee_error_max": max(ee_err, default=None),
        "dm_start": dm_start,
        "dm_end": next(p["dm"] for p in per_phase if p["phase"] == "dm_nullspace"),
        "collision": final.status.collision,
        "collision_summary": final.status.collision_summary,
        "rejected": final.status.rejected,
        "last_fault": final.status.last_fault,
        "last_fault_code": final.status.last_fault_code,
        "faults": final.status.faults,
        "protective_stops": st.protective_stops if st is not None else None,
        "sim_refused": dict(st.refused) if st is not None else {},
        "phases": per_phase,
    }
