"""The FR3 stack idle in hold: franky-sim, ``wmm-qp driver franka`` and ``wmm-qp serve``, the
console open in headless chromium (or not), for a while; then the daemon's faults by code, its
loop, and franky-sim's clock against the wall's. Prints one JSON object.

    python benchmarks/fr3/idle.py [--duration 120] [--no-console | --no-browser] [--hogs N] [--logs DIR]

Needs the ``franka`` extra (pylibfranka, franky-sim), Debian's chromium and Playwright for the
console. The test-support rig (``tests/support``) starts franky-sim and the stack, as the FR3
tests do.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tests"))

from support.console_helpers import chromium_page, console_process, service_args
from support.franky_rig import FR3, driver_stack, start_franky_sim
from wmm_qp_service.client import Client
from wmm_qp_service.processes import free_port
from wmm_qp_tools.stress import CpuHogs

import wmm_qp as w


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--duration", type=float, default=120.0, help="[s] idle in hold (default 120)")
    ap.add_argument("--no-console", action="store_true", help="no console, no browser")
    ap.add_argument("--no-browser", action="store_true", help="the console process, no browser page")
    ap.add_argument("--hogs", type=int, default=0, metavar="N",
                    help="N processes spinning at normal priority beside the stack (default 0)")
    ap.add_argument("--logs", type=Path, default=None, help="the processes' logs (default: a fresh folder)")
    a = ap.parse_args()
    if a.duration <= 0:
        ap.error("--duration must be > 0")
    logs = a.logs or Path(tempfile.mkdtemp(prefix="wmm-qp-fr3-idle-"))
    logs.mkdir(parents=True, exist_ok=True)
    sim = start_franky_sim(w.load_robot_config(FR3))
    try:
        with driver_stack(sim, logs) as (svc, _), Client(svc, name="fr3-idle") as c:
            info = c.wait_for_daemon(60.0)
            t_end = time.monotonic() + 60.0
            while (info is None or not info.status.state_ok) and time.monotonic() < t_end:
                time.sleep(0.2)
                info = c.info()
            if info is None or not info.status.state_ok:
                print(json.dumps({"error": "the stack did not come up", "logs": str(logs)}))
                return 1
            faults0 = dict(info.status.faults)
            steps0, wall0 = sim.shared[14], time.monotonic()
            print(f"fr3 idle: {a.duration:g} s in hold, {_beside(a)}; logs {logs}", file=sys.stderr, flush=True)
            with contextlib.ExitStack() as ctx:
                if not a.no_console:
                    port = free_port()
                    _, url = ctx.enter_context(console_process(["--port", str(port), *service_args(svc)],
                                                               logs / "console.log"))
                    if not a.no_browser:
                        page = ctx.enter_context(chromium_page(logs / "chromium-profile"))
                        page.goto(url)
                if a.hogs:
                    ctx.enter_context(CpuHogs(a.hogs))
                time.sleep(a.duration)
                info = c.info()
            wall = time.monotonic() - wall0
            steps = sim.shared[14] - steps0
    finally:
        sim.close()
    assert info is not None
    st = info.status
    new = {k: n - faults0.get(k, 0) for k, n in st.faults.items() if n - faults0.get(k, 0)}
    print(json.dumps({"duration_s": round(wall, 1), "beside": _beside(a), "faults": new,
                      "last_fault_code": st.last_fault_code, "last_fault": st.last_fault,
                      "loop": {"ticks": st.loop.ticks, "deadline_misses": st.loop.deadline_misses,
                               "tick_p50_us": st.loop.tick_p50_us, "tick_p99_us": st.loop.tick_p99_us},
                      "franky_sim_steps_per_s": round(steps / wall, 1),
                      "franky_sim_realtime_factor": round(steps * 1e-3 / wall, 3),
                      "logs": str(logs)}))
    return 0


def _beside(a: argparse.Namespace) -> str:
    """What runs beside the stack, in words."""
    parts = [] if a.no_console else ["the console" + (" (no browser)" if a.no_browser else " in chromium")]
    if a.hogs:
        parts.append(f"{a.hogs} CPU hogs")
    return ", ".join(parts) or "nothing"


if __name__ == "__main__":
    sys.exit(main())
