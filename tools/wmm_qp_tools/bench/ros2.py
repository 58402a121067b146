"""Through the ROS 2 driver (``--only ros2``): state → command latency and deadline misses at the
driver's cycle rates, beside the Zenoh and embedded stacks of :mod:`.e2e` (docs/ros2.md
"Measured").

Per rate R (:data:`RATES`: 250 and 500 Hz): ``wmm-qp sim --ros2 --rate R`` (the Panda on a
differential drive, kinematic: a stand-in ros2_control robot), ``wmm-qp driver ros2 --rate R
--report F`` and ``wmm-qp serve`` (500 Hz) on an isolated prefix; a client tracks the paper's
circle for ``seconds``; then every process gets SIGINT and the driver's report is read:

- ``state_to_command``: a joint state's arrival at the driver → the rates computed from it
  written back to ROS 2 (the state over Zenoh, the daemon's tick, the command back, the wait for
  the driver's next cycle; the command names its state in ``state_seq``), p50/p99/max [ms];
- ``joint_states_in``: the joint state's header stamp → its arrival at the driver [ms];
- ``deadline_misses`` / ``cycles``: the driver's loop; ``daemon_deadline_misses`` /
  ``daemon_ticks``: the daemon's over the circle; ``violations``: the driver's referee.

Every ROS 2 process runs in a network namespace with only loopback: the section re-runs itself
under ``unshare -n`` (root or user namespaces), or says why it cannot (no rclpy, no unshare).

    python -m wmm_qp_tools.bench.ros2 [SECONDS] [RATE ...]     # one JSON object on stdout
"""

from __future__ import annotations

import importlib.util
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

RATES = (250.0, 500.0)
NETNS = "WMM_QP_ROS2_NETNS"


def why_not() -> str | None:
    """Why the section cannot run here (None: it can)."""
    if importlib.util.find_spec("rclpy") is None:
        return "needs ROS 2's rclpy (pip install 'wmm-qp[ros2]')"
    if os.environ.get(NETNS) == "1":
        return None
    if shutil.which("unshare") is None or shutil.which("ip") is None:
        return "needs unshare (util-linux) and ip (iproute2) for a network namespace"
    r = subprocess.run(["unshare", "-n", "true"], capture_output=True, text=True, timeout=30, check=False)
    return None if r.returncode == 0 else f"cannot make a network namespace: {r.stderr.strip()[:200]}"


def one(rate: float, seconds: float, tmp: Path) -> dict[str, Any]:
    """One rate, in this (namespaced) process's network."""
    import numpy as np
    from wmm_qp_service.client import Client
    from wmm_qp_service.processes import CLI, isolated_config
    from wmm_qp_service.teleop import stream_circle

    import wmm_qp as w
    from wmm_qp.config import default_config_dir

    robot_file = default_config_dir() / "robots" / "panda_diffdrive.toml"
    svc = isolated_config(robot=w.load_robot_config(robot_file))
    common = ["--prefix", svc.prefix, "--robot", svc.robot, "--daemon-endpoint", svc.zenoh.daemon_endpoint,
              "--sim-endpoint", svc.zenoh.sim_endpoint, "--robot-config", str(robot_file)]
    report = tmp / f"driver_{rate:g}.json"
    argv = {"sim": ["sim", "--ros2", "--rate", f"{rate:g}", "--robot-config", str(robot_file)],
            "driver": ["driver", "ros2", *common, "--rate", f"{rate:g}", "--report", str(report)],
            "daemon": ["serve", *common, "--rate", "500"]}
    procs: dict[str, subprocess.Popen[bytes]] = {}
    try:
        for name, a in argv.items():
            with open(tmp / f"{name}_{rate:g}.log", "wb") as log:
                procs[name] = subprocess.Popen([*CLI, *a], stdout=log, stderr=log, stdin=subprocess.DEVNULL)
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
            if p.poll() is None:
                p.send_signal(signal.SIGINT)
        for p in procs.values():
            try:
                p.wait(timeout=30)
            except subprocess.TimeoutExpired:
                p.kill()
    out: dict[str, Any] = json.loads(report.read_text())
    out["daemon_deadline_misses"] = lp1.deadline_misses - lp0.deadline_misses
    out["daemon_ticks"] = lp1.ticks - lp0.ticks
    return out


def run(seconds: float = 10.0, rates: tuple[float, ...] = RATES) -> dict[str, Any]:
    """The section: {"available", "why" | "seconds", "logs", "rates": {rate: figures}}."""
    if (why := why_not()) is not None:
        return {"available": False, "why": why}
    if os.environ.get(NETNS) != "1":
        argv = ["unshare", "-n", "sh", "-c", 'ip link set lo up && exec "$@"', "sh", sys.executable, "-m",
                "wmm_qp_tools.bench.ros2", f"{seconds:g}", *(f"{r:g}" for r in rates)]
        r = subprocess.run(argv, env={**os.environ, NETNS: "1"}, capture_output=True, text=True,
                           timeout=600 + 60 * seconds * len(rates), check=False)
        if r.returncode != 0:
            return {"available": False, "why": f"exit {r.returncode}: {r.stderr.strip()[-500:]}"}
        out: dict[str, Any] = json.loads(r.stdout)
        return out
    tmp = Path(tempfile.mkdtemp(prefix="wmm-qp-bench-ros2-"))
    return {"available": True, "seconds": seconds, "logs": str(tmp),
            "rates": {f"{r:g}": one(r, seconds, tmp) for r in rates}}


if __name__ == "__main__":
    a = sys.argv[1:]
    print(json.dumps(run(float(a[0]) if a else 10.0, tuple(float(x) for x in a[1:]) or RATES)))
