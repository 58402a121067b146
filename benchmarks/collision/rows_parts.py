"""The rows' kernel and its parts alone, per robot: the controller tracks the paper's circle in the
default scene (rows on) for ``--ticks`` ticks, the arguments of ``_rows`` (``wmm_qp/limits/collision.py``)
at the last tick are kept, and ``_rows``, ``_assemble``, ``damper_bounds`` and ``_distinct_rows``
are each called 3,000 times on them, beside a compiled function that takes ``_rows``'s arguments
and does nothing (the call's own cost). Each part's figure includes its own call and the arrays it
returns to Python (docs/benchmarks.md §12).

    python benchmarks/collision/rows_parts.py panda_diffdrive fr3 [--ticks 1500]
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np
from numba import njit
from wmm_qp_tools.bench.collision import for_each_robot, kernel_arguments_at_tick

from wmm_qp.limits import collision
from wmm_qp.limits._pair_passes import candidates_of
from wmm_qp.limits.dampers import damper_bounds

CALLS = 3000


def _p50_us(fn: Callable[..., Any], *args: Any) -> float:
    fn(*args)
    t = np.empty(CALLS)
    for k in range(CALLS):
        t0 = time.perf_counter_ns()
        fn(*args)
        t[k] = time.perf_counter_ns() - t0
    return float(np.median(t)) / 1e3


def one(name: str, ticks: int) -> str:
    _, a = kernel_arguments_at_tick(f"configs/robots/{name}.toml", ticks)
    rows = collision._rows
    (F, Lf, I, Li, d_i, max_rows, n_v, Jw, support, bj, M, n_w, body_link, n_links, n_obstacles, gain, accel, braking,
     _W, _Wi, n, _velocity_b, v_prev, lb, ub, latency) = a
    d, P, Q, N, body, other, safety = candidates_of(F, Lf, I, Li)
    parts = (d, P, Q, N, body, other, safety, n, d_i, max_rows, n_v, Jw, support, bj, M, n_w, body_link, n_links,
             n_obstacles)
    C, D, DS, _, _, _, keys, _, _ = collision._assemble(*parts)
    m = D.shape[0]
    bounds = (C, v_prev, lb, ub, D, DS, d_i, gain, latency, np.zeros(m), accel, braking, np.zeros(m))
    l = damper_bounds(*bounds)[0]
    names = ", ".join(f"a{i}" for i in range(len(a)))
    scope: dict[str, Any] = {}
    exec(f"def null({names}):\n    return 0\n", scope)  # a function of _rows's arity
    null = njit(scope["null"])
    kept_rows = collision._distinct_rows(C, l, keys).shape[0]
    return (f"{name}: {n} candidates, {m} rows, {kept_rows} kept; p50 µs: _rows {_p50_us(rows, *a):.2f} "
            f"(a call that does nothing with its arguments {_p50_us(null, *a):.2f}), _assemble "
            f"{_p50_us(collision._assemble, *parts):.2f}, damper_bounds {_p50_us(damper_bounds, *bounds):.2f}, "
            f"_distinct_rows {_p50_us(collision._distinct_rows, C, l, keys):.2f}")


if __name__ == "__main__":
    for_each_robot(__doc__, one)
