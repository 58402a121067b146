"""``wmm-qp verify``: random states through a controller, every command refereed.

Any robot (``--robot-config FILE``, default the Gen3); ``--task position|pose`` overrides the
controller config's ``[task] kind`` (with ``pose`` every sample also carries a target
orientation and an angular feed-forward)."""

from __future__ import annotations

import argparse
import json
import sys

import wmm_qp as w
from wmm_qp.config import TASK_KINDS
from wmm_qp.controllers.qp import QpController
from wmm_qp.solvers import SOLVER_NAMES
from wmm_qp.verify import KINDS, SATURATION_NOTE, verify_controller

from ..progress import ProgressLine
from ..verdict import EXIT_CODES_HELP, judge
from .common import add_collision_argument, add_config_arguments, add_scene_argument, load_configs, load_scene_arg

HELP = "sample random states and check every command against every hard bound"


def _positive(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
    if n <= 0:
        raise argparse.ArgumentTypeError("must be > 0")
    return n


def _seed(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
    if n < 0:
        raise argparse.ArgumentTypeError("must be >= 0")
    return n


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.epilog = EXIT_CODES_HELP + " Progress goes to stderr (about once a second)."
    parser.add_argument("--controller", choices=w.config.CONTROLLER_KINDS, default="qp")
    parser.add_argument("--solver", choices=SOLVER_NAMES, default=None, help="QP backend (default: config's)")
    parser.add_argument("--samples", type=_positive, default=1000, help="random states (each run in every mode)")
    parser.add_argument("--seed", type=_seed, default=0, help="RNG seed (>= 0)")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--task", choices=TASK_KINDS, default=None,
                        help="task kind, overriding the controller config's [task] kind")
    add_config_arguments(parser)
    add_scene_argument(parser, "configs/scenes/default.toml: a fence 3 m around the start, no obstacles; every "
                               "command is refereed for collisions too — self, floor, the scene's obstacles and "
                               "fence — and states are sampled near self-collisions, obstacles and the fence")
    add_collision_argument(parser)


def run(args: argparse.Namespace) -> int:
    robot, cfg = load_configs(args)
    if args.solver:
        cfg = cfg.with_(qp={"solver": args.solver})
    if args.task:
        cfg = cfg.with_(task={"kind": args.task})
    if args.no_collision and args.scene is not None:
        print("wmm-qp verify: error: --scene and --no-collision exclude each other (--no-collision referees "
              "the bounds only, without a scene)", file=sys.stderr)
        return 2
    # collisions refereed by default (self, floor, the default scene's fence; --scene: its obstacles
    # too); --no-collision: the bounds only, and the qp controller without rows
    scene = None if args.no_collision else load_scene_arg(args)
    if args.no_collision:
        cfg = cfg.with_(collision={"enabled": False})
    elif args.scene is not None:  # a scene's obstacles: the qp controller's rows on
        cfg = cfg.with_(collision={"enabled": True})
    model = w.WmmModel(robot)
    ctl = w.make_controller(args.controller, model, cfg)
    bar = ProgressLine("verify")
    bar.update(f"0/{args.samples} samples (a first run also compiles the kernels)")

    def progress(i: int, n: int, violations: int) -> None:
        text = f"{i}/{n} samples, {violations} violations"
        bar.done(text) if i == n else bar.update(text)

    rep = verify_controller(ctl, model, args.samples, args.seed, progress, scene=scene)
    verdict = judge(rep.by_kind, also=f"in {rep.steps} commands ({rep.samples} states x {len(rep.by_mode)} modes)")
    label = f"{robot.name}, {cfg.task.kind} task: " + args.controller
    label += f" ({ctl.solver})" if isinstance(ctl, QpController) else ""
    if args.json:
        print(
            json.dumps(
                {
                    "robot": robot.name,
                    "robot_file": str(robot.path),
                    "task": cfg.task.kind,
                    "controller": args.controller,
                    "solver": ctl.solver if isinstance(ctl, QpController) else None,
                    "samples": rep.samples,
                    "steps": rep.steps,
                    "violations": rep.violations,
                    "by_kind": rep.by_kind,
                    "by_mode": rep.by_mode,
                    "by_case": rep.by_case,
                    "statuses": rep.statuses,
                    "cut_by": rep.cut_by,
                    "examples": rep.examples,
                    "seed": args.seed,
                    "scene": None if scene is None else str(scene.path),
                    **verdict.json_fields(),
                    "collision": scene is not None,
                    "collision_rows": ctl.collision_on,
                }
            )
        )
        print(verdict.line(), file=sys.stderr)
    else:
        where = "no collision referee" if scene is None else f"scene {scene.path}"
        print(f"{label}: {rep.samples} states x {len(rep.by_mode)} modes = {rep.steps} commands, seed {args.seed}, "
              f"{where}")
        print(f"{'mode':<14}" + "".join(f"{k:>14}" for k in KINDS))
        for mode, counts in rep.by_mode.items():
            print(f"{mode:<14}" + "".join(f"{counts[k]:>14}" for k in KINDS))
        print(f"{'total':<14}" + "".join(f"{rep.by_kind[k]:>14}" for k in KINDS))
        print("command statuses: " + ", ".join(f"{k} {v}" for k, v in sorted(rep.statuses.items())))
        if rep.cut_by:
            cuts = sorted(rep.cut_by.items(), key=lambda kv: -kv[1])
            print("  the task cut by: " + ", ".join(f"{k} {v}" for k, v in cuts))
            print(f"  ({SATURATION_NOTE})")
        print(f"violations: {rep.violations}")
        print(verdict.line())
    return verdict.exit_code
