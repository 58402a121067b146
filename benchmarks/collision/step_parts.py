"""Where the collision rows' cost goes in a step, per robot: two qp controllers on the paper's
circle, one with the default rows and scene and one without, ticked in turns in one process; each
part of the step timed (inclusive, each figure with its own wrapper's ~0.2 µs) by wrapping the
controller's methods with a clock. Prints, per part, its p50 with rows and without (docs/benchmarks.md §12).
The rows' compiled calls: ``_robot_rows`` (the search and the rows in one, the default scene: no
obstacles), or ``PairSearch.search`` and ``_rows`` (with obstacles; "-" where not called).

    python benchmarks/collision/step_parts.py panda_diffdrive fr3 [--ticks 3000]
"""

from __future__ import annotations

import time
from collections import defaultdict
from collections.abc import Callable
from typing import Any

import numpy as np
from wmm_qp_tools.bench.collision import for_each_robot, rows_on_the_default_scene
from wmm_qp_tools.bench.trajectory import IdealRobot, circle

import wmm_qp as w
from wmm_qp.controllers.qp.controller import QpController
from wmm_qp.limits import collision, pair_search

PARTS = ("context", "reference_velocity", "stage_rows", "build_arm_first", "build", "_solve", "finish")


def one(name: str, ticks: int) -> str:
    model, on, _ = rows_on_the_default_scene(f"configs/robots/{name}.toml")
    model_off = w.WmmModel(model.config)
    off = w.make_controller("qp", model_off, w.load_controller_config().with_(collision={"enabled": False}))
    off.warm_up()
    rec: dict[tuple[str, str], list[int]] = defaultdict(list)
    label = ["on"]
    undo: list[tuple[Any, str, Any]] = []

    def wrap(owner: Any, attr: str, key: str) -> None:
        orig = getattr(owner, attr)

        def timed(*a: Any, **kw: Any) -> Any:
            t0 = time.perf_counter_ns()
            r = orig(*a, **kw)
            rec[(label[0], key)].append(time.perf_counter_ns() - t0)
            return r

        undo.append((owner, attr, orig))
        setattr(owner, attr, timed)

    for attr in PARTS:
        wrap(QpController, attr, attr)
    wrap(pair_search.PairSearch, "search", "  PairSearch.search")
    wrap(collision, "_robot_rows", "  _robot_rows")
    wrap(collision, "_rows", "  _rows")
    try:
        bots = {"on": IdealRobot.at_start(model), "off": IdealRobot.at_start(model_off)}
        x0 = model.ee_position(bots["on"].q_base, bots["on"].q_arm)
        ctls: dict[str, Callable[..., Any]] = {"on": on.step, "off": off.step}
        for k in range(ticks):
            x_d, xd_d = circle(x0, k * on.dt)
            for which in ("on", "off"):
                label[0] = which
                st, ref = bots[which].state(), w.Reference(w.Mode.TRACK, x_d=x_d, xd_d=xd_d)
                t0 = time.perf_counter_ns()
                cmd = ctls[which](st, ref)
                rec[(which, "step")].append(time.perf_counter_ns() - t0)
                bots[which].apply(cmd, on.dt)
    finally:
        for owner, attr, orig in reversed(undo):
            setattr(owner, attr, orig)

    def p50(which: str, key: str) -> str:
        v = rec.get((which, key), [])
        v = v[len(v) // 6 :]  # (the first ticks: the warm-up)
        return f"{np.median(v) / 1e3:6.1f}" if len(v) else "     -"

    lines = [f"{name} (p50 µs, rows on / off; {ticks} ticks)"]
    for key in ("step", *PARTS[:3], "  _robot_rows", "  PairSearch.search", "  _rows", *PARTS[3:]):
        lines.append(f"  {key:22s} {p50('on', key)} / {p50('off', key)}")
    return "\n".join(lines)


if __name__ == "__main__":
    for_each_robot(__doc__, one)
