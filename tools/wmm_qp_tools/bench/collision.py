"""The cost of the collision rows: the track-mode tick with and without them, in one run.

``collision_default`` (:func:`run_default`): every shipped robot on the paper's circle with the
default scene (its rows: self, floor, the fence), the cost of the default.

``collisions`` (:func:`run`): the paper's circle (:mod:`.trajectory`) among obstacles:
``configs/scenes/cluttered.toml`` (a wall, a pillar, a ball, a side wall) with one more ball
placed on the circle's path near the EE, so that
about ten monitored pairs are inside the influence distance (the arm's self pairs, the ball, the
floor). Both controllers see every state of one trajectory (the rows-on controller's, executed by
an ideal robot); their ``step`` calls alternate tick by tick, so machine noise hits both alike.
Reported: the p50/p99 of each, their ratio, and how many rows (pairs within d_i) the ticks had;
and the sim's step on the same commands with its referee's motion budget and without it.
"""

from __future__ import annotations

import argparse
import inspect
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

import wmm_qp as w
from wmm_qp.config import ShapeConfig, default_config_dir
from wmm_qp.limits import _pair_passes, collision
from wmm_qp.scene import load_scene
from wmm_qp_tools.bench.robot_files import loaded, shipped_robots
from wmm_qp_tools.bench.stats import now_ns, summarize_ns
from wmm_qp_tools.bench.trajectory import IdealRobot, circle


def rows_on_the_default_scene(robot_config: str | Path) -> tuple[w.WmmModel, Any, Any]:
    """The robot's model, a warmed-up qp controller with the default rows and scene, and its pair
    search (the benchmarks of ``benchmarks/collision/``)."""
    from wmm_qp.limits.pair_search import PairSearch

    model = w.WmmModel(w.load_robot_config(robot_config))
    on = w.make_controller("qp", model, w.load_controller_config().with_(collision={"enabled": True}))
    on.warm_up()
    on.set_scene(load_scene())
    search: PairSearch = on.collision.search  # type: ignore[attr-defined]
    return model, on, search


def arguments_at_tick(robot_config: str | Path, module: Any, kernel: str, ticks: int) -> tuple[Callable[..., Any],
                                                                                             tuple[Any, ...]]:
    """``module.kernel`` (a compiled function the rows call each tick, e.g. ``pair_search``'s
    ``robot_passes``) and its arguments at the last of ``ticks`` ticks of the paper's circle with
    the default rows and scene (:func:`rows_on_the_default_scene`), the robot ideal: what the
    kernel benchmarks time it on."""
    model, ctl, _ = rows_on_the_default_scene(robot_config)
    fn = getattr(module, kernel)
    kept: list[tuple[Any, ...]] = []

    def keep(*args: Any) -> Any:
        kept[:] = [args]
        return fn(*args)

    setattr(module, kernel, keep)
    try:
        bot = IdealRobot.at_start(model)
        x0 = model.ee_position(bot.q_base, bot.q_arm)
        for k in range(ticks):
            x_d, xd_d = circle(x0, k * ctl.dt)
            cmd = ctl.step(bot.state(), w.Reference(w.Mode.TRACK, x_d=x_d, xd_d=xd_d))
            bot.apply(cmd, ctl.dt)
    finally:
        setattr(module, kernel, fn)
    return fn, kept[0]


def kernel_arguments_at_tick(robot_config: str | Path, ticks: int) -> tuple[tuple[Any, ...], tuple[Any, ...]]:
    """The arguments of the rows' two kernels at the last of ``ticks`` ticks of the paper's circle
    in the default scene (:func:`arguments_at_tick` of ``_robot_rows``, which makes both calls there):
    (``robot_passes``'s, ``_rows``'s on the candidates ``robot_passes`` gives on them)."""
    _, a = arguments_at_tick(robot_config, collision, "_robot_rows", ticks)
    k = len(inspect.signature(_pair_passes.robot_passes).parameters)  # (_robot_rows takes its arguments first)
    robot, statics, (v_prev, lb, ub, latency) = a[:k], a[k:-4], a[-4:]
    n, _ = _pair_passes.robot_passes(*robot)
    return robot, (*robot[1:5], *statics, n, np.zeros((0, 3)), v_prev, lb, ub, latency)


def robot_and_ticks(doc: str) -> argparse.Namespace:
    """The collision benchmarks' arguments: ``robot_config`` and ``--ticks`` (3000)."""
    ap = argparse.ArgumentParser(description=doc.split("\n\n")[0])
    ap.add_argument("robot_config")
    ap.add_argument("--ticks", type=int, default=3000)
    return ap.parse_args()


