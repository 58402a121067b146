"""A/B of the inside-d_s rows' cost: the in-process circle (rows on, default scene), 5 s, alternating
runs with CollisionRows._add_inside as shipped (A) and as a no-op (B), in one process; prints a line
per robot (median seconds, the ratio), then the JSON of every run (docs/benchmarks.md §9).

Usage, from the repository root: python benchmarks/collision/inside_rows_ab.py gen3_mecanum panda_diffdrive
"""
import contextlib
import io
import json
import sys
import time

from wmm_qp_service.cli import main

from wmm_qp.limits import collision as col

shipped = col.CollisionRows._add_inside


def off(self, out, *a, **k):  # the rows of the pairs inside d_s left out
    return None


res = {}
for robot in sys.argv[1:]:
    argv = ["experiment", "circle", "--robot-config", f"configs/robots/{robot}.toml", "--scene",
            "configs/scenes/default.toml", "--duration", "5", "--json"]
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        main(argv)  # warm-up
    t = {"with": [], "without": []}
    for k in range(6):
        for name, fn in (("with", shipped), ("without", off))[:: 1 if k % 2 == 0 else -1]:
            col.CollisionRows._add_inside = fn
            buf = io.StringIO()
            t0 = time.perf_counter()
            with contextlib.redirect_stdout(buf), contextlib.redirect_stderr(io.StringIO()):
                main(argv)
            t[name].append(time.perf_counter() - t0)
    col.CollisionRows._add_inside = shipped
    med = {n: sorted(v)[len(v) // 2] for n, v in t.items()}
    res[robot] = {"seconds": t, "median_s": med, "ratio_with_over_without": med["with"] / med["without"],
                  "ticks": 2500}
    print(robot, json.dumps(res[robot]["median_s"]), round(res[robot]["ratio_with_over_without"], 3), flush=True)
print(json.dumps(res))
