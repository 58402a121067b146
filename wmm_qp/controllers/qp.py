"""The product's controller: the weighted pseudoinverse and the α switch recast as a QP.

Decision variable z = [v_b; v_m; s⁺; s⁻] (wheel speeds, joint rates, task slack s = s⁺ − s⁻ ∈ Rʳ;
r = 3 for the position task, 6 for the pose task, whose angular rows the base controller scales
by ``task.orientation_weight``). Every size comes from the robot description.
Every tick:

    minimize    ½ vᵀ W_x⁻¹ v − (W_x⁻¹ v_n)ᵀ v + ρ₁ 1ᵀ(s⁺ + s⁻) + ½ ρ₂ (‖s⁺‖² + ‖s⁻‖²)
    subject to  J v + s⁺ − s⁻ = ẋ_ref                      task, eq. (5)
                Q_min(q) ≤ v_m ≤ Q_max(q)                    eq. (13)
                wheel speed and acceleration bounds, s± ≥ 0
                x_min ≤ x + Δt·J v ≤ x_max                   EE box (DM_CARTESIAN, eq. (17))
                ∇σ_min·v_m ≥ −γ(σ_min − σ_f)                 σ_min floor (DM modes, near σ_f)

W_x = diag(α I_wheels, (1−α) I_joints) is eq. (12) (α = ``qp.alpha`` small: the base is expensive; in
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
every arm joint's cost alike does not change its optimum.) The base's yaw is priced up by the same
factor (``base_rotation_weight``: ½ c ω² with ω the yaw row of the base's M, eq. (3)), so that the
damping hands the arm's work to the base's translation and not to its rotation; the wheel block of
the cost is then diag(W_x⁻¹) + c·rot rotᵀ, which the closed form inverts by Sherman–Morrison.

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

The σ_min floor (DM modes, limits/singularity_floor.py): raising DM (eqs. (16)–(19)) heads into a
singularity wherever DM along u has no interior optimum, so while σ_min(J_m) is within twice
``dm.sigma_min_floor`` the whole-robot stage carries one more row, a damper that lets σ_min fall
ever slower as it nears the floor. Priority: task, floor, DM. In DM_NULLSPACE a stage whose task
the row cuts (or that no solver solves with it) is solved again without it; in DM_CARTESIAN the
task is the DM ascent itself, which the row cuts.

Each stage first tries the closed-form optimum (no bound active, zero slack), taken only when
it meets every KKT condition (``qp.closed_form_first``); otherwise the solver runs.
A stage the configured solver fails on is solved again by DAQP (when the configured solver is
another one); only if that fails too is the command a safe stop. Every result is clipped to the box bounds (a no-op for
exact solvers; the guarantee for iterative solvers' tolerances).

The EE box rows (DM_CARTESIAN) are not bounds the clip can restore, and every backend meets them
only to its primal tolerance (DAQP's and OSQP's ~1e-6 m per tick on these rows: up to 5e-7 m in
``wmm-qp verify``'s random states, proxsuite's up to 2e-8 m): so the achieved command is
re-checked against them after every solver path (closed form, the configured solver, the DAQP
fallback, the exact re-solve) and, where it leaves a row, projected back onto it inside the box
bounds (``_hold_ee_box``; status SATURATED with the reason).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from .._jit import jit
from .._typing import FloatArray, IntArray
from ..config import ControllerConfig, ShapeConfig
from ..limits.collision import CollisionRows, warm_up_obstacles
from ..limits.rows import Rows
from ..limits.singularity_floor import FloorRow, floor_row
from ..linalg3 import solve_spd, solve_sym3
from ..manipulability.preference import dm_preference_gain
from ..model.collision import robot_geometry
from ..model.wmm import WmmModel
from ..pseudoinverse import weight_matrix_diag
from ..scene import Scene
from ..solvers import INF, QPBackend, QPProblem, available_solvers, make_backend
from ..types import AT_REST, Command, Mode, Reference, RobotState, Status
from .base import Controller, TickContext

SLACK_ACCEPT = 1e-7  # [m/s] slack below this counts as "the task is met"
TASK_CUT = 1e-6  # [m/s] a stage's max |J v − ẋ_ref| above this: the task was cut (status saturated)
RETURN_TIME = 0.05  # [s] a joint past a position limit is pulled back in over about this long
_NO_BOUNDS = np.zeros(0)  # no EE box rows (read only)
_NO_REF = np.zeros(0)  # _hold_ee_box's reference point: the braking command clip(0, lb, ub) (read only)
_NO_BOUNDS.setflags(write=False)
_NO_HOLD = np.zeros(0)  # stage 2 holds no column
EE_BOX_TOL = 1e-14  # [m] over one tick: an EE box row violated by less is roundoff (the referee allows 1e-9·Δt)
RETURN_WEIGHT = 1e3  # outweighs minimal-motion costs (the base's too), stays below the task's ρ₁


def task_residual(problem: QPProblem, z: FloatArray) -> float:
    """max |J v − ẋ_ref| of a solution [m/s]: judged on v itself, never on the slack entries (a
    solver may leave a slack a hair below its bound 0, which clipping would then hide)."""
    n = problem.n - 2 * problem.A.shape[0]  # z = [v; s⁺; s⁻], s± ∈ Rʳ
    return float(np.max(np.abs(problem.A[:, :n] @ z[:n] - problem.b)))


@jit
def _closed_form(
    H: FloatArray,
    g: FloatArray,
    A: FloatArray,
    b: FloatArray,
    C: FloatArray,
    l: FloatArray,
    u: FloatArray,
    lb: FloatArray,
    ub: FloatArray,
    rot: FloatArray,
    c: float,
    z: FloatArray,
) -> bool:
    """:meth:`QpController.closed_form` compiled: z ← the optimum, True iff every KKT condition holds.

    H's block on v is D + c·rot rotᵀ (D diagonal, c ≥ 0: the base's rotation cost of
    :meth:`QpController.base_rotation_weight`), inverted by Sherman–Morrison:
    H⁻¹ = D⁻¹ − β (D⁻¹rot)(D⁻¹rot)ᵀ, β = c / (1 + c rotᵀD⁻¹rot).
    """
    m = A.shape[0]  # r, the task's rows
    n = z.shape[0] - 2 * m
    d, d_inv = np.empty(n), np.empty(n)
    for i in range(n):
        d[i] = H[i, i] - c * rot[i] * rot[i]
        d_inv[i] = 1.0 / d[i]
    beta, ug, jr = 0.0, 0.0, np.zeros(m)  # β, rotᵀD⁻¹g, J D⁻¹ rot
    if c > 0.0:
        q = 0.0
        for i in range(n):
            q += rot[i] * d_inv[i] * rot[i]
            ug += rot[i] * d_inv[i] * g[i]
            for a in range(m):
                jr[a] += A[a, i] * d_inv[i] * rot[i]
        beta = c / (1.0 + c * q)
    # G = J H⁻¹ Jᵀ (r×r) and r = b + J H⁻¹ g, J = A[:, :n]
    G = np.zeros((m, m))
    r = b.copy()
    for i in range(n):
        for a in range(m):
            jd = A[a, i] * d_inv[i]
            r[a] += jd * g[i]
            for e in range(m):
                G[a, e] += jd * A[e, i]
    for a in range(m):
        r[a] -= beta * jr[a] * ug
        for e in range(m):
            G[a, e] -= beta * jr[a] * jr[e]
    # λ = G⁻¹ r (G symmetric)
    if m == 3:
        det, l0, l1, l2 = solve_sym3(G[0, 0], G[0, 1], G[0, 2], G[1, 1], G[1, 2], G[2, 2], r[0], r[1], r[2])
        if not abs(det) > 1e-300:
            return False
        lam = np.array((l0, l1, l2))
    else:
        lam = np.empty(m)
        if not solve_spd(G, r, lam):
            return False
    rho1 = g[n]
    for a in range(m):  # the exact penalty's subgradient condition (NaN fails it)
        if not abs(lam[a]) <= rho1:
            return False
    z[:] = 0.0
    w = np.empty(n)  # Jᵀλ − g
    uw = 0.0  # rotᵀD⁻¹(Jᵀλ − g)
    for i in range(n):
        jl = 0.0
        for a in range(m):
            jl += A[a, i] * lam[a]
        w[i] = jl - g[i]
        uw += rot[i] * d_inv[i] * w[i]
    for i in range(n):  # v = H⁻¹(Jᵀλ − g) inside its bounds
        vi = (w[i] - beta * rot[i] * uw) / d[i]
        if not (lb[i] <= vi <= ub[i]):
            return False
        z[i] = vi
    res = 0.0  # a near-singular G is not exact: let the solver work
    for a in range(m):
        e = -b[a]
        for i in range(n):
            e += A[a, i] * z[i]
        res += e * e
    if not res <= 1e-20:
        return False
    for k in range(C.shape[0]):  # l ≤ C v ≤ u
        cv = 0.0
        for i in range(n):
            cv += C[k, i] * z[i]
        if not (l[k] <= cv <= u[k]):
            return False
    return True


@jit
def _fill_stage(
    J: FloatArray,
    xdot: FloatArray,
    lo: FloatArray,
    hi: FloatArray,
    cost: FloatArray,
    rot: FloatArray,
    c: float,
    H: FloatArray,
    A: FloatArray,
    b: FloatArray,
    lb: FloatArray,
    ub: FloatArray,
    w_hold: FloatArray,
) -> None:
    """A stage's H, A, b, lb, ub over the last len(cost) columns of v = [v_b; v_m]. The columns
    before them (the wheels in stage 1; none in stage 2) are held at w_hold, the admissible
    speed nearest 0, and their motion leaves the stage's task: b = ẋ_ref − J_held w_hold.
    H's block on them is diag(cost) + c·rot rotᵀ, written whole (a template may serve both
    stages: a fixed base's)."""
    first, n = w_hold.shape[0], cost.shape[0]
    for j in range(first):
        w_hold[j] = min(max(lo[j], 0.0), hi[j])
    for a in range(J.shape[0]):
        r = xdot[a]
        for j in range(first):
            r -= J[a, j] * w_hold[j]
        b[a] = r
        for i in range(n):
            A[a, i] = J[a, first + i]
    for i in range(n):
        for j in range(n):
            H[i, j] = c * rot[i] * rot[j]
        H[i, i] += cost[i]
        lb[i], ub[i] = lo[first + i], hi[first + i]


