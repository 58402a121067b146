"""The QP controller's stages as problems (build, then solve: the solving is :mod:`.cascade`).

Decision variable z = [v_b; v_m; s⁺; s⁻] (wheel speeds, joint rates, task slack s = s⁺ − s⁻ ∈ Rʳ;
r = 3 for the position task, 6 for the pose task, whose angular rows the base controller scales
by ``task.orientation_weight``):

    minimize    ½ vᵀ W_x⁻¹ v − (W_x⁻¹ v_n)ᵀ v + ρ₁ 1ᵀ(s⁺ + s⁻) + ½ ρ₂ (‖s⁺‖² + ‖s⁻‖²)
    subject to  J v + s⁺ − s⁻ = ẋ_ref                      task, eq. (5)
                lb ≤ v ≤ ub                                   eq. (13), the wheel bounds; s± ≥ 0
                l ≤ C v ≤ u                                   the row sources' rows (limits/rows.py)

W_x = diag(α I_wheels, (1−α) I_joints) is eq. (12) (α = ``qp.alpha`` small: the base is expensive; in
DM_NULLSPACE α = ``qp.dm_alpha``, close to 1, so the base serves the DM objective) and
v_n = k_N [0; ∇H2ᵀ] is eq. (19), in DM_NULLSPACE only. With s ≡ 0 and no bound active,
½(v − v_n)ᵀW_x⁻¹(v − v_n) subject to J v = ẋ_ref is solved by J# ẋ_ref + (I − J#J) v_n:
eqs. (11) and (18) exactly. The slack's exact penalty ρ₁‖s‖₁ keeps the task a hard equality
whenever the bounds admit it; when they cannot, the task degrades instead of the stage failing.

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
factor (:meth:`QpStages.base_rotation_weight`: ½ c ω² with ω the yaw row of the base's M, eq. (3)),
so that the damping hands the arm's work to the base's translation and not to its rotation; the
wheel block of the cost is then diag(W_x⁻¹) + c·rot rotᵀ, which the closed form inverts by
Sherman–Morrison.

Stages: 1. the arm first (TRACK/HOLD, ``qp.arm_first``): the wheels held at the admissible speed
nearest 0, the arm alone (:meth:`QpStages.build_arm_first`); 2. the whole robot (:meth:`QpStages.build`).
"""

from __future__ import annotations

import math

import numpy as np

from ..._jit import jit
from ..._typing import FloatArray
from ...config import ControllerConfig
from ...manipulability.preference import dm_preference_gain
from ...model.wmm import WmmModel
from ...pseudoinverse import weight_matrix_diag
from ...solvers import INF, QPProblem
from ...types import Mode, Reference
from ..base import Controller, TickContext
from .kernels import _add_nullspace_term, _add_return_term, _fill_stage
from .stage_rows import StageRows

RETURN_TIME = 0.05  # [s] a joint past a position limit is pulled back in over about this long
RETURN_WEIGHT = 1e3  # outweighs minimal-motion costs (the base's too), stays below the task's ρ₁
_NO_HOLD = np.zeros(0)  # stage 2 holds no column


def _saturated(v: FloatArray, feedforward: FloatArray, limit: float) -> FloatArray:
    """v with its feedback part v − feedforward scaled down to the norm ``limit``."""
    fb = v - feedforward
    e = math.sqrt(float(fb @ fb))
    return feedforward + fb * (limit / e) if e > limit else v


@jit
def _track_velocity(xd_d: FloatArray, x_d: FloatArray, x: FloatArray, K_x: float, recovery: float,
                    cap: float) -> FloatArray:
    """:meth:`QpStages.reference_velocity` of the position task with a target x_d, compiled:
    ẋ_d + K_x (x_d − x) (eq. (18)), its error term saturated at ``recovery``, then the whole scaled
    down to the norm ``cap``."""
    v = np.empty(3)
    for i in range(3):
        v[i] = xd_d[i] + K_x * (x_d[i] - x[i])  # eq. (18)
    e = math.sqrt((v[0] - xd_d[0]) ** 2 + (v[1] - xd_d[1]) ** 2 + (v[2] - xd_d[2]) ** 2)
    if e > recovery:  # _saturated
        for i in range(3):
            v[i] = xd_d[i] + (v[i] - xd_d[i]) * (recovery / e)
    n = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    if n > cap:
        for i in range(3):
            v[i] = v[i] * (cap / n)
    return v


class QpStages(Controller):
    """The QP controller's stage problems (the module docstring): its cost, its task rows, its
    bounds and rows, in preallocated problems (the hot path allocates no QP matrices)."""

    def __init__(self, model: WmmModel, config: ControllerConfig) -> None:
        super().__init__(model, config)
        qp = config.qp
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
        self._v_n_max = 10.0 * self.robot.arm.velocity_max
        # ρ of the normalised DM preference, at most the slowest joint's velocity limit
        self._dm_speed = min(qp.dm_speed, float(np.min(self.robot.arm.velocity_max, initial=np.inf)))
        self._return_gain = RETURN_WEIGHT * self._w_inv[self.n_wheels :] / RETURN_TIME  # see return_term

    def build_arm_first(self, ctx: TickContext, xdot: FloatArray, rows: StageRows) -> tuple[QPProblem, FloatArray]:
        """Stage 1: the arm alone, wheels held at the admissible speed nearest 0; every row with the
        held wheels' share moved to its bounds, relaxed to what the arm alone can do
        (:meth:`StageRows.for_the_arm`). Returns the problem and the held wheel speeds."""
        p = self._template(self.n_arm, rows.n)
        w_hold = np.empty(self.n_wheels)
        arm = self.robot.arm
        _fill_stage(ctx.kin.J, xdot, ctx.lo, ctx.hi, self._w_inv[self.n_wheels :], self._no_rot, 0.0,
                    p.H, p.A, p.b, p.lb, p.ub, w_hold)
        self._cost_rank1 = (self._no_rot, 0.0)
        p.g[: self.n_arm] = 0.0
        _add_return_term(ctx.kin.q_arm, arm.position_lower, arm.position_upper, self._return_gain, p.g)
        if rows.n:  # l ≤ C_arm v_m + C_w w_hold ≤ u
            rows.for_the_arm(self.n_wheels, w_hold, p.lb, p.ub, p.C, p.l, p.u)  # (v_m's bounds: their first n_arm)
        return p, w_hold

    def build(self, ctx: TickContext, xdot: FloatArray, mode: Mode, rows: StageRows, brake: bool = False) -> QPProblem:
        """Stage 2: the whole robot (see the module docstring), with every row of ``rows``;
        ``brake``: the rows relaxed as the stage solved again when they exclude each other has them."""
        C, l, u = rows.limits(brake)
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

    def box(self, ctx: TickContext) -> tuple[FloatArray, FloatArray]:
        """Hard bounds on v = [v_b; v_m]: wheel bounds and eq. (13)."""
        return ctx.lo, ctx.hi

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
        if not self.pose and reference.x_d is not None and reference.mode != Mode.DM_CARTESIAN:
            qp = self.config.qp  # the position task's every tick but the Cartesian DM's: one compiled call
            return _track_velocity(reference.xd_d, reference.x_d, ctx.kin.x, self.config.K_x, qp.recovery_speed,
                                   qp.task_speed_max)
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
