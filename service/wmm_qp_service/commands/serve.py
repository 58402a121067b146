"""``wmm-qp serve``: run the control daemon."""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import wmm_qp as w

HELP = "run the control daemon (Zenoh)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from ..cli_common import add_service_arguments
    from .common import add_collision_argument, add_robot_argument, add_scene_argument

    add_service_arguments(parser)
    add_robot_argument(parser)
    add_scene_argument(parser)
    add_collision_argument(parser)
    parser.add_argument("--rate", type=float, help="[Hz] control rate (default: the service config's)")
    parser.add_argument("--trigger", choices=("rate", "state"),
                        help="what starts a tick: the fixed-rate clock, or each new state (default: the "
                             "service config's loop.trigger)")
    parser.add_argument("--breakdown", metavar="JSON",
                        help="time each stage of every tick and write the summary to this file at exit")
    parser.add_argument("--controller", choices=("qp", "paper", "traditional"),
                        help="controller kind (default: controller.toml's)")
    parser.add_argument("--solver", help="QP solver (default: controller.toml's)")
    parser.add_argument("--task", choices=("position", "pose"),
                        help="the EE task: position (r = 3) or pose (r = 6, setpoints' orientation "
                             "followed) (default: controller.toml's task.kind)")
    parser.add_argument("--controller-config", metavar="TOML", help="default: configs/controller.toml")
    parser.add_argument("--ros2", action="store_true",
                        help="also a ROS 2 face under /<robot>/: ee_pose, status, markers out; ee_target, mode in "
                             "(docs/ros2.md; pip install 'wmm-qp[ros2]')")
    parser.add_argument("--wait-lease", action="store_true",
                        help="when another daemon controls this robot, wait for its lease instead of "
                             "refusing to start")
    from ..recording.options import add_record_arguments

    add_record_arguments(parser)


def controller_config(args: argparse.Namespace) -> w.ControllerConfig:
    """The controller config of ``--controller-config`` with the command line's changes: the
    collision rows (on unless ``--no-collision`` or the file's ``[collision] enabled = false``;
    ``--scene`` turns them on), the task kind of ``--task``.

    Raises:
        wmm_qp.ConfigError: a bad controller file (one line, exit 2).
    """
    import wmm_qp as w

    from .common import collision_config

    ctl_cfg = collision_config(args, w.load_controller_config(args.controller_config))
    if args.task is not None:
        ctl_cfg = ctl_cfg.with_(task={"kind": args.task})
    return ctl_cfg


def run(args: argparse.Namespace) -> int:

    from ..cli_common import stop_on_signals
    from ..daemon import Daemon, LeaseHeld
    from ..recording.options import record_options, report_recording
    from .common import load_scene_arg, robot_service_config

    record = record_options(args, "serve")  # a missing extra or a bad split: one line, before anything starts
    robot, svc = robot_service_config(args)
    scene = load_scene_arg(args)  # the default scene's fence clamps setpoints in any case
    if args.rate is not None:
        if not 0 < args.rate <= 5000:
            print("wmm-qp serve: error: --rate must be in (0, 5000] Hz", file=sys.stderr)
            return 2
        svc = svc.with_(loop={"rate_hz": args.rate})
    if args.trigger is not None:
        svc = svc.with_(loop={"trigger": args.trigger})
    ctl_cfg = controller_config(args)
    if args.solver:
        from wmm_qp.solvers import available_solvers

        if args.solver not in available_solvers():
            print(f"wmm-qp serve: error: unknown solver {args.solver!r}; available: "
                  f"{', '.join(available_solvers())}", file=sys.stderr)
            return 2
        ctl_cfg = ctl_cfg.with_(qp={"solver": args.solver})
    daemon = Daemon(svc, ctl_cfg, robot, kind=args.controller, wait_lease=args.wait_lease, scene=scene,
                    breakdown=args.breakdown, **record)
    stop = stop_on_signals()
    face = None
    if args.ros2:
        from ..ros2.node import Ros2Missing

        try:
            from ..ros2.face import Ros2Face

            face = Ros2Face(svc.with_robot(robot), robot, scene)
            face.start()
        except Ros2Missing as e:
            print(f"wmm-qp serve: error: --ros2 {e}", file=sys.stderr)
            return 2
        ns = face.ros.node.get_namespace() if face.ros is not None else ""
        print(f"wmm-qp serve: ROS 2 face under {ns}/: ee_pose, status, markers; takes ee_target, mode",
              file=sys.stderr, flush=True)
    print(f"wmm-qp serve: {svc.prefix}/{svc.robot} at {svc.loop.rate_hz:g} Hz ({svc.loop.trigger} trigger) "
          f"({daemon.core.kind}, {ctl_cfg.task.kind} task; {robot.n_arm} joints, {robot.base.kind} base "
          f"with {robot.n_wheels} wheels; scene {scene.path}: {len(scene.obstacles)} obstacles, "
          f"{daemon.core.ctl.collision_summary()}), listening on {svc.zenoh.daemon_endpoint}",
          file=sys.stderr, flush=True)
    try:
        final = daemon.run(stop)
    except LeaseHeld as e:
        print(f"wmm-qp serve: error: {e}", file=sys.stderr, flush=True)
        return 3
    finally:
        if face is not None:
            face.close()
            print(f"wmm-qp serve: ROS 2 face: sent {dict(face.sent)}, refused {dict(face.refused) or 'none'}",
                  file=sys.stderr, flush=True)
    lp = final.loop
    print(f"wmm-qp serve: stopped after {lp.ticks} ticks, {lp.deadline_misses} deadline misses, "
          f"tick p50 {lp.tick_p50_us:.0f} µs p99 {lp.tick_p99_us:.0f} µs", file=sys.stderr, flush=True)
    if args.record:
        return report_recording("serve", daemon.recorded)
    return 0
