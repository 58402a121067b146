"""The pair search with the convex hulls of meshes through the compiled GJK (:mod:`wmm_qp.limits._gjk`)
against the same search with them left to coal one pair at a time (as before GJK): two
``PairSearch`` of one controller's geometry, timed interleaved tick by tick on the track circle of
the default scene (rows on), one process; every tick their candidates are compared (the same
pairs and sides). Prints the two p50, their ratio, the largest distance difference (coal at its
default GJK tolerance, 1e-6) and how many entries GJK left to coal. Then the whole track tick
(``ctl.step``) the same way: three controllers on the same states, rows on with GJK, rows on with
the hulls left to coal, rows off; their p50 and p99 and the ratios.

    python benchmarks/collision/gjk_ab.py configs/robots/fr3.toml [--ticks 3000]
"""

from __future__ import annotations

import time

import numpy as np
from wmm_qp_tools.bench.collision import (
    IdealRobot,
    circle,
    coal_search,
    leave_to_coal,
    load_scene,
    robot_and_ticks,
    rows_on_the_default_scene,
)

import wmm_qp as w


def main() -> None:
    a = robot_and_ticks(__doc__)
    model, on, gjk = rows_on_the_default_scene(a.robot_config)
    coal_only = coal_search(gjk)  # the hulls to coal, one pair at a time
    hulls = int((gjk._shapes.kind == 3).sum())
    bot = IdealRobot.at_start(model)
    x0 = model.ee_position(bot.q_base, bot.q_arm)
    times: dict[str, list[int]] = {"coal": [], "gjk": []}
    worst, left, entries = 0.0, 0, 0
    for k in range(a.ticks):
        x_d, xd_d = circle(x0, k * on.dt)
        bot.apply(on.step(bot.state(), w.Reference(w.Mode.TRACK, x_d=x_d, xd_d=xd_d)), on.dt)
        for name in ("coal", "gjk") if k % 2 else ("gjk", "coal"):  # alternate which runs first
            s = gjk if name == "gjk" else coal_only
            t0 = time.perf_counter_ns()
            s.search(bot.q_base)
            times[name].append(time.perf_counter_ns() - t0)
        cg, cc = gjk.candidates, coal_only.candidates
        assert cg.n == cc.n and (cg.body[:cg.n] == cc.body[:cc.n]).all() and (cg.other[:cg.n] == cc.other[:cc.n]).all()
        if cg.n:
            worst = max(worst, float(np.abs(cg.d[:cg.n] - cc.d[:cc.n]).max()))
        entries += cg.n
        left += int((~cg.ok[:cg.n]).sum())
    c50, g50 = (float(np.median(times[n])) / 1e3 for n in ("coal", "gjk"))
    print(f"{model.config.name} ({hulls} hulls): PairSearch.search p50 {c50:.1f} µs with coal, {g50:.1f} µs with GJK, "
          f"ratio {c50 / g50:.2f}; largest |d_gjk - d_coal| {worst:.2e} m; {left} of {entries} entries left to coal "
          f"({a.ticks} ticks)")
    ticks(model, a.ticks)


def ticks(model: w.WmmModel, n: int) -> None:
    """The track tick with rows (GJK; hulls to coal) and without, interleaved on the same states."""
    cfg = w.load_controller_config()
    ctls = {"gjk": w.make_controller("qp", model, cfg.with_(collision={"enabled": True})),
            "coal": w.make_controller("qp", model, cfg.with_(collision={"enabled": True})),
            "off": w.make_controller("qp", model, cfg.with_(collision={"enabled": False}))}
    for name, ctl in ctls.items():
        ctl.warm_up()
        if name != "off":
            ctl.set_scene(load_scene())  # type: ignore[attr-defined]
    leave_to_coal(ctls["coal"].collision.search)  # type: ignore[attr-defined]
    bot = IdealRobot.at_start(model)
    x0 = model.ee_position(bot.q_base, bot.q_arm)
    times: dict[str, list[int]] = {k: [] for k in ctls}
    order = list(ctls)
    for k in range(n):
        x_d, xd_d = circle(x0, k * ctls["gjk"].dt)
        ref = w.Reference(w.Mode.TRACK, x_d=x_d, xd_d=xd_d)
        state = bot.state()
        cmd = None
        for name in order[k % 3:] + order[:k % 3]:  # rotate which runs first
            t0 = time.perf_counter_ns()
            out = ctls[name].step(state, ref)
            times[name].append(time.perf_counter_ns() - t0)
            if name == "gjk":
                cmd = out
        bot.apply(cmd, ctls["gjk"].dt)
    p = {k: (float(np.median(v)) / 1e3, float(np.percentile(v, 99)) / 1e3) for k, v in times.items()}
    print(f"{model.config.name}: track tick p50 / p99 [µs]: rows with GJK {p['gjk'][0]:.1f} / {p['gjk'][1]:.1f}, "
          f"rows with the hulls to coal {p['coal'][0]:.1f} / {p['coal'][1]:.1f}, rows off {p['off'][0]:.1f} / "
          f"{p['off'][1]:.1f}; coal / GJK {p['coal'][0] / p['gjk'][0]:.2f}, with rows (GJK) / without "
          f"{p['gjk'][0] / p['off'][0]:.2f} at p50 ({n} ticks)")


if __name__ == "__main__":
    main()
