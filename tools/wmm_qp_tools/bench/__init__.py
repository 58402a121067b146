"""Performance benchmarks behind ``wmm-qp bench`` (docs/benchmarks.md): one module per section.

* :mod:`.controller` — per-tick controller time per solver and mode, with a breakdown;
* :mod:`.oneshot` — qpsolvers' one-shot API versus our persistent workspaces;
* :mod:`.pink_race` — the same robot and trajectory through pink's ``solve_ik``;
* :mod:`.scaling` — per-tick cost against the number of arm joints;
* :mod:`.e2e` — daemon + sim over Zenoh (achieved rate, latency, deadline misses);
* :mod:`.machine` — what the figures were measured on.
"""

from wmm_qp_tools.bench.runner import SECTIONS, run_bench

__all__ = ["SECTIONS", "run_bench"]