def for_each_robot(doc: str, one: Callable[[str, int], str]) -> None:
    """The A/B benchmarks' command line: robots by name (``configs/robots/<name>.toml``) and
    ``--ticks`` (3000); prints ``one(name, ticks)`` for each, as it comes."""
    ap = argparse.ArgumentParser(description=doc.split("\n\n")[0])
    ap.add_argument("robots", nargs="+", help="names of configs/robots/<name>.toml")
    ap.add_argument("--ticks", type=int, default=3000)
    a = ap.parse_args()
    for name in a.robots:
        print(one(name, a.ticks), flush=True)


def leave_to_coal(search: Any, kinds: tuple[int, ...] = (3,)) -> None:
    """``search`` (a :class:`~wmm_qp.limits.pair_search.PairSearch`) leaves its primitives of
    ``kinds`` (3 the hulls, 1 the boxes) to coal, one pair at a time: the reference its compiled
    distances are checked and timed against."""
    for t in (search._shapes, search.placed):
        t.kind[np.isin(t.kind, kinds)] = 2


def coal_search(search: Any, kinds: tuple[int, ...] = (3,), gjk_tolerance: float | None = None) -> Any:
    """A search of ``search``'s geometry, parameters and obstacles that leaves ``kinds`` to coal
    (:func:`leave_to_coal`), coal's GJK at ``gjk_tolerance`` where given."""
    from wmm_qp.limits.pair_search import PairSearch

    out = PairSearch(search.geo, search.p)
    out.set_obstacles(search.shapes)
    if gjk_tolerance is not None:
        out._req.gjk_tolerance = gjk_tolerance
    leave_to_coal(out, kinds)
    return out


def bench_scene(x0: np.ndarray) -> w.scene.Scene:
    """The cluttered scene plus a ball 0.2 m beside the EE's start, on the circle's inside."""
    scene = load_scene(default_config_dir() / "scenes" / "cluttered.toml")
    ball = ShapeConfig("near_ball", "", "sphere", np.array([0.06, 0.0, 0.0]),
                       np.asarray(x0, dtype=float) + [-0.12, 0.2, 0.0], np.zeros(3))
    return replace(scene, obstacles=(*scene.obstacles, ball))


def run(robot: w.RobotConfig, cfg: w.ControllerConfig, ticks: int, max_seconds: float = 30.0) -> dict[str, Any]:
    """Interleaved timing of ``step`` with the collision rows and without them (the same states).

    Returns:
        {"robot", "scene", "ticks", "with_rows" {p50, p99, …}, "without_rows" {…}, "ratio_p50",
        "rows" {p50, max} per tick, "monitored" (pairs the geometry monitors), "violations"}.
    """
    model = w.WmmModel(robot)
    bot = IdealRobot.at_start(model)
    scene = bench_scene(model.ee_position(bot.q_base, bot.q_arm))
    out = _on_off(model, cfg, scene, ticks, max_seconds)
    judged = referee(model, scene, out.pop("_cmds"), out.pop("_dt"))  # before the spread: no commands in the JSON
    return {"robot": robot.name, "scene": "configs/scenes/cluttered.toml + a ball beside the circle", **out,
            "referee": judged}


def run_default(cfg: w.ControllerConfig, ticks: int, max_seconds: float = 30.0,
                files: list[Path] | None = None) -> dict[str, Any]:
    """The cost of the default (rows on): for every shipped robot, the track-mode ``step`` on the
    paper's circle from its ``arm.start`` with the default scene's rows (self, floor, the fence of
    ``configs/scenes/default.toml``) and without rows, interleaved tick by tick (:func:`_on_off`).

    Returns:
        {robot name: {"file", "available", "scene", "solver", "ticks", "with_rows" {p50, p99, …},
        "without_rows" {…}, "ratio_p50", "rows" {p50, max, mean}, "monitored"}} (a robot file that
        does not load: {"file", "available": False, "reason"}).
    """
    scene = load_scene()  # configs/scenes/default.toml: the fence, no obstacles
    out: dict[str, Any] = {}
    for f, robot in loaded(files if files is not None else shipped_robots(), out):
        res = _on_off(w.WmmModel(robot), cfg, scene, ticks, max_seconds)
        res.pop("_cmds"), res.pop("_dt")
        out[robot.name] = {"file": str(f), "available": True, "scene": "configs/scenes/default.toml",
                           "solver": cfg.qp.solver, **res}
    return out


