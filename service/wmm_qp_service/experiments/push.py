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

Any robot: the run starts at the robot's ``arm.start``, the box stands 1 cm ahead of its EE and
reaches at least ``HEADROOM`` above the EE (:func:`box_at`; for the Gen3 that is the sim's
0.6 m box). The mass and μ stay the ones calibrated for the Gen3 above, so on another robot the
run shows whether that arm can push this box, not the paper's claim.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from wmm_qp_sim import BoxConfig

import wmm_qp

from .dm import DIRECTIONS, cartesian_end, dm_reference
from .runner import ObserveFn, Setup, Trace, concat, run

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


def _push_phase(setup: Setup, trace0: Trace | None, scale: float, progress: str | None,
                mass: float = MASS, observe: ObserveFn | None = None) -> Trace:
    m = setup.model
    sim = trace0.sim if trace0 is not None else None
    if sim is None:
        from wmm_qp_sim import SimRobot

        sim = SimRobot(m, setup.sim_cfg, seed=setup.seed, scene=setup.scene)
        sim.reset()
    st = sim.state()
    x_start = m.ee_position(st.base_odom, st.q_arm)
    sim.place_box(box_at(st.ee_true, mass))
    # the box is an obstacle for every body but the EE's (the sim's referee checks it too)
    set_obstacles = getattr(setup.controller, "set_obstacles", None)
    scene_obstacles = setup.scene.obstacles if setup.scene is not None else ()
    placed = [math.nan, 0.0]  # face x [m], tilt [rad] the controller last saw

    def box_obstacle() -> None:
        if set_obstacles is not None and sim.box is not None and (
                abs(sim.box.face_x - placed[0]) > 1e-3 or abs(sim.box.tilt - placed[1]) > 1e-3):
            placed[:] = [sim.box.face_x, sim.box.tilt]
            box = sim.box_obstacle()
            set_obstacles(scene_obstacles + ((box,) if box is not None else ()))

    box_obstacle()
    distance = GAP + TARGET + OVERSHOOT
    speed = PUSH_SPEED / scale
    t_move = distance / speed
    duration = t_move + SETTLE * scale

    def reference(t: float, _st: Any, _cmd: Any) -> wmm_qp.Reference:
        box_obstacle()  # where the box is now
        s = min(t, t_move)
        v = speed if t < t_move else 0.0
        return wmm_qp.Reference(
            mode=wmm_qp.Mode.TRACK,
            x_d=x_start + np.array([speed * s, 0, 0]),
            xd_d=np.array([v, 0.0, 0.0]),
            direction=DIRECTIONS["x"],
        )

    def stop(_t: float, st: Any) -> bool:
        return bool(st.box_displacement >= TARGET)

    tr = run(
        setup,
        reference,
        duration,
        dm_direction=DIRECTIONS["x"],
        stop=stop,
        progress=progress,
        sim=sim,
        previous=trace0.last_command if trace0 is not None else None,
        observe=observe,
    )
    return tr if trace0 is None else concat(trace0, tr)


def run_push(
    setup_factory: Any, dm_duration: float = DEFAULT_DM_DURATION, progress: bool = True,
    mass: float = MASS, runs: tuple[str, ...] = ("with_dm", "without_dm"),
    observe: dict[str, ObserveFn] | None = None,
) -> dict[str, tuple[Setup, Trace, int]]:
    """Both runs. Returns {"with_dm": (setup, trace, push_start_index), "without_dm": ...}.

    Args:
        setup_factory: () → a fresh :class:`Setup` (each run gets its own controller).
        dm_duration: [s] DM enhancement before the push; a value below 20 s also speeds the
            push up in proportion (quasi-static: the forces do not depend on speed).
        mass: [kg] the box's mass.
        runs: which of the two runs.
        observe: per run, called with the sim after every tick of its push phase.
    """
    scale = min(1.0, dm_duration / DEFAULT_DM_DURATION)
    out: dict[str, tuple[Setup, Trace, int]] = {}
    if "with_dm" in runs:
        s = setup_factory()
        u = DIRECTIONS["x"]
        pre = run(
            s,
            dm_reference(s.model, u, cartesian_end(dm_duration), pose=s.controller.pose),
            dm_duration,
            dm_direction=u,
            progress="push: dm" if progress else None,
        )
        tr = _push_phase(s, pre, scale, "push: with dm" if progress else None, mass,
                         (observe or {}).get("with_dm"))
        out["with_dm"] = (s, tr, len(pre.t))
    if "without_dm" in runs:
        s = setup_factory()
        tr = _push_phase(s, None, scale, "push: without dm" if progress else None, mass,
                         (observe or {}).get("without_dm"))
        out["without_dm"] = (s, tr, 0)
    return out


def push_metrics(setup: Setup, trace: Trace, i0: int) -> dict[str, Any]:
    """Fig. 8 metrics of one run (JSON keys of issue 5).

    ``max_weighted_torque_norm`` is max_t ‖W τ(t)‖ [N·m] with the W of eq. (8);
    ``saturated_joint`` the 0-based index of the first joint that stalled the push (null if none);
    ``box_tilt_deg`` [deg] how far the box leans at the end (0 unless a physics box tipped).
    """
    tau = trace.tau[i0:]
    W = np.asarray(setup.W, dtype=float)
    stalled = trace.stalled_joint[i0:]
    first = np.flatnonzero(stalled >= 0)
    distance = float(trace.sim.state().box_displacement) if trace.sim is not None else float("nan")
    return {
        "completed": bool(distance >= TARGET - 1e-9),
        "distance": distance,
        "max_abs_torque": [float(v) for v in np.abs(tau).max(axis=0)],
        "max_weighted_torque_norm": float(np.linalg.norm(tau * W, axis=1).max()),
        "saturated_joint": int(stalled[first[0]]) if first.size else None,
        "stall_ticks": int(first.size),
        "dm_at_push_start": float(trace.dm[i0]),
        "push_force": MU * MASS * 9.81,
        "box_tilt_deg": math.degrees(trace.sim.box.tilt) if trace.sim is not None and trace.sim.box else 0.0,
        "violations": trace.violations,
    }
