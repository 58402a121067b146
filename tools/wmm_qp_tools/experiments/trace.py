"""The per-tick record of an experiment's run, the same for both drivers (in process, real time):
the metrics, the CSV log and the plots read it."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from wmm_qp_sim import SimRobot

from wmm_qp.config import FloatArray


@dataclass
class Trace:
    """Per-tick record of a run (arrays with one row per control tick).

    Attributes:
        t: [s] tick times.
        mode: the reference's mode per tick.
        status: the command's status per tick.
        q: [rad] (n, n_arm) true joint angles at the tick (m for a prismatic joint).
        qd_cmd: [rad/s] (n, n_arm) commanded joint rates.
        wheel_cmd: [rad/s] (n, n_wheels) commanded wheel speeds (n_wheels = 0: a fixed base).
        base_twist_cmd: (n, 3) commanded body twist M·wheel_cmd [m/s, m/s, rad/s].
        base_odom, base_true: (n, 3) base poses [m, m, rad].
        ee_des, ee_true: [m] (n, 3) desired and true EE positions.
        dm: H2 along the run's DM direction at the true joint angles.
        tau: [N·m] (n, n_arm) joint torques from contact.
        box_displacement: [m] how far the box has moved (nan without a box).
        stalled_joint: per tick, the joint stalling the push or -1.
        violations: the referee's counts at the end.
        reasons: the controller's reasons (or statuses) that were not "ok", counted by kind.
        phase_starts: per phase name, the row of its first tick (the scenario's phases, in order;
            a phase without a row: the number of rows).
        box_displacement_end: [m] how far the box had moved after the last tick (nan: no box).
        box_tilt_end: [rad] how far the box leaned then (nan: no box, or unknown).
        wall_time: [s] wall-clock time of the run (informative only).
        sim: the sim at the end of the run (in process; None in real time).
    """

    t: FloatArray
    mode: list[str]
    status: list[str]
    q: FloatArray
    qd_cmd: FloatArray
    wheel_cmd: FloatArray
    base_twist_cmd: FloatArray
    base_odom: FloatArray
    base_true: FloatArray
    ee_des: FloatArray
    ee_true: FloatArray
    dm: FloatArray
    tau: FloatArray
    box_displacement: FloatArray
    stalled_joint: np.ndarray
    violations: dict[str, int] = field(default_factory=dict)
    reasons: dict[str, int] = field(default_factory=dict)
    phase_starts: dict[str, int] = field(default_factory=dict)
    box_displacement_end: float = math.nan
    box_tilt_end: float = math.nan
    wall_time: float = 0.0
    sim: SimRobot | None = None

    def at(self, t: float) -> int:
        """Index of the last tick at or before time t [s]."""
        return max(0, int(np.searchsorted(self.t, t + 1e-9)) - 1)

    def start_of(self, phase: str) -> int:
        """The row of ``phase``'s first tick, at most the last row (a phase without a row: the last)."""
        return min(self.phase_starts.get(phase, len(self.t)), len(self.t) - 1)
