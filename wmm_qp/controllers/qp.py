"""The product's controller: the weighted pseudoinverse and the α switch recast as a QP.

Decision variable z = [v_b; v_m; s⁺; s⁻] (wheel speeds, joint rates, task slack s = s⁺ − s⁻).
Every tick:

    minimize    ½ vᵀ W_x⁻¹ v − (W_x⁻¹ v_n)ᵀ v + ρ₁ 1ᵀ(s⁺ + s⁻) + ½ ρ₂ (‖s⁺‖² + ‖s⁻‖²)
    subject to  J v + s⁺ − s⁻ = ẋ_ref                      task, eq. (5)
                Q_min(q) ≤ v_m ≤ Q_max(q)                    eq. (13)
                wheel speed and acceleration bounds, s± ≥ 0
                x_min ≤ x + Δt·J v ≤ x_max                   EE box (DM_CARTESIAN, eq. (17))

W_x = diag(α I₄, (1−α) I₇) is eq. (12) (α = ``qp.alpha`` small: the base is expensive; in
DM_NULLSPACE α = ``qp.dm_alpha``, close to 1, so the base serves the DM objective) and
v_n = k_N [0; ∇H2ᵀ] is eq. (19), in DM_NULLSPACE only. With s ≡ 0 and no bound active,
½(v − v_n)ᵀW_x⁻¹(v − v_n) subject to J v = ẋ_ref is solved by J# ẋ_ref + (I − J#J) v_n:
eqs. (11) and (18) exactly.

The slack carries an exact penalty ρ₁‖s‖₁: when ρ₁ exceeds the task constraint's Lagrange
multiplier, the optimum has s = 0 exactly whenever the bounds admit the task — then the task
is a hard equality, the DM term lives in the task's null space only and cannot change the
achieved task velocity (strict priority, in one solve while ρ₁ suffices; see below for when it
does not). When the bounds cannot meet the task, the task degrades gracefully instead of the
solve failing: every stage is always feasible, so no solver has to detect infeasibility.

Damping near singularities. The paper's controller replaces J# by damped least squares on the
whole J when σ_min(J_m) < threshold. On a WMM that is the wrong thing to damp: the whole J is
rarely singular (the base spans x, y), and damping the task lets the EE lag while the base
could have moved it (a wheel speed moves the EE by only ~R/4 per rad/s, so λ² swamps the
base's share). The QP instead damps the *arm*: below the threshold the arm's cost is
multiplied by 1 + κ·(λ/λ_max)² (κ = ``qp.singular_arm_weight``, λ from the same variable-
damping law), so arm motion grows expensive as the arm approaches its singularity and the
base takes over, the task still met. The joint velocity bounds (13) already rule out
the unbounded joint rates DLS exists to prevent. (The arm-first stage is unaffected: scaling
every arm joint's cost alike does not change its optimum.)

The penalty alone is exact only while ρ₁ exceeds the task's multiplier, which near a
singularity or with a large DM gradient (∝ H2³) it may not. So whenever a stage leaves slack,
(judged on |J v − ẋ_ref| itself), it is solved again with s ≡ 0 by DAQP (exact infeasibility
detection): if the task is feasible that optimum is used (strict priority: task, then cost);
if not, the penalised best effort.

Stages:

1. arm first (TRACK/HOLD, ``qp.arm_first``): the wheels are held at
   the admissible speed nearest 0 and the arm alone tries to meet the task inside (13). If its
   slack is 0, that is the command: the base does not move while the arm can do the task.
   This replaces the α switch (14).
2. whole robot: the QP above.

Each stage first tries the closed-form optimum (no bound active, zero slack), taken only when
it meets every KKT condition (``qp.closed_form_first``); otherwise the solver runs.
A stage the configured solver fails on is solved again by DAQP (when the configured solver is
another one); only if that fails too is the command a safe stop. Every result is clipped to the box bounds (a no-op for
exact solvers; the guarantee for iterative solvers' tolerances).
"""

from __future__ import annotations

import math

import numpy as np

