"""The pair search reading the joints' placements in Pinocchio's memory (``placement_table``)
against the same search copying each one off ``data.oMi`` a tick (the fallback where the memory
is laid out otherwise): two ``PairSearch`` of one controller's geometry, then two controllers,
timed interleaved tick by tick on the track circle of the default scene (rows on), one process,
so that the machine's state is the same for both. Every tick their candidates are compared (equal
bit for bit). Prints, per robot, both searches' p50 and both ticks' p50 and their ratios.

    python benchmarks/collision/placements_ab.py gen3_mecanum fr3 panda_diffdrive ur5_omni tiago [--ticks 3000]
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from wmm_qp_tools.bench.collision import for_each_robot, load_scene
from wmm_qp_tools.bench.trajectory import IdealRobot, circle

import wmm_qp as w
from wmm_qp.limits.pair_search import SE3_DOUBLES, PairSearch


def copying(search: PairSearch) -> None:
    """``search`` copies each placement off ``data.oMi`` a tick, as where the table is refused."""
    search._in_place, search._oMi = False, np.zeros((0, SE3_DOUBLES))
    search._bind()


def one(name: str, ticks: int) -> str:
    model = w.WmmModel(w.load_robot_config(f"configs/robots/{name}.toml"))
    cfg = w.load_controller_config().with_(collision={"enabled": True})
    ctls: dict[str, Any] = {k: w.make_controller("qp", model, cfg) for k in ("in place", "copied")}
    for k, c in ctls.items():
        c.warm_up()
        c.set_scene(load_scene())
        if k == "copied":
            copying(c.collision.search)
    a, b = ctls["in place"].collision.search, ctls["copied"].collision.search
    bot = IdealRobot.at_start(model)
    x0 = model.ee_position(bot.q_base, bot.q_arm)
    search: dict[str, list[int]] = {k: [] for k in ctls}
    tick: dict[str, list[int]] = {k: [] for k in ctls}
    order = list(ctls)
    for i in range(ticks):
        x_d, xd_d = circle(x0, i * ctls["in place"].dt)
        ref, state, cmd = w.Reference(w.Mode.TRACK, x_d=x_d, xd_d=xd_d), bot.state(), None
        for key in order if i % 2 else order[::-1]:  # alternate which runs first
            t0 = time.perf_counter_ns()
            out = ctls[key].step(state, ref)
            tick[key].append(time.perf_counter_ns() - t0)
            cmd = out if key == "in place" else cmd
        for key, found in (("in place", a), ("copied", b)) if i % 2 else (("copied", b), ("in place", a)):
            t0 = time.perf_counter_ns()
            found.search(bot.q_base)
            search[key].append(time.perf_counter_ns() - t0)
        ca, cb = a.candidates, b.candidates
        assert ca.n == cb.n and np.array_equal(ca.d[:ca.n], cb.d[:cb.n])
        assert np.array_equal(ca.body[:ca.n], cb.body[:cb.n]) and np.array_equal(ca.other[:ca.n], cb.other[:cb.n])
        assert cmd is not None
        bot.apply(cmd, ctls["in place"].dt)
    s = {k: float(np.median(v)) / 1e3 for k, v in search.items()}
    t = {k: float(np.median(v)) / 1e3 for k, v in tick.items()}
    return (f"{name}: PairSearch.search p50 copied {s['copied']:.1f} -> in place {s['in place']:.1f} µs "
            f"({s['copied'] / s['in place']:.2f}x); track tick p50 {t['copied']:.1f} -> {t['in place']:.1f} µs "
            f"({t['copied'] / t['in place']:.2f}x)")


if __name__ == "__main__":
    for_each_robot(__doc__, one)
