"""The pair search and the track tick with the default rows, per robot, in this checkout: the
controller tracks the paper's circle in the default scene (rows on), each tick timed, then
``PairSearch.search`` timed once more at the state the tick left. Prints, per robot, the search's
p50 and the tick's p50 and p99 on one line. To compare two commits, run it in each (the older from
a ``git worktree``, with ``PYTHONPATH`` set to that tree and its ``sim``, ``service``, ``robot``
and ``tools`` folders), alternating, on a quiet machine.

    python benchmarks/collision/search_tick.py gen3_mecanum fr3 panda_diffdrive ur5_omni tiago [--ticks 2000]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from wmm_qp_tools.bench.collision import rows_on_the_default_scene
from wmm_qp_tools.bench.trajectory import IdealRobot, circle

import wmm_qp as w


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("robots", nargs="+", help="names of configs/robots/<name>.toml")
    ap.add_argument("--ticks", type=int, default=2000)
    a = ap.parse_args()
    out = []
    for name in a.robots:
        model, on, search = rows_on_the_default_scene(f"configs/robots/{name}.toml")
        bot = IdealRobot.at_start(model)
        x0 = model.ee_position(bot.q_base, bot.q_arm)
        t_search, t_tick = [], []
        for k in range(a.ticks):
            x_d, xd_d = circle(x0, k * on.dt)
            state = bot.state()
            t0 = time.perf_counter_ns()
            cmd = on.step(state, w.Reference(w.Mode.TRACK, x_d=x_d, xd_d=xd_d))
            t1 = time.perf_counter_ns()
            search.search(bot.q_base)
            t2 = time.perf_counter_ns()
            bot.apply(cmd, on.dt)
            t_tick.append(t1 - t0)
            t_search.append(t2 - t1)
        out.append(f"{name}: search p50 {np.median(t_search) / 1e3:.1f} µs, tick p50 {np.median(t_tick) / 1e3:.1f} "
                   f"p99 {np.percentile(t_tick, 99) / 1e3:.1f} µs")
    print(" | ".join(out))


if __name__ == "__main__":
    main()
