"""The box push (paper Sec. IV-C, Figs. 7–8): once after DM enhancement, once without.

A 26 kg box with Coulomb friction μ = 0.65 (rubber feet on concrete) stands 1 cm in front of
the EE; the push force needed to slide it is μ m g = 165.8 N along +x (world). The
teleop-like command is a slow (quasi-static) TRACK reference moving x_d forward at 2 cm/s by
0.23 m (1 cm gap + the 0.2 m push + 2 cm the operator keeps pushing); the run ends when the
box has moved 0.2 m or the push phase times out.

Why μ = 0.65: in this quasi-static model the arm can push at most min_i τ_lim,i / |(J_mᵀx̂)_i|
— 154 N at the paper's start configuration (joint 2 limits) and 183 N after the x-direction
DM enhancement (joint 4 limits). 165.8 N lies between: the push is near the arm's limit, as
the paper's was. The paper's torque-sensor figures (weighted norm ≈ 7.5 N·m) imply a smaller
force; a 26 kg box with such a force would move with or without DM in a quasi-static model.

One scenario per run (:func:`scenarios`) for both drivers: in process (:func:`run_push`) and in
real time, each run on a fresh robot.

Any robot: the run starts at the robot's ``arm.start``, the box stands 1 cm ahead of its EE and
reaches at least ``HEADROOM`` above the EE (:func:`box_at`; for the Gen3 that is the sim's
0.6 m box). The mass and μ stay the ones calibrated for the Gen3 above, so on another robot the
run shows whether that arm can push this box, not the paper's claim.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
from wmm_qp_sim import BoxConfig

import wmm_qp
from wmm_qp.config import FloatArray
from wmm_qp_tools.experiments.dm import DIRECTIONS
from wmm_qp_tools.experiments.dm import phases as dm_phases
from wmm_qp_tools.experiments.runner import ObserveFn, run
from wmm_qp_tools.experiments.scenario import Anchor, Phase, Probe, Scenario, Target
from wmm_qp_tools.experiments.setup import Setup
from wmm_qp_tools.experiments.trace import Trace

MASS = 26.0  # [kg]
MU = 0.65  # [-]
GAP = 0.01  # [m] box face ahead of the EE at the push start
TARGET = 0.2  # [m] push distance
OVERSHOOT = 0.02  # [m] the operator keeps pushing a little beyond
PUSH_SPEED = 0.02  # [m/s] quasi-static
DEFAULT_DM_DURATION = 20.0  # [s] DM enhancement before the push (with_dm)
SETTLE = 2.0  # [s] after the reference stops
HEADROOM = 0.1  # [m] the box's top is at least this far above the EE
TIP_MARGIN = 2.0  # [-] the box is this many times deeper than the depth below which it tips (box_at)
PUSH = "push"  # the push phase's name
RUNS = ("with_dm", "without_dm")


def box_at(ee_true: Any, mass: float = MASS) -> BoxConfig:
    """The push's box: its face ``GAP`` ahead of the true EE position, centred on it in y, at
    least ``HEADROOM`` taller than the EE's height (the sim's default box where that suffices),
    and deep enough that the push slides it rather than tips it.

    A box of depth d pushed at height h with the force μ m g that slides it tips about its far
    bottom edge when μ m g h > m g d / 2, i.e. when d < 2 μ h; its depth (= its width, the sims'
    boxes are square) is at least ``TIP_MARGIN`` times that. The quasi-static contact knows only
    the face; a physics box 0.4 m deep pushed at the Gen3's 0.49 m tips (docs/results.md).

    Args:
        ee_true: [m] the true EE position (world) at the push start.
        mass: [kg] the box's mass (the paper's 26 kg by default).
    """
    ee = np.asarray(ee_true, dtype=float)
    height = max(BoxConfig().height, float(ee[2]) + HEADROOM)
    width = max(BoxConfig().width, TIP_MARGIN * 2.0 * MU * float(ee[2]))
    return BoxConfig(mass=mass, mu=MU, face_x=float(ee[0]) + GAP, center_y=float(ee[1]), height=height,
                     width=width)


def push_phase(scale: float = 1.0, mass: float = MASS) -> Phase:
    """The push: the box of ``mass`` [kg] placed ``GAP`` ahead of the true EE (:func:`box_at`),
    then x_d moving from the EE's start position along +x at ``PUSH_SPEED / scale`` by gap +
    target + overshoot and staying there for ``SETTLE * scale`` s; the phase ends when the box
    has moved ``TARGET``."""
    speed = PUSH_SPEED / scale
    t_move = (GAP + TARGET + OVERSHOOT) / speed

    def target(t: float, start: Anchor) -> Target:
        s = min(t, t_move)
        v = speed if t < t_move else 0.0
        return Target(start.x + np.array([speed * s, 0, 0]), np.array([v, 0.0, 0.0]))

    def box(ee_true: FloatArray) -> BoxConfig:
        return box_at(ee_true, mass)

    def moved(_t: float, robot: Probe) -> bool:
        return bool(robot.box_moved() >= TARGET)

    return Phase(PUSH, wmm_qp.Mode.TRACK, t_move + SETTLE * scale, direction=DIRECTIONS["x"], target=target,
                 box=box, done=moved)


def scenarios(dm_duration: float = DEFAULT_DM_DURATION, mass: float = MASS,
              runs: tuple[str, ...] = RUNS) -> dict[str, Scenario]:
    """The push's runs: ``with_dm`` (the DM enhancement along x for ``dm_duration`` [s], then the
    push) and ``without_dm`` (the push from the start configuration); a ``dm_duration`` below
    20 s also speeds the push up in proportion (quasi-static: the forces do not depend on speed)."""
    scale = min(1.0, dm_duration / DEFAULT_DM_DURATION)
    u = DIRECTIONS["x"]
    push = push_phase(scale, mass)
    out = {"with_dm": Scenario("push: with dm", (*dm_phases(u, dm_duration), push), u),
           "without_dm": Scenario("push: without dm", (push,), u)}
    return {name: out[name] for name in runs}


def run_push(
    setup_factory: Callable[[], Setup], dm_duration: float = DEFAULT_DM_DURATION, progress: bool = True,
    mass: float = MASS, runs: tuple[str, ...] = RUNS, observe: dict[str, ObserveFn] | None = None,
) -> dict[str, tuple[Setup, Trace]]:
    """The runs in process, each with a fresh :class:`Setup`. Returns {"with_dm": (setup,
    trace), "without_dm": ...}.

    Args:
        setup_factory: () → a fresh :class:`Setup` (each run gets its own controller).
        dm_duration: [s] DM enhancement before the push (:func:`scenarios`).
        mass: [kg] the box's mass.
        runs: which of the two runs.
        observe: per run, called with the sim after every tick of its push phase.
    """
    out: dict[str, tuple[Setup, Trace]] = {}
    for name, sc in scenarios(dm_duration, mass, runs).items():
        s = setup_factory()
        seen = (observe or {}).get(name)
        out[name] = (s, run(s, sc, progress=progress, observe=None if seen is None else {PUSH: seen}))
    return out


def push_metrics(setup: Setup, trace: Trace) -> dict[str, Any]:
    """Fig. 8 metrics of one run, from its push phase's first tick on (the JSON keys of
    ``wmm-qp experiment push --json``).

    ``max_weighted_torque_norm`` is max_t ‖W τ(t)‖ [N·m] with the W of eq. (8);
    ``saturated_joint`` the 0-based index of the first joint that stalled the push (null if none);
    ``box_tilt_deg`` [deg] how far the box leans at the end (0 unless a physics box tipped; null
    where the robot does not report it, in real time).
    """
    i0 = trace.start_of(PUSH)
    tau = trace.tau[i0:]
    W = np.asarray(setup.W, dtype=float)
    stalled = trace.stalled_joint[i0:]
    first = np.flatnonzero(stalled >= 0)
    distance = float(trace.box_displacement_end)
    return {
        "completed": bool(distance >= TARGET - 1e-9),
        "distance": distance,
        "max_abs_torque": [float(v) for v in np.abs(tau).max(axis=0)],
        "max_weighted_torque_norm": float(np.linalg.norm(tau * W, axis=1).max()),
        "saturated_joint": int(stalled[first[0]]) if first.size else None,
        "stall_ticks": int(first.size),
        "dm_at_push_start": float(trace.dm[i0]),
        "push_force": MU * MASS * 9.81,
        "box_tilt_deg": math.degrees(trace.box_tilt_end) if math.isfinite(trace.box_tilt_end) else None,
        "violations": trace.violations,
    }
