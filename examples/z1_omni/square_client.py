"""Track a 10 cm square with the end effector; after a fault, resume deliberately and finish.

Start the simulated robot and the daemon, then this client (docs/robots.md, "A robot of your
own")::

    wmm-qp sim --robot-config examples/z1_omni/z1_omni.toml &
    wmm-qp serve --robot-config examples/z1_omni/z1_omni.toml &
    python examples/z1_omni/square_client.py --robot-config examples/z1_omni/z1_omni.toml

The square lies in the horizontal plane through the EE's start, its first corner the start.
The trajectory's clock runs only while the daemon follows setpoints: a fault pauses it where
it was, :meth:`Client.resume` resumes tracking (``watchdog.resume = "manual"``), and the square
goes on from there. The last line is a JSON summary: per corner the closest the EE came (ground
truth) [m], the faults seen and the resumes made; exit status 1 when a corner was missed by
more than ``--tolerance``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from wmm_qp_service.cli_common import add_service_arguments, service_config
from wmm_qp_service.client import Client, NotReady

HERE = Path(__file__).resolve().parent


def corner_path(x0: np.ndarray, side: float) -> np.ndarray:
    """The square's corners [m] in visiting order, back to the first: +x, +y, −x, −y."""
    steps = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 0]], dtype=float)
    return x0 + side * steps


def target(corners: np.ndarray, t: float, leg: float, dwell: float) -> tuple[np.ndarray, int]:
    """The setpoint [m] at trajectory time t [s] (each side in ``leg`` s, then ``dwell`` s at its
    end corner), and the corner it dwells at (its index in ``corners[1:]``; −1: on a side)."""
    k, s = divmod(t, leg + dwell)
    k = min(int(k), len(corners) - 2)
    a = min(s / leg, 1.0)
    return corners[k] + a * (corners[k + 1] - corners[k]), (k if a == 1.0 else -1)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_service_arguments(p)  # --prefix, --robot, the endpoints, --zenoh-config
    p.add_argument("--robot-config", type=Path, default=HERE / "z1_omni.toml", metavar="FILE")
    p.add_argument("--side", type=float, default=0.10, help="[m] the square's side")
    p.add_argument("--leg", type=float, default=2.0, help="[s] time per side")
    p.add_argument("--tolerance", type=float, default=0.005, help="[m] a corner missed by more fails")
    args = p.parse_args(argv)
    svc = service_config(args)  # the robot id as `wmm-qp sim` and `serve` resolve it for these flags
    dwell = 0.5  # [s] at each corner: the EE settles on it
    with Client(svc, name="square",
                on_fault=lambda st: print(f"fault: {st.last_fault}", file=sys.stderr, flush=True)) as c:
        try:
            info = c.wait_ready(timeout=60.0)  # the daemon answers with the sim's first states
        except NotReady as e:
            print(f"square_client: error: {e.reason}", file=sys.stderr)
            return 2
        corners = corner_path(np.array(info.status.x), args.side)
        if not c.resume("track"):  # set the mode and wait until the daemon follows setpoints
            print(f"square_client: error: no tracking: {c.latest_status()}", file=sys.stderr)
            return 2
        print("square: started", flush=True)
        t, last, resumes = 0.0, time.monotonic(), 0
        closest = np.full(len(corners) - 1, np.inf)  # [m] per corner, while dwelling there
        while t < (len(corners) - 1) * (args.leg + dwell):
            now = time.monotonic()
            x, at = target(corners, t, args.leg, dwell)
            if c.send_setpoint(x):
                t += min(now - last, 0.05)  # only while followed; a stalled client slows it, never skips
            elif c.resume("track"):  # after a fault: the deliberate act the daemon waits for
                resumes += 1
            last = time.monotonic()
            if at >= 0 and (st := c.latest_truth()) is not None:
                closest[at] = min(closest[at], float(np.linalg.norm(corners[at + 1] - st.ee_true)))
            time.sleep(0.01)
        c.set_mode("hold")
    print(json.dumps({"corner_error_m": closest.tolist(), "faults": c.faults_seen, "resumes": resumes}))
    return 0 if closest.max() <= args.tolerance else 1


if __name__ == "__main__":
    raise SystemExit(main())
