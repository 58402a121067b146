"""The daemon's tick while a moving obstacle's rows hold the arm: the daemon's core (``ControlCore``)
and a simulated robot joined in memory, the Gen3 holding, a ball coming at its EE from 0.25 m at
1.25 cm/s (as the suite's obstacle test over Zenoh does). Prints the tick's p50 / p99 (the core's
tick plus the robot's two 1 ms steps) over the ball's approach and once its rows hold the arm,
and how the QP's stages were solved.

    python benchmarks/collision/ball_tick.py [--ticks 7000]

The core ticks at 500 Hz on a fake clock (no sleeping: only the work is timed).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from wmm_qp_service.config import ServiceConfig
from wmm_qp_service.daemon import ControlCore
from wmm_qp_service.protocol import StateMsg
from wmm_qp_sim import SimCommand, SimRobot, load_sim_config

import wmm_qp as w
from wmm_qp.config.shapes import ShapeConfig

PERIOD = 0.002  # [s] the core's tick
DT = 0.001  # [s] the robot's step
SPEED = 0.0125  # [m/s] the ball's


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--ticks", type=int, default=7000, help="core ticks (default 7000: 14 s)")
    a = ap.parse_args()
    if a.ticks < 2:
        ap.error("--ticks must be at least 2")
    robot = w.load_robot_config()
    core = ControlCore(ServiceConfig(), w.load_controller_config(), robot)
    sim = SimRobot(core.model, load_sim_config(), ramp=True)
    sim.reset()
    x0 = core.model.ee_position(sim.base_odom, sim.q_arm)
    seq = 0
    applied = -1
    times: list[float] = []
    engaged = -1
    for k in range(a.ticks):
        t = k * PERIOD
        if k % 25 == 0:  # the obstacle message at 20 Hz
            ball = ShapeConfig(name="ball", link="", kind="sphere", size=np.array([0.08, 0.0, 0.0]),
                               xyz=x0 + [0.0, 0.25 - SPEED * t, 0.0], rpy=np.zeros(3),
                               velocity=np.array([0.0, -SPEED, 0.0]))
            core.on_obstacles((ball,), t)
        t0 = time.perf_counter()
        st = sim.state()
        core.on_state(StateMsg(robot="wmm", seq=k + 1, stamp=0.0, t=st.t, q_base=st.base_odom.tolist(),
                               q_arm=st.q_arm.tolist(), v_arm=st.v_arm.tolist(),
                               wheel_speeds=st.wheel_speeds.tolist(), tau=st.tau.tolist(),
                               stale_stop=st.stale_stop, cmd_seq=applied, instance="sim", lease=core.lease,
                               protective_stop=st.protective_stop, protective_stops=st.protective_stops), t)
        cmd = core.tick(t)
        c = None
        if cmd is not None:
            seq += 1
            core.stream.seq = seq
            core.stream.sent(seq, t)
            c = SimCommand(cmd.wheel_speeds.copy(), cmd.arm_rates.copy(), period=PERIOD, seq=seq,
                           stream=core.stream.start, sent=t, received=sim.t)
            applied = seq
        sim.step(c, DT)
        sim.step(None, DT)
        times.append(time.perf_counter() - t0)
        if engaged < 0 and cmd is not None and "ball" in cmd.reason:
            engaged = k
    us = np.array(times) * 1e6
    half, last = a.ticks // 2, min(2500, a.ticks // 2)
    print(f"ticks {a.ticks}; the ball's rows first cut the task at tick {engaged}")
    for name, part in (("approach (first half)", us[:half]), (f"rows holding (last {last:,})", us[-last:])):
        print(f"{name}: tick p50 {np.percentile(part, 50):.0f} µs, p99 {np.percentile(part, 99):.0f} µs")
    ctl = core.ctl
    print(f"stages DAQP solved after proxsuite failed: {getattr(ctl, 'fallbacks', 0)}, first in the window "
          f"after a failure: {getattr(ctl, 'daqp_first', 0)}; referee: {sim.state().violations}")


if __name__ == "__main__":
    main()
