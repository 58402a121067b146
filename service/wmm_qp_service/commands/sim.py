"""``wmm-qp sim``: run the simulated robot as a Zenoh node."""

from __future__ import annotations

import argparse
import sys
from typing import Any

HELP = "run the simulated robot (Zenoh)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from ..cli_common import add_service_arguments
    from .common import add_embedded_arguments, add_physics_argument, add_robot_argument, add_scene_argument

    add_service_arguments(parser)
    add_robot_argument(parser)
    add_scene_argument(parser)
    parser.add_argument("--sim-config", metavar="TOML", help="sim config (default: configs/sim.toml)")
    parser.add_argument("--seed", type=int, help="slip/drift noise seed (default: the sim config's)")
    parser.add_argument("--rate", type=float, help="[Hz] sim rate (default: the sim config's)")
    parser.add_argument("--rt-priority", type=int, default=None, metavar="N",
                        help="SCHED_FIFO priority of the step loop, 0 = normal scheduling (default: "
                             "the sim config's rt_priority, 50; without root or CAP_SYS_NICE the sim "
                             "says so and runs normally)")
    add_physics_argument(parser)
    parser.add_argument("--no-ramp", action="store_true",
                        help="apply each command at once (no drive acceleration ramp)")
    parser.add_argument("--no-truth", action="store_true",
                        help="publish no evaluation data on <robot>/sim/truth (ground truth, the referee's "
                             "counts): a robot that reports only what a real one does")
    e = add_embedded_arguments(
        parser, "embedded mode: the control core in the sim's own cycle (docs/protocol.md)",
        "host the control daemon's core in the sim's step loop: each cycle reads the state, ticks and writes the "
        "command in one thread, no transport between them; Zenoh still carries setpoints, modes, obstacles, "
        "status, telemetry, info and the lease (no wmm-qp serve: clients talk to this process)",
        "with --embedded: [Hz] the core's rate, dividing the sim's (default: the sim's rate; 500 ticks every 2nd "
        "cycle of a 1 kHz sim)")
    e.add_argument("--cycle-report", metavar="JSON",
                   help="with --embedded: write the cycle's figures (ticks, misses, tick work, the garbage "
                        "collector's work in the slack) to this file at exit")
    e.add_argument("--plain-cycle", action="store_true",
                   help="with --embedded: without the cycle's cost cuts (the garbage collector in the slack "
                        "only, the spin before each deadline, the service thread one level below the cycle's "
                        "priority): to measure them (docs/benchmarks.md)")
    parser.add_argument("--ros2", action="store_true",
                        help="a stand-in ROS 2 robot instead of a Zenoh node: the plant behind the ros2_control-shaped "
                             "topics of the robot file's [ros2] table (joint_states, odom out; forward velocity "
                             "commands, cmd_vel in), for wmm-qp driver ros2 (docs/ros2.md); --rate: its cycle "
                             "(default: [ros2] rate_hz). With --embedded: the ROS 2 face of wmm-qp serve --ros2 "
                             "instead (ee_pose, status, markers; ee_target, mode)")

    from ..recording.options import add_record_arguments

    add_record_arguments(parser)  # with --embedded: the core's ticks
    f = parser.add_argument_group("fault injection (reliability tests)")
    f.add_argument("--state-loss", type=float, default=0.0, metavar="P",
                   help="drop each state publication with probability P in [0, 1)")
    f.add_argument("--state-delay-ms", type=float, default=0.0, metavar="MS",
                   help="publish every state MS milliseconds late")


