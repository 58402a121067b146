"""The circle in-process with the controller seeing the whole state ``delay`` ticks late.

A diagnostic for the service path's latency (docs/results.md §4). With a state one control
tick old, joint 4 used to overshoot its upper limit by 0.53 mrad near t = 15.7 s and stay there
(~4000 referee counts). The controller now brakes from where the joint can be after
``state_latency`` (bounds (13)) and pulls a joint past a limit back in: about 0.3 mrad and
~55 counts remain here, because this diagnostic delays the joint *rates* too (the controller's
acceleration bounds are then centred on a rate two commands old, hence also a few acceleration
counts), which the daemon never does. With no delay there are none.

    python -m wmm_qp_tools.experiments.latency_check [DELAY_TICKS] [DURATION_S]
"""

from __future__ import annotations

import collections
import sys

import numpy as np
from wmm_qp_sim import SimCommand, SimRobot

import wmm_qp as w
from wmm_qp_tools.experiments.circle import circle
from wmm_qp_tools.experiments.setup import make_setup


def run(delay: int, duration: float = 20.0) -> tuple[dict[str, int], float]:
    """Referee counts and the max joint excess over the upper limits [rad]."""
    s = make_setup("qp")
    m = s.model
    sim = SimRobot(m, s.sim_cfg, seed=s.seed)
    sim.reset()
    x0 = m.ee_position(np.zeros(3), np.array(s.robot.arm.start))
    dt = s.ctl_cfg.dt
    n_sub = max(1, round(s.sim_cfg.rate_hz / s.ctl_cfg.rate_hz))
    hist: collections.deque[w.RobotState] = collections.deque(maxlen=delay + 1)
    hi = np.asarray(m.config.arm.position_upper, dtype=float)
    worst = -np.inf
    st = sim.state()
    for k in range(round(duration / dt)):
        hist.append(sim.robot_state())
        x, xd = circle(x0, k * dt)
        cmd = s.controller.step(hist[0], w.Reference(mode=w.Mode.TRACK, x_d=x, xd_d=xd))
        st = sim.step(SimCommand(cmd.wheel_speeds, cmd.arm_rates, period=dt, seq=k), dt / n_sub)
        for _ in range(n_sub - 1):
            st = sim.step(None, dt / n_sub)
        worst = max(worst, float(np.max(st.q_arm - hi)))
    return dict(st.violations), worst


def main(argv: list[str]) -> int:
    delay = int(argv[0]) if argv else 1
    duration = float(argv[1]) if len(argv) > 1 else 20.0
    violations, worst = run(delay, duration)
    print(f"state delay {delay} ticks: violations {violations}, max q - q_max {worst:.2e} rad")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
