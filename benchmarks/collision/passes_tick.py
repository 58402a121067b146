"""The pair search's compiled robot-side call alone (``robot_passes`` in
``wmm_qp/limits/_pair_passes.py``: the bodies placed, the robot's own pairs, the floor), per robot:
the controller tracks the paper's circle in the default scene (rows on) for ``--ticks`` ticks, the
call's arguments at the last tick are kept, and the call is timed 5,000 times on them (the robot at
rest between calls: the pairs left out by their last distance stay out). Prints, per robot, its
p50 and how many candidates it gave. To compare two commits, run it in each (the older
from a ``git worktree``, with ``PYTHONPATH`` set to that tree and its ``sim``, ``service``,
``robot`` and ``tools`` folders): it takes the call's arguments as that tree's search passes them.

    python benchmarks/collision/passes_tick.py gen3_mecanum fr3 panda_diffdrive ur5_omni tiago [--ticks 3000]
"""

from __future__ import annotations

import time

import numpy as np
from wmm_qp_tools.bench.collision import for_each_robot, kernel_arguments_at_tick

from wmm_qp.limits._pair_passes import robot_passes as passes

CALLS = 5000


def one(name: str, ticks: int) -> str:
    args, _ = kernel_arguments_at_tick(f"configs/robots/{name}.toml", ticks)
    n, _left = passes(*args)
    t = np.empty(CALLS)
    for k in range(CALLS):
        t0 = time.perf_counter_ns()
        passes(*args)
        t[k] = time.perf_counter_ns() - t0
    return f"{name}: robot_passes p50 {np.median(t) / 1e3:.1f} µs, {n} candidates (after {ticks} ticks)"


if __name__ == "__main__":
    for_each_robot(__doc__, one)
