"""Run inside the console host's network namespace by tests/integration/test_remote_netns.py: consoles
reach two robot stacks through the router (TLS, the remote users' own credentials); prints one
JSON line with what it saw. Usage, with tests/ on PYTHONPATH: python -m support.remote_scenario PREFIX
OPERATOR_CFG VIEWER_CFG LOGDIR."""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np
from wmm_qp_service.config import load_service_config
from wmm_qp_service.console.link import RouterClient as Client
from wmm_qp_service.console.wire import move_gizmo
from wmm_qp_service.processes import free_port

from support.console_helpers import Drag, console_process, wait_for


def track(c: Client) -> bool:
    """Ask for track until the daemon reports it (a fault on a loaded machine holds it again:
    an operator would press Track again)."""
    s = c.latest_status()
    if s is not None and s.mode == "track" and not s.resume_needed:
        return True
    c.set_mode("track")
    time.sleep(0.3)
    return False


T0 = time.monotonic()


def say(what: str) -> None:
    """A progress line on stderr (the test shows it when it fails): seconds since start, the step."""
    print(f"{time.monotonic() - T0:6.1f} s  {what}", file=sys.stderr, flush=True)


def main() -> int:
    prefix, op_cfg, viewer_cfg, logdir = sys.argv[1], Path(sys.argv[2]), Path(sys.argv[3]), Path(sys.argv[4])
    base = load_service_config().with_(prefix=prefix, zenoh={"config": op_cfg.resolve()})
    out: dict[str, object] = {}
    with Client(base.with_(robot="r1"), name="probe1") as c1, Client(base.with_(robot="r2"), name="probe2") as c2:
        for c in (c1, c2):
            assert c.wait_for_daemon(60.0) is not None, c.no_daemon_reason()
        say("both daemons answer through the router")
        out["robots_seen_by_probe"] = c1.robots()
        # the operator's console, attached to r2 of the two
        port = free_port()
        args = ["--port", str(port), "--prefix", prefix, "--robot", "r2", "--zenoh-config", str(op_cfg)]
        with console_process(args, logdir / "console_operator.log") as (p, url):
            say("the operator's console is up")
            out["console_line"] = p.url_line  # type: ignore[attr-defined]
            wait_for("r2 in track", lambda: track(c2), timeout=90.0, every=0.0)
            wait_for("r1 in track", lambda: track(c1), timeout=90.0, every=0.0)
            say("both robots in track")
            st2 = wait_for("r2's EE", lambda: (s := c2.latest_status()) and s.x and s)
            ee1_0 = np.asarray(wait_for("r1's truth", c1.wait_truth).ee_true)
            target = np.asarray(st2.x) + np.array([0.05, 0.03, -0.04])
            drag = Drag(url, target)

            def near() -> bool:
                s = c2.latest_truth()
                if s is not None and float(np.linalg.norm(np.asarray(s.ee_true) - target)) < 0.01:
                    return True
                if not track(c2):  # a safe stop on a loaded machine: resume and drag again
                    drag.now()
                drag.if_due()
                return False

            try:
                wait_for("r2's EE at the operator console's target", near, timeout=90.0)
            except AssertionError as e:
                s, st = c2.latest_status(), c2.latest_truth()
                ee = None if st is None else np.round(st.ee_true, 4).tolist()
                raise AssertionError(f"{e}: target {target.round(4).tolist()}, EE {ee}, status {s}") from None
            say("the operator's drag moved r2 to its target")
            out["operator_drove_r2"] = True
            s2 = c2.latest_status()
            out["r2_operator"] = s2.operator if s2 is not None else ""
            time.sleep(1.0)
            ee1 = np.asarray(wait_for("r1's truth", c1.wait_truth).ee_true)
            out["r1_moved_mm"] = float(1000 * np.linalg.norm(ee1 - ee1_0))
        # a viewer's console on r1: the page works, its gizmo reaches nothing
        st1 = wait_for("r1's status", lambda: (s := c1.latest_status()) and s.x and s)
        accepted0 = st1.accepted.get("setpoint", 0)
        port = free_port()
        args = ["--port", str(port), "--prefix", prefix, "--robot", "r1", "--zenoh-config", str(viewer_cfg)]
        say("the operator's console is closed")
        with console_process(args, logdir / "console_viewer.log") as (p, url):
            say("the viewer's console is up")
            ee1_0 = np.asarray(wait_for("r1's truth", c1.wait_truth).ee_true)
            target = np.asarray(st1.x) + np.array([0.05, 0.0, 0.0])
            for _ in range(5):
                move_gizmo(url, target)
                time.sleep(0.3)
            time.sleep(2.0)
            s1 = c1.latest_status()
            ee1 = np.asarray(wait_for("r1's truth", c1.wait_truth).ee_true)
            out["viewer_moved_r1_mm"] = float(1000 * np.linalg.norm(ee1 - ee1_0))
            out["viewer_setpoints_accepted"] = (s1.accepted.get("setpoint", 0) - accepted0) if s1 else -1
            out["viewer_console_attached"] = True
    say("the viewer's console is closed")
    print(json.dumps(out), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
