"""The QP controller (docs/model.md "The QP"): its properties, for every solver."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from support.core_fixtures import Q0, model
from support.core_fixtures import config as _config

import wmm_qp as w
from wmm_qp.pseudoinverse import weight_matrix_diag, weighted_pinv
from wmm_qp.solvers import QPProblem, available_solvers
from wmm_qp.verify import check_command

SOLVERS = available_solvers()


def config() -> w.ControllerConfig:
    """The shipped controller config without the collision rows: these tests are about bounds (13),
    the stages and strict priority (the collision rows have their own, tests/core/test_collision.py)."""
    return _config().with_(collision={"enabled": False})


def advance(qb: np.ndarray, qa: np.ndarray, cmd: w.Command, dt: float) -> tuple[np.ndarray, ...]:
    """A kinematic robot executing ``cmd`` for ``dt``: (q_base, q_arm, v_arm, wheel_speeds)."""
    va, wh = cmd.arm_rates, cmd.wheel_speeds
    return qb + model().base.P(qb[2]) @ wh * dt, qa + va * dt, va, wh


def qp(solver: str, **qp_changes: object) -> w.QpController:
    return w.QpController(model(), config().with_(qp={"solver": solver, **qp_changes}))


# 1 ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("closed_form", [True, False])
@pytest.mark.parametrize("solver", SOLVERS)
@pytest.mark.parametrize("alpha", [0.1, 0.2, 0.6])
@pytest.mark.parametrize("seed", range(3))
def test_bounds_inactive_qp_equals_weighted_pseudoinverse(
    solver: str, alpha: float, seed: int, closed_form: bool
) -> None:
    rng = np.random.default_rng(seed)
    qa = Q0 + rng.normal(scale=0.2, size=7)
    qb = np.array([*rng.normal(size=2), rng.uniform(-np.pi, np.pi)])
    kin = model().kinematics(qb, qa)
    xdot = rng.normal(scale=0.02, size=3)
    expected = weighted_pinv(kin.J, weight_matrix_diag(alpha, 4, 7)) @ xdot  # eq. (11)
    # the robot already moves at that command: acceleration bounds centred on it, inactive
    state = w.RobotState(qb, qa, v_arm=expected[4:], wheel_speeds=expected[:4])
    ctl = qp(solver, alpha=alpha, arm_first=False, closed_form_first=closed_form)
    cmd = ctl.step(state, w.Reference("track", x_d=kin.x, xd_d=xdot))
    assert cmd.status == w.Status.OK, cmd.reason
    assert ctl.closed_form_hits == int(closed_form)  # the solver itself ran when closed_form is off
    np.testing.assert_allclose(cmd.v, expected, atol=1e-8, rtol=0)


def _damped_arm() -> np.ndarray:
    """The arm nearly stretched (σ_min(J_m) < 0.06 < 0.08: the singularity damping acts)."""
    from wmm_qp.pseudoinverse import sigma_min

    q = Q0.copy()
    for q4 in np.linspace(1.0, 0.0, 400):  # unfold the elbow towards the stretched singularity
        q[3] = q4
        if sigma_min(model().kinematics(np.zeros(3), q).J_m) < 0.06:
            return q
    raise AssertionError("no damped configuration found")


@pytest.mark.parametrize("closed_form", [True, False])
@pytest.mark.parametrize("solver", SOLVERS)
def test_the_damping_prices_the_base_rotation_like_the_arm(solver: str, closed_form: bool) -> None:
    """Near a singularity the arm's cost is scaled by s = 1 + κ(λ/λ_max)² and so is the base's
    yaw (a rank-one term on the wheels, QpController.base_rotation_weight); the base's
    translation keeps its W_x⁻¹ price. With the bounds inactive every path (closed form by
    Sherman–Morrison, every solver) gives v = H⁻¹Jᵀ(J H⁻¹Jᵀ)⁻¹ ẋ of that H."""
    qa = _damped_arm()
    qb = np.array([0.3, -0.2, 0.7])
    kin = model().kinematics(qb, qa)
    xdot = np.array([0.01, -0.02, 0.005])
    ctl = qp(solver, arm_first=False, closed_form_first=closed_form)
    ctx = ctl.context(w.RobotState(qb, qa), w.Reference("track", x_d=kin.x, xd_d=xdot), need_gradient=False)
    scale = ctl.singular_scale(ctx)
    assert scale > 10.0
    n_w = ctl.n_wheels
    M, M_pinv = model().base.M, model().base.M_pinv
    H = np.diag(ctl.cost_diagonal(ctx, w.Mode.TRACK))
    rot = np.zeros(ctl.n_v)
    rot[:n_w] = M[2]
    H += ctl.base_rotation_weight(ctx, w.Mode.TRACK) * np.outer(rot, rot)
    w_b = 1.0 / weight_matrix_diag(ctl.config.qp.alpha, n_w, 7)[0]
    yaw, trans = M_pinv[:, 2], M_pinv[:, 0]  # the wheel speeds of a pure unit yaw, of a unit v_x
    np.testing.assert_allclose(yaw @ H[:n_w, :n_w] @ yaw, scale * w_b * (yaw @ yaw), rtol=1e-12)
    np.testing.assert_allclose(trans @ H[:n_w, :n_w] @ trans, w_b * (trans @ trans), rtol=1e-12)
    Hi_Jt = np.linalg.solve(H, kin.J.T)
    expected = Hi_Jt @ np.linalg.solve(kin.J @ Hi_Jt, xdot)
    state = w.RobotState(qb, qa, v_arm=expected[n_w:], wheel_speeds=expected[:n_w])  # bounds inactive
    cmd = ctl.step(state, w.Reference("track", x_d=kin.x, xd_d=xdot))
    assert cmd.status == w.Status.DAMPED, cmd.reason
    assert ctl.closed_form_hits == int(closed_form)
    np.testing.assert_allclose(cmd.v, expected, atol=1e-8, rtol=0)


# 2 ------------------------------------------------------------------------------------------
ARM = model().config.arm
LO = np.where(np.isfinite(ARM.position_lower), ARM.position_lower, -np.pi)
HI = np.where(np.isfinite(ARM.position_upper), ARM.position_upper, np.pi)
unit = arrays(np.float64, 7, elements=st.floats(-1.0, 1.0))


@st.composite
def states_and_references(draw: st.DrawFn) -> tuple[w.RobotState, w.Reference]:
    # positions from inside to 0.1 rad beyond the limits; rates up to 1.3× the limits
    q = (LO + HI) / 2 + draw(unit) * ((HI - LO) / 2 + 0.1)
    if draw(st.booleans()):
        q[[1, 3, 5]] *= draw(st.sampled_from([0.0, 0.01]))  # at or near a singularity
    v = draw(unit) * ARM.velocity_max * draw(st.sampled_from([0.0, 0.5, 1.0, 1.3]))
    wmax = model().config.base.wheel_speed_max
    wheels = draw(arrays(np.float64, 4, elements=st.floats(-1.3, 1.3))) * wmax
    qb = draw(arrays(np.float64, 3, elements=st.floats(-3.0, 3.0)))
    x = model().ee_position(qb, q)
    scale = draw(st.sampled_from([1e-3, 0.1, 10.0, 1e3]))
    dx = draw(arrays(np.float64, 3, elements=st.floats(-1.0, 1.0))) * scale
    xd = draw(arrays(np.float64, 3, elements=st.floats(-1.0, 1.0))) * draw(st.sampled_from([0.0, 0.1, 10.0]))
    mode = draw(st.sampled_from(list(w.Mode)))
    direction = draw(st.sampled_from([None, [1.0, 0, 0], [0, 0, 1.0], [0.3, -0.5, 0.8]]))
    return w.RobotState(qb, q, v, wheels), w.Reference(mode, x_d=x + dx, xd_d=xd, direction=direction)


CONTROLLERS = {s: qp(s) for s in SOLVERS}


@pytest.mark.parametrize("solver", SOLVERS)
@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(case=states_and_references())
def test_every_command_respects_every_hard_bound(solver: str, case: tuple[w.RobotState, w.Reference]) -> None:
    state, ref = case
    ctl = CONTROLLERS[solver]
    cmd = ctl.step(state, ref)
    box = (ctl.config.ee_box_lower, ctl.config.ee_box_upper) if ref.mode == w.Mode.DM_CARTESIAN else None
    res = check_command(model().config, ctl.dt, state, cmd, tol=1e-9, model=model(), ee_box=box)
    assert sum(res.values()) == 0, (res, cmd.status, cmd.reason)


# 3 ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("closed_form", [True, False])
@pytest.mark.parametrize("solver", SOLVERS)
@pytest.mark.parametrize("seed", range(4))
def test_dm_term_never_changes_the_achieved_task_velocity(solver: str, seed: int, closed_form: bool) -> None:
    rng = np.random.default_rng(10 + seed)
    qa = Q0 + rng.normal(scale=0.3, size=7)
    qb = np.zeros(3)
    kin = model().kinematics(qb, qa)
    xdot = rng.normal(scale=0.01, size=3)
    v_prev = np.linalg.pinv(kin.J) @ xdot  # moving: the task is feasible from here
    state = w.RobotState(qb, qa, v_arm=v_prev[4:], wheel_speeds=v_prev[:4])
    with_dm = qp(solver, closed_form_first=closed_form).step(
        state, w.Reference("dm_nullspace", x_d=kin.x, xd_d=xdot, direction=rng.normal(size=3))
    )
    without = qp(solver, arm_first=False, closed_form_first=closed_form).step(
        state, w.Reference("track", x_d=kin.x, xd_d=xdot)
    )
    assert without.task_error < 1e-8  # feasible
    np.testing.assert_allclose(kin.J @ with_dm.v, kin.J @ without.v, atol=1e-8, rtol=0)
    assert np.linalg.norm(with_dm.v - without.v) > 1e-6  # the DM term did act, in the null space


# 4 ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("solver", SOLVERS)
def test_wheels_still_while_the_arm_suffices_then_base_supplies_the_rest(solver: str) -> None:
    ctl = qp(solver)
    dt = ctl.dt
    qb, qa, va, wh = np.zeros(3), Q0.copy(), np.zeros(7), np.zeros(4)
    x0 = model().ee_position(qb, qa)
    # +x at 0.15 m/s, ramped in over 1 s (as the service's Ruckig smoothing does): the arm alone
    # can follow at first, then runs out of reach
    wheels_zero_until, errs = None, []
    for k in range(int(8.0 / dt)):
        t = k * dt
        speed = 0.15 * min(t, 1.0)
        pos = 0.075 * t**2 if t < 1.0 else 0.075 + 0.15 * (t - 1.0)
        ref = w.Reference("track", x_d=x0 + [pos, 0, 0], xd_d=[speed, 0, 0])
        cmd = ctl.step(w.RobotState(qb, qa, va, wh), ref)
        assert cmd.status != w.Status.SAFE_STOP, cmd.reason
        if wheels_zero_until is None and np.abs(cmd.wheel_speeds).max() >= 1e-9:
            wheels_zero_until = t
        qb, qa, va, wh = advance(qb, qa, cmd, dt)
        errs.append(np.linalg.norm(model().ee_position(qb, qa) - ref.x_d))
    assert wheels_zero_until is not None and wheels_zero_until > 1.0  # arm alone at first: |w| < 1e-9
    assert np.abs(wh).max() > 0.1  # base supplies the remainder at the end
    assert max(errs[-500:]) < 1e-3  # and the task is still met


# 5 ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("solver", SOLVERS)
def test_solver_failure_gives_a_safe_stop_inside_the_acceleration_bounds(
    solver: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    from wmm_qp.solvers import QPSolution

    ctl = qp(solver)
    for backend in (ctl._arm, ctl._full, ctl._fallback):
        if backend is not None:
            monkeypatch.setattr(backend, "solve", lambda p: QPSolution(z=None, ok=False, status="forced failure"))
    v = np.linspace(-1, 1, 7)
    state = w.RobotState(np.zeros(3), Q0, v_arm=v, wheel_speeds=np.full(4, 3.0))
    cmd = ctl.step(state, w.Reference("track", x_d=[1, 0, 0.5]))
    assert cmd.status == w.Status.SAFE_STOP and "failed" in cmd.reason
    assert sum(check_command(model().config, ctl.dt, state, cmd).values()) == 0
    assert (np.abs(cmd.arm_rates) < np.abs(v) + 1e-15).all()  # braking


@pytest.mark.parametrize("solver", SOLVERS)
def test_backend_exception_never_leaks(solver: str, monkeypatch: pytest.MonkeyPatch) -> None:
    ctl = qp(solver)
    monkeypatch.setattr(ctl, "build", lambda *a: (_ for _ in ()).throw(np.linalg.LinAlgError("singular")))
    monkeypatch.setattr(ctl, "build_arm_first", lambda *a: (_ for _ in ()).throw(np.linalg.LinAlgError("singular")))
    cmd = ctl.step(w.RobotState(np.zeros(3), Q0), w.Reference("track", x_d=[1, 0, 0.5]))
    assert cmd.status == w.Status.SAFE_STOP and "singular" in cmd.reason


def test_unknown_solver_is_a_clear_error() -> None:
    with pytest.raises(w.SolverNotFound, match="choose one of"):
        qp("cplex")


# 6 is tests/service/test_cli.py::test_verify_reports_zero_violations_for_every_qp_solver


def test_the_problem_is_inspectable() -> None:
    ctl = qp(SOLVERS[0], arm_first=False)
    x = model().ee_position(np.zeros(3), Q0)
    ctl.step(w.RobotState(np.zeros(3), Q0), w.Reference("track", x_d=x, xd_d=[1e-3, 0, 0]))
    p = ctl.last_problem
    assert p is not None and p.n == 17 and p.n_eq == 3
    assert p.violation(np.zeros(p.n)) > 0  # zero does not meet the task: the equality is real


def _dm_after(ctl: w.QpController, seconds: float) -> tuple[float, float]:
    """Null-space DM along x from the paper's start, closed loop; (final DM, max |wheel|)."""
    dt = ctl.dt
    qb, qa, va, wh = np.zeros(3), Q0.copy(), np.zeros(7), np.zeros(4)
    x0 = model().ee_position(qb, qa)
    ref = w.Reference("dm_nullspace", x_d=x0, direction=[1.0, 0, 0])
    wmax, dm = 0.0, float("nan")
    for _ in range(int(seconds / dt)):
        cmd = ctl.step(w.RobotState(qb, qa, va, wh), ref)
        assert cmd.status != w.Status.SAFE_STOP and cmd.task_error < 1e-6, (cmd.status, cmd.reason)
        qb, qa, va, wh = advance(qb, qa, cmd, dt)
        wmax, dm = max(wmax, float(np.abs(wh).max())), cmd.dm
    return dm, wmax


