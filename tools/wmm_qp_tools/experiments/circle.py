"""The circle beyond the arm's workspace (paper Sec. IV-B, Table I, Figs. 5–6).

x_d(t) = x0 + [r(cos ωt − 1), r sin ωt, 0], ω = π/20 rad/s, r = 0.25 m (the paper's; any
radius with ``radius``), with its feed-forward velocity, TRACK mode, from the robot's start
configuration (``arm.start``; the Gen3's is the paper's), base slip on. x0 is the EE position
the controller estimates at t = 0 (at rest there, the true one). Any robot: with the pose task
the reference also holds the EE's start orientation (quat_d, ω_d = 0). One scenario
(:func:`scenario`) for both drivers: in process (:func:`run_circle`) and in real time.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

import wmm_qp
from wmm_qp.config import FloatArray
from wmm_qp_tools.experiments.runner import ObserveFn, run
from wmm_qp_tools.experiments.scenario import Anchor, Phase, Scenario, Target
from wmm_qp_tools.experiments.setup import Setup
from wmm_qp_tools.experiments.trace import Trace

RADIUS = 0.25  # [m] the paper's
LARGE_RADIUS = 1.7  # [m] the large circle: ~2.27x the arm-alone largest (the paper: 0.25 vs 0.11 m); results.md §1
OMEGA = math.pi / 20.0  # [rad/s]
DEFAULT_DURATION = 40.0  # [s] one full circle
BASE_MOVING = 1e-4  # [m/s] / [rad/s]: the base counts as moving above this commanded speed
CIRCLE = "circle"  # the scenario's one phase


def circle(x0: FloatArray, t: float, radius: float = RADIUS) -> tuple[FloatArray, FloatArray]:
    """x_d(t) [m] and ẋ_d(t) [m/s] of the circle of ``radius`` [m] through x0."""
    c, s = math.cos(OMEGA * t), math.sin(OMEGA * t)
    x_d = x0 + np.array([radius * (c - 1.0), radius * s, 0.0])
    xd_d = np.array([-radius * OMEGA * s, radius * OMEGA * c, 0.0])
    return x_d, xd_d


def plot_tag(tag: str, radius: float, wheel_units: str = "rad") -> str:
    """The plots' file tag: the controller's, ``_r<cm>`` for another radius than the paper's,
    ``_rim`` for the traditional controller's rim-speed J⁺ (``circle_qp.png`` stays the paper's)."""
    if abs(radius - RADIUS) > 1e-12:
        tag += f"_r{radius * 100:g}"
    return tag + ("_rim" if wheel_units == "rim" else "")


def scenario(direction: FloatArray, duration: float = DEFAULT_DURATION, radius: float = RADIUS) -> Scenario:
    """The circle: one TRACK phase along the circle of ``radius`` [m] through the EE's position
    at its start, with its feed-forward velocity (and, with the pose task, the EE's start
    orientation held); ``direction`` is u of the DM the trace records."""

    def target(t: float, start: Anchor) -> Target:
        x_d, xd_d = circle(start.x, t, radius)
        return Target(x_d, xd_d, start.quat)

    return Scenario(CIRCLE, (Phase(CIRCLE, wmm_qp.Mode.TRACK, duration, target=target),), direction)


def run_circle(
    setup: Setup, duration: float = DEFAULT_DURATION, progress: bool = True, radius: float = RADIUS,
    observe: ObserveFn | None = None,
) -> Trace:
    """Run the circle of ``radius`` [m] in process and return its trace (``observe``: called
    with the sim after every tick)."""
    sc = scenario(np.asarray(setup.ctl_cfg.direction, dtype=float), duration, radius)
    return run(setup, sc, progress=progress, observe=None if observe is None else {CIRCLE: observe})


def circle_metrics(trace: Trace) -> dict[str, Any]:
    """Table I and Figs. 5–6 metrics (the JSON keys of ``wmm-qp experiment circle --json``).

    - ``base_velocity``: max |·| and RMS of the commanded body twist (vx, vy [m/s], wz [rad/s]).
    - ``ee_error_max``: max |x_d − x_true| in x and y [m] (ground truth EE).
    - ``base_motion_window``: first and last tick [s] the commanded base twist exceeds
      1e-4 (null if the base never moves).
    - ``base_error_integral``: ∫ |e_b| dt over that window [m·s], e_b = true − odometry base
      position (the base's own tracking error, what slip costs).
    """
    tw = trace.base_twist_cmd
    err = np.abs(trace.ee_des - trace.ee_true)
    moving = np.flatnonzero(np.abs(tw).max(axis=1) > BASE_MOVING)
    e_b = np.abs(trace.base_true[:, :2] - trace.base_odom[:, :2])
    dt = float(trace.t[1] - trace.t[0]) if len(trace.t) > 1 else 0.0
    if moving.size:
        i0, i1 = int(moving[0]), int(moving[-1])
        window: list[float] | None = [float(trace.t[i0]), float(trace.t[i1])]
        integral = e_b[i0 : i1 + 1].sum(axis=0) * dt
    else:
        window, integral = None, np.zeros(2)
    return {
        "base_velocity": {
            name: {"max": float(np.abs(tw[:, i]).max()), "rms": rms(tw[:, i])}
            for i, name in enumerate(("vx", "vy", "wz"))
        },
        "ee_error_max": {
            "x": float(err[:, 0].max()),
            "y": float(err[:, 1].max()),
            "z": float(err[:, 2].max()),
        },
        "ee_error_rms": {"x": rms(err[:, 0]), "y": rms(err[:, 1])},
        "base_motion_window": window,
        "base_error_integral": {"x": float(integral[0]), "y": float(integral[1])},
        "violations": trace.violations,
    }


def rms(a: FloatArray) -> float:
    """Root mean square (0 for an empty array)."""
    return float(np.sqrt(np.mean(np.square(a)))) if a.size else 0.0