def run(args: argparse.Namespace) -> int:
    from wmm_qp_sim import load_sim_config

    from ..cli_common import stop_on_signals
    from ..drivers.sim_node import SimNode
    from .common import embedded_only_given, load_scene_arg, robot_service_config

    robot, svc = robot_service_config(args)
    scene = load_scene_arg(args)
    sim_cfg = load_sim_config(args.sim_config)
    if args.rate is not None:
        if not args.rate > 0:
            print("wmm-qp sim: error: --rate must be > 0", file=sys.stderr)
            return 2
        if not args.ros2:
            sim_cfg = sim_cfg.with_(rate_hz=args.rate)
    if not (0.0 <= args.state_loss < 1.0 and 0.0 <= args.state_delay_ms < 10_000.0):
        print("wmm-qp sim: error: --state-loss must be in [0, 1) and --state-delay-ms in [0, 10000)",
              file=sys.stderr)
        return 2
    if args.physics is not None:
        sim_cfg = sim_cfg.with_(physics={"plant": args.physics})
    if args.ros2 and not args.embedded:
        return _run_ros2(args, robot, scene, sim_cfg)
    prio = sim_cfg.rt_priority if args.rt_priority is None else args.rt_priority
    if not 0 <= prio <= 99:
        print("wmm-qp sim: error: --rt-priority must be in [0, 99]", file=sys.stderr)
        return 2
    if args.embedded:
        return _run_embedded(args, robot, svc, scene, sim_cfg, prio)
    if args.record is not None:
        print("wmm-qp sim: error: --record needs --embedded (it records the control core's ticks; the daemon "
              "records with wmm-qp serve --record)", file=sys.stderr)
        return 2
    if (flag := embedded_only_given(args, shared=("--scene",))) is not None:
        print(f"wmm-qp sim: error: {flag} needs --embedded (without it the sim hosts no controller: "
              f"give it to wmm-qp serve)", file=sys.stderr)
        return 2
    node = SimNode(svc, sim_cfg, robot, seed=args.seed, ramp=not args.no_ramp,
                   state_loss=args.state_loss, state_delay=args.state_delay_ms * 1e-3, rt_priority=prio, scene=scene,
                   truth=not args.no_truth)
    stop = stop_on_signals()
    print(f"wmm-qp sim: {svc.prefix}/{svc.robot} at {sim_cfg.rate_hz:g} Hz ({robot.n_arm} joints, "
          f"{robot.base.kind} base with {robot.n_wheels} wheels; {sim_cfg.physics.plant} plant; scene {scene.path}: "
          f"{len(scene.obstacles)} obstacles; collision referee "
          f"{'on' if node.sim.collision is not None else 'off'}), listening on {svc.zenoh.sim_endpoint}",
          file=sys.stderr, flush=True)
    st = node.run(stop)
    print(f"wmm-qp sim: stopped at t = {st.t:.3f} s, violations {st.violations}, "
          f"commands rejected {dict(node.validate.rejected)}, "
          f"states dropped by fault injection {node.states_dropped}"
          + (f"; steps per joint at its torque limit {st.drives['torque_limit']}, not following its command "
             f"{st.drives['tracking']}" if sim_cfg.physics.plant != "kinematic" and st.drives else ""),
          file=sys.stderr, flush=True)
    return 0