def _on_off(model: w.WmmModel, cfg: w.ControllerConfig, scene: w.scene.Scene, ticks: int,
            max_seconds: float) -> dict[str, Any]:
    """``step`` with the rows (and ``scene``) and without them, on the states of one circle (the
    rows-on controller's commands executed by an ideal robot), alternating which runs first."""
    robot = model.config
    on = w.make_controller("qp", model, cfg.with_(collision={"enabled": True}))
    off = w.make_controller("qp", w.WmmModel(robot), cfg.with_(collision={"enabled": False}))
    for c in (on, off):
        c.warm_up()
    bot = IdealRobot.at_start(model)
    x0 = model.ee_position(bot.q_base, bot.q_arm)
    on.set_scene(scene)
    t_on: list[int] = []
    t_off: list[int] = []
    rows: list[int] = []
    cmds: list[w.Command] = []
    deadline = time.monotonic() + max_seconds
    for k in range(ticks):
        x_d, xd_d = circle(x0, k * on.dt)
        ref = w.Reference(w.Mode.TRACK, x_d=x_d, xd_d=xd_d)
        st = bot.state()
        first, second = (on, off) if k % 2 else (off, on)  # alternate which runs first
        t0 = now_ns()
        a = first.step(st, ref)
        t1 = now_ns()
        b = second.step(st, ref)
        t2 = now_ns()
        cmd_on = a if first is on else b
        (t_on if first is on else t_off).append(t1 - t0)
        (t_off if first is on else t_on).append(t2 - t1)
        lr = on.last_collision_rows()
        rows.append(0 if lr is None else len(lr.names))
        cmds.append(cmd_on)
        bot.apply(cmd_on, on.dt)
        if time.monotonic() > deadline:
            break
    s_on, s_off = summarize_ns(t_on[100:]), summarize_ns(t_off[100:])
    geo = on.collision.geo  # type: ignore[attr-defined]
    r = np.array(rows[100:] or [0])
    return {
        "ticks": len(t_on),
        "with_rows": s_on,
        "without_rows": s_off,
        "ratio_p50": round(s_on["p50"] / s_off["p50"], 2) if s_off["p50"] else float("nan"),
        "rows": {"p50": float(np.median(r)), "max": int(r.max()), "mean": round(float(r.mean()), 1)},
        "monitored": {"self_pairs": len(geo.self_pairs), "self_pairs_in_rows": len(geo.row_pairs),
                      "floor_bodies": len(geo.floor_bodies),
                      "obstacles": len(scene.obstacles), "bodies": len(geo.bodies)},
        "_cmds": cmds, "_dt": on.dt,
    }


def referee(model: w.WmmModel, scene: w.scene.Scene, cmds: list[w.Command], dt: float) -> dict[str, Any]:
    """The sim's step with its collision referee's motion budget and without it (every pair at
    every step), two sims fed the same commands (the rows-on controller's), steps interleaved.

    Returns:
        {"steps", "with_budget" {p50, p99, …}, "every_pair" {…}, "ratio_p50", "distances" (computed
        per step, each), "counts_equal"}.
    """
    from wmm_qp_sim import SimCommand, SimRobot, load_sim_config

    cfg = replace(load_sim_config(), firmware=False)
    sims = [SimRobot(model, cfg, seed=1, scene=scene, collisions=True) for _ in range(2)]
    for sim, skip in zip(sims, (True, False), strict=True):
        assert sim.collision is not None
        sim.collision.skip = skip
        sim.reset()
    times: tuple[list[int], list[int]] = ([], [])
    for k, c in enumerate(cmds):
        order = (0, 1) if k % 2 else (1, 0)
        for i in order:
            t0 = now_ns()
            sims[i].step(SimCommand(c.wheel_speeds, c.arm_rates, period=dt, seq=k), dt)
            times[i].append(now_ns() - t0)
    a, b = summarize_ns(times[0][100:]), summarize_ns(times[1][100:])
    ca, cb = sims[0].collision, sims[1].collision
    assert ca is not None and cb is not None
    n = max(len(cmds), 1)
    return {
        "steps": len(cmds),
        "with_budget": a,
        "every_pair": b,
        "ratio_p50": round(b["p50"] / a["p50"], 2) if a["p50"] else float("nan"),
        "distances": {"with_budget": round(ca.computed / n, 2), "every_pair": round(cb.computed / n, 2)},
        "counts_equal": ca.counts == cb.counts,
    }
