"""What the collision rows cost a task, on every shipped robot: the qp controller tracks two steps
(0.15 m along x, then 0.15 m down) from the robot's start, in process with the sim and its referee,
with the rows off and on (no scene: self and floor pairs only).

    python benchmarks/collision/track_steps.py [--robot NAME.toml ...] [--ticks N]

Prints, per robot and rows off/on: the EE error at the end of each step, the ticks whose status
named a collision row, the most frequent of those rows, and the referee's counts."""

from __future__ import annotations

import argparse
from collections import Counter
from dataclasses import replace

import numpy as np
from wmm_qp_sim import SimCommand, SimRobot, load_sim_config

import wmm_qp as w
from wmm_qp.config import default_config_dir

ROBOTS = ("gen3_mecanum.toml", "panda_diffdrive.toml", "ur5_omni.toml", "tiago.toml")


def run(name: str, enabled: bool, ticks: int) -> str:
    m = w.WmmModel(w.load_robot_config(default_config_dir() / "robots" / name))
    ctl = w.make_controller("qp", m, w.load_controller_config().with_(collision={"enabled": enabled}))
    sim = SimRobot(m, replace(load_sim_config(), firmware=False), seed=1, collisions=True)
    sim.reset()
    x0 = m.ee_position(np.zeros(3), m.config.arm.start)
    rows: Counter[str] = Counter()
    errors = []
    k = 0
    for goal in (x0 + [0.15, 0.0, 0.0], x0 + [0.15, 0.0, -0.15]):
        for _ in range(ticks):
            cmd = ctl.step(sim.robot_state(), w.Reference("track", x_d=goal))
            if cmd.reason.startswith("collision"):
                rows[cmd.reason.split(":")[1].split()[0].strip() if ":" in cmd.reason else cmd.reason] += 1
            sim.step(SimCommand(cmd.wheel_speeds, cmd.arm_rates, period=ctl.dt, seq=k), ctl.dt)
            k += 1
        errors.append(float(np.linalg.norm(m.ee_position(sim.base_odom, sim.q_arm) - goal)))
    top = rows.most_common(1)
    counts = {kind: n for kind, n in sim.referee.counts.items() if n}
    state = "on " if enabled else "off"
    return (f"{name:22s} rows {state}  EE error {errors[0] * 100:6.2f} / {errors[1] * 100:6.2f} cm"
            f"  ticks on a collision row {sum(rows.values()):5d}/{k}"
            f"  {('most: ' + top[0][0]) if top else '':36s} referee {counts or 0}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--robot", action="append", choices=ROBOTS, help="a shipped robot file (default: all)")
    ap.add_argument("--ticks", type=int, default=1500, help="ticks per step (default 1500: 3 s at 500 Hz)")
    a = ap.parse_args()
    for name in a.robot or ROBOTS:
        for enabled in (False, True):
            print(run(name, enabled, a.ticks), flush=True)


if __name__ == "__main__":
    main()
