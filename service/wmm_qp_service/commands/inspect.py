"""``wmm-qp inspect``: kinematics and directional manipulability at one configuration."""

from __future__ import annotations

import argparse
import json

import numpy as np

import wmm_qp as w
from wmm_qp.manipulability import dm_cartesian_gradient, dm_gradient, torque_norm_per_newton, yoshikawa_manipulability
from wmm_qp.pseudoinverse import sigma_min
from wmm_qp.tasks import rotation_to_quat

from .common import add_config_arguments, floats, load_configs

HELP = "kinematics and directional manipulability at one configuration"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--arm-q", type=floats(None, "--arm-q"), default=None, metavar="Q1,...,Qn",
        help="joint values [rad or m], one per joint of the robot (default: the robot's start)",
    )
    parser.add_argument(
        "--base-q",
        type=floats(3, "--base-q"),
        default=np.zeros(3),
        metavar="X,Y,YAW",
        help="base pose [m, m, rad] (default 0,0,0)",
    )
    parser.add_argument(
        "--direction",
        type=floats(3, "--direction"),
        default=None,
        metavar="UX,UY,UZ",
        help="DM direction u in the base frame (default: the controller config's)",
    )
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    add_config_arguments(parser)


def run(args: argparse.Namespace) -> int:
    robot, cfg = load_configs(args)
    if args.arm_q is None:
        q_arm = np.array(robot.arm.start)
    elif len(args.arm_q) != robot.n_arm:
        raise w.InvalidInput("--arm-q", f"needs {robot.n_arm} comma-separated numbers (the joints of "
                             f"{robot.name}: {', '.join(robot.arm.joints)}), got {len(args.arm_q)}")
    else:
        q_arm = args.arm_q
    W = cfg.weights_for(robot)
    u = cfg.direction if args.direction is None else args.direction
    if np.linalg.norm(u) < 1e-12:
        raise w.InvalidInput("--direction", "must not be the zero vector")
    u = u / np.linalg.norm(u)
    model = w.WmmModel(robot)
    kin = model.kinematics(args.base_q, q_arm, hessian=True)
    assert kin.dJ_arm is not None
    dm, grad = dm_gradient(kin.J_arm, kin.dJ_arm, u, W)  # eqs. (8), (9)
    grad_x = dm_cartesian_gradient(grad, kin.J_m)  # eq. (10)
    per_n = torque_norm_per_newton(kin.J_arm, u, W)
    _, R = model.ee_pose(args.base_q, q_arm)
    out = {
        "robot": robot.name,
        "joints": list(robot.arm.joints),
        "arm_q": np.asarray(q_arm).tolist(),
        "ee_position": kin.x.tolist(),
        "ee_orientation": rotation_to_quat(R).tolist(),
        "sigma_min": sigma_min(kin.J_m),
        "dm": dm,
        "dm_gradient": grad.tolist(),
        "dm_cartesian_gradient": grad_x.tolist(),
        "torque_norm_per_newton": per_n,
        "yoshikawa": yoshikawa_manipulability(kin.J_m),
        "direction": u.tolist(),
        "singular": bool(sigma_min(kin.J_m) < cfg.sigma_threshold),
    }
    if args.json:
        print(json.dumps(out))
        return 0
    f = lambda v: "[" + ", ".join(f"{x:+.4f}" for x in v) + "]"  # noqa: E731
    print(f"robot                       {robot.name} ({robot.n_arm} joints, {robot.base.kind} base)")
    print(f"EE position (world)         {f(kin.x)} m")
    print(f"EE orientation (x,y,z,w)    {f(out['ee_orientation'])}")
    print(
        f"sigma_min(J_m)              {out['sigma_min']:.4f}" + ("  (below threshold: DLS)" if out["singular"] else "")
    )
    print(f"direction u (base frame)    {f(u)}")
    print(f"DM H2 along u               {dm:.4f}                  eq. (8)")
    print(f"dH2/dq                      {f(grad)}  eq. (9)")
    print(f"dH2/dx                      {f(grad_x)}  eq. (10)")
    print(f"weighted torque per newton  {per_n:.4f} N·m/N (10 N: {10 * per_n:.2f} N·m)")
    print(f"Yoshikawa index             {out['yoshikawa']:.5f}")
    return 0
