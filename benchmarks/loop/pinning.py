"""One e2e case with the daemon pinned to CPU 1 and the sim to CPU 0 (``taskset -a -cp``), or not
(docs/benchmarks.md §5.3).

    python benchmarks/loop/pinning.py none|pin rate|state TICKS
"""

import subprocess
import sys
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
sys.path[:0] = [str(ROOT), str(ROOT / "service"), str(ROOT / "sim")]

from wmm_qp_service import processes  # noqa: E402
from wmm_qp_tools.bench import e2e  # noqa: E402


def main() -> None:
    mode, trigger, ticks = sys.argv[1], sys.argv[2], int(sys.argv[3])
    start = processes.Stack.start

    def pinned_start(self: Any, *a: Any, **k: Any) -> Any:
        r = start(self, *a, **k)
        if mode == "pin":
            subprocess.run(["taskset", "-a", "-cp", "1", str(self.procs["daemon"].pid)], capture_output=True)
            subprocess.run(["taskset", "-a", "-cp", "0", str(self.procs["sim"].pid)], capture_output=True)
        return r

    processes.Stack.start = pinned_start  # type: ignore[method-assign]
    c = e2e.run_case(trigger, 1000.0, ticks)
    keys = ("achieved_hz", "tick_over_step_p50", "misses_per_10k", "watchdog_ticks", "applied_next_step",
            "cmds_not_applied", "cpu_pct")
    print(mode, trigger, {k: c.get(k) for k in keys}, "tick", c["tick_us"]["p50"], "step", c["step_us"]["p50"],
          "s2c", c["state_to_cmd_us"]["p50"], c["state_to_cmd_us"]["p99"],
          "transport", c["state_transport_us"]["p50"], "daemon", c["daemon_us"]["p50"])


if __name__ == "__main__":
    main()