def test_in_nullspace_dm_mode_the_base_serves_the_dm_objective() -> None:
    """DESIGN §2 item 4: eq. (18)'s projector uses the full J, so the base moves and the arm can
    stretch beyond what it reaches with the base (nearly) still."""
    dm_base, wheels_base = _dm_after(qp("daqp"), 8.0)  # dm_alpha = 0.99: the base is cheap here
    dm_arm, _ = _dm_after(qp("daqp", dm_alpha=0.2), 8.0)
    assert wheels_base > 0.1
    assert dm_base > 4.5 > dm_arm  # the arm alone tops out near 4.1


@pytest.mark.parametrize("solver", [s for s in SOLVERS if s != "daqp"])
def test_a_stage_the_solver_fails_on_is_solved_by_the_fallback(solver: str, monkeypatch: pytest.MonkeyPatch) -> None:
    from wmm_qp.solvers import QPSolution

    ctl = qp(solver)
    monkeypatch.setattr(ctl._full, "solve", lambda p: QPSolution(z=None, ok=False, status="forced failure"))
    x = model().ee_position(np.zeros(3), Q0)
    cmd = ctl.step(w.RobotState(np.zeros(3), Q0), w.Reference("dm_nullspace", x_d=x))
    assert cmd.status != w.Status.SAFE_STOP and ctl.fallbacks == 1


