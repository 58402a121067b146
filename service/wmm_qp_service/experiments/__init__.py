"""The paper's experiments, reproduced in simulation: circle, DM enhancement, box push.

Each runs on any robot description (``make_setup(..., robot=...)``; the default is the Gen3,
whose runs are the paper's tables).

One module per experiment, a shared in-process runner (:mod:`.runner`), the per-tick CSV log
(:mod:`.log`) and plots (:mod:`.plots`). ``wmm-qp experiment`` drives them.
"""

from .circle import circle_metrics, run_circle
from .dm import dm_metrics, run_dm
from .log import columns, write_csv
from .push import push_metrics, run_push
from .runner import Setup, Trace, make_setup, run

__all__ = [
    "Setup",
    "Trace",
    "circle_metrics",
    "columns",
    "dm_metrics",
    "make_setup",
    "push_metrics",
    "run",
    "run_circle",
    "run_dm",
    "run_push",
    "write_csv",
]