@jit
def _add_return_term(q: FloatArray, q_lower: FloatArray, q_upper: FloatArray, gain: FloatArray, g: FloatArray) -> None:
    """g[:n] += gain·(q − clip(q, q_lower, q_upper)): see :meth:`QpController.return_term`."""
    for i in range(q.shape[0]):
        g[i] += gain[i] * (q[i] - min(max(q[i], q_lower[i]), q_upper[i]))


@jit
def _add_nullspace_term(cost: FloatArray, grad_q: FloatArray, k_N: float, v_n_max: FloatArray, g: FloatArray) -> None:
    """g += −W_x⁻¹ v_n, v_n = [0; k_N ∇H2] of eq. (19) (k_N: the gain of the preference,
    manipulability/preference.py), each joint's preference clipped to ±v_n_max: ∇H2 grows like
    H2³ and is astronomically large next to a singular direction (H2 is capped at 1e6 there)."""
    n_w = cost.shape[0] - grad_q.shape[0]
    for i in range(grad_q.shape[0]):
        v_n = min(max(k_N * grad_q[i], -v_n_max[i]), v_n_max[i])
        g[n_w + i] -= cost[n_w + i] * v_n


@jit
def _ee_box(
    J: FloatArray,
    x: FloatArray,
    lo: FloatArray,
    hi: FloatArray,
    rows: IntArray,
    lb: FloatArray,
    ub: FloatArray,
    dt: float,
    C: FloatArray,
    l: FloatArray,
    u: FloatArray,
) -> None:
    """C, l, u of :meth:`QpController.ee_box_rows` (compiled)."""
    for k in range(rows.shape[0]):
        r = rows[k]
        reach = 0.0  # where the command nearest zero inside the box bounds takes the EE
        for i in range(J.shape[1]):
            C[k, i] = dt * J[r, i]
            reach += C[k, i] * min(max(0.0, lb[i]), ub[i])
        l[k] = max(min(min(lo[r], x[r]) - x[r], reach), -INF)  # never further out than x already is
        u[k] = min(max(max(hi[r], x[r]) - x[r], reach), INF)