def test_after_a_failure_the_stage_goes_to_daqp_first_for_a_window(monkeypatch: pytest.MonkeyPatch) -> None:
    """Hard instances come in runs: after the configured solver failed on a stage, that stage's
    next DAQP_FIRST solves go to DAQP first; at the window's end the configured solver starts
    again, cold; a DAQP failure ends the window at once (the configured solver tries the stage)."""
    import copy

    from wmm_qp.controllers.qp.cascade import DAQP_FIRST
    from wmm_qp.solvers import QPSolution

    ctl = qp("proxsuite", closed_form_first=False)
    x = model().ee_position(np.zeros(3), Q0)
    ctl.step(w.RobotState(np.zeros(3), Q0), w.Reference("dm_nullspace", x_d=x))
    problem = ctl.last_problem  # the full stage's QP of one step at Q0
    assert problem is not None
    ctl.reset()  # (that step's solve may have opened a window: its QP is a hard one)
    full, daqp = ctl._full, ctl._fallback
    assert daqp is not None
    calls: list[str] = []
    fail_full = [True]
    solve_full, solve_daqp, reset_full = full.solve, daqp.solve, full.reset

    def full_solve(p: QPProblem) -> QPSolution:
        calls.append("full")
        return QPSolution(z=None, ok=False, status="forced") if fail_full[0] else solve_full(p)

    def daqp_solve(p: QPProblem) -> QPSolution:
        calls.append("daqp")
        return solve_daqp(p)

    def full_reset() -> None:
        calls.append("reset")
        reset_full()

    monkeypatch.setattr(full, "solve", full_solve)
    monkeypatch.setattr(daqp, "solve", daqp_solve)
    monkeypatch.setattr(full, "reset", full_reset)

    def solve() -> object:
        return ctl._solve(full, copy.deepcopy(problem))

    assert solve() is not None
    assert calls == ["full", "daqp"] and ctl.fallbacks == 1  # failed, DAQP solved it
    fail_full[0] = False
    calls.clear()
    for _ in range(DAQP_FIRST):
        assert solve() is not None
    assert calls == ["daqp"] * (DAQP_FIRST - 1) + ["reset", "daqp"] and ctl.daqp_first == DAQP_FIRST
    calls.clear()
    solve()
    assert calls == ["full"]  # the window is over: the configured solver again (cold)
    fail_full[0] = True
    solve()  # a failure opens a new window
    fail_full[0] = False
    monkeypatch.setattr(daqp, "solve", lambda p: QPSolution(z=None, ok=False, status="forced"))
    calls.clear()
    assert solve() is not None  # DAQP failed in the window: the configured solver solved it
    assert calls == ["full"]
    calls.clear()
    solve()
    assert calls == ["full"]  # and the window ended there


