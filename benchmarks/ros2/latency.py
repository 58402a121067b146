"""State → command latency through the ROS 2 driver, at its cycle rates (docs/ros2.md
"Measured"). Re-runs itself in a network namespace with only loopback (root or user namespaces).

Per rate R (default 250 and 500 Hz): ``wmm-qp sim --ros2 --rate R`` (the Panda on a differential
drive, kinematic), ``wmm-qp driver ros2 --rate R --report F`` and ``wmm-qp serve --rate 500`` on an
isolated prefix; a client tracks the paper's circle for ``SECONDS``; then every process gets
SIGINT and the driver's report is read: ``state_to_command`` (a joint state's arrival at the
driver → the rates computed from it written back to ROS 2: the state over Zenoh, the daemon's
tick, the command back, the wait for the driver's next cycle), ``joint_states_in`` (the joint
state's header stamp → its arrival), the driver's deadline misses, the daemon's.

    python benchmarks/ros2/latency.py [SECONDS] [RATE ...]     # e.g. 20 250 500
"""

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path[:0] = [str(ROOT), str(ROOT / "robot"), str(ROOT / "sim"), str(ROOT / "service"), str(ROOT / "tools")]

NETNS = "WMM_QP_ROS2_NETNS"


def one(rate: float, seconds: float, tmp: Path) -> dict:
    import numpy as np
    from wmm_qp_service.client import Client
    from wmm_qp_service.processes import CLI, isolated_config
    from wmm_qp_service.teleop import stream_circle

    import wmm_qp as w

    robot_file = ROOT / "configs" / "robots" / "panda_diffdrive.toml"
    robot = w.load_robot_config(robot_file)
    svc = isolated_config(robot=robot)
    common = ["--prefix", svc.prefix, "--robot", svc.robot, "--daemon-endpoint", svc.zenoh.daemon_endpoint,
              "--sim-endpoint", svc.zenoh.sim_endpoint, "--robot-config", str(robot_file)]
    report = tmp / f"driver_{rate:g}.json"
    logs = {n: open(tmp / f"{n}_{rate:g}.log", "wb") for n in ("sim", "driver", "daemon")}  # noqa: SIM115
    procs = {
        "sim": subprocess.Popen([*CLI, "sim", "--ros2", "--rate", f"{rate:g}", "--robot-config", str(robot_file)],
                                stdout=logs["sim"], stderr=logs["sim"]),
        "driver": subprocess.Popen([*CLI, "driver", "ros2", *common, "--rate", f"{rate:g}", "--report", str(report)],
                                   stdout=logs["driver"], stderr=logs["driver"]),
        "daemon": subprocess.Popen([*CLI, "serve", *common, "--rate", "500"], stdout=logs["daemon"],
                                   stderr=logs["daemon"]),
    }
    try:
        with Client(svc, name="bench") as c:
            info = c.wait_ready(300.0, 60.0)
            lp0 = info.status.loop
            c.set_mode("track")
            time.sleep(0.3)
            stream_circle(c, np.array(info.status.x), seconds)
            i = c.info()
            lp1 = i.status.loop if i is not None else lp0
    finally:
        for p in procs.values():
            p.send_signal(2)
        for p in procs.values():
            p.wait(timeout=30)
    out = json.loads(report.read_text())
    out["daemon_deadline_misses"] = lp1.deadline_misses - lp0.deadline_misses
    out["daemon_ticks"] = lp1.ticks - lp0.ticks
    return out


def main() -> None:
    args = sys.argv[1:]
    if os.environ.get(NETNS) != "1":
        env = {**os.environ, NETNS: "1"}
        r = subprocess.run(["unshare", "-n", "sh", "-c", 'ip link set lo up && exec "$@"', "sh", sys.executable,
                            __file__, *args], env=env, check=False)
        sys.exit(r.returncode)
    seconds = float(args[0]) if args else 20.0
    rates = [float(a) for a in args[1:]] or [250.0, 500.0]
    tmp = Path(tempfile.mkdtemp(prefix="wmm-qp-ros2-latency-"))
    res = {f"{r:g}": one(r, seconds, tmp) for r in rates}
    print(json.dumps({"seconds": seconds, "logs": str(tmp), "rates": res}, indent=1))


if __name__ == "__main__":
    main()
