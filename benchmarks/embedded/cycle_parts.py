"""Where the embedded cycle's time goes, part by part, in process: the robot's step (the sim's
firmware, plant and referees), the state message, the control core's update (validation, the
tick, the command handed over), the evaluation data, the slack's work (telemetry, status,
inputs). The real clock, a 1 kHz cycle that sleeps out its period (no spin: what a cycle that
slept finds), no transport, the default robot tracking the paper's circle.

    python benchmarks/embedded/cycle_parts.py [--collision] [--cycles N]

Prints p50 / p90 / p99 [µs] of each part over the cycles after the first 500.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from wmm_qp_service.config import ServiceConfig
from wmm_qp_service.embedded.sim import EmbeddedSim
from wmm_qp_service.protocol import ModeMsg, SetpointMsg, encode
from wmm_qp_sim import load_sim_config

import wmm_qp as w


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--collision", action="store_true", help="collision rows on in the controller")
    ap.add_argument("--cycles", type=int, default=6000, help="robot cycles (default 6000)")
    a = ap.parse_args()
    robot = w.load_robot_config()
    ctl_cfg = w.load_controller_config().with_(collision={"enabled": a.collision})
    emb = EmbeddedSim(ServiceConfig(), load_sim_config(), robot, ctl_cfg)
    emb.control.tel_listened = True  # a client listens: telemetry is built every tick
    emb.start()
    node, control, name = emb.node, emb.control, emb.svc.robot
    parts: dict[str, list[float]] = {k: [] for k in ("step", "state_msg", "update", "truth", "after", "total")}
    st = node.sim.state()
    x0 = np.array(st.ee_true)
    pc = time.perf_counter_ns
    for k in range(a.cycles):
        if k == 20:
            control.inbox.append(("mode", encode(ModeMsg(robot=name, seq=1, stamp=time.time(), mode="track"))))
            x0 = np.array(st.ee_true)
        if k > 20 and k % 10 == 0:
            t = k * 1e-3
            x = x0 + 0.05 * np.array([np.sin(2 * t), 1 - np.cos(2 * t), 0.0])
            control.inbox.append(("setpoint", encode(SetpointMsg(robot=name, seq=k, stamp=time.time(),
                                                                 x=x.tolist(), source="op"))))
        now = time.monotonic()
        t0 = pc()
        st = node.advance(now, emb.inbox, node.accept_msg)
        t1 = pc()
        node.publications += 1
        msg = node.state_msg(st, node.publications)
        t2 = pc()
        control.update(msg, now)
        t3 = pc()
        truth = node.truth_msg(st, node.publications)
        t4 = pc()
        control.after(now, msg, truth, True)
        control.outbox.clear()  # no service thread here: what it would publish is dropped
        t5 = pc()
        for key, b, e in (("step", t0, t1), ("state_msg", t1, t2), ("update", t2, t3), ("truth", t3, t4),
                          ("after", t4, t5), ("total", t0, t5)):
            parts[key].append((e - b) / 1e3)
        emb.cycles += 1
        time.sleep(max(0.0, 0.001 - (time.monotonic() - now)))
    control.stop()
    for key, v in parts.items():
        arr = np.array(v[500:])
        print(f"{key:10s} p50 {np.percentile(arr, 50):7.1f}  p90 {np.percentile(arr, 90):7.1f}  "
              f"p99 {np.percentile(arr, 99):7.1f} µs")
    print("referee counts:", st.violations, "; mode:", control.core.mode.value)


if __name__ == "__main__":
    main()
