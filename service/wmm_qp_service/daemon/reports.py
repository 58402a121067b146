"""What the daemon tells its clients: the status message, the ``info`` reply and the running
configuration, built from the control core's state (read only; never on the command's path)."""

from __future__ import annotations

import math
import time
from collections import Counter
from dataclasses import asdict
from typing import TYPE_CHECKING, Any

import numpy as np

import wmm_qp as w
from wmm_qp.tasks import orientation_error as log_rotation_error
from wmm_qp.tasks import quat_to_matrix

from ..protocol import InfoMsg, StatusMsg
from ..rate_loop import LoopTiming

if TYPE_CHECKING:
    from .core import ControlCore

NAN3 = [math.nan] * 3


def target(ref: w.Reference) -> list[float]:
    """The reference's target for messages (NaN when it means "where the EE is")."""
    return list(NAN3) if ref.x_d is None else ref.x_d.tolist()


def orientation_error(core: ControlCore) -> float:
    """[rad] the angle between the EE's orientation (the last state; model, odometry) and the
    orientation target (``quat_d``); NaN with the position task or before a state."""
    if not core.pose or core.state is None:
        return math.nan
    _, R = core.model.ee_pose(core.state.q_base, core.state.q_arm)
    return float(np.linalg.norm(log_rotation_error(quat_to_matrix(core.orient.quat), R)))  # ‖log(R_d Rᵀ)‖


def ee_now(core: ControlCore) -> list[float]:
    """[m] the EE position of the last command, or — when it has none (a safe stop's) — of
    the last state (model, odometry); [] before any state. Never NaN: clients start
    streams from it."""
    cmd = core.cmd
    if cmd is not None and np.isfinite(cmd.x).all():
        return cmd.x.tolist()
    st = core.state
    if st is None:
        return []
    x = core.model.ee_position(st.q_base, st.q_arm)
    return x.tolist() if np.isfinite(x).all() else []


def status(core: ControlCore, loop: LoopTiming, rejected: Counter[str], accepted: dict[str, int]) -> StatusMsg:
    """The status message (``<robot>/status``)."""
    cmd = core.cmd
    rows = core.ctl.last_collision_rows()
    faults, sp, obstacles = core.fault_record, core.setpoints, core.obstacles
    return StatusMsg(
        robot=core.svc.robot, stamp=time.time(), mode=core.mode.value,
        state_ok=core.state is not None and not core.safe, safe_stop=core.safe,
        controller_status=cmd.status.value if cmd else "", reason=cmd.reason if cmd else "",
        last_fault=faults.last, last_fault_code=faults.last_code, fault_active=core.fault_active,
        last_fault_age=core.now - faults.last_time if math.isfinite(faults.last_time) else math.nan,
        loop=loop.stats(), rejected=dict(rejected),
        accepted=accepted,
        robot_violations=dict(core.truth.violations) if core.truth is not None else {},
        x=ee_now(core), x_d=target(core.ref),
        dm=float(cmd.dm) if cmd is not None else math.nan, robot_alive=core.robot_alive,
        faults=dict(faults.counts), lease=core.lease, lease_holder=core.lease_holder,
        robot_instance=core.gate.instance, operator=sp.operator,
        operator_conflicts=sp.operator_conflicts, resume_needed=core.resume_needed,
        round_trip_ms=core.stream.round_trip * 1e3, protective_stop=bool(core.protective),
        quat_d=core.orient.quat.tolist() if core.pose else [],
        orientation_error=orientation_error(core),
        orientation_ignored=sp.orientation_ignored, clamped=sp.clamped, last_clamp=sp.last_clamp,
        obstacles=len(core.scene.obstacles) + len(obstacles.shapes),
        obstacles_live=len(obstacles.shapes), obstacles_stale=obstacles.stale,
        collision_distance=rows.min_distance if rows is not None and math.isfinite(rows.min_distance) else math.nan,
        collision_pair=rows.closest if rows is not None else "",
        collision=core.ctl.collision_on, collision_summary=core.ctl.collision_summary())


def config_dict(core: ControlCore) -> dict[str, Any]:
    """The running configuration as plain data (for the ``info`` queryable)."""
    c, r = core.cfg, core.robot
    t = c.task
    return {
        "service": plain(asdict(core.svc)),
        "controller": {"kind": core.kind, "rate_hz": c.rate_hz, "K_x": c.K_x, "alpha": c.alpha,
                       "k_C": c.k_C, "k_N": c.k_N, "W": c.weights_for(r).tolist(),
                       "direction": c.direction.tolist(), "solver": c.qp.solver,
                       "task": {"kind": t.kind, "r": t.r, "K_R": t.K_R,
                                "orientation_weight": t.orientation_weight,
                                "angular_speed_max": t.angular_speed_max,
                                "angular_recovery_speed": t.angular_recovery_speed}},
        "robot": {"name": r.name, "file": str(r.path) if r.path is not None else "",
                  "ee_frame": r.arm.ee_frame, "joint_types": list(r.arm.joint_types),
                  "start": r.arm.start.tolist()},
    }


def info(core: ControlCore, loop: LoopTiming, rejected: Counter[str], accepted: dict[str, int]) -> InfoMsg:
    """The ``info`` reply: status, the robot description's names and sizes, the configuration."""
    return InfoMsg(robot=core.svc.robot, stamp=time.time(), status=status(core, loop, rejected, accepted),
                   config=config_dict(core), joints=list(core.robot.arm.joints),
                   wheels=list(core.model.base.wheel_names), base_kind=core.model.base.kind,
                   task=core.cfg.task.kind, n_arm=core.model.n_arm, n_wheels=core.model.n_wheels,
                   collision=core.ctl.collision_on, collision_summary=core.ctl.collision_summary())


def plain(d: Any) -> Any:
    """``d`` as plain data for a message: non-finite floats and other objects as strings."""
    if isinstance(d, dict):
        return {k: plain(v) for k, v in d.items()}
    if isinstance(d, float) and not math.isfinite(d):
        return str(d)
    if isinstance(d, int | float | str | bool) or d is None:
        return d
    return str(d)
