"""A worker of :mod:`.compare_commits`: the QP controller's track-mode ticks, in blocks on request.

Run as a script with ``PYTHONPATH`` (and the working directory) set to one source tree, so that it
imports *that* tree's ``wmm_qp`` and reads its ``configs/``; it imports nothing else of this
package and uses only what every version of ``wmm_qp`` since the compiled hot path (``59f50a6``) has
(the default robot, the default controller config, ``make_controller``, ``warm_up``, ``RobotState``,
``Reference``).

    python -P _tick_worker.py SOLVER

Protocol (one JSON object per line on stdout): first ``{"ready": true}``; then for each line
``N`` on stdin the next N ticks of the paper's circle from the robot's start (the trajectory goes
on across blocks), answered with ``{"ns": [...]}`` (one ``ctl.step`` duration per tick); a line
``stats`` is answered with the stage and status counts and the tracking RMS so far; EOF ends it.
"""

from __future__ import annotations

import json
import math
import sys
import time

import numpy as np

import wmm_qp as w

RADIUS, OMEGA = 0.25, math.pi / 20.0  # the paper's circle (as bench/trajectory.py)


def main(solver: str) -> int:
    robot, cfg = w.load_robot_config(), w.load_controller_config()
    if hasattr(cfg, "collision"):  # a tree with collision rows: timed without them, as every tree
        cfg = cfg.with_(collision={"enabled": False})
    model = w.WmmModel(robot)
    ctl = w.make_controller("qp", model, cfg.with_(qp={"solver": solver}))
    ctl.warm_up()
    start = getattr(robot.arm, "start", None)
    old_start = getattr(w, "PAPER_START_Q_ARM", None)  # a tree from before the robot description
    q_arm = np.asarray(start if start is not None else old_start, dtype=np.float64)
    n_arm = q_arm.size
    n_wheels = model.base.M.shape[1]
    q_base, v_arm, wheels = np.zeros(3), np.zeros(n_arm), np.zeros(n_wheels)
    x0 = model.ee_position(q_base, q_arm)
    dt, k = ctl.dt, 0
    stages: dict[str, int] = {}
    status: dict[str, int] = {}
    err2: list[float] = []
    print(json.dumps({"ready": True}), flush=True)
    for line in sys.stdin:
        line = line.strip()
        if line == "stats":
            rms = float(np.sqrt(np.mean(err2))) if err2 else None
            print(json.dumps({"stages": stages, "status": status, "track_rms_m": rms, "ticks": k}), flush=True)
            continue
        ns: list[int] = []
        for _ in range(int(line)):
            t = k * dt
            c, s = math.cos(OMEGA * t), math.sin(OMEGA * t)
            x_d = x0 + np.array([RADIUS * (c - 1.0), RADIUS * s, 0.0])
            xd_d = np.array([-RADIUS * OMEGA * s, RADIUS * OMEGA * c, 0.0])
            ref = w.Reference(mode=w.Mode.TRACK, x_d=x_d, xd_d=xd_d)
            state = w.RobotState(q_base=q_base, q_arm=q_arm, v_arm=v_arm, wheel_speeds=wheels)
            t0 = time.perf_counter_ns()
            cmd = ctl.step(state, ref)
            ns.append(time.perf_counter_ns() - t0)
            stage = str(getattr(ctl, "last_stage", ""))
            stages[stage] = stages.get(stage, 0) + 1
            status[str(cmd.status)] = status.get(str(cmd.status), 0) + 1
            q_arm = q_arm + dt * cmd.arm_rates
            q_base = q_base + dt * (model.base.P(float(q_base[2])) @ cmd.wheel_speeds)
            v_arm, wheels = np.array(cmd.arm_rates), np.array(cmd.wheel_speeds)
            k += 1
            if k * dt > 1.0:
                t1 = k * dt
                x_next = x0 + np.array([RADIUS * (math.cos(OMEGA * t1) - 1.0), RADIUS * math.sin(OMEGA * t1), 0.0])
                err2.append(float(np.sum((model.ee_position(q_base, q_arm) - x_next) ** 2)))
        print(json.dumps({"ns": ns}), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1]))
