"""The collision rows from the candidates in one compiled call (``_rows`` in
``wmm_qp/limits/collision.py``) against the same rows in three calls and Python between them (the
previous ``CollisionRows.rows``, kept here as :func:`rows_in_three_calls`): two controllers, one
of them with its rows computed the old way, stepped on the same states interleaved tick by tick
on the track circle of the default scene (rows on), one process. Every tick their rows must be
equal bit for bit (their commands too, but where proxsuite solves a stage: its last bits depend on
its buffers' alignment, docs/model.md). Prints, per robot, both track ticks' p50 and their ratio.

    python benchmarks/collision/rows_ab.py gen3_mecanum fr3 panda_diffdrive ur5_omni tiago [--ticks 3000]
"""

from __future__ import annotations

import math
import time
import types
from typing import Any

import numpy as np
from wmm_qp_tools.bench.collision import for_each_robot, load_scene
from wmm_qp_tools.bench.trajectory import IdealRobot, circle

import wmm_qp as w
from wmm_qp.limits.collision import MAX_ROWS, CollisionRows, _assemble, _distinct_rows
from wmm_qp.limits.dampers import damper_bounds
from wmm_qp.limits.pair_search import PairNames
from wmm_qp.limits.rows import Rows


def rows_in_three_calls(self: CollisionRows, q_base: Any, q_arm: Any, v_prev: Any, lb: Any, ub: Any) -> Rows:
    """``CollisionRows.rows`` as it was: ``_assemble``, ``damper_bounds``, ``_distinct_rows``."""
    p, d_i = self.p, self.p.influence_distance
    n_v = self.n_w + self.n_a
    found = self.search.search(q_base)
    if not found.n:
        return Rows(np.zeros((0, n_v)), np.zeros(0))
    C, dist, safety, body, other, normal, keys, closest, n_inside = _assemble(
        found.d, found.p_a, found.p_b, found.normal, found.body, found.other, found.safety, found.n, d_i,
        MAX_ROWS, n_v, self._Jw, self._support, self._body_joint, self.M, self.n_w,
        self._body_link, self._n_links, len(self.search.obstacles))
    min_distance, nearest = math.inf, ""
    if closest >= 0:
        min_distance = float(found.d[closest])
        nearest = self.search.name(int(found.body[closest]), int(found.other[closest]))
    m = dist.shape[0]
    if not m:
        return Rows(np.zeros((0, n_v)), np.zeros(0), min_distance=min_distance, closest=nearest)
    shift = self._obstacle_shift(normal, other)
    l, l_brake, damper = damper_bounds(C, v_prev, lb, ub, dist, safety, d_i, p.gain, self.latency, shift,
                                       self._accel, p.braking, np.zeros(m))
    keep = _distinct_rows(C, l, keys)
    if keep.shape[0] == m:
        out = Rows(C, l, l_brake, damper, PairNames(self.search.namer(), body, other), dist, min_distance, nearest)
    else:
        out = Rows(C[keep], l[keep], l_brake[keep], damper[keep],
                   PairNames(self.search.namer(), body[keep], other[keep]), dist[keep], min_distance, nearest)
    if n_inside:
        inside = np.flatnonzero(dist < safety)
        self._add_inside(out, body[inside], other[inside], safety[inside], q_base, q_arm, v_prev, lb, ub)
    return out


def one(name: str, ticks: int) -> str:
    model = w.WmmModel(w.load_robot_config(f"configs/robots/{name}.toml"))
    cfg = w.load_controller_config().with_(collision={"enabled": True})
    ctls: dict[str, Any] = {k: w.make_controller("qp", model, cfg) for k in ("one call", "three calls")}
    old = ctls["three calls"].collision
    old.rows = types.MethodType(rows_in_three_calls, old)
    for c in ctls.values():
        c.warm_up()
        c.set_scene(load_scene())
    bot = IdealRobot.at_start(model)
    x0 = model.ee_position(bot.q_base, bot.q_arm)
    tick: dict[str, list[int]] = {k: [] for k in ctls}
    order = list(ctls)
    for i in range(ticks):
        x_d, xd_d = circle(x0, i * ctls["one call"].dt)
        ref, state = w.Reference(w.Mode.TRACK, x_d=x_d, xd_d=xd_d), bot.state()
        out = {}
        for key in order if i % 2 else order[::-1]:  # alternate which runs first
            t0 = time.perf_counter_ns()
            out[key] = ctls[key].step(state, ref)
            tick[key].append(time.perf_counter_ns() - t0)
        ra, rb = (ctls[k].last_collision_rows() for k in ("one call", "three calls"))
        if ra is not None or rb is not None:  # the rows: equal bit for bit
            assert ra is not None and rb is not None, i
            assert all(np.array_equal(getattr(ra, f), getattr(rb, f)) for f in ("C", "l", "l_brake", "damper")), i
        bot.apply(out["one call"], ctls["one call"].dt)
    t = {k: float(np.median(v)) / 1e3 for k, v in tick.items()}
    return (f"{name}: track tick p50 three calls {t['three calls']:.1f} -> one call {t['one call']:.1f} µs "
            f"({t['three calls'] / t['one call']:.2f}x), rows equal bit for bit ({ticks} ticks)")


if __name__ == "__main__":
    for_each_robot(__doc__, one)
