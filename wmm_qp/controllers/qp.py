"""The product's controller: the weighted pseudoinverse and the α switch recast as a QP.

Decision variable z = [v_b; v_m; s] (wheel speeds, joint rates, task slack). Every tick:

    minimize    ½ vᵀ W_x⁻¹ v − (W_x⁻¹ v_n)ᵀ v  [+ ½ ρ ‖s‖²]
    subject to  J v + s = ẋ_ref                           task, eq. (5)
                Q_min(q) ≤ v_m ≤ Q_max(q)                  eq. (13)
                wheel speed and acceleration bounds
                x_min ≤ x + Δt·J v ≤ x_max                 EE box (DM_CARTESIAN, eq. (17))

with W_x = diag(α I₄, (1−α) I₇) of eq. (12) (α small: the base is expensive) and
v_n = k_N [0; ∇H2ᵀ] (eq. (19), DM_NULLSPACE only). Without bounds, ½(v − v_n)ᵀW_x⁻¹(v − v_n)
subject to J v = ẋ_ref has the solution J# ẋ_ref + (I − J#J) v_n — eqs. (11), (18) exactly.

Stages (strict priorities, each an exact QP):

1. arm first (TRACK/HOLD, ``qp.arm_first``): the wheels are held at the admissible speed
   nearest 0 and the arm alone must meet J_m v_m = ẋ_ref − J_b P v_b inside (13). If it
   can, that is the command: the base does not move while the arm can do the task. This
   replaces the α switch (14).
2. whole robot, exact task: s ≡ 0 (the task is a hard equality), so the DM term lives only in
   the task's null space and can never change the achieved task velocity.
3. whole robot, slack: when stage 2 is infeasible (the bounds cannot meet the task) the task
   degrades gracefully: ρ = ``qp.slack_weight``. Near a singularity (σ_min(J_m) below the
   threshold) this stage runs directly with ρ = 1/λ², which is exactly the damped least
   squares J#_λ = W_x Jᵀ(J W_x Jᵀ + λ² I)⁻¹.

If every stage fails, the command is a safe stop. Every result is clipped to the box bounds
(a no-op for exact solvers; the guarantee for OSQP's tolerances).
"""

from __future__ import annotations

import numpy as np

from ..config import N_ARM, N_WHEELS, ControllerConfig, FloatArray
from ..model.wmm import WmmModel
from ..pseudoinverse import weight_matrix_diag
from ..solvers import INF, QPBackend, QPProblem, make_backend
from ..types import Command, Mode, Reference, RobotState, Status
from .base import Controller, TickContext

N_V = N_WHEELS + N_ARM