def test_failures_right_after_windows_lengthen_them_and_daqps_infeasible_verdict_stands(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """A stage the configured solver keeps failing on (TIAGo's rows at its column): each failure
    on the first solve after a window opens one four times as long (up to DAQP_FIRST_MAX); a
    plain success brings it back to DAQP_FIRST; a success the backend reports hard opens a window
    and keeps its answer; DAQP's "infeasible" inside a window is the stage's answer (None), the
    configured solver is not asked, and the window goes on."""
    import copy

    from wmm_qp.controllers.qp.cascade import DAQP_FIRST, DAQP_FIRST_MAX
    from wmm_qp.solvers import QPSolution

    ctl = qp("proxsuite", closed_form_first=False)
    x = model().ee_position(np.zeros(3), Q0)
    ctl.step(w.RobotState(np.zeros(3), Q0), w.Reference("dm_nullspace", x_d=x))
    problem = ctl.last_problem
    assert problem is not None
    ctl.reset()
    full, daqp = ctl._full, ctl._fallback
    assert daqp is not None
    mode = ["fail"]
    solve_full, solve_daqp = full.solve, daqp.solve
    calls: list[str] = []

    def full_solve(p: QPProblem) -> QPSolution:
        calls.append("full")
        if mode[0] == "fail":
            return QPSolution(z=None, ok=False, status="forced")
        sol = solve_full(p)
        sol.hard = mode[0] == "hard"
        return sol

    def daqp_solve(p: QPProblem) -> QPSolution:
        calls.append("daqp")
        return solve_daqp(p)

    monkeypatch.setattr(full, "solve", full_solve)
    monkeypatch.setattr(daqp, "solve", daqp_solve)

    def solve() -> object:
        return ctl._solve(full, copy.deepcopy(problem))

    def window() -> int:
        """Solves that go to DAQP first before the configured solver is asked again (and is)."""
        n = 0
        while True:
            calls.clear()
            solve()
            if calls[0] == "full":
                return n
            n += 1

    solve()  # the first failure: a window of DAQP_FIRST
    lengths = [window() for _ in range(5)]  # the configured solver fails again at each window's end
    assert lengths == [DAQP_FIRST, 4 * DAQP_FIRST, 16 * DAQP_FIRST, min(64 * DAQP_FIRST, DAQP_FIRST_MAX),
                       DAQP_FIRST_MAX], lengths
    mode[0] = "ok"
    assert window() == DAQP_FIRST_MAX  # ... and now succeeds: the next failure opens DAQP_FIRST again
    mode[0] = "fail"
    calls.clear()
    solve()
    assert calls == ["full", "daqp"]
    mode[0] = "ok"
    assert window() == DAQP_FIRST
    mode[0] = "hard"
    calls.clear()
    assert solve() is not None and calls == ["full"]  # solved, but hard: its answer kept ...
    mode[0] = "ok"
    assert window() == DAQP_FIRST  # ... and a window opened
    mode[0] = "fail"
    solve()  # a window again
    assert daqp._prev is not None  # DAQP's primal start, kept between its solves ...
    ctl.reset()
    assert daqp._prev is None  # ... and forgotten by a reset, as every warm start
    mode[0] = "fail"
    solve()  # a window again
    monkeypatch.setattr(daqp, "solve", lambda p: (calls.append("daqp"), QPSolution(z=None, ok=False,
                                                                                    status="infeasible"))[1])
    calls.clear()
    assert solve() is None and calls == ["daqp"]  # DAQP's exact verdict stands inside the window
    calls.clear()
    solve()
    assert calls == ["daqp"]  # and the window goes on


def test_proxsuite_reports_a_cold_retry_or_many_iterations_as_hard(monkeypatch: pytest.MonkeyPatch) -> None:
    """The backend's side of the windows: an easy solve is not hard; one that reached
    HARD_ITERATIONS is; so is one solved only on the cold retry after a failed warm start."""
    from wmm_qp.solvers import proxsuite_backend as pb

    ctl = qp("proxsuite", closed_form_first=False)
    x = model().ee_position(np.zeros(3), Q0)
    ctl.step(w.RobotState(np.zeros(3), Q0), w.Reference("dm_nullspace", x_d=x))
    problem = ctl.last_problem
    assert problem is not None
    backend = pb.ProxsuiteBackend()
    easy = backend.solve(problem)
    assert easy.ok and not easy.hard and easy.iterations < pb.HARD_ITERATIONS
    monkeypatch.setattr(pb, "HARD_ITERATIONS", max(1, easy.iterations))
    backend.reset()  # the same cold solve again (warm, it takes none)
    assert backend.solve(problem).hard  # as many iterations as the threshold: hard
    monkeypatch.setattr(pb, "HARD_ITERATIONS", 1000)
    backend.reset()
    real = backend._solve
    first = [True]

    def warm_fails(p: QPProblem) -> pb.QPSolution:
        if first[0]:
            first[0] = False
            return pb.QPSolution(z=None, ok=False, status="PROXQP_MAX_ITER_REACHED", iterations=30)
        return real(p)

    monkeypatch.setattr(backend, "_solve", warm_fails)
    retried = backend.solve(problem)
    assert retried.ok and retried.hard and "cold retry" in retried.status


def test_jumpy_reference_stream_never_needs_a_safe_stop() -> None:
    """Regression: warm-started ProxQP stalled after reference jumps (now: cold retry, then DAQP)."""
    ctl = qp("proxsuite").__class__(model(), config().with_(rate_hz=1000.0))
    rng = np.random.default_rng(0)
    qb, qa, va, wh = np.zeros(3), Q0.copy(), np.zeros(7), np.zeros(4)
    x0 = model().ee_position(qb, qa)
    target, xd = x0.copy(), x0.copy()
    for _ in range(4000):
        if rng.random() < 0.01:
            target = x0 + rng.normal(scale=0.08, size=3)
        step = np.clip(target - xd, -0.2e-3, 0.2e-3)
        xd = xd + step
        cmd = ctl.step(w.RobotState(qb, qa, va, wh), w.Reference("track", x_d=xd, xd_d=step / 1e-3))
        assert cmd.status != w.Status.SAFE_STOP, cmd.reason
        qb, qa, va, wh = advance(qb, qa, cmd, 1e-3)


@pytest.mark.parametrize("solver", SOLVERS)
@pytest.mark.parametrize("mode", ["track", "dm_nullspace"])
def test_a_joint_past_its_limit_is_brought_back_without_breaking_the_task(solver: str, mode: str) -> None:
    q = Q0.copy()
    q[3] = ARM.position_upper[3] + 1e-3  # 1 mrad past joint 4's limit, at rest
    ctl = qp(solver)
    x = model().ee_position(np.zeros(3), q)
    qa, va, wh, qb = q.copy(), np.zeros(7), np.zeros(4), np.zeros(3)
    for _ in range(100):
        cmd = ctl.step(w.RobotState(qb, qa, va, wh), w.Reference(mode, x_d=x))
        assert cmd.task_error < 1e-6
        qb, qa, va, wh = advance(qb, qa, cmd, ctl.dt)
    assert qa[3] <= ARM.position_upper[3]  # back inside within 0.2 s


@st.composite
def feasible_nullspace_cases(draw: st.DrawFn) -> tuple[w.RobotState, np.ndarray, list[float]]:
    """A state (near singularities, moving, bounds active) and θ ∈ [0, 1]¹¹ that places a command
    v* = lo + θ(hi − lo) inside the state's hard bounds (θ's entries are often exactly 0 or 1: v* on
    a face or a vertex of the bounds)."""
    q = Q0 + draw(arrays(np.float64, 7, elements=st.floats(-1.0, 1.0)))
    if draw(st.booleans()):
        q[[1, 3, 5]] = draw(arrays(np.float64, 3, elements=st.floats(-0.05, 0.05)))  # near singular
    v = (
        draw(arrays(np.float64, 7, elements=st.floats(-1.0, 1.0)))
        * ARM.velocity_max
        * draw(st.sampled_from([0.0, 0.3, 1.0]))
    )
    wh = draw(arrays(np.float64, 4, elements=st.floats(-1.0, 1.0))) * draw(st.sampled_from([0.0, 1.0, 5.0]))
    theta = draw(arrays(np.float64, 11, elements=st.floats(0.0, 1.0)))
    u = draw(st.sampled_from([[1.0, 0, 0], [0, 0, 1.0], [0.6, 0.0, 0.8]]))
    return w.RobotState(np.zeros(3), q, v, wh), theta, u


# task_speed_max raised so that ẋ_ref = J v* is never scaled down (a scaled task need not be feasible)
PRIORITY = {
    (s, k_N): w.QpController(model(), config().with_(k_N=k_N, qp={"solver": s, "task_speed_max": 1e3}))
    for s in SOLVERS
    for k_N in (config().k_N, 0.0)
}


@pytest.mark.parametrize("solver", SOLVERS)
@settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(case=feasible_nullspace_cases())
def test_strict_priority_whenever_the_task_is_feasible(
    solver: str, case: tuple[w.RobotState, np.ndarray, list[float]]
) -> None:
    """Property 3 over random states (near singularities, active bounds): the DM term (k_N = 0.2,
    vs. 0 with the same weights) never changes the achieved task velocity while it is feasible.

    Feasible by construction, no solver asked: ẋ_ref = J v* for a v* inside this state's hard bounds
    (wheel bounds and eq. (13), the controller's own feasible set), with x_d = x so that ẋ_ref = ẋ_d.
    No example is skipped."""
    state, theta, u = case
    with_dm, without = PRIORITY[solver, config().k_N], PRIORITY[solver, 0.0]
    ctx = with_dm.context(state, w.Reference("dm_nullspace", direction=u), need_gradient=False)
    lo, hi = with_dm.box(ctx)  # the bounds depend on the state only
    v_star = lo + theta * (hi - lo)
    J = ctx.kin.J
    ref = w.Reference("dm_nullspace", x_d=ctx.kin.x, xd_d=J @ v_star, direction=u)
    xdot_ref = with_dm.reference_velocity(with_dm.context(state, ref, True), ref)
    np.testing.assert_allclose(xdot_ref, J @ v_star, atol=1e-12, rtol=0)  # the task is J v = J v*
    # the controller's own exactness contract: a stage whose max |J v − ẋ_ref| exceeds 1e-6 m/s
    # is re-solved exactly (qp.py); OSQP (ADMM) works to its 1e-6 on top. (1e-7 failed for DAQP
    # next to a singularity: 2e-7, inside the contract.)
    tol = 2e-6 if solver == "osqp" else 1e-6
    a, b = with_dm.step(state, ref), without.step(state, ref)
    for cmd in (a, b):
        assert cmd.status in (w.Status.OK, w.Status.DAMPED), (cmd.status, cmd.reason)  # feasible: met
        assert sum(check_command(model().config, with_dm.dt, state, cmd).values()) == 0
        np.testing.assert_allclose(J @ cmd.v, xdot_ref, atol=tol, rtol=0)
    np.testing.assert_allclose(J @ a.v, J @ b.v, atol=2 * tol, rtol=0)  # the DM term changed no task velocity


@pytest.mark.parametrize("solver", SOLVERS)
def test_wheels_exactly_still_on_every_tick_the_arm_alone_can_do_it(solver: str) -> None:
    """Property 4 per tick: whenever an arm-only, hard-equality QP is feasible (wheels at rest), |w| < 1e-9."""
    from wmm_qp.solvers import QPProblem, make_backend

    ctl = qp(solver)
    checker = make_backend("daqp")
    dt = ctl.dt
    rng = np.random.default_rng(3)
    qb, qa, va, wh = np.zeros(3), Q0.copy(), np.zeros(7), np.zeros(4)
    x = model().ee_position(qb, qa)
    checked = 0
    for k in range(1500):
        if k % 150 == 0:
            target = x + rng.normal(scale=0.05, size=3)
        x = x + np.clip(target - x, -1e-4, 1e-4)
        ref = w.Reference("track", x_d=x, xd_d=np.clip(target - x, -1e-4, 1e-4) / dt)
        state = w.RobotState(qb, qa, va, wh)
        ctx = ctl.context(state, ref, False)
        xdot = ctl.reference_velocity(ctx, ref)
        if np.abs(wh).max() == 0.0:
            p = QPProblem(
                H=np.eye(7),
                g=np.zeros(7),
                A=ctx.kin.J_m,
                b=xdot,
                C=np.zeros((0, 7)),
                l=np.zeros(0),
                u=np.zeros(0),
                lb=ctx.arm_lo,
                ub=ctx.arm_hi,
            )
            arm_alone = checker.solve(p).ok
        else:
            arm_alone = False
        cmd = ctl.step(state, ref)
        if arm_alone:
            checked += 1
            assert np.abs(cmd.wheel_speeds).max() < 1e-9
        qb, qa, va, wh = advance(qb, qa, cmd, dt)
    assert checked > 1000


@pytest.mark.parametrize("solver", SOLVERS)
def test_driving_into_a_joint_limit_never_passes_it(solver: str) -> None:
    """Closed loop: pull the EE towards the base so the elbow (joint 4) folds into its limit."""
    ctl = qp(solver)
    dt = ctl.dt
    qb, qa, va, wh = np.zeros(3), Q0.copy(), np.zeros(7), np.zeros(4)
    x0 = model().ee_position(qb, qa)
    for k in range(2500):
        t = k * dt
        ref = w.Reference("track", x_d=x0 + [-0.12 * t, 0, 0], xd_d=[-0.12, 0, 0])
        cmd = ctl.step(w.RobotState(qb, qa, va, wh), ref)
        qb, qa, va, wh = advance(qb, qa, cmd, dt)
        assert (qa <= ARM.position_upper + 1e-12).all() and (qa >= ARM.position_lower - 1e-12).all()
    assert qa[3] > ARM.position_upper[3] - 0.05  # it did reach the limit's neighbourhood


def test_hold_without_a_target_holds_still() -> None:
    ctl = qp("daqp")
    cmd = ctl.step(w.RobotState(np.zeros(3), Q0), w.Reference("hold"))
    np.testing.assert_allclose(cmd.v, 0.0, atol=1e-12)


# The EE box of DM_CARTESIAN, eq. (17), re-checked on every solver path (once relaxed, never re-checked) -
def _box_edge_case() -> tuple[w.ControllerConfig, w.RobotState, w.Reference, np.ndarray]:
    """At rest at the paper's start, DM along z moves the EE down by dt·1.76 mm/s per tick; the box's
    floor sits half a tick's motion below it. The exact-task command (the paper's J# v_c, inside
    bounds (13)) crosses the floor; a command that respects the box must leave the task unmet."""
    state = w.RobotState(np.zeros(3), Q0)
    ref = w.Reference("dm_cartesian", direction=[0.0, 0.0, 1.0])
    v_task = w.PaperController(model(), config()).step(state, ref).v
    x, J, dt = model().ee_position(state.q_base, Q0), model().kinematics(state.q_base, Q0).J, config().dt
    assert (J @ v_task)[2] < -1e-3  # moving down
    floor = x[2] + 0.5 * dt * (J @ v_task)[2]
    cfg = config().with_(ee_box_lower=np.array([-np.inf, -np.inf, floor]))
    return cfg, state, ref, v_task


def _solution(v: np.ndarray) -> object:
    from wmm_qp.solvers import QPSolution

    return QPSolution(z=np.concatenate([v, np.zeros(6)]), ok=True, status="solved")


PATHS = [("primary", s) for s in SOLVERS] + [("task_first", s) for s in SOLVERS]
PATHS += [("fallback", s) for s in SOLVERS if s != "daqp"] + [("real", s) for s in SOLVERS]


@pytest.mark.parametrize(("path", "solver"), PATHS)
def test_the_ee_box_holds_whatever_solved_the_stage(path: str, solver: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """A solver answer that meets the task but leaves the EE box (within a solver's primal
    tolerance, DAQP's and OSQP's are ~1e-6 on these rows) is pulled back onto the box: from the
    configured solver ("primary"), from the DAQP fallback after a failure ("fallback"), from DAQP's
    exact re-solve of a stage that left slack ("task_first"); "real": no solver replaced."""
    from wmm_qp.solvers import QPSolution

    cfg, state, ref, v_task = _box_edge_case()
    ctl = w.QpController(model(), cfg.with_(qp={"solver": solver}))
    crossing = _solution(v_task)
    failed = QPSolution(z=None, ok=False, status="forced failure")
    slack_left = _solution(np.zeros(11))  # meets no task: the stage is re-solved with the task exact
    assert ctl._fallback is not None
    if path == "primary":
        monkeypatch.setattr(ctl._full, "solve", lambda p: crossing)
    elif path == "fallback":
        monkeypatch.setattr(ctl._full, "solve", lambda p: failed)
        monkeypatch.setattr(ctl._fallback, "solve", lambda p: crossing)
    elif path == "task_first":
        monkeypatch.setattr(ctl._full, "solve", lambda p: slack_left)
        monkeypatch.setattr(ctl._fallback, "solve", lambda p: crossing)
    cmd = ctl.step(state, ref)
    box = (cfg.ee_box_lower, cfg.ee_box_upper)
    assert check_command(model().config, ctl.dt, state, cmd, model=model(), ee_box=box) == dict.fromkeys(
        ("position", "velocity", "acceleration", "wheel", "ee_box", "collision"), 0
    )
    x, J = model().ee_position(state.q_base, Q0), model().kinematics(state.q_base, Q0).J
    z_next = x[2] + ctl.dt * (J @ cmd.v)[2]
    assert z_next >= cfg.ee_box_lower[2] - 1e-15  # the EE stays above the floor ...
    assert z_next < cfg.ee_box_lower[2] + 1e-12  # ... and goes down to it: the least change
    assert cmd.status == w.Status.SATURATED
    if path != "real":
        assert ctl.ee_box_corrections == 1 and "EE box" in cmd.reason
        assert np.abs(cmd.v - v_task).max() < np.abs(v_task).max()  # projected, not a full stop


@settings(max_examples=300, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    rows=st.integers(1, 3),
    relaxed=st.booleans(),
)
def test_the_ee_box_recheck_restores_every_row_inside_the_box_bounds(seed: int, rows: int, relaxed: bool) -> None:
    """_hold_ee_box on random rows that admit v₀ = clip(0, lb, ub) (as _ee_box builds them, some
    relaxed to exactly C v₀): after it, every row and every box bound holds."""
    from wmm_qp.controllers.qp.kernels import EE_BOX_TOL, _hold_ee_box

    rng = np.random.default_rng(seed)
    n = 11
    lb = rng.uniform(-1.0, 0.5, n)
    ub = lb + rng.uniform(0.0, 1.0, n)
    C = np.zeros((rows, n + 6))
    C[:, :n] = rng.normal(size=(rows, n)) * 1e-3
    reach = C[:, :n] @ np.clip(0.0, lb, ub)
    l = np.minimum(reach, reach - rng.uniform(0, 1e-3, rows) * (not relaxed))
    u = np.maximum(reach, reach + rng.uniform(0, 1e-3, rows) * (not relaxed))
    z = np.concatenate([rng.uniform(lb, ub), np.zeros(6)])
    before = z.copy()
    worst = _hold_ee_box(C, l, u, lb, ub, z, n, np.clip(0.0, lb, ub))
    Cv = C[:, :n] @ z[:n]
    assert (Cv <= u + EE_BOX_TOL).all() and (Cv >= l - EE_BOX_TOL).all()
    assert (z[:n] >= lb).all() and (z[:n] <= ub).all()
    was = C[:, :n] @ before[:n]
    held = ((was <= u + EE_BOX_TOL) & (was >= l - EE_BOX_TOL)).all()
    assert (worst == 0.0) == held
    if held:
        np.testing.assert_array_equal(z, before)  # a command inside the box is not touched
