"""The product's controller: the weighted pseudoinverse and the α switch recast as a QP (docs/model.md "The QP").

Every tick, every row source (``limits/``: the EE box of eq. (17), the collision dampers, the
fence, the σ_min floor) gives its rows for the tick, and the stages run:

1. arm first (TRACK/HOLD, ``qp.arm_first``): the wheels held at the admissible speed nearest 0,
   the arm alone tries to meet the task inside (13). If its slack is 0, that is the command: the
   base does not move while the arm can do the task. This replaces the α switch (14).
2. whole robot: the QP of :mod:`.stages` (the problems), solved by :mod:`.cascade`.

Priority: the task, then the rows that yield to it (the σ_min floor in DM_NULLSPACE: a stage whose
task it cuts, or that no solver solves with it, is solved again without it), then the DM and
return terms. Every row yields to bounds (13); should the rows together leave a stage without a
solution, it is solved again with them relaxed further (the dampers together, to their joint
command; the others to admit it), and should no solver solve that either, the joint command itself
is commanded (it meets every row and bound by construction). Only when nothing solves a stage is
the command a safe stop.

Whatever solved a stage, the command is re-checked on the re-checked rows (the EE box, the
dampers: every backend meets them only to its primal tolerance, DAQP's and OSQP's ~1e-6 m per tick
on the EE box's, proxsuite's ~2e-8 m) and projected back onto any it leaves
(``_hold_ee_box``, inside the box bounds; status SATURATED with the reason).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..._typing import FloatArray
from ...config import ControllerConfig, ShapeConfig
from ...limits.collision import CollisionRows, warm_up_obstacles
from ...limits.ee_box import EeBox
from ...limits.fence import FenceRows
from ...limits.rows import Rows, RowSource, Tick
from ...limits.singularity_floor import SigmaMinFloor
from ...model.collision import robot_geometry
from ...model.wmm import WmmModel
from ...scene import Scene
from ...types import Command, Mode, Reference, RobotState, Status
from ..base import TickContext
from .cascade import SLACK_ACCEPT, SolveCascade
from .kernels import EE_BOX_TOL, NO_REF, _hold_ee_box, task_residual
from .stage_rows import StageRows
from .stages import QpStages

TASK_CUT = 1e-6  # [m/s] a stage's max |J v − ẋ_ref| above this: the task was cut (status saturated)


class QpController(QpStages, SolveCascade):
    """QP controller (docs/model.md "The QP").

    Args:
        model: the robot.
        config: gains; ``config.qp`` selects the solver and the weights, ``config.collision`` the
            dampers (on unless ``enabled = false``).

    Raises:
        SolverNotFound: the configured solver cannot be used here (at construction).
    """

    name = "qp"

    def __init__(self, model: WmmModel, config: ControllerConfig) -> None:
        super().__init__(model, config)
        self.ee_box_corrections = 0  # commands the re-check had to pull back onto their rows
        self.braking_stages = 0  # stages every solver failed on, commanded the joint command that meets their rows
        self.joint_relaxations = 0  # stages whose dampers were infeasible together, relaxed together
        self.floor_dropped = 0  # stages re-solved without rows that yield to the task: they cut it
        self.last_stage = ""
        self.collision: CollisionRows | None = None  # the collision dampers (limits/collision.py)
        self.fence: FenceRows | None = None  # the scene's fence (limits/fence.py)
        self.row_sources: list[RowSource] = [EeBox(config.ee_box_lower, config.ee_box_upper, self.dt)]
        """Every source of rows, in the order of the stages' rows."""
        if config.collision.enabled:
            geometry = robot_geometry(self.robot, model.arm)
            self.collision = CollisionRows(geometry, model.base.M, config.collision, config.state_latency,
                                           self.bounds.a_max, self.dt)
            self.fence = FenceRows(model.base.M, self.n_arm, self.collision.p, config.state_latency,
                                   self.bounds.a_max)
            self.row_sources += [self.collision, self.fence]
        self.row_sources.append(SigmaMinFloor(config.sigma_min_floor, config.state_latency))
        self.last_rows: Rows | None = None  # the dampers' rows of the last tick
        self._no_rows = StageRows([], self.n_v)  # a tick without rows (read only, shared)

    def warm_up(self, q_arm: FloatArray | None = None) -> None:
        """:meth:`Controller.warm_up`, then, with collision rows, every mode once more among
        :func:`~wmm_qp.limits.collision.warm_up_obstacles` around the EE: the obstacles' kernels
        (boxes, planes, moving obstacles) load now, not in the tick an obstacle first comes near
        (a first compilation there takes seconds). The obstacles in force are restored."""
        super().warm_up(q_arm)
        if self.collision is None:
            return
        q = self.warm_up_configuration(q_arm)
        kept = self.collision.shapes
        self.collision.set_obstacles(warm_up_obstacles(self.model.ee_position(np.zeros(3), q)))
        try:
            state = RobotState(q_base=np.zeros(3), q_arm=q)
            for mode in Mode:  # a safe stop among the obstacles is no failure here: the kernels ran
                self.step(state, Reference(mode))
            ones = np.ones(self.n_v)  # the retry's kernel (rows relaxed together), which these may not reach
            Rows(np.zeros((1, self.n_v)), np.zeros(1), damper=np.zeros(1)).relax_together(-ones, ones)
        finally:
            self.collision.set_obstacles(kept)
        self.reset()
        self.clear_statistics()

    def reset(self) -> None:
        """Every warm start forgotten: the solvers' (:meth:`SolveCascade.reset`) and GJK's."""
        super().reset()
        if self.collision is not None:
            self.collision.search.reset()

    def clear_statistics(self) -> None:
        self.ee_box_corrections = self.braking_stages = self.floor_dropped = 0
        super().clear_statistics()

    # ------------------------------------------------------------------ declared capabilities
    def set_scene(self, scene: Scene) -> None:
        """The obstacles and the fence the collision rows keep the robot away from / inside."""
        if self.collision is not None and self.fence is not None:
            self.collision.set_obstacles(scene.obstacles)
            self.fence.set_fence(scene.fence)

    def set_obstacles(self, obstacles: Sequence[ShapeConfig]) -> None:
        """Replace the obstacle set (live obstacles; the fence stays)."""
        if self.collision is not None:
            self.collision.set_obstacles(list(obstacles))

    def set_latency(self, latency: float) -> None:
        """[s] the margin of bounds (13) and of the collision and fence rows, which share it."""
        super().set_latency(latency)
        if self.collision is not None and self.fence is not None:
            self.collision.latency = self.fence.latency = latency

    @property
    def collision_on(self) -> bool:
        return self.collision is not None

    def collision_summary(self) -> str:
        if self.collision is None or self.fence is None:
            return "no collision rows"
        geo = self.collision.geo
        pairs = (f"{len(geo.row_pairs)} self pairs" if geo.bodies
                 else "no self pairs — this robot file has no [collision] shapes")
        inside = sum(c >= 0 for c in geo.covered_by)
        within = (f"; {len(geo.covered_pairs)} more of {inside} bodies inside another of their link, near d_s only"
                  if inside else "")
        return (f"collision rows on ({pairs}, {len(geo.floor_bodies)} bodies vs the floor, "
                f"{len(self.collision.obstacles)} obstacles, {'fence' if self.fence.fenced else 'no fence'}{within})")

    def last_collision_rows(self) -> Rows | None:
        return self.last_rows

    # ------------------------------------------------------------------ the tick
    def stage_rows(self, ctx: TickContext, mode: Mode) -> StageRows:
        """Every source's rows this tick, stacked (the dampers pooled: ``last_rows``)."""
        tick = Tick(mode, ctx.kin, ctx.v_prev, ctx.lo, ctx.hi)  # centred on the daemon's last command
        parts = [(s, r) for s in self.row_sources if (r := s.compute_rows(tick)) is not None]
        rows = StageRows(parts, self.n_v) if parts else self._no_rows  # most ticks of a free robot: none
        self.last_rows = rows.dampers
        return rows

    def _step(self, state: RobotState, reference: Reference) -> Command:
        mode = reference.mode
        ctx = self.context(state, reference, need_gradient=self.needs_gradient(mode))
        xdot = self.reference_velocity(ctx, reference)
        rows = self.stage_rows(ctx, mode)
        if self.config.qp.arm_first and mode in (Mode.TRACK, Mode.HOLD):
            p, w_hold = self.build_arm_first(ctx, xdot, rows)
            z = self._solve(self._arm, p)
            if z is not None and p.n_in:  # the re-checked rows, whatever solved
                C, lo, hi = self._rechecked(rows, p.C, p.l, p.u)
                _hold_ee_box(C, lo, hi, p.lb, p.ub, z, self.n_arm, NO_REF)
            if z is not None and (self._closed_form_hit or task_residual(p, z) <= SLACK_ACCEPT):
                self.last_stage = "arm"
                return self.finish(ctx, np.concatenate([w_hold, z[: self.n_arm]]), xdot, alpha=0.0)
        problem = self.build(ctx, xdot, mode, rows)
        z = self._solve(self._full, problem)
        loose_rows = rows.without_yielding(mode)
        task_cut = z is None or (not self._closed_form_hit and task_residual(problem, z) > TASK_CUT)
        if loose_rows is not None and task_cut:
            # the task before the rows that yield to it: where they cut the task (or leave the stage
            # without a solution: a row the bounds can barely meet pins v to a vertex of them) and the
            # stage without them meets the task, that one is the command
            loose = self.build(ctx, xdot, mode, loose_rows)
            z_loose = self._solve(self._full, loose)
            if z_loose is not None and (self._closed_form_hit or task_residual(loose, z_loose) <= TASK_CUT):
                self.floor_dropped += 1
                rows, problem, z = loose_rows, loose, z_loose
            else:  # the bounds cut the task anyway: the stage with every row stands
                self._last_problem, self._closed_form_hit = problem, False
        ref = NO_REF  # v₀ = clip(0, lb, ub), the braking command: the rows admit it unless relaxed together
        if z is None and rows.relaxable:  # the rows together infeasible: relax them further
            ref = rows.relax_together(ctx.lo, ctx.hi)
            self.joint_relaxations += int(ref.shape[0] > 0)
            problem = self.build(ctx, xdot, mode, rows, brake=True)
            z = self._solve(self._full, problem)
            if z is None and problem.g[: self.n_v].any():  # still failing: without the DM and return terms
                problem.g[: self.n_v] = 0.0
                z = self._solve(self._full, problem)
        if z is None and rows.relaxable:
            # every solver read the relaxed stage as infeasible: its rows all pass within 1e-9 m/s of
            # the command they were relaxed to, at a vertex of the box, degenerate for an active-set
            # solver (the UR5 at its position limits, docs/results.md); that command meets every row
            if not ref.shape[0]:
                ref = np.clip(0.0, ctx.lo, ctx.hi)
            e = problem.C[:, : self.n_v] @ ref
            if bool(((e >= problem.l - EE_BOX_TOL) & (e <= problem.u + EE_BOX_TOL)).all()):
                self.last_stage = "brake"
                self.braking_stages += 1
                why = f"the rows' joint command (qp ({self.solver}): no solution of the stage that admits it)"
                return self.finish(ctx, ref, xdot, status=Status.SATURATED, reason=f"{rows.cut_reason(ref)}: {why}")
        if z is None:
            self.last_stage = "failed"
            return self.safe_stop(state, f"qp ({self.solver}): the solver failed")
        self.last_stage = "full"
        status, reason = Status.OK, ""
        if problem.n_in:  # the re-checked rows (the EE box, the dampers), whatever solved the stage
            C, lo, hi = self._rechecked(rows, problem.C, problem.l, problem.u)
            e = C[:, : self.n_v] @ z[: self.n_v]
            left = np.flatnonzero((e > hi + EE_BOX_TOL) | (e < lo - EE_BOX_TOL))
            out = _hold_ee_box(C, lo, hi, problem.lb, problem.ub, z, self.n_v, ref) if C.shape[0] else 0.0
            if out > 0.0:
                self.ee_box_corrections += 1
                status = Status.SATURATED
                what = rows.recheck_label(int(left[0]) if left.size else 0)
                reason = f"{what}: the solution left it by {out / self.dt:.3g} m/s; projected back onto it"
        if not self._closed_form_hit and task_residual(problem, z) > TASK_CUT:  # the task cut: by which rows first
            cut = rows.cut_reason(z[: self.n_v])
            status, reason = Status.SATURATED, f"{cut}; {reason}" if reason else cut
        alpha = self.config.qp.dm_alpha if mode == Mode.DM_NULLSPACE else self.config.qp.alpha
        return self.finish(ctx, z[: self.n_v], xdot, status=status, reason=reason, alpha=alpha)

    @staticmethod
    def _rechecked(rows: StageRows, C: FloatArray, l: FloatArray,
                   u: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """The re-checked rows of a stage's (C, l, u)."""
        mask = rows.rechecked()
        return (C, l, u) if mask is None else (C[mask], l[mask], u[mask])