@jit
def _hold_ee_box(
    C: FloatArray, l: FloatArray, u: FloatArray, lb: FloatArray, ub: FloatArray, z: FloatArray, n: int,
    ref: FloatArray,
) -> float:
    """The EE box re-checked on the achieved command v = z[:n], whatever solved the stage.

    A solver meets the rows l ≤ C v ≤ u of ``_ee_box`` (eq. (17)) only to its primal tolerance
    (DAQP's and OSQP's are ~1e-6 on these rows; the clip to lb ≤ v ≤ ub does not touch them).
    A row left by more than ``EE_BOX_TOL`` is restored by the Euclidean projection of v onto
    that row's half-space inside the box bounds, v ← clip(v − λ·C_k, lb, ub) with the least λ ≥ 0
    that meets it (by bisection; it exists: the rows admit ``ref``, inside the box: the braking
    command v₀ = clip(0, lb, ub) — an empty ``ref`` (``_NO_REF``) — or in the stage whose
    collision rows are relaxed together the command they were relaxed to). If one row's
    projection moved another out, v ← ref + t(v − ref)
    with the largest t ∈ [0, 1) that meets every row (both ends inside the box bounds, so v still
    is). Returns the largest violation found [m over one tick], 0.0 if v met every row (then
    unchanged).
    """
    worst = 0.0
    for k in range(C.shape[0]):
        e = 0.0
        for i in range(n):
            e += C[k, i] * z[i]
        if e > u[k] + EE_BOX_TOL:
            target, sign = u[k], 1.0
        elif e < l[k] - EE_BOX_TOL:
            target, sign = l[k], -1.0
        else:
            continue
        worst = max(worst, abs(e - target))
        lam_lo, lam_hi = 0.0, 0.0  # at lam_hi every entry that lowers sign·C_k v sits at its bound
        for i in range(n):
            c = sign * C[k, i]
            if c > 0.0:
                lam_hi = max(lam_hi, (z[i] - lb[i]) / c)
            elif c < 0.0:
                lam_hi = max(lam_hi, (z[i] - ub[i]) / c)
        for _ in range(200):  # bisection on λ until the bracket stops shrinking
            mid = 0.5 * (lam_lo + lam_hi)
            if not lam_lo < mid < lam_hi:
                break
            g = 0.0
            for i in range(n):
                g += sign * C[k, i] * min(max(z[i] - mid * sign * C[k, i], lb[i]), ub[i])
            if g <= sign * target:
                lam_hi = mid
            else:
                lam_lo = mid
        for i in range(n):
            z[i] = min(max(z[i] - lam_hi * sign * C[k, i], lb[i]), ub[i])
    if worst > 0.0:  # every row again (a projection may have moved another row); else towards ref
        t = 1.0
        for k in range(C.shape[0]):
            e, r = 0.0, 0.0
            for i in range(n):
                e += C[k, i] * z[i]
                r += C[k, i] * (ref[i] if ref.shape[0] else min(max(0.0, lb[i]), ub[i]))
            if e > u[k] + EE_BOX_TOL:  # r ≤ u[k] by construction
                t = min(t, (u[k] - r) / (e - r))
            elif e < l[k] - EE_BOX_TOL:
                t = min(t, (l[k] - r) / (e - r))
        if not t >= 0.0:  # NaN, or a row that does not admit ref (cannot happen): ref
            t = 0.0
        if t < 1.0:
            for i in range(n):
                r = ref[i] if ref.shape[0] else min(max(0.0, lb[i]), ub[i])
                z[i] = r + t * (z[i] - r)
    return worst


