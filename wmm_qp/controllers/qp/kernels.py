"""The QP controller's compiled kernels: each stage's fill, the closed-form optimum, the re-check of
the rows (numba, ``wmm_qp/_jit.py``; docs/model.md "Hot path")."""

from __future__ import annotations

import numpy as np

from ..._jit import jit
from ..._typing import FloatArray
from ...linalg3 import solve_spd, solve_sym3
from ...solvers import QPProblem

EE_BOX_TOL = 1e-14  # [m] over one tick: an EE box row violated by less is roundoff (the referee allows 1e-9·Δt)
NO_REF = np.zeros(0)  # _hold_ee_box's reference point: the braking command clip(0, lb, ub) (read only)
NO_REF.setflags(write=False)


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
    """:meth:`SolveCascade.closed_form` compiled: z ← the optimum, True iff every KKT condition holds.

    H's block on v is D + c·rot rotᵀ (D diagonal, c ≥ 0: the base's rotation cost of
    :meth:`QpStages.base_rotation_weight`), inverted by Sherman–Morrison:
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
    """g[:n] += gain·(q − clip(q, q_lower, q_upper)): see :meth:`QpStages.return_term`."""
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
def _hold_ee_box(
    C: FloatArray, l: FloatArray, u: FloatArray, lb: FloatArray, ub: FloatArray, z: FloatArray, n: int,
    ref: FloatArray,
) -> float:
    """The re-checked rows (the EE box of eq. (17), the dampers) on the achieved command v = z[:n],
    whatever solved the stage.

    A solver meets rows l ≤ C v ≤ u only to its primal tolerance (DAQP's and OSQP's are ~1e-6 on
    the EE box's; the clip to lb ≤ v ≤ ub does not touch them). A row left by more than
    ``EE_BOX_TOL`` is restored by the Euclidean projection of v onto that row's half-space inside
    the box bounds, v ← clip(v − λ·C_k, lb, ub) with the least λ ≥ 0 that meets it (by bisection;
    it exists: the rows admit ``ref``, inside the box: the braking command v₀ = clip(0, lb, ub) —
    an empty ``ref`` (``NO_REF``) — or, in the stage whose dampers are relaxed together, the
    command they were relaxed to). If one row's projection moved another out, v ← ref + t(v − ref)
    with the largest t ∈ [0, 1) that meets every row (both ends inside the box bounds, so v still
    is). Returns the largest violation found [m over one tick for the EE box], 0.0 if v met every
    row (then unchanged).
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