def _run_embedded(args: argparse.Namespace, robot: Any, svc: Any, scene: Any, sim_cfg: Any, prio: int) -> int:
    """``wmm-qp sim --embedded``: the sim and the control core in one cycle (exit 3: another
    daemon holds the robot's lease)."""
    from ..cli_common import stop_on_signals
    from ..daemon import LeaseHeld
    from ..embedded.sim import EmbeddedSim
    from .serve import controller_config

    if args.state_loss or args.state_delay_ms:
        print("wmm-qp sim: error: --state-loss and --state-delay-ms are faults of the transport between a sim and "
              "a daemon: not with --embedded (no transport carries the state)", file=sys.stderr)
        return 2
    if args.control_rate is not None and not 0 < args.control_rate <= sim_cfg.rate_hz:
        print(f"wmm-qp sim: error: --control-rate must be in (0, {sim_cfg.rate_hz:g}] Hz (the sim's rate)",
              file=sys.stderr)
        return 2
    from ..recording.options import record_options, report_recording

    record = record_options(args, "sim")  # a missing extra or a bad split: one line, before anything starts
    ctl_cfg = controller_config(args)  # a bad file: one line, exit 2
    emb = EmbeddedSim(svc, sim_cfg, robot, ctl_cfg, control_rate=args.control_rate, kind=args.controller,
                      scene=scene, seed=args.seed, ramp=not args.no_ramp, truth=not args.no_truth,
                      rt_priority=prio, spin_s=svc.loop.spin_us * 1e-6, cuts=not args.plain_cycle)
    core = emb.control.core
    if record:  # the writer process starts before the cycle's priority is raised
        from ..recording.journal import TickJournal, recording_meta

        emb.control.journal = TickJournal(record["record"], recording_meta(core, "embedded", "embedded"),
                                          robot.n_arm, robot.n_wheels, record["split_size"], record["split_time"],
                                          emb.control.timing.rate_hz)
    stop = stop_on_signals()
    print(f"wmm-qp sim: {svc.prefix}/{svc.robot} at {sim_cfg.rate_hz:g} Hz, embedded control at "
          f"{emb.control.timing.rate_hz:g} Hz ({core.kind}, {ctl_cfg.task.kind} task; {robot.n_arm} joints, "
          f"{robot.base.kind} base with {robot.n_wheels} wheels; {sim_cfg.physics.plant} plant; scene {scene.path}: "
          f"{len(scene.obstacles)} obstacles, {core.ctl.collision_summary()}; collision referee "
          f"{'on' if emb.node.sim.collision is not None else 'off'}), listening on {svc.zenoh.sim_endpoint} and "
          f"{svc.zenoh.daemon_endpoint}", file=sys.stderr, flush=True)
    face = None
    if args.ros2:  # the daemon's ROS 2 face, a Zenoh client of this process (docs/ros2.md)
        from ..ros2.node import Ros2Missing

        try:
            from ..ros2.face import Ros2Face

            face = Ros2Face(svc.with_robot(robot), robot, scene)
            face.start()
        except Ros2Missing as e:
            print(f"wmm-qp sim: error: --ros2 {e}", file=sys.stderr)
            return 2
    try:
        st = emb.run(stop, wait_lease=args.wait_lease, report=args.cycle_report)
    except LeaseHeld as e:
        print(f"wmm-qp sim: error: {e}", file=sys.stderr, flush=True)
        return 3
    finally:
        if face is not None:
            face.close()
            print(f"wmm-qp sim: ROS 2 face: sent {dict(face.sent)}, refused {dict(face.refused) or 'none'}",
                  file=sys.stderr, flush=True)
        recorded = emb.control.journal.close(emb.control.timing.ticks) if emb.control.journal is not None else {}
    lp = emb.control.timing
    p50, p99 = lp.percentiles_us(50.0, 99.0)
    print(f"wmm-qp sim: stopped at t = {st.t:.3f} s, violations {st.violations}, {lp.ticks} ticks, "
          f"{lp.deadline_misses} deadline misses, tick p50 {p50:.0f} µs p99 {p99:.0f} µs, faults "
          f"{dict(core.fault_record.counts) or 'none'}", file=sys.stderr, flush=True)
    if record:
        return report_recording("sim", recorded)
    return 0


def _run_ros2(args: argparse.Namespace, robot: Any, scene: Any, sim_cfg: Any) -> int:
    """``wmm-qp sim --ros2``: the plant behind ros2_control-shaped topics (no Zenoh)."""
    from ..cli_common import stop_on_signals
    from ..ros2.node import Ros2Missing

    if args.state_loss or args.state_delay_ms or args.no_truth:
        print("wmm-qp sim: error: --ros2 is a ROS 2 robot alone: not with --state-loss, --state-delay-ms or "
              "--no-truth (it publishes no Zenoh state)", file=sys.stderr)
        return 2
    if args.rate is not None and not 1.0 <= args.rate <= 2000.0:
        print("wmm-qp sim: error: --rate must be in [1, 2000] Hz", file=sys.stderr)
        return 2
    try:
        from ..ros2.sim_robot import Ros2SimRobot

        sim = Ros2SimRobot(robot, sim_cfg, plant=sim_cfg.physics.plant, scene=scene, rate_hz=args.rate,
                           seed=args.seed)
        return sim.run(stop_on_signals())
    except Ros2Missing as e:
        print(f"wmm-qp sim: error: {e}", file=sys.stderr)
        return 2