def _saturated(v: FloatArray, feedforward: FloatArray, limit: float) -> FloatArray:
    """v with its feedback part v − feedforward scaled down to the norm ``limit``."""
    fb = v - feedforward
    e = math.sqrt(float(fb @ fb))
    return feedforward + fb * (limit / e) if e > limit else v


class QpController(Controller):
    """QP controller (docs/model.md "The QP").

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
        self.task_without_objective = 0  # ... of which only with the DM/return terms dropped
        self.ee_box_corrections = 0  # commands the EE box re-check had to pull back into the box
        self.braking_stages = 0  # stages every solver failed on, commanded the joint command that meets their rows
        self.joint_relaxations = 0  # stages whose collision rows were infeasible together, relaxed together
        self._templates: dict[tuple[int, int], QPProblem] = {}
        self._w_inv = 1.0 / weight_matrix_diag(qp.alpha, self.n_wheels, self.n_arm)  # W_x⁻¹, eq. (12)
        self._w_inv_dm = 1.0 / weight_matrix_diag(qp.dm_alpha, self.n_wheels, self.n_arm)  # in DM_NULLSPACE
        self._n_s = 2 * self.r  # s⁺, s⁻ ∈ Rʳ
        # The base's rotation, ω = rot·v_b (the yaw row of the base's M, eq. (3)), and its price in
        # W_x⁻¹'s wheel cost: ‖M⁺ e_ω‖², the squared wheel speeds of a pure yaw of 1 rad/s
        base = model.base
        self._rot = np.zeros(self.n_v)
        self._rot[: self.n_wheels] = base.M[2]
        self._rot.setflags(write=False)
        self._rot_price = float(np.sum(base.M_pinv[:, 2] ** 2)) if self.n_wheels else 0.0
        self._no_rot = np.zeros(self.n_arm)  # stage 1: no wheel columns
        self._no_rot.setflags(write=False)
        # (rot, c) of the problem the builders filled last (H's block on v: diag + c·rot rotᵀ); every
        # problem is solved right after it is built, so this is the one closed_form() reads
        self._cost_rank1: tuple[FloatArray, float] = (self._no_rot, 0.0)
        self._no_rows = np.zeros((0, self.n_v))  # no EE box rows (read only)
        self._no_rows.setflags(write=False)
        self._v_n_max = 10.0 * self.robot.arm.velocity_max
        # ρ of the normalised DM preference, at most the slowest joint's velocity limit
        self._dm_speed = min(qp.dm_speed, float(np.min(self.robot.arm.velocity_max, initial=np.inf)))
        self._return_gain = RETURN_WEIGHT * self._w_inv[self.n_wheels :] / RETURN_TIME  # see return_term
        self._last_problem: QPProblem | None = None
        self.last_stage = ""
        self.collision: CollisionRows | None = None  # the dampers and the fence (limits/collision.py)
        if config.collision.enabled:
            geometry = robot_geometry(self.robot, model.arm)
            self.collision = CollisionRows(geometry, model.base.M, config.collision, config.state_latency,
                                           self.bounds.a_max)
        self.last_rows: Rows | None = None  # the collision rows of the last tick
        self.last_floor: FloorRow | None = None  # the σ_min floor's row of the last tick
        self.floor_dropped = 0  # DM_NULLSPACE stages re-solved without the floor row: it cut the task

    @property
    def solver(self) -> str:
        return self.config.qp.solver

    @property
    def last_problem(self) -> QPProblem | None:
        """The last QP handed to a backend (for tests and logs)."""
        return self._last_problem

    def warm_up(self, q_arm: FloatArray | None = None) -> None:
        """:meth:`Controller.warm_up`, then, with collision rows, every mode once more among
        :func:`~wmm_qp.limits.collision.warm_up_obstacles` around the EE: the obstacles' kernels
        (boxes, planes, moving obstacles) load now, not in the tick an obstacle first comes near
        (compiling them there took a tick of 5.6 s on a fresh install). The obstacles in force are
        restored."""
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
        self._arm.reset()
        self._full.reset()

    def clear_statistics(self) -> None:
        self.fallbacks = self.closed_form_hits = self.task_checks = self.floor_dropped = 0
        self.task_recovered = self.task_without_objective = self.ee_box_corrections = self.braking_stages = 0

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
            return self._no_rows, _NO_BOUNDS, _NO_BOUNDS
        k = self._boxed_axes.shape[0]
        C, l, u = np.empty((k, self.n_v)), np.empty(k), np.empty(k)
        box_lo, box_hi = self.config.ee_box_lower, self.config.ee_box_upper
        _ee_box(ctx.kin.J, ctx.kin.x, box_lo, box_hi, self._boxed_axes, lb, ub, self.dt, C, l, u)
        return C, l, u

    def return_term(self, q: FloatArray) -> FloatArray:
        """Linear cost −dᵢ·v_ret,i that pulls a joint beyond a position limit back in (n_arm,).

        Bounds (13) only forbid moving further out (and always admit braking); a joint pushed
        past a limit (latency, a stalled controller) would otherwise stay there while the task
        pulls outwards. v_ret = −excess/τ_ret, τ_ret = 0.05 s, weighted 1000× the joint's own
        cost so that it outweighs the motion of the joints (and wheels) that compensate, and below
        the task's exact penalty ρ₁ so the task still comes first; it acts in the
        task's null space. (The stages' builders add it in their compiled fill.)
        """
        out = np.zeros(self.n_arm)
        arm = self.robot.arm
        _add_return_term(q, arm.position_lower, arm.position_upper, self._return_gain, out)
        return out

    def slack_weights(self) -> tuple[float, float]:
        """(ρ₁, ρ₂): the slack's exact penalty and quadratic weight."""
        return self.config.qp.slack_l1, self.config.qp.slack_weight

    def singular_scale(self, ctx: TickContext) -> float:
        """1 + κ·(λ/λ_max)²: the factor the singularity damping puts on the arm's cost (κ =
        ``qp.singular_arm_weight``, λ of the variable-damping law; 1 away from singularities)."""
        if ctx.damping == 0.0 or self.config.damping_max <= 0.0:
            return 1.0
        return 1.0 + self.config.qp.singular_arm_weight * (ctx.damping / self.config.damping_max) ** 2

    def cost_diagonal(self, ctx: TickContext, mode: Mode) -> FloatArray:
        """Diagonal of the cost on v: W_x⁻¹ (eq. (12); ``qp.dm_alpha`` in DM_NULLSPACE), the arm
        block damped near singularities (:meth:`singular_scale`)."""
        w_inv = self._w_inv_dm if mode == Mode.DM_NULLSPACE else self._w_inv
        scale = self.singular_scale(ctx)
        if scale == 1.0:
            return w_inv
        d = w_inv.copy()
        d[self.n_wheels :] *= scale
        return d

    def base_rotation_weight(self, ctx: TickContext, mode: Mode) -> float:
        """c of the cost's rank-one term ½ c ω², ω = rot·v_b the base's yaw rate: the damping
        applied to the base's rotation as to the arm.

        Near a singularity the arm's cost rises (:meth:`cost_diagonal`) so that the base takes
        over the motion the arm can no longer make, which only the base's translation supplies (a
        yaw turns the EE about the base's vertical axis, as the arm's own joints can). Damping the
        arm alone would leave the yaw at W_x⁻¹'s price while the arm's grows up to 1 + κ: the
        yaw, which moves a stretched-out EE ~its reach per rad, then takes a share of every EE
        motion the arm used to make (on the Gen3, joint 1's). So the yaw's price is scaled alike:
        c = (scale − 1)·w_b·‖M⁺ e_ω‖², w_b the wheels' entry of W_x⁻¹ (eq. (12)), ‖M⁺ e_ω‖² the
        squared wheel speeds of a pure unit yaw (eq. (3)); the yaw then costs scale × its W_x⁻¹
        price (exactly, on a base whose yaw pattern is orthogonal to its translations: Mecanum,
        the symmetric omni, diff drive), the split between arm and base rotation stays eq. (12)'s,
        and the base's translation alone gets relatively cheaper. 0 away from singularities (so
        the QP still equals eq. (11) there) and without wheels.
        """
        scale = self.singular_scale(ctx)
        if scale == 1.0 or not self.n_wheels:
            return 0.0
        w_inv = self._w_inv_dm if mode == Mode.DM_NULLSPACE else self._w_inv
        return (scale - 1.0) * float(w_inv[0]) * self._rot_price  # W_x⁻¹ of eq. (12), M of eq. (3)

    def reference_velocity(self, ctx: TickContext, reference: Reference) -> FloatArray:
        """ẋ_ref of the mode, its error term K_x (x_d − x) (eq. (18)) saturated at
        ``qp.recovery_speed``, then scaled down to ``qp.task_speed_max``.

        The saturation leaves tracking untouched (errors of millimetres, K_x·e of mm/s) and makes
        a large error — a robot pushed off its hold target — recover at the recovery speed
        instead of K_x·e (10 m/s per metre), with the base at full speed and the arm at its
        speed limits.
        """
        lin = self.linear_velocity(ctx, reference)
        if reference.x_d is not None and reference.mode != Mode.DM_CARTESIAN:
            lin = _saturated(lin, reference.xd_d, self.config.qp.recovery_speed)  # eq. (18)
        n = math.sqrt(float(lin @ lin))
        cap = self.config.qp.task_speed_max
        if not self.pose:
            return lin * (cap / n) if n > cap else lin
        task = self.config.task  # the pose task: the same for the angular part, one common scale
        ang = self.angular_velocity(ctx, reference)
        if reference.quat_d is not None:
            ang = _saturated(ang, reference.omega_d, task.angular_recovery_speed)
        n_w = math.sqrt(float(ang @ ang))
        scale = min(1.0, cap / n if n > 0 else 1.0, task.angular_speed_max / n_w if n_w > 0 else 1.0)
        return np.concatenate((lin * scale, (self._w_R * scale) * ang))

    def _template(self, n: int, n_in: int) -> QPProblem:
        """A preallocated problem in z = [v (n); s⁺; s⁻] with the slack's fixed parts filled in.

        Built once per shape; every tick only overwrites the parts that change (in place: the
        hot path allocates no QP matrices). ``last_problem`` is therefore valid until the next step.
        """
        key = (n, n_in)
        p = self._templates.get(key)
        if p is None:
            rho1, rho2 = self.slack_weights()
            r = self.r
            m = n + self._n_s
            H = np.zeros((m, m))
            H[n:, n:] = rho2 * np.eye(self._n_s)
            A = np.zeros((r, m))
            A[:, n : n + r] = np.eye(r)
            A[:, n + r :] = -np.eye(r)
            g = np.zeros(m)
            g[n:] = rho1
            ub = np.full(m, INF)
            p = QPProblem(
                H=H,
                g=g,
                A=A,
                b=np.zeros(self.r),
                C=np.zeros((n_in, m)),
                l=np.zeros(n_in),
                u=np.zeros(n_in),
                lb=np.zeros(m),
                ub=ub,
            )
            self._templates[key] = p
        return p

    def set_scene(self, scene: Scene) -> None:
        """The obstacles and the fence the collision rows keep the robot away from / inside."""
        if self.collision is not None:
            self.collision.set_scene(scene)

    def set_obstacles(self, obstacles: Sequence[ShapeConfig]) -> None:
        """Replace the obstacle set (live obstacles; the fence stays)."""
        if self.collision is not None:
            self.collision.set_obstacles(list(obstacles))

    def set_latency(self, latency: float) -> None:
        """[s] the margin of bounds (13) and of the collision rows, which share it."""
        super().set_latency(latency)
        if self.collision is not None:
            self.collision.latency = latency

    @property
    def collision_on(self) -> bool:
        return self.collision is not None

    def collision_summary(self) -> str:
        rows = self.collision
        if rows is None:
            return "no collision rows"
        geo, fence = rows.geo, rows.fence
        fenced = fence.base.shape[0] >= 3 or np.isfinite(fence.ee_lower).any() or np.isfinite(fence.ee_upper).any()
        return (f"collision rows on ({len(geo.self_pairs)} self pairs, {len(geo.floor_bodies)} bodies vs the floor, "
                f"{len(rows.obstacles)} obstacles, {'fence' if fenced else 'no fence'})")

    def last_collision_rows(self) -> Rows | None:
        return self.last_rows

    def collision_rows(self, ctx: TickContext, state: RobotState) -> Rows | None:
        """The dampers' and the fence's rows this tick (None without collision checking)."""
        if self.collision is None:
            return None
        wheels = self._rest_wheels if state.wheel_speeds is AT_REST else state.wheel_speeds
        v_prev = np.concatenate((wheels, state.v_arm))  # the bounds' centre (the daemon's last command)
        J = ctx.kin.J[:3] if self.pose else ctx.kin.J
        rows = self.collision.rows(ctx.kin.q_base, ctx.kin.x, J, v_prev, ctx.lo, ctx.hi)
        return rows

    def floor_row(self, ctx: TickContext, state: RobotState, mode: Mode) -> FloorRow | None:
        """The σ_min floor's row this tick (limits/singularity_floor.py): in the DM modes only, and only
        while σ_min is near ``dm.sigma_min_floor``; None otherwise.

        Eqs. (16)–(19) raise H2 (8) wherever its gradient (9) leads, and along many directions it
        leads into a singularity: the floor keeps the ascent out of it (docs/model.md, "The QP").
        """
        if not self.needs_gradient(mode) or ctx.kin.dJ_arm is None:
            return None
        wheels = self._rest_wheels if state.wheel_speeds is AT_REST else state.wheel_speeds
        v_prev = np.concatenate((wheels, state.v_arm))  # the bounds' centre (the daemon's last command)
        return floor_row(ctx.kin.J_arm, ctx.kin.dJ_arm, self.config.sigma_min_floor, v_prev, ctx.lo, ctx.hi,
                         self.config.state_latency)

    def build_arm_first(
        self, ctx: TickContext, xdot: FloatArray, rows: Rows | None = None
    ) -> tuple[QPProblem, FloatArray]:
        """Stage 1: the arm alone, wheels held at the admissible speed nearest 0 (the collision
        rows with the held wheels' share moved to their bounds)."""
        k = 0 if rows is None else rows.l.shape[0]
        p = self._template(self.n_arm, k)
        w_hold = np.empty(self.n_wheels)
        arm = self.robot.arm
        _fill_stage(ctx.kin.J, xdot, ctx.lo, ctx.hi, self._w_inv[self.n_wheels :], self._no_rot, 0.0,
                    p.H, p.A, p.b, p.lb, p.ub, w_hold)
        self._cost_rank1 = (self._no_rot, 0.0)
        p.g[: self.n_arm] = 0.0
        _add_return_term(ctx.kin.q_arm, arm.position_lower, arm.position_upper, self._return_gain, p.g)
        if k:  # l ≤ C_arm v_m + C_w w_hold, the damper relaxed to what the arm alone can do (limits/collision.py)
            assert rows is not None
            Ca, held = rows.C[:, self.n_wheels :], rows.C[:, : self.n_wheels] @ w_hold
            best = np.sum(np.where(Ca > 0.0, Ca * p.ub[: self.n_arm], Ca * p.lb[: self.n_arm]), axis=1)
            p.C[:, : self.n_arm] = Ca
            p.l[:] = np.minimum(rows.damper, best + held) - held
            p.u[:] = INF
        return p, w_hold

    def build(
        self, ctx: TickContext, xdot: FloatArray, mode: Mode, rows: Rows | None = None, brake: bool = False,
        floor: FloorRow | None = None,
    ) -> QPProblem:
        """Stage 2: the whole robot (see the module docstring); ``brake``: the collision rows relaxed
        together (``Rows.relax_together``) and the σ_min floor's relaxed to admit their command (the
        retry when the rows are infeasible together). Rows, in order: the EE box, the collision rows,
        the σ_min floor."""
        C, l, u = self.ee_box_rows(ctx, mode, ctx.lo, ctx.hi)
        if rows is not None and rows.l.shape[0]:
            C = np.vstack((C, rows.C))
            l = np.concatenate((l, rows.l_brake if brake else rows.l))
            u = np.concatenate((u, np.full(rows.l.shape[0], INF)))
        if floor is not None:
            C = np.vstack((C, floor.C))
            l = np.append(l, floor.l_brake if brake else floor.l)
            u = np.append(u, INF)
        p = self._template(self.n_v, C.shape[0])
        cost = self.cost_diagonal(ctx, mode)
        c = self.base_rotation_weight(ctx, mode)
        _fill_stage(ctx.kin.J, xdot, ctx.lo, ctx.hi, cost, self._rot, c, p.H, p.A, p.b, p.lb, p.ub, _NO_HOLD)
        self._cost_rank1 = (self._rot, c)
        p.g[: self.n_v] = 0.0
        if mode == Mode.DM_NULLSPACE:
            assert ctx.grad_q is not None
            # eq. (19)'s k_N, floored where ∇H2 is flat (manipulability/preference.py)
            gain = dm_preference_gain(ctx.grad_q, self.config.k_N, self._dm_speed, self.config.qp.dm_gradient_floor)
            _add_nullspace_term(cost, ctx.grad_q, gain, self._v_n_max, p.g)
        arm = self.robot.arm
        _add_return_term(ctx.kin.q_arm, arm.position_lower, arm.position_upper, self._return_gain, p.g[self.n_wheels :])
        if C.shape[0]:
            p.C[:, : self.n_v] = C
            p.l[:] = l
            p.u[:] = u
        return p

    @staticmethod
    def _cut_reason(rows: Rows | None, v: FloatArray, floor: FloorRow | None = None) -> str:
        """Why the task was cut: the collision or fence rows the command sits on, else the σ_min
        floor's row if the command sits on it, else the bounds."""
        if rows is not None and rows.l.shape[0]:
            slack = rows.C @ v - rows.l
            active = np.flatnonzero(slack <= 1e-9 * np.maximum(1.0, np.abs(rows.l)))
            if active.size:
                k = active[np.argmin(rows.distances[active])]
                more = f" (+{active.size - 1} more)" if active.size > 1 else ""
                return f"collision: {rows.names[k]} at {rows.distances[k]:.3f} m{more} (task cut)"
        if floor is not None and float(floor.C @ v) - floor.l <= 1e-6:  # on the row, to a solver's tolerance
            return f"sigma_min floor: sigma_min {floor.sigma:.3g} near {floor.floor:.3g} (task cut)"
        return "the bounds cut the task (best effort)"

    # ------------------------------------------------------------------ solving
    def closed_form(self, problem: QPProblem) -> FloatArray | None:
        """The QP's optimum if no bound is active and the slack is zero, else None.

        With H = D + c·rot rotᵀ on v (D diagonal; c·rot rotᵀ the stage's base-rotation term, 0
        unless damped, recorded by the stage's builder), the candidate v = H⁻¹(Jᵀλ − g),
        λ = (J H⁻¹ Jᵀ)⁻¹(b + J H⁻¹ g), s = 0 satisfies stationarity and the task (H⁻¹ by
        Sherman–Morrison); it is the (unique) optimum by the KKT conditions iff lb ≤ v ≤ ub,
        l ≤ C v ≤ u and |λᵢ| ≤ ρ₁ (the exact penalty's subgradient condition). This is an
        active-set solver's first iterate: exact, no tolerance involved.
        """
        z = np.empty(problem.n)
        rot, c = self._cost_rank1
        ok = _closed_form(
            problem.H, problem.g, problem.A, problem.b, problem.C, problem.l, problem.u, problem.lb, problem.ub,
            rot, c, z,
        )
        return z if ok else None

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

        Next to a singularity the DM term can be 10⁵× the cost's scale while a row of J is ~1e-6:
        DAQP (and proxsuite) then report such a feasible task infeasible (found by hypothesis:
        the arm straight up, DM along z). So a failed exact solve is repeated once without the
        linear term (DM and return terms: the lower priorities, given up for this tick) before
        the task is declared infeasible.
        """
        checker = self._fallback if self._fallback is not None else self._full
        self.task_checks += 1
        n = problem.n - self._n_s
        saved = problem.ub[n:].copy()
        problem.ub[n:] = 0.0  # s⁺ = s⁻ = 0
        try:
            sol = checker.solve(problem)
            if not (sol.ok and sol.z is not None) and problem.g[:n].any():
                g = problem.g[:n].copy()
                problem.g[:n] = 0.0
                try:
                    sol = checker.solve(problem)
                finally:
                    problem.g[:n] = g
                self.task_without_objective += int(sol.ok and sol.z is not None)
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
        rows = self.last_rows = self.collision_rows(ctx, state)
        if self.config.qp.arm_first and mode in (Mode.TRACK, Mode.HOLD):
            p, w_hold = self.build_arm_first(ctx, xdot, rows)
            z = self._solve(self._arm, p)
            if z is not None and p.n_in:  # the collision rows, whatever solved
                _hold_ee_box(p.C, p.l, p.u, p.lb, p.ub, z, self.n_arm, _NO_REF)
            if z is not None and (self._closed_form_hit or task_residual(p, z) <= SLACK_ACCEPT):
                self.last_stage = "arm"
                return self.finish(ctx, np.concatenate([w_hold, z[: self.n_arm]]), xdot, alpha=0.0)
        floor = self.last_floor = self.floor_row(ctx, state, mode)
        problem = self.build(ctx, xdot, mode, rows, floor=floor)
        z = self._solve(self._full, problem)
        if (floor is not None and mode == Mode.DM_NULLSPACE
                and (z is None or (not self._closed_form_hit and task_residual(problem, z) > TASK_CUT))):
            # the task before the floor: where the floor row cuts the hold (or leaves the stage without
            # a solution: a row the bounds can barely meet pins v to a vertex of them) and the stage
            # without it meets the task, that one is the command (the floor outranks only the DM
            # objective; in DM_CARTESIAN the task is that objective, and the floor cuts it)
            loose = self.build(ctx, xdot, mode, rows)
            z_loose = self._solve(self._full, loose)
            if z_loose is not None and (self._closed_form_hit or task_residual(loose, z_loose) <= TASK_CUT):
                self.floor_dropped += 1
                floor = self.last_floor = None
                problem, z = loose, z_loose
            else:  # the bounds cut the task anyway: the floored stage stands
                self._last_problem, self._closed_form_hit = problem, False
        ref = _NO_REF  # v₀ = clip(0, lb, ub), the braking command: the rows admit it unless relaxed together
        has_rows = rows is not None and rows.l.shape[0] > 0
        if z is None and (floor is not None or has_rows):  # the rows together infeasible: relax them together
            if has_rows:
                assert rows is not None
                n_box = problem.n_in - rows.l.shape[0] - (0 if floor is None else 1)
                ref = rows.relax_together(ctx.lo, ctx.hi, problem.C[:n_box, : self.n_v], problem.l[:n_box],
                                          problem.u[:n_box])
                self.joint_relaxations += 1
                if floor is not None:  # the floor's row admits the rows' command too
                    floor = self.last_floor = replace(floor, l_brake=min(floor.l_brake, float(floor.C @ ref)))
            problem = self.build(ctx, xdot, mode, rows, brake=True, floor=floor)
            z = self._solve(self._full, problem)
            if z is None and problem.g[: self.n_v].any():  # still failing: without the DM and return terms
                problem.g[: self.n_v] = 0.0
                z = self._solve(self._full, problem)
        if z is None and (floor is not None or has_rows):
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
                return self.finish(ctx, ref, xdot, status=Status.SATURATED,
                                   reason=f"{self._cut_reason(rows, ref, floor)}: {why}")
        if z is None:
            self.last_stage = "failed"
            return self.safe_stop(state, f"qp ({self.solver}): the solver failed")
        self.last_stage = "full"
        status, reason = Status.OK, ""
        # the EE box (eq. (17)) and collision rows, re-checked whatever solved the stage; not the σ_min
        # floor's row (last): it steers the DM ascent, met to the solver's tolerance (~1e-7 m/rad/s)
        n_hard = problem.n_in - (0 if floor is None else 1)
        if n_hard:
            C, lo, hi = problem.C[:n_hard], problem.l[:n_hard], problem.u[:n_hard]
            e = C[:, : self.n_v] @ z[: self.n_v]
            left = np.flatnonzero((e > hi + EE_BOX_TOL) | (e < lo - EE_BOX_TOL))
            out = _hold_ee_box(C, lo, hi, problem.lb, problem.ub, z, self.n_v, ref)
            if out > 0.0:
                self.ee_box_corrections += 1
                status = Status.SATURATED
                n_box = n_hard - (0 if rows is None else rows.l.shape[0])
                k = int(left[0]) if left.size else 0
                what = "EE box" if k < n_box or rows is None else f"collision row {rows.names[k - n_box]}"
                reason = f"{what}: the solution left it by {out / self.dt:.3g} m/s; projected back onto it"
        if not self._closed_form_hit and task_residual(problem, z) > TASK_CUT:  # the task cut: by which rows first
            cut = self._cut_reason(rows, z[: self.n_v], floor)
            status, reason = Status.SATURATED, f"{cut}; {reason}" if reason else cut
        alpha = self.config.qp.dm_alpha if mode == Mode.DM_NULLSPACE else self.config.qp.alpha
        return self.finish(ctx, z[: self.n_v], xdot, status=status, reason=reason, alpha=alpha)