class QpController(Controller):
    """QP controller (DESIGN.md §2).

    Args:
        model: the robot.
        config: gains; ``config.qp`` selects the solver and the weights.

    Raises:
        SolverNotFound: the configured solver cannot be used here (at construction).
    """

    name = "qp"

    def __init__(self, model: WmmModel, config: ControllerConfig) -> None:
        super().__init__(model, config)
        qp = config.qp
        # One backend (workspace) per stage: shapes differ, warm starts stay meaningful.
        self._arm = make_backend(qp.solver, qp.eps_abs)
        self._exact = make_backend(qp.solver, qp.eps_abs)
        self._slack = make_backend(qp.solver, qp.eps_abs)
        w = weight_matrix_diag(qp.alpha)  # eq. (12)
        self._w_inv = 1.0 / w
        self._H_exact = np.diag(self._w_inv)
        self._last_problem: QPProblem | None = None
        self.last_stage = ""

    @property
    def solver(self) -> str:
        return self.config.qp.solver

    @property
    def last_problem(self) -> QPProblem | None:
        """The last QP handed to a backend (for tests and logs)."""
        return self._last_problem

    def reset(self) -> None:
        for b in (self._arm, self._exact, self._slack):
            b.reset()

    # ------------------------------------------------------------------ building
    def box(self, ctx: TickContext) -> tuple[FloatArray, FloatArray]:
        """Hard bounds on v = [v_b; v_m]: wheel bounds and eq. (13)."""
        return np.concatenate([ctx.wheel_lo, ctx.arm_lo]), np.concatenate([ctx.wheel_hi, ctx.arm_hi])

    def ee_box_rows(self, ctx: TickContext, mode: Mode) -> tuple[FloatArray, FloatArray, FloatArray]:
        """C, l, u of the EE box x_min ≤ x + Δt J v ≤ x_max (DM_CARTESIAN only; never further out)."""
        if mode != Mode.DM_CARTESIAN:
            return np.zeros((0, N_V)), np.zeros(0), np.zeros(0)
        lo, hi, x = self.config.ee_box_lower, self.config.ee_box_upper, ctx.kin.x
        rows = np.flatnonzero(np.isfinite(lo) | np.isfinite(hi))
        C = self.dt * ctx.kin.J[rows]
        l = np.minimum(lo[rows], x[rows]) - x[rows]
        u = np.maximum(hi[rows], x[rows]) - x[rows]
        return C, np.maximum(l, -INF), np.minimum(u, INF)

    def linear_term(self, ctx: TickContext, mode: Mode) -> FloatArray:
        """g = −W_x⁻¹ v_n with v_n of eq. (19) in DM_NULLSPACE, else 0."""
        if mode != Mode.DM_NULLSPACE:
            return np.zeros(N_V)
        assert ctx.grad_q is not None
        v_n = self.config.k_N * np.concatenate([np.zeros(N_WHEELS), ctx.grad_q])  # eq. (19)
        return -self._w_inv * v_n

    def build_arm_first(self, ctx: TickContext, xdot: FloatArray) -> tuple[QPProblem, FloatArray]:
        """Stage 1: arm alone, wheels held at the admissible speed nearest 0."""
        w_hold = np.clip(0.0, ctx.wheel_lo, ctx.wheel_hi)
        b = xdot - ctx.kin.J[:, :N_WHEELS] @ w_hold
        p = QPProblem(H=np.eye(N_ARM), g=np.zeros(N_ARM), A=ctx.kin.J_m, b=b,
                      C=np.zeros((0, N_ARM)), l=np.zeros(0), u=np.zeros(0), lb=ctx.arm_lo, ub=ctx.arm_hi)
        return p, w_hold

    def build_exact(self, ctx: TickContext, xdot: FloatArray, mode: Mode) -> QPProblem:
        """Stage 2: whole robot, task as a hard equality."""
        lb, ub = self.box(ctx)
        C, l, u = self.ee_box_rows(ctx, mode)
        return QPProblem(H=self._H_exact, g=self.linear_term(ctx, mode), A=ctx.kin.J, b=xdot,
                         C=C, l=l, u=u, lb=lb, ub=ub)

    def build_slack(self, ctx: TickContext, xdot: FloatArray, mode: Mode) -> QPProblem:
        """Stage 3: whole robot with task slack s (ρ = slack weight, or 1/λ² near singularities)."""
        rho = 1.0 / ctx.damping**2 if ctx.damping > 0.0 else self.config.qp.slack_weight
        lb, ub = self.box(ctx)
        C, l, u = self.ee_box_rows(ctx, mode)
        H = np.zeros((N_V + 3, N_V + 3))
        H[:N_V, :N_V] = self._H_exact
        H[N_V:, N_V:] = rho * np.eye(3)
        return QPProblem(
            H=H, g=np.concatenate([self.linear_term(ctx, mode), np.zeros(3)]),
            A=np.hstack([ctx.kin.J, np.eye(3)]), b=xdot,
            C=np.hstack([C, np.zeros((C.shape[0], 3))]), l=l, u=u,
            lb=np.concatenate([lb, np.full(3, -INF)]), ub=np.concatenate([ub, np.full(3, INF)]))

    # ------------------------------------------------------------------ solving
    def _solve(self, backend: QPBackend, problem: QPProblem, tol: float) -> FloatArray | None:
        self._last_problem = problem
        sol = backend.solve(problem)
        if not sol.ok or sol.z is None:
            return None
        z = np.clip(sol.z, problem.lb, problem.ub)  # hard bounds exactly, whatever the solver's tolerance
        if problem.n_eq and np.max(np.abs(problem.A @ z - problem.b)) > tol:
            return None
        return z

    def _step(self, state: RobotState, reference: Reference) -> Command:
        mode = reference.mode
        ctx = self.context(state, reference, need_gradient=self.needs_gradient(mode))
        xdot = self.task_velocity(ctx, reference)
        alpha = self.config.qp.alpha
        tol = max(1e-7, 100 * self.config.qp.eps_abs)
        if ctx.damping == 0.0:
            if self.config.qp.arm_first and mode in (Mode.TRACK, Mode.HOLD):
                p, w_hold = self.build_arm_first(ctx, xdot)
                z = self._solve(self._arm, p, tol)
                if z is not None:
                    self.last_stage = "arm"
                    return self.finish(ctx, np.concatenate([w_hold, z]), xdot, alpha=0.0)
            z = self._solve(self._exact, self.build_exact(ctx, xdot, mode), tol)
            if z is not None:
                self.last_stage = "exact"
                return self.finish(ctx, z, xdot, alpha=alpha)
        z = self._solve(self._slack, self.build_slack(ctx, xdot, mode), np.inf)
        if z is None:
            self.last_stage = "failed"
            return self.safe_stop(state, f"qp ({self.solver}): no stage could be solved")
        self.last_stage = "slack"
        v = z[:N_V]
        saturated = float(np.linalg.norm(z[N_V:])) > 1e-6
        status = Status.SATURATED if saturated and ctx.damping == 0.0 else Status.OK
        reason = "bounds cut the task (best effort)" if status == Status.SATURATED else ""
        return self.finish(ctx, v, xdot, status=status, reason=reason, alpha=alpha)


def make_qp_controller(model: WmmModel, config: ControllerConfig, solver: str | None = None) -> QpController:
    """A QP controller, optionally with another solver than the config's."""
    if solver is not None:
        config = config.with_(qp={"solver": solver})
    return QpController(model, config)
