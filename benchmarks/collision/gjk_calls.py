"""GJK's warm calls alone (``gjk`` in ``wmm_qp/limits/_gjk.py``), per robot: the controller tracks
the paper's circle in the default scene (rows on) for ``--ticks`` ticks; then each of the robot's
own pairs of two convex hulls that GJK computed at that tick (a warm start kept) is called 20,000
times in a compiled loop, where the shapes are then (the call ends after one support step, as a
pair that moved little does). Prints, per robot, the calls' time summed over those pairs and their
number. To compare two commits, run it in each (the older from a ``git worktree``, with
``PYTHONPATH`` set to that tree and its ``sim``, ``service``, ``robot`` and ``tools`` folders).

    python benchmarks/collision/gjk_calls.py fr3 tiago [--ticks 3000]
"""

from __future__ import annotations

import time

import numpy as np
from numba import njit
from wmm_qp_tools.bench.collision import for_each_robot, rows_on_the_default_scene
from wmm_qp_tools.bench.trajectory import IdealRobot, circle

import wmm_qp as w
from wmm_qp.limits._gjk import gjk

CALLS = 20_000


@njit(cache=False)
def _calls(n, kind, a0, a1, c, R, h, verts, vs, vc, i, j, p, q, warm, k):
    total = 0.0
    for _ in range(n):
        total += gjk(kind, a0, a1, c, R, h, verts, vs, vc, i, kind, a0, a1, c, R, h, verts, vs, vc, j, p, q, warm, k)
    return total


def one(name: str, ticks: int) -> str:
    model, ctl, search = rows_on_the_default_scene(f"configs/robots/{name}.toml")
    bot = IdealRobot.at_start(model)
    x0 = model.ee_position(bot.q_base, bot.q_arm)
    for k in range(ticks):
        x_d, xd_d = circle(x0, k * ctl.dt)
        bot.apply(ctl.step(bot.state(), w.Reference(w.Mode.TRACK, x_d=x_d, xd_d=xd_d)), ctl.dt)
    s = search.placed
    p, q, warm = np.zeros(3), np.zeros(3), search._warm.copy()
    hulls = [k for k, (i, j) in enumerate(search._pairs) if s.kind[i] == 3 and s.kind[j] == 3 and warm[k, 3] > 0]
    total = 0.0
    for k in hulls:
        i, j = search._pairs[k]
        args = (s.kind, s.a0, s.a1, s.c, s.R, s.h, s.verts, s.vs, s.vc, i, j, p, q, warm, k)
        _calls(1, *args)
        t0 = time.perf_counter_ns()
        _calls(CALLS, *args)
        total += (time.perf_counter_ns() - t0) / CALLS
    return f"{name}: {len(hulls)} hull pairs, their warm GJK calls {total / 1e3:.2f} µs together (after {ticks} ticks)"


if __name__ == "__main__":
    for_each_robot(__doc__, one)
