"""ctl.step's time with and without a 0.8 ms sleep between ticks (docs/benchmarks.md §5.3).

    python benchmarks/issue15/sleep_between_steps.py

The in-process bench steps back to back; the daemon sleeps between ticks, so its caches are cold.
Prints the p50/p99 of 2,500 ticks (after 500) for gaps of 0, 0.8, 0.8 and 0 ms.
"""

import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path[:0] = [str(ROOT), str(ROOT / "service"), str(ROOT / "sim")]

from wmm_qp_service.bench.controller import CleanCase  # noqa: E402

from wmm_qp.config import load_controller_config, load_robot_config  # noqa: E402


def main() -> None:
    robot, cfg = load_robot_config(None), load_controller_config(None)
    for gap in (0.0, 0.0008, 0.0008, 0.0):
        case = CleanCase(robot, cfg, "proxsuite", "track")
        for _ in range(3000):
            case.run(1)
            if gap:
                until = time.perf_counter() + gap
                time.sleep(gap * 0.7)
                while time.perf_counter() < until:
                    pass
        s = np.array(case.samples[500:]) / 1e3
        print(f"gap {gap * 1e6:.0f} us: step p50 {np.median(s):.1f} p99 {np.percentile(s, 99):.1f} us")


if __name__ == "__main__":
    main()
