"""The paper's experiments, reproduced in simulation: circle, DM enhancement, box push.

Each runs on any robot description (``make_setup(..., robot=...)``; the default is the Gen3,
whose runs are the paper's tables).

One module per experiment, each defining its scenario once (:mod:`.scenario`: its phases, their
references, a box to place) and its metrics; two drivers run a scenario and record the same
per-tick :class:`Trace` (:mod:`.trace`): in process (:mod:`.runner`, deterministic) and in real
time through the daemon and the sim over Zenoh (:mod:`.realtime`, :mod:`.stack`,
:mod:`.recorder`). The per-tick CSV log (:mod:`.log`) and plots (:mod:`.plots`) read the trace.
``wmm-qp experiment`` drives them.
"""

from wmm_qp_tools.experiments.circle import circle_metrics, run_circle
from wmm_qp_tools.experiments.dm import dm_metrics, run_dm
from wmm_qp_tools.experiments.log import columns, write_csv
from wmm_qp_tools.experiments.push import push_metrics, run_push
from wmm_qp_tools.experiments.runner import run
from wmm_qp_tools.experiments.scenario import Anchor, Phase, Probe, Scenario, Target
from wmm_qp_tools.experiments.setup import Setup, make_setup
from wmm_qp_tools.experiments.trace import Trace

__all__ = [
    "Anchor",
    "Phase",
    "Probe",
    "Scenario",
    "Setup",
    "Target",
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