from ..config import N_ARM, N_WHEELS, ControllerConfig, FloatArray
from ..model.wmm import WmmModel
from ..pseudoinverse import weight_matrix_diag
from ..solvers import INF, QPBackend, QPProblem, available_solvers, make_backend
from ..types import Command, Mode, Reference, RobotState, Status
from .base import Controller, TickContext

N_V = N_WHEELS + N_ARM
N_S = 6  # s⁺, s⁻ ∈ R³
SLACK_ACCEPT = 1e-7  # [m/s] slack below this counts as "the task is met"
RETURN_TIME = 0.05  # [s] a joint past a position limit is pulled back in over about this long
_ARM_DIAG = np.arange(N_ARM)  # diagonal indices of the cost's v block, stage 1 and stage 2
_V_DIAG = np.arange(N_V)
_NO_ROWS, _NO_BOUNDS = np.zeros((0, N_V)), np.zeros(0)  # no EE box rows (read only)
_NO_ROWS.setflags(write=False)
_NO_BOUNDS.setflags(write=False)
RETURN_WEIGHT = 1e3  # outweighs minimal-motion costs (the base's too), stays below the task's ρ₁


def task_residual(problem: QPProblem, z: FloatArray) -> float:
    """max |J v − ẋ_ref| of a solution [m/s]: judged on v itself, never on the slack entries (a
    solver may leave a slack a hair below its bound 0, which clipping would then hide)."""
    n = problem.n - N_S
    return float(np.max(np.abs(problem.A[:, :n] @ z[:n] - problem.b)))


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
        self._full = make_backend(qp.solver, qp.eps_abs)
        # DAQP (dual active set, exact) re-solves a stage another solver failed on (iterative
        # solvers stall on rare, hard instances) and decides, exactly, whether a task the
        # penalised solve left unmet is feasible (_task_first).
        self._fallback = make_backend("daqp", qp.eps_abs) if "daqp" in available_solvers() else None
        self.fallbacks = 0  # stages the fallback solved
        self.closed_form_hits = 0  # stages solved in closed form (no bound active)
        self._closed_form_hit = False  # the last _solve was answered in closed form
        self.task_checks = 0  # stages that left slack and were re-solved with the task as an equality
        self.task_recovered = 0  # ... and turned out feasible (the penalty alone was too weak)
        self._templates: dict[tuple[int, int], QPProblem] = {}
        self._w_inv = 1.0 / weight_matrix_diag(qp.alpha)  # W_x⁻¹, eq. (12)
        self._w_inv_dm = 1.0 / weight_matrix_diag(qp.dm_alpha)  # W_x⁻¹ in DM_NULLSPACE
        self._v_n = np.zeros(N_V)  # eq. (19)'s v_n, reused
        self._v_n_max = 10.0 * self.robot.arm.velocity_max
        self._return_gain = RETURN_WEIGHT * self._w_inv[N_WHEELS:] / RETURN_TIME  # see return_term
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
        self._arm.reset()
        self._full.reset()

    # ------------------------------------------------------------------ building
    def box(self, ctx: TickContext) -> tuple[FloatArray, FloatArray]:
        """Hard bounds on v = [v_b; v_m]: wheel bounds and eq. (13)."""
        return ctx.lo, ctx.hi

    def ee_box_rows(
        self, ctx: TickContext, mode: Mode, lb: FloatArray, ub: FloatArray
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """C, l, u of the EE box x_min ≤ x + Δt J v ≤ x_max, DM_CARTESIAN only.

        Never asks to go further out than the EE already is, and always admits the command
        nearest zero inside the box bounds (so the QP is always feasible).
        """
        if mode != Mode.DM_CARTESIAN:
            return _NO_ROWS, _NO_BOUNDS, _NO_BOUNDS
        lo, hi, x = self.config.ee_box_lower, self.config.ee_box_upper, ctx.kin.x
        rows = np.flatnonzero(np.isfinite(lo) | np.isfinite(hi))
        C = self.dt * ctx.kin.J[rows]
        reach = C @ np.clip(0.0, lb, ub)
        l = np.minimum(np.minimum(lo[rows], x[rows]) - x[rows], reach)
        u = np.maximum(np.maximum(hi[rows], x[rows]) - x[rows], reach)
        return C, np.maximum(l, -INF), np.minimum(u, INF)

    def return_term(self, q: FloatArray) -> FloatArray:
        """Linear cost −dᵢ·v_ret,i that pulls a joint beyond a position limit back in (7,).

        Bounds (13) only forbid moving further out (and always admit braking); a joint pushed
        past a limit (latency, a stalled controller) would otherwise stay there while the task
        pulls outwards. v_ret = −excess/τ_ret, τ_ret = 0.05 s, weighted 1000× the joint's own
        cost so that it outweighs the motion of the joints (and wheels) that compensate, and below
        the task's exact penalty ρ₁ so the task still comes first; it acts in the
        task's null space.
        """
        arm = self.robot.arm
        excess = q - np.minimum(np.maximum(q, arm.position_lower), arm.position_upper)  # 0 inside
        return self._return_gain * excess  # = −κ·d·v_ret

    def linear_term(self, ctx: TickContext, mode: Mode) -> FloatArray:
        """−W_x⁻¹ v_n with v_n of eq. (19) (clipped to ±V) in DM_NULLSPACE, else 0."""
        if mode != Mode.DM_NULLSPACE:
            return np.zeros(N_V)
        assert ctx.grad_q is not None
        # eq. (19), each joint's preference clipped to 10× its velocity limit: ∇H2 grows like H2³
        # and is astronomically large next to a singular direction (H2 is capped at 1e6 there).
        v_n = self._v_n  # wheels: 0
        np.minimum(np.maximum(self.config.k_N * ctx.grad_q, -self._v_n_max), self._v_n_max, out=v_n[N_WHEELS:])
        return -self.cost_diagonal(ctx, mode) * v_n

    def slack_weights(self) -> tuple[float, float]:
        """(ρ₁, ρ₂): the slack's exact penalty and quadratic weight."""
        return self.config.qp.slack_l1, self.config.qp.slack_weight

    def cost_diagonal(self, ctx: TickContext, mode: Mode) -> FloatArray:
        """Diagonal of the cost on v: W_x⁻¹ (eq. (12); ``qp.dm_alpha`` in DM_NULLSPACE), the arm
        block damped near singularities."""
        w_inv = self._w_inv_dm if mode == Mode.DM_NULLSPACE else self._w_inv
        if ctx.damping == 0.0 or self.config.damping_max <= 0.0:
            return w_inv
        scale = 1.0 + self.config.qp.singular_arm_weight * (ctx.damping / self.config.damping_max) ** 2
        d = w_inv.copy()
        d[N_WHEELS:] *= scale
        return d

    def reference_velocity(self, ctx: TickContext, reference: Reference) -> FloatArray:
        """ẋ_ref of the mode, scaled down to ``qp.task_speed_max``."""
        xdot = self.task_velocity(ctx, reference)
        n = math.sqrt(float(xdot @ xdot))
        cap = self.config.qp.task_speed_max
        return xdot * (cap / n) if n > cap else xdot

    def _template(self, n: int, n_in: int) -> QPProblem:
        """A preallocated problem in z = [v (n); s⁺; s⁻] with the slack's fixed parts filled in.

        Built once per shape; every tick only overwrites the parts that change (in place: the
        hot path allocates no QP matrices). ``last_problem`` is therefore valid until the next step.
        """
        key = (n, n_in)
        p = self._templates.get(key)
        if p is None:
            rho1, rho2 = self.slack_weights()
            m = n + N_S
            H = np.zeros((m, m))
            H[n:, n:] = rho2 * np.eye(N_S)
            A = np.zeros((3, m))
            A[:, n : n + 3] = np.eye(3)
            A[:, n + 3 :] = -np.eye(3)
            g = np.zeros(m)
            g[n:] = rho1
            ub = np.full(m, INF)
            p = QPProblem(
                H=H,
                g=g,
                A=A,
                b=np.zeros(3),
                C=np.zeros((n_in, m)),
                l=np.zeros(n_in),
                u=np.zeros(n_in),
                lb=np.zeros(m),
                ub=ub,
            )
            self._templates[key] = p
        return p

    def build_arm_first(self, ctx: TickContext, xdot: FloatArray) -> tuple[QPProblem, FloatArray]:
        """Stage 1: the arm alone, wheels held at the admissible speed nearest 0."""
        w_hold = np.minimum(np.maximum(ctx.wheel_lo, 0.0), ctx.wheel_hi)
        p = self._template(N_ARM, 0)
        p.H[_ARM_DIAG, _ARM_DIAG] = self._w_inv[N_WHEELS:]
        p.g[:N_ARM] = self.return_term(ctx.kin.q_arm)
        p.A[:, :N_ARM] = ctx.kin.J_m
        np.subtract(xdot, ctx.kin.J[:, :N_WHEELS] @ w_hold, out=p.b)
        p.lb[:N_ARM] = ctx.arm_lo
        p.ub[:N_ARM] = ctx.arm_hi
        return p, w_hold

    def build(self, ctx: TickContext, xdot: FloatArray, mode: Mode) -> QPProblem:
        """Stage 2: the whole robot (see the module docstring)."""
        lb, ub = self.box(ctx)
        C, l, u = self.ee_box_rows(ctx, mode, lb, ub)
        p = self._template(N_V, C.shape[0])
        p.H[_V_DIAG, _V_DIAG] = self.cost_diagonal(ctx, mode)
        p.g[:N_V] = self.linear_term(ctx, mode)
        p.g[N_WHEELS:N_V] += self.return_term(ctx.kin.q_arm)
        p.A[:, :N_V] = ctx.kin.J
        p.b[:] = xdot
        if C.shape[0]:
            p.C[:, :N_V] = C
            p.l[:] = l
            p.u[:] = u
        p.lb[:N_V] = lb
        p.ub[:N_V] = ub
        return p

    # ------------------------------------------------------------------ solving
    def closed_form(self, problem: QPProblem) -> FloatArray | None:
        """The QP's optimum if no bound is active and the slack is zero, else None.

        With D = diag(H) on v (diagonal by construction), the candidate
        v = D⁻¹(Jᵀλ − g), λ = (J D⁻¹ Jᵀ)⁻¹(b + J D⁻¹ g), s = 0 satisfies stationarity and the
        task; it is the (unique) optimum by the KKT conditions iff lb ≤ v ≤ ub, l ≤ C v ≤ u and
        |λᵢ| ≤ ρ₁ (the exact penalty's subgradient condition). This is an active-set solver's
        first iterate: exact, no tolerance involved.
        """
        n = problem.n - N_S
        d_inv = 1.0 / problem.H.diagonal()[:n]
        J = problem.A[:, :n]
        g = problem.g[:n]
        JD = J * d_inv
        # 3×3 symmetric system J D⁻¹ Jᵀ λ = r solved by its adjugate, in Python floats
        # (np.linalg.solve costs several µs of overhead for a 3×3).
        (a, b_, c), (_, d, e), (_, _, f) = (JD @ J.T).tolist()
        r0, r1, r2 = (problem.b + JD @ g).tolist()
        A0, A1, A2 = d * f - e * e, c * e - b_ * f, b_ * e - c * d
        det = a * A0 + b_ * A1 + c * A2
        if not abs(det) > 1e-300:
            return None
        B1, B2, C2 = a * f - c * c, b_ * c - a * e, a * d - b_ * b_
        l0, l1, l2 = (
            (A0 * r0 + A1 * r1 + A2 * r2) / det,
            (A1 * r0 + B1 * r1 + B2 * r2) / det,
            (A2 * r0 + B2 * r1 + C2 * r2) / det,
        )
        rho1 = float(problem.g[n])
        # |λᵢ| ≤ ρ₁ first, in Python floats (NaN fails it): then λ is finite and bounded, and v
        # below cannot overflow.
        if not (abs(l0) <= rho1 and abs(l1) <= rho1 and abs(l2) <= rho1):
            return None
        v = (J.T @ np.array((l0, l1, l2)) - g) * d_inv
        resid = J @ v - problem.b
        # the remaining KKT conditions; NaN/inf fail every comparison
        # (min over tolist(): a numpy .all() on a 7-vector costs twice as much; a NaN in v, which
        # Python's min would not propagate, already fails the residual test)
        ok = (
            resid.dot(resid) <= 1e-20  # a near-singular J D⁻¹ Jᵀ is not exact: let the solver work
            and min((v - problem.lb[:n]).tolist()) >= 0.0
            and min((problem.ub[:n] - v).tolist()) >= 0.0
        )
        if not ok:
            return None
        if problem.n_in:
            Cv = problem.C[:, :n] @ v
            if not ((problem.l <= Cv) & (Cv <= problem.u)).all():
                return None
        z = np.zeros(problem.n)
        z[:n] = v
        return z

    def _solve(self, backend: QPBackend, problem: QPProblem) -> FloatArray | None:
        self._last_problem = problem
        self._closed_form_hit = False
        if self.config.qp.closed_form_first:
            z = self.closed_form(problem)
            if z is not None:  # its residual is already checked to 1e-10
                self.closed_form_hits += 1
                self._closed_form_hit = True
                return z
        sol = backend.solve(problem)
        if (not sol.ok or sol.z is None) and self._fallback is not None and self.solver != "daqp":
            sol = self._fallback.solve(problem)
            self.fallbacks += int(sol.ok)
        if not sol.ok or sol.z is None:
            return None
        z = np.clip(sol.z, problem.lb, problem.ub)  # hard bounds exactly, whatever the tolerance
        if task_residual(problem, z) > SLACK_ACCEPT:
            z = self._task_first(problem, z)
        return z

    def _task_first(self, problem: QPProblem, z: FloatArray) -> FloatArray:
        """Strict task priority when the penalised solve left slack.

        The exact penalty keeps s = 0 only while ρ₁ exceeds the task's multiplier; near a
        singularity, with the null-space DM term (∝ H2³) or the return term, the multiplier can
        exceed it although the bounds admit the task. So: solve again with s ≡ 0 (the task a hard
        equality) by DAQP, whose infeasibility detection is exact. Feasible → that optimum is the
        lexicographic answer (task first, then the cost with its DM/return terms); infeasible →
        the task truly cannot be met and the penalised solution stands.
        """
        checker = self._fallback if self._fallback is not None else self._full
        self.task_checks += 1
        n = problem.n - N_S
        saved = problem.ub[n:].copy()
        problem.ub[n:] = 0.0  # s⁺ = s⁻ = 0
        try:
            sol = checker.solve(problem)
        finally:
            problem.ub[n:] = saved
        if sol.ok and sol.z is not None:
            self.task_recovered += 1
            exact = np.clip(sol.z, problem.lb, problem.ub)
            exact[n:] = 0.0
            return exact
        return z

    def _step(self, state: RobotState, reference: Reference) -> Command:
        mode = reference.mode
        ctx = self.context(state, reference, need_gradient=self.needs_gradient(mode))
        xdot = self.reference_velocity(ctx, reference)
        if self.config.qp.arm_first and mode in (Mode.TRACK, Mode.HOLD):
            p, w_hold = self.build_arm_first(ctx, xdot)
            z = self._solve(self._arm, p)
            if z is not None and (self._closed_form_hit or task_residual(p, z) <= SLACK_ACCEPT):
                self.last_stage = "arm"
                return self.finish(ctx, np.concatenate([w_hold, z[:N_ARM]]), xdot, alpha=0.0)
        problem = self.build(ctx, xdot, mode)
        z = self._solve(self._full, problem)
        if z is None:
            self.last_stage = "failed"
            return self.safe_stop(state, f"qp ({self.solver}): the solver failed")
        self.last_stage = "full"
        status, reason = Status.OK, ""
        if task_residual(problem, z) > 1e-6:
            status, reason = Status.SATURATED, "the bounds cut the task (best effort)"
        alpha = self.config.qp.dm_alpha if mode == Mode.DM_NULLSPACE else self.config.qp.alpha
        return self.finish(ctx, z[:N_V], xdot, status=status, reason=reason, alpha=alpha)
