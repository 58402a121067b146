"""``wmm-qp experiment circle|dm|push``: reproduce one of the paper's experiments.

In-process by default: deterministic (seeded slip), faster than real time, a progress bar on
stderr when it is a terminal. ``--realtime``: through the daemon and the sim
processes over Zenoh on loopback, in real time (push: no ``--log``/``--plots``). Prints a
summary, or one JSON object with ``--json``; ``--log`` writes the per-tick CSV, ``--plots``
PNG figures.

Any robot: ``--robot-config FILE`` (default: the Gen3 on its Mecanum base, whose runs are the
paper's tables in docs/results.md); every experiment starts at the robot's ``arm.start``.
``--task pose`` overrides the controller config's task kind (in-process only).

``--physics kinematic|mujoco``: the sim's plant, in process and ``--realtime`` (the JSON's
``physics``); with ``mujoco``, ``push --max-mass`` bisects the heaviest box each arm
configuration pushes and ``--frames DIR`` renders a strip of frames (docs/results.md §7).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np
from wmm_qp_service.commands.common import (
    add_config_arguments,
    add_physics_argument,
    add_scene_argument,
    load_configs,
    load_scene_arg,
)

from wmm_qp.config import TASK_KINDS

HELP = "reproduce one of the paper's experiments (circle, dm, push)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("name", choices=("circle", "dm", "push"), help="which experiment")
    add_config_arguments(parser)
    parser.add_argument("--task", choices=TASK_KINDS, default=None,
                        help="task kind, overriding the controller config's [task] kind (not with --realtime)")
    parser.add_argument("--controller", choices=("traditional", "paper", "qp"), default="qp")
    parser.add_argument("--solver", default=None, help="QP backend (qp controller only)")
    parser.add_argument("--direction", choices=("x", "z"), default="x", help="DM direction (dm)")
    parser.add_argument("--radius", type=float, default=None,
                        help="circle radius [m] (circle; default the paper's 0.25; the large circle: 1.7)")
    parser.add_argument("--wheel-units", choices=("rad", "rim"), default="rad",
                        help="units of the wheel entries of v for the traditional controller's J+: wheel speeds "
                             "in rad/s (ours) or rim speeds in m/s (the paper's, likely); docs/results.md §1")
    parser.add_argument(
        "--duration",
        type=float,
        default=None,
        help="run length [s] (circle 40, dm 20; push: the DM phase, 20)",
    )
    parser.add_argument("--seed", type=int, default=None, help="slip/drift seed (default: sim.toml)")
    parser.add_argument("--no-slip", action="store_true", help="turn the base slip/drift off")
    add_physics_argument(parser)
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument(
        "--log",
        type=Path,
        default=None,
        help="per-tick CSV log (push: FILE gets _with_dm/_without_dm suffixes)",
    )
    add_scene_argument(parser, "none: the paper's setting, no obstacles and no collision rows; "
                               "a scene turns the qp controller's rows on")
    parser.add_argument("--plots", type=Path, default=None, help="folder for PNG plots")
    parser.add_argument("--frames", type=Path, default=None, metavar="DIR",
                        help="circle, push with --physics mujoco: a strip of frames rendered offscreen (PNG) "
                             "in DIR (without a screen: MUJOCO_GL=osmesa)")
    parser.add_argument("--max-mass", action="store_true",
                        help="push: bisect the heaviest box each arm configuration (with and without DM) "
                             "pushes 0.2 m, beside the ratio the DM values predict (in process; progress on "
                             "stderr)")
    parser.add_argument(
        "--realtime",
        action="store_true",
        help="run through the daemon and sim processes over Zenoh in real time",
    )
    parser.add_argument("--rate", type=float, default=None, help="[Hz] control rate with --realtime (default 500)")
    parser.add_argument("--process-logs", type=Path, default=None, help="--realtime: keep the processes' logs here")


def _fail(msg: str) -> int:
    print(f"wmm-qp experiment: error: {msg}", file=sys.stderr)
    return 2


def _suffixed(path: Path, suffix: str) -> Path:
    return path.with_name(f"{path.stem}_{suffix}{path.suffix or '.csv'}")


def run(args: argparse.Namespace) -> int:
    from wmm_qp_tools.experiments import circle, dm, log, push, runner
    from wmm_qp_tools.experiments.setup import make_setup

    if args.realtime and args.name == "push" and (args.log is not None or args.plots is not None):
        return _fail("push --realtime writes no --log or --plots (the JSON has the metrics)")
    if args.max_mass and (args.name != "push" or args.realtime or args.log is not None or args.plots is not None):
        return _fail("--max-mass applies to push in process only, without --log or --plots")
    if args.frames is not None and (args.physics != "mujoco" or args.name == "dm" or args.realtime or args.max_mass):
        return _fail("--frames applies to circle and push in process with --physics mujoco")
    if args.rate is not None and not args.realtime:
        return _fail("--rate only applies with --realtime")
    if args.rate is not None and not (np.isfinite(args.rate) and 10.0 <= args.rate <= 2000.0):
        return _fail(f"--rate must be in [10, 2000] Hz, got {args.rate}")
    if args.duration is not None and not (np.isfinite(args.duration) and args.duration > 0):
        return _fail(f"--duration must be > 0, got {args.duration}")
    if args.solver is not None and args.controller != "qp":
        return _fail("--solver only applies to --controller qp")
    if args.radius is not None and (args.name != "circle" or not (np.isfinite(args.radius) and args.radius > 0)):
        return _fail(f"--radius applies to circle only and must be > 0, got {args.radius}")
    if args.radius is not None and args.realtime:
        return _fail("--radius does not apply with --realtime yet (the realtime circle is the paper's 0.25 m)")
    if args.wheel_units != "rad" and args.controller != "traditional":
        return _fail("--wheel-units only applies to --controller traditional")
    if args.wheel_units != "rad" and args.realtime:
        return _fail("--wheel-units does not apply with --realtime (the daemon builds its own controller)")
    if args.task is not None and args.realtime:
        return _fail("--task does not apply with --realtime (the daemon loads its own --controller-config)")
    robot, ctl_cfg = load_configs(args)
    # the paper's setting by default: no obstacles and no collision rows (the sim's referee still
    # checks self and floor collisions); --scene adds the scene and the qp controller's rows (in
    # process and, with --realtime, in the daemon, which otherwise runs with --no-collision)
    scene = load_scene_arg(args) if args.scene is not None else None
    ctl_cfg = ctl_cfg.with_(collision={"enabled": scene is not None})
    if args.task is not None:
        ctl_cfg = ctl_cfg.with_(task={"kind": args.task})
    if args.plots is not None:
        args.plots.mkdir(parents=True, exist_ok=True)
        from wmm_qp_tools.experiments import plots

        plots._plt()

    def setup() -> Any:
        return make_setup(args.controller, args.solver, slip=not args.no_slip, seed=args.seed, robot=robot,
                          ctl_cfg=ctl_cfg, wheel_units=args.wheel_units, scene=scene, physics=args.physics)

    first = setup()  # a config error (a W of another length, a solver missing) before anything runs
    show_progress = True  # progress on stderr, also with --json (stdout stays the JSON alone)
    tag = args.controller
    result: dict[str, Any] = {"experiment": args.name, "robot": robot.name, "task": ctl_cfg.task.kind,
                              "controller": args.controller, "physics": first.sim_cfg.physics.plant}
    if args.controller == "qp":
        result["solver"] = args.solver
    # the controller's collision rows: the qp controller's with --scene only (the baselines have none)
    result["collision"] = getattr(first.controller, "collision", None) is not None
    if args.controller == "traditional":
        result["wheel_units"] = args.wheel_units
    if args.name == "circle":
        result["radius"] = circle.RADIUS if args.radius is None else args.radius
    traces: dict[str, Any] = {}
    if args.max_mass:
        from wmm_qp_tools.experiments.max_mass import max_mass

        result |= max_mass(setup, args.duration or push.DEFAULT_DM_DURATION, progress=show_progress)
        result["box"] = {"mu": push.MU, "target": push.TARGET}
    elif args.name == "push":
        dm_duration = args.duration or push.DEFAULT_DM_DURATION
        if args.realtime:
            runs, result["realtime"] = _push_realtime(args, setup, dm_duration, show_progress)
        else:
            scale = min(1.0, dm_duration / push.DEFAULT_DM_DURATION)
            span = (push.GAP + push.TARGET) / push.PUSH_SPEED * scale  # [s] the push's frames
            strips = {n: _strip(args, span) for n in push.RUNS}
            runs = push.run_push(setup, dm_duration, progress=show_progress,
                                 observe={n: v for n, v in strips.items() if v is not None})
            if args.frames is not None:
                result["frames"] = [str(v.save(args.frames / f"frames_push_{n}.png", f"push {n.replace('_', ' ')}, "
                                               f"{robot.name}, MuJoCo")) for n, v in strips.items() if v is not None]
        for name, (s, tr) in runs.items():
            result[name] = push.push_metrics(s, tr)
        result["box"] = {"mass": push.MASS, "mu": push.MU, "target": push.TARGET}
        traces = {name: tr for name, (_, tr) in runs.items()}
        result["violations"] = {
            k: sum(tr.violations.get(k, 0) for tr in traces.values()) for k in traces["with_dm"].violations
        }
        if args.plots:
            from wmm_qp_tools.experiments.plots import plot_push

            s0 = runs["with_dm"][0]
            plot_push(
                {n: (tr, tr.start_of(push.PUSH)) for n, tr in traces.items()},
                np.asarray(s0.W),
                np.asarray(s0.robot.arm.torque_limit),
                args.plots,
                tag,
            )
    else:
        s = first
        default = circle.DEFAULT_DURATION if args.name == "circle" else dm.DEFAULT_DURATION
        duration = args.duration or default
        radius = circle.RADIUS if args.radius is None else args.radius
        if args.name == "circle":
            scenario = circle.scenario(np.asarray(s.ctl_cfg.direction, dtype=float), duration, radius)
        else:
            scenario = dm.scenario(args.direction, duration)
            tag = f"{args.controller}_{args.direction}"
        if args.realtime:
            rt = _realtime(args, s, scenario, args.name, show_progress)
            tr = rt.trace
            result["realtime"] = rt.service
            result["duration"] = float(tr.t[-1] - tr.t[0]) + 1.0 / rt.service["rate_hz"]
            tag = f"{tag}_realtime"
        elif args.name == "circle":
            strip = _strip(args, duration, elevation=-50.0)  # from above: the circle shows
            tr = circle.run_circle(s, duration, progress=show_progress, radius=radius, observe=strip)
            if strip is not None:
                result["frames"] = [str(strip.save(args.frames / f"frames_circle{circle.plot_tag('', radius)}.png",
                                                   f"circle r = {radius:g} m, {robot.name}, MuJoCo"))]
            result["duration"] = float(tr.t[-1] + s.ctl_cfg.dt)
            tag = circle.plot_tag(tag, radius, args.wheel_units)
        else:
            tr = runner.run(s, scenario, progress=show_progress)
            result["duration"] = duration
        result |= circle.circle_metrics(tr) if args.name == "circle" else dm.dm_metrics(tr, s, args.direction)
        traces = {"": tr}
        if args.plots:
            from wmm_qp_tools.experiments import plots

            (plots.plot_circle if args.name == "circle" else plots.plot_dm)(tr, args.plots, tag)
    if args.log is not None:
        for name, tr in traces.items():
            log.write_csv(tr, _suffixed(args.log, name) if name else args.log)
    if traces:
        result["controller_reasons"] = {k: v for r in traces.values() for k, v in r.reasons.items()}
    if args.json:
        print(json.dumps(result))
    else:
        _summary(result)
    return 0


def _strip(args: argparse.Namespace, span: float, elevation: float = -10.0) -> Any:
    """A frame strip over ``span`` [s] of the run (camera ``elevation`` [deg]) when ``--frames``
    asks for one, else None."""
    if args.frames is None:
        return None
    from wmm_qp_tools.experiments.frames import Strip

    args.frames.mkdir(parents=True, exist_ok=True)
    return Strip(span, elevation=elevation)


def _options(args: argparse.Namespace, name: str, s: Any, log_dir: Path | None) -> Any:
    """The processes' options of one realtime run named ``name`` (its logs under ``log_dir``)."""
    from wmm_qp_tools.experiments.stack import options

    return options(name, s, args.controller, args.solver, not args.no_slip, args.seed, args.rate, log_dir,
                   args.controller_config)


