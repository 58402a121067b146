"""Directional-manipulability enhancement (paper Sec. IV-C, Fig. 9).

Phase 1, 0–5 s: Cartesian-space DM enhancement (Mode.DM_CARTESIAN, eqs. (16)–(17)), the EE
moves along the Cartesian DM gradient with z kept in [0.36, 0.56] m (the controller config's
EE box). Phase 2, 5–20 s: null-space enhancement (Mode.DM_NULLSPACE, eqs. (18)–(19)) holding
x_d = the EE position at t = 5 s (the controller's own estimate, odometry-based: what a real
controller knows). u = x (base, yaw-compensated frame) or u = z. Any robot: it starts at the
robot's ``arm.start``; with the pose task the null-space phase also holds the EE orientation of
t = 5 s. The EE box is the controller config's (the paper's z ∈ [0.36, 0.56] m by default): on
a robot whose start EE height lies outside it, the Cartesian phase has no active axis and stays
still (``dm_metrics``' ``ee_box_holds_start`` says so). One scenario (:func:`scenario`) for
both drivers: in process (:func:`run_dm`) and in real time.
"""

from __future__ import annotations

from typing import Any

import numpy as np

import wmm_qp
from wmm_qp.config import FloatArray
from wmm_qp_tools.experiments.runner import run
from wmm_qp_tools.experiments.scenario import Anchor, Phase, Scenario, Target
from wmm_qp_tools.experiments.setup import Setup
from wmm_qp_tools.experiments.trace import Trace

CARTESIAN_END = 5.0  # [s]
DEFAULT_DURATION = 20.0  # [s]
DIRECTIONS = {"x": np.array([1.0, 0.0, 0.0]), "z": np.array([0.0, 0.0, 1.0])}
PAPER_DM_FINAL = {"x": 5.88, "z": 4.031}  # the paper's final DM: Fig. 9 (x), its simulation (z)
CARTESIAN, NULLSPACE = "dm_cartesian", "dm_nullspace"  # the phases' names


def cartesian_phase(u: FloatArray, duration: float = CARTESIAN_END) -> Phase:
    """Cartesian-space enhancement along u for ``duration`` [s]: no setpoint, the controller
    moves the EE along the Cartesian DM gradient inside its EE box (eqs. (16)–(17))."""
    return Phase(CARTESIAN, wmm_qp.Mode.DM_CARTESIAN, duration, direction=u)


def _hold(_t: float, start: Anchor) -> Target:
    return Target(start.x, np.zeros(3), start.quat)


def phases(u: FloatArray, duration: float = DEFAULT_DURATION) -> tuple[Phase, Phase]:
    """Both DM phases along u over ``duration`` [s]: Cartesian until :func:`cartesian_end`, then
    the null space holding the EE where the controller estimates it at the switch (with the
    pose task, its orientation too)."""
    t_switch = cartesian_end(duration)
    return (cartesian_phase(u, t_switch),
            Phase(NULLSPACE, wmm_qp.Mode.DM_NULLSPACE, duration - t_switch, direction=u, target=_hold))


def scenario(direction: str = "x", duration: float = DEFAULT_DURATION) -> Scenario:
    """The DM experiment along ``direction`` ("x" or "z")."""
    u = DIRECTIONS[direction]
    return Scenario(f"dm {direction}", phases(u, duration), u)


def run_dm(
    setup: Setup, direction: str = "x", duration: float = DEFAULT_DURATION, progress: bool = True
) -> Trace:
    """Run both DM phases in process (the Cartesian phase is shortened when duration < 10 s)."""
    return run(setup, scenario(direction, duration), progress=progress)


def cartesian_end(duration: float) -> float:
    """[s] end of the Cartesian phase: 5 s, or a quarter of a run shorter than 10 s."""
    return CARTESIAN_END if duration >= 2 * CARTESIAN_END else duration / 4.0


def dm_metrics(trace: Trace, setup: Setup, direction: str) -> dict[str, Any]:
    """Fig. 9 metrics (the JSON keys of ``wmm-qp experiment dm --json``); the switch is the null-space
    phase's first tick.

    - ``dm_start``, ``dm_after_cartesian``, ``dm_final``: H2 along u (true joint angles).
    - ``z_after_cartesian``: [m] true EE height at the end of the Cartesian phase.
    - ``ee_drift_max``: [m] max ‖x_true(t) − x_true(t_5)‖ in the null-space phase (ground truth,
      so base slip counts); ``ee_drift_max_model``: the same from the odometry-based model EE.
    - ``torque_norm_per_10N_*``: [N·m] ‖W J_mᵀ u‖·10 N = 10 / H2.
    - ``ee_box_holds_start``: the start EE position lies inside the controller config's EE box
      on every boxed axis (else the Cartesian phase cannot move, eq. (17)).
    - ``paper_dm_final``, ``t_paper_dm_final``: the paper's final DM along this direction and the
      first tick [s] our DM reaches it (null if never).
    - ``dm_max``: the largest DM of the run; ``dm_final_rate``: [1/s] the DM's mean rate of change
      over the last second (≈ 0: the ascent has settled).
    """
    i5 = trace.start_of(NULLSPACE)
    ns = slice(i5, None)
    drift = np.linalg.norm(trace.ee_true[ns] - trace.ee_true[i5], axis=1)
    m = setup.model
    x_model = np.array(
        [m.ee_position(b, q) for b, q in zip(trace.base_odom[ns], trace.q[ns], strict=True)]
    )
    drift_model = np.linalg.norm(
        x_model - trace.ee_des[i5 + 1] if i5 + 1 < len(trace.t) else x_model, axis=1
    )
    target = PAPER_DM_FINAL.get(direction)
    reached = np.flatnonzero(trace.dm >= target) if target is not None else np.zeros(0, dtype=int)
    i_last = trace.at(float(trace.t[-1]) - 1.0)
    span = float(trace.t[-1] - trace.t[i_last])
    return {
        "direction": direction,
        "dm_start": float(trace.dm[0]),
        "dm_after_cartesian": float(trace.dm[i5]),
        "z_start": float(trace.ee_true[0, 2]),
        "z_after_cartesian": float(trace.ee_true[i5, 2]),
        "dm_final": float(trace.dm[-1]),
        "dm_max": float(trace.dm.max()),
        "dm_final_rate": float(trace.dm[-1] - trace.dm[i_last]) / span if span > 0 else 0.0,
        "paper_dm_final": target,
        "t_paper_dm_final": float(trace.t[reached[0]]) if reached.size else None,
        "ee_drift_max": float(drift.max()) if drift.size else 0.0,
        "ee_drift_max_model": float(drift_model.max()) if drift_model.size else 0.0,
        "base_travel": float(np.linalg.norm(trace.base_true[-1, :2] - trace.base_true[0, :2])),
        "torque_norm_per_10N_start": 10.0 / float(trace.dm[0]),
        "torque_norm_per_10N_final": 10.0 / float(trace.dm[-1]),
        "ee_box_holds_start": _in_box(setup, trace.ee_true[0]),
        "violations": trace.violations,
    }


def _in_box(setup: Setup, x: FloatArray) -> bool:
    lo, hi = np.asarray(setup.ctl_cfg.ee_box_lower), np.asarray(setup.ctl_cfg.ee_box_upper)
    return bool(np.all((lo <= x) & (x <= hi)))
