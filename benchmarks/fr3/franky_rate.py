"""franky-sim's physics steps per second, paced by the tests' rig (absolute deadlines) and by
franky-sim's own loop (sleep 1 ms minus the tick's work), one after the other.

    python benchmarks/fr3/franky_rate.py [--seconds 8]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tests"))

import support.franky_rig as rig

import wmm_qp as w


def steps_per_second(seconds: float) -> float:
    sim = rig.start_franky_sim(w.load_robot_config(rig.FR3))
    try:
        time.sleep(2.0)  # past the start
        s0, t0 = sim.shared[14], time.monotonic()
        time.sleep(seconds)
        return float((sim.shared[14] - s0) / (time.monotonic() - t0))
    finally:
        sim.close()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=8.0, help="[s] counted per case (default 8)")
    a = ap.parse_args()
    paced = steps_per_second(a.seconds)
    own = steps_per_second_own(a.seconds)
    print(f"franky-sim physics steps per second: paced {paced:.0f}, its own loop {own:.0f} "
          f"(1000 is real time)")


def steps_per_second_own(seconds: float) -> float:
    """The same with franky-sim's own loop: the child reads ``WMM_QP_FRANKY_OWN_LOOP``."""
    import os

    os.environ["WMM_QP_FRANKY_OWN_LOOP"] = "1"
    try:
        return steps_per_second(seconds)
    finally:
        del os.environ["WMM_QP_FRANKY_OWN_LOOP"]


if __name__ == "__main__":
    main()
