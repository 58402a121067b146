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

from numba import njit
from wmm_qp_tools.bench.collision import for_each_robot, rows_on_the_default_scene
from wmm_qp_tools.bench.trajectory import IdealRobot, circle

import wmm_qp as w
from wmm_qp.limits._gjk import WARM_WIDTH, gjk
from wmm_qp.limits._pair_passes import ROBOT_FLOATS, ROBOT_INTS, layout

CALLS = 20_000


@njit(cache=False)
def _calls(n, F, I, L, i, j, ow, ws, wi):
    total = 0.0
    for _ in range(n):
        total += gjk(F, I, L, i, F, I, L, j, ow, ws, wi)
    return total


def one(name: str, ticks: int) -> str:
    model, ctl, search = rows_on_the_default_scene(f"configs/robots/{name}.toml")
    bot = IdealRobot.at_start(model)
    x0 = model.ee_position(bot.q_base, bot.q_arm)
    for k in range(ticks):
        x_d, xd_d = circle(x0, k * ctl.dt)
        bot.apply(ctl.step(bot.state(), w.Reference(w.Mode.TRACK, x_d=x_d, xd_d=xd_d)), ctl.dt)
    s = search.placed
    F, Lf, I, Li = (a.copy() for a in search.arenas)  # (the search's own left as they are)
    L = layout(Lf, Li, ROBOT_FLOATS, ROBOT_INTS)
    warm, ws, wi = (int(Lf[ROBOT_FLOATS.index("warm"), 0]), int(Lf[ROBOT_FLOATS.index("work"), 0]),
                    int(Li[ROBOT_INTS.index("work_ids"), 0]))
    hulls = [k for k, (i, j) in enumerate(search._pairs)
             if s.kind[i] == 3 and s.kind[j] == 3 and F[warm + WARM_WIDTH * k + 3] > 0]
    total = 0.0
    for k in hulls:
        i, j = search._pairs[k]
        args = (F, I, L, i, j, warm + WARM_WIDTH * k, ws, wi)
        _calls(1, *args)
        t0 = time.perf_counter_ns()
        _calls(CALLS, *args)
        total += (time.perf_counter_ns() - t0) / CALLS
    return f"{name}: {len(hulls)} hull pairs, their warm GJK calls {total / 1e3:.2f} µs together (after {ticks} ticks)"


if __name__ == "__main__":
    for_each_robot(__doc__, one)