def _realtime(args: argparse.Namespace, s: Any, scenario: Any, name: str, show_progress: bool) -> Any:
    """Run circle or dm through the daemon and the sim."""
    from wmm_qp_tools.experiments.realtime import run_realtime

    return run_realtime(s, scenario, _options(args, name, s, args.process_logs), progress=show_progress)


def _push_realtime(args: argparse.Namespace, setup: Any, dm_duration: float,
                   show_progress: bool) -> tuple[dict[str, Any], dict[str, Any]]:
    """The push's runs through the daemon and the sim, each on a fresh pair of processes (logs
    under ``--process-logs``/<run>): ({run: (setup, trace)}, {run: the service-side figures})."""
    from wmm_qp_tools.experiments import push
    from wmm_qp_tools.experiments.realtime import run_realtime

    runs, service = {}, {}
    for name, scenario in push.scenarios(dm_duration).items():
        s = setup()
        opts = _options(args, f"push-{name}", s, None if args.process_logs is None else args.process_logs / name)
        rt = run_realtime(s, scenario, opts, progress=show_progress)
        runs[name], service[name] = (s, rt.trace), rt.service
    return runs, service


def _summary(result: dict[str, Any]) -> None:
    def fmt(v: Any) -> str:
        if isinstance(v, float):
            return f"{v:.4g}"
        if isinstance(v, list):
            return "[" + ", ".join(fmt(x) for x in v) + "]"
        if isinstance(v, dict):
            return "{" + ", ".join(f"{k}: {fmt(x)}" for k, x in v.items()) + "}"
        return str(v)

    for k, v in result.items():
        print(f"{k:28s} {fmt(v)}")
