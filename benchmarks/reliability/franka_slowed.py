"""``wmm-qp demo --driver franka`` against a franky-sim slowed down: frozen and continued
(SIGSTOP/SIGCONT) on a duty cycle, or run at ``SCHED_IDLE`` under CPU hogs. Prints the demo's
referee counts, faults and verdict, the robot's time at the driver's stop against the wall time
since its first cycle (the slowing starts there), and where its logs are. Needs pylibfranka and
franky-sim.

    python benchmarks/reliability/franka_slowed.py --run-ms 5 --stop-ms 15     # ~25 % duty
    python benchmarks/reliability/franka_slowed.py --idle --hogs 2              # starved
    python benchmarks/reliability/franka_slowed.py --idle --hogs 2 --embedded
    python benchmarks/reliability/franka_slowed.py --run-ms 4 --stop-ms 16 --rt-hogs 15/25
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import random
import re
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tests"))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--run-ms", type=float, default=5.0, help="[ms] franky-sim runs this long (±50 %%)")
    ap.add_argument("--stop-ms", type=float, default=15.0, help="[ms] then is frozen this long (±50 %%)")
    ap.add_argument("--idle", action="store_true", help="SCHED_IDLE under CPU hogs instead of freezing")
    ap.add_argument("--hogs", type=int, default=2, help="CPU hogs with --idle (default 2)")
    ap.add_argument("--embedded", action="store_true", help="the demo with the core in the driver's cycle")
    ap.add_argument("--rt-hogs", metavar="BUSY/IDLE", default="",
                    help="[ms] besides: a SCHED_FIFO hog per core, busy then idle (e.g. 15/25: a second "
                         "stack's real-time threads)")
    a = ap.parse_args()
    from support.franky_rig import FR3, start_franky_sim
    from wmm_qp_service.processes import CLI
    from wmm_qp_tools.stress import CpuHogs, RealtimeHogs

    import wmm_qp as w

    sim = start_franky_sim(w.load_robot_config(FR3))
    stop = threading.Event()

    def slow() -> None:
        pid = sim.proc.pid
        assert pid is not None
        if a.idle:
            for t in os.listdir(f"/proc/{pid}/task"):
                os.sched_setscheduler(int(t), os.SCHED_IDLE, os.sched_param(0))
            with CpuHogs(a.hogs):
                stop.wait()
            return
        while not stop.is_set():
            time.sleep(a.run_ms * 1e-3 * random.uniform(0.5, 1.5))
            os.kill(pid, signal.SIGSTOP)
            time.sleep(a.stop_ms * 1e-3 * random.uniform(0.5, 1.5))
            os.kill(pid, signal.SIGCONT)

    logs = Path(tempfile.mkdtemp(prefix="wmm-franka-slowed-"))
    th = threading.Thread(target=slow, daemon=True)
    load = contextlib.nullcontext()
    if a.rt_hogs:
        busy, idle = (float(x) * 1e-3 for x in a.rt_hogs.split("/"))
        load = RealtimeHogs(busy, idle)
    try:
        argv = [*CLI, "demo", "--robot-config", str(FR3), "--driver", "franka", "--robot-ip", sim.host,
                "--duration", "8", "--json", "--logs", str(logs), *(["--embedded"] if a.embedded else [])]
        p = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, stdin=subprocess.DEVNULL)
        t0 = time.monotonic()
        driver_log = logs / "driver.log"
        while p.poll() is None and time.monotonic() - t0 < 120:  # slowed from the driver's first cycle on
            if driver_log.exists() and "driving the robot" in driver_log.read_text():
                break
            time.sleep(0.01)
        t_slow = time.monotonic()
        th.start()
        with load:
            out, err = p.communicate(timeout=600)
        wall = time.monotonic() - t_slow
    finally:
        stop.set()
        if th.is_alive():
            th.join()
        if sim.proc.pid is not None:
            os.kill(sim.proc.pid, signal.SIGCONT)
        sim.close()
    try:
        d = json.loads(out)
    except ValueError:
        print(f"franka_slowed.py: the demo gave no JSON (exit {p.returncode}); logs {logs}\n{err[-800:]}",
              file=sys.stderr)
        return 1
    m = re.search(r"stopped at t = ([0-9.]+) s", (logs / "driver.log").read_text())
    clock = f"robot time {float(m.group(1)):.2f} s in {wall:.2f} s of wall time" if m else "robot time not logged"
    print(f"violations {d['violations']}, faults {d.get('faults')}, verdict {d.get('verdict')}; {clock}; logs {logs}")
    return 0 if d.get("violations_total", 1) == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
