"""The pair search's coal part (the pairs the compiled kernels leave to coal: meshes, box-box),
before and after its transforms were computed once per body per tick and its normal's norm by
hand: ``PairSearch.search`` timed with each ``_coal_fill``, interleaved tick by tick on the
track circle of the default scene (rows on), one process. Prints the two p50 and their ratio.
The "before" is replayed here for the robot and the floor (the default scene has no obstacle).

    python benchmarks/collision/coal_fill_ab.py configs/robots/tiago.toml [--ticks 3000]
"""

from __future__ import annotations

import time
import types
from typing import Any

import coal
import numpy as np
from wmm_qp_tools.bench.collision import IdealRobot, circle, robot_and_ticks, rows_on_the_default_scene

import wmm_qp as w
import wmm_qp.limits.pair_search as ps
from wmm_qp.model.collision import transform


def _old_normal(res: Any) -> np.ndarray:
    n = -np.asarray(res.normal, dtype=float)
    nn = float(np.linalg.norm(n))
    return n / nn if nn > 1e-12 else np.array([0.0, 0.0, 1.0])


def old_fill(self: ps.PairSearch, n: int, Rb: Any, tb: Any) -> None:
    """``_coal_fill`` as it was: a body's pose from Pinocchio for each pair it is in."""
    c, bodies = self.candidates, self.geo.bodies

    def pose(i: int) -> coal.Transform3s:
        return transform(self.geo.placement(i, self.geo.arm.data.oMi))

    for k in np.flatnonzero(~c.ok[:n]).tolist():
        body, other = int(c.body[k]), int(c.other[k])
        b, Tb = (bodies[other].shape, pose(other)) if other >= 0 else (self._floor, self._identity)
        res = self._res
        res.clear()
        d = coal.distance(bodies[body].shape, pose(body), b, Tb, self._req, res)
        c.d[k], c.p_a[k], c.p_b[k] = float(d), np.asarray(res.getNearestPoint1()), np.asarray(res.getNearestPoint2())
        c.normal[k] = _old_normal(res)


def main() -> None:
    a = robot_and_ticks(__doc__)
    model, on, search = rows_on_the_default_scene(a.robot_config)
    bot = IdealRobot.at_start(model)
    x0 = model.ee_position(bot.q_base, bot.q_arm)
    times: dict[str, list[int]] = {"before": [], "after": []}
    fills = {"before": old_fill, "after": ps.PairSearch._coal_fill}
    for k in range(a.ticks):
        x_d, xd_d = circle(x0, k * on.dt)
        bot.apply(on.step(bot.state(), w.Reference(w.Mode.TRACK, x_d=x_d, xd_d=xd_d)), on.dt)
        for name in ("before", "after") if k % 2 else ("after", "before"):  # alternate which runs first
            search._coal_fill = types.MethodType(fills[name], search)  # type: ignore[method-assign]
            t0 = time.perf_counter_ns()
            search.search(bot.q_base)
            times[name].append(time.perf_counter_ns() - t0)
    before, after = (float(np.median(times[n])) / 1e3 for n in ("before", "after"))
    print(f"{model.config.name}: PairSearch.search p50 {before:.1f} µs before, {after:.1f} µs after, "
          f"ratio {before / after:.2f} ({a.ticks} ticks)")


if __name__ == "__main__":
    main()
