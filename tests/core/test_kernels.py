"""The compiled hot path's guards: shapes, caches, warm-up (wmm_qp/_jit.py and its callers)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from support.core_fixtures import Q0, config, model, random_arm_q

import wmm_qp as w
from wmm_qp import _jit
from wmm_qp.controllers.qp.stage_rows import RowGroup, StageRows
from wmm_qp.controllers.qp.stages import _saturated
from wmm_qp.limits import joint_motion_bounds
from wmm_qp.limits.ee_box import EeBox
from wmm_qp.limits.rows import Rows
from wmm_qp.solvers import INF


def test_a_state_whose_arrays_were_replaced_with_wrong_shapes_is_a_safe_stop() -> None:
    """The kernels do not bounds-check: a mutated RobotState must never reach them."""
    ctl = w.QpController(model(), config())
    state = w.RobotState(np.zeros(3), Q0)
    state.q_arm = np.zeros(8)  # RobotState is mutable
    cmd = ctl.step(state, w.Reference("hold"))
    assert cmd.status == w.Status.SAFE_STOP and "shape" in cmd.reason
    state.q_arm = Q0.astype(np.float32)  # right length, wrong type
    assert ctl.step(state, w.Reference("hold")).status == w.Status.SAFE_STOP


def test_public_entry_points_reject_wrong_lengths() -> None:
    arm = model().config.arm
    with pytest.raises(ValueError, match="entries"):
        lim = (arm.position_lower, arm.position_upper, arm.velocity_max, arm.acceleration_max)
        joint_motion_bounds(np.zeros(5), np.zeros(5), *lim, 0.002)
    with pytest.raises(ValueError, match="entries"):
        model().arm.pin_q(np.zeros(8))
    with pytest.raises(ValueError, match="entries"):
        model().kinematics(np.zeros(2), Q0)


def test_state_fields_are_own_contiguous_float_copies() -> None:
    q = np.array(Q0)
    q.setflags(write=False)
    s = w.RobotState(np.zeros(3), q[::1], v_arm=np.zeros(14)[::2])
    assert s.q_arm is not q and s.q_arm.flags.writeable and s.v_arm.flags.c_contiguous


def test_warm_up_raises_if_a_kernel_fails_and_clears_the_counters(monkeypatch: pytest.MonkeyPatch) -> None:
    ctl = w.QpController(model(), config())
    ctl.warm_up()
    assert ctl.closed_form_hits == 0 and ctl.task_checks == 0
    monkeypatch.setattr(ctl, "closed_form", lambda p: 1 / 0)
    with pytest.raises(RuntimeError, match="warm-up"):
        ctl.warm_up()


def test_a_source_change_drops_the_packages_kernel_caches(tmp_path: Path) -> None:
    pkg = tmp_path / "pkg"
    (pkg / "sub" / "__pycache__").mkdir(parents=True)
    (pkg / "a.py").write_text("x = 1\n")
    (pkg / "sub" / "b.py").write_text("y = 2\n")
    cached = pkg / "sub" / "__pycache__" / "b.f-1.py311.nbi"
    cached.write_text("index")
    assert _jit._drop_stale_caches(pkg)  # no stamp yet: dropped, stamp written
    assert not cached.exists()
    cached.write_text("index")
    assert not _jit._drop_stale_caches(pkg) and cached.exists()  # unchanged sources: kept
    (pkg / "a.py").write_text("x = 3\n")  # another file than the cached kernel's
    assert _jit._drop_stale_caches(pkg) and not cached.exists()


def test_without_a_writable_cache_the_kernels_compile_in_memory(monkeypatch: pytest.MonkeyPatch) -> None:
    calls: list[bool] = []

    def fake_njit(**kw: object):  # type: ignore[no-untyped-def]
        calls.append(bool(kw["cache"]))
        if kw["cache"]:
            raise RuntimeError("cannot cache function 'f': no locator available for file '<x>'")
        return lambda fn: fn

    monkeypatch.setattr(_jit, "njit", fake_njit)
    f = _jit.jit(lambda x: x + 1)
    assert f(1) == 2 and calls == [True, False]


def test_the_rows_read_pinocchios_joint_placements_and_jacobians_of_this_tick() -> None:
    """The pair search keeps references to the arm data's joint placements and the rows the array of
    its joint Jacobians, fetched once: each must hold the values of the last kinematics (a
    Pinocchio that handed out copies would leave the rows on the first tick's)."""
    ctl = w.QpController(model(), w.load_controller_config())
    assert ctl.collision is not None
    arm, search = model().arm, ctl.collision.search
    rng = np.random.default_rng(3)
    for _ in range(3):
        q = random_arm_q(rng)
        ctl.step(w.RobotState(np.zeros(3), q), w.Reference("hold"))
        assert np.array_equal(ctl.collision._Jw, np.asarray(arm.data.J))
        fresh = arm.model.createData()
        pin.computeJointJacobians(arm.model, fresh, arm.pin_q(q))
        assert np.allclose(ctl.collision._Jw, fresh.J, atol=1e-12)
        for k, (M, j) in enumerate(zip(search._placements, search._joint_ids, strict=True)):
            assert np.allclose(M.homogeneous, fresh.oMi[j].homogeneous, atol=1e-12)
            assert np.allclose(search._Hj[k], fresh.oMi[j].homogeneous, atol=1e-12)  # read in place


def test_the_rows_approach_of_a_moving_obstacle_in_one_call_equals_its_numpy_formula() -> None:
    """The rows' bounds from the candidates in one compiled call (``_rows``) equal those of the
    calls it replaced, a moving obstacle's approach n̂ᵀ(Rbᵀ v_w) included (``_obstacle_shift``)."""
    from wmm_qp.limits.collision import MAX_ROWS, _assemble, warm_up_obstacles
    from wmm_qp.limits.dampers import damper_bounds

    ctl = w.QpController(model(), w.load_controller_config())
    col = ctl.collision
    assert col is not None
    q_base = np.array([0.3, -0.2, 0.7])
    x0 = model().ee_position(q_base, Q0)
    col.set_obstacles(warm_up_obstacles(x0))  # a moving sphere among them
    assert col.search.moving
    ctl.step(w.RobotState(q_base, Q0), w.Reference("hold"))  # the arm's data at Q0
    v_prev = np.linspace(-0.1, 0.1, ctl.n_v)
    lb, ub = v_prev - 0.05, v_prev + 0.05
    out = col.rows(q_base, Q0, v_prev, lb, ub)
    f, p = col.search.candidates, col.p
    C, dist, safety, _body, other, normal, _keys, _closest, n_inside = _assemble(
        f.d, f.p_a, f.p_b, f.normal, f.body, f.other, f.safety, f.n, p.influence_distance, MAX_ROWS, ctl.n_v,
        col._Jw, col._support, col._body_joint, col.M, col.n_w, col._body_link, col._n_links, len(col.obstacles))
    shift = col._obstacle_shift(normal, other)
    assert np.abs(shift).max() > 1e-3  # rows against the moving sphere
    l, l_brake, damper = damper_bounds(C, v_prev, lb, ub, dist, safety, p.influence_distance, p.gain, col.latency,
                                       shift, col._accel, p.braking, np.zeros(dist.shape[0]))
    m = dist.shape[0]  # nothing merged here: the first m rows are these (then those inside d_s)
    assert out.n == m + n_inside and np.array_equal(out.C[:m], C)
    np.testing.assert_allclose(out.damper[:m], damper, rtol=0, atol=1e-15)
    np.testing.assert_allclose(out.l[:m], l, rtol=0, atol=1e-15)
    np.testing.assert_allclose(out.l_brake[:m], l_brake, rtol=0, atol=1e-15)


def _for_the_arm_reference(C: np.ndarray, damper: np.ndarray, u: np.ndarray, n_w: int, held: np.ndarray,
                           lb: np.ndarray, ub: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """StageRows.for_the_arm as numpy wrote it before it was compiled."""
    u = np.minimum(u, INF)
    Ca, share = C[:, n_w:], C[:, :n_w] @ held
    best = np.sum(np.where(Ca > 0.0, Ca * ub, Ca * lb), axis=1)
    return Ca, np.minimum(damper, best + share) - share, np.where(u >= INF, INF, u - share)


def test_the_arms_rows_compiled_equal_their_numpy_formula() -> None:
    rng = np.random.default_rng(5)
    for groups in (1, 2, 3):
        n_w, n_a = 4, 7
        parts = []
        for g in range(groups):
            k = int(rng.integers(1, 6))
            r = Rows(rng.normal(size=(k, n_w + n_a)), rng.normal(size=k), damper=rng.normal(size=k))
            if g == 1:  # one source with upper bounds, some of them none (+inf)
                r.u = np.where(rng.random(k) < 0.5, np.inf, rng.normal(size=k) + 2.0)
            parts.append(r)
        rows = object.__new__(StageRows)
        rows.groups = [RowGroup(EeBox(np.zeros(3), np.ones(3), 0.002), r) for r in parts]
        rows.n = sum(r.n for r in parts)
        held, lb = rng.normal(size=n_w), -rng.random(n_a)
        ub = rng.random(n_a)
        C_out, l_out, u_out = np.zeros((rows.n, n_a + 6)), np.zeros(rows.n), np.zeros(rows.n)
        rows.for_the_arm(n_w, held, lb, ub, C_out, l_out, u_out)
        C = np.vstack([r.C for r in parts])
        Ca, l, u = _for_the_arm_reference(C, np.concatenate([r.damper for r in parts]),
                                          np.concatenate([r.upper() for r in parts]), n_w, held, lb, ub)
        assert np.array_equal(C_out[:, :n_a], Ca) and not C_out[:, n_a:].any()
        assert np.allclose(l_out, l, rtol=0, atol=1e-14) and np.allclose(u_out, u, rtol=0, atol=1e-14)
        assert np.array_equal(u_out == INF, u == INF)
        assert (u_out == INF).any() or groups == 1


def test_the_track_velocity_compiled_equals_the_general_path() -> None:
    """The position task's ẋ_ref with a target, in one compiled call, against the general path
    (linear_velocity, its error saturated, the whole capped): plain tracking, a saturated error and a
    capped feed-forward."""
    ctl = w.QpController(model(), config())
    state = w.RobotState(np.zeros(3), Q0)
    ctx = ctl.context(state, w.Reference("track"), need_gradient=False)
    x = ctx.kin.x
    qp = ctl.config.qp
    cases = [(x + 1e-3, np.array([0.01, 0.0, 0.0])), (x + np.array([2.0, 0.0, 0.5]), np.zeros(3)),
             (x, np.array([0.0, 50.0, 0.0])), (x - 0.3, np.array([0.2, -0.1, 0.05]))]
    for mode in ("track", "hold", "dm_nullspace"):
        for x_d, xd_d in cases:
            ref = w.Reference(mode, x_d=x_d, xd_d=xd_d)
            got = ctl.reference_velocity(ctx, ref)
            lin = _saturated(ctl.linear_velocity(ctx, ref), ref.xd_d, qp.recovery_speed)
            n = float(np.linalg.norm(lin))
            want = lin * (qp.task_speed_max / n) if n > qp.task_speed_max else lin
            assert np.allclose(got, want, rtol=1e-15, atol=1e-15), (mode, got, want)
    saturated = ctl.reference_velocity(ctx, w.Reference("track", x_d=x + np.array([2.0, 0.0, 0.5])))
    assert np.linalg.norm(saturated) == pytest.approx(min(qp.recovery_speed, qp.task_speed_max))


_NO_COMPILE_AFTER_WARM_UP = """
import gc, json, sys
import numpy as np
from numba.core.dispatcher import Dispatcher
import wmm_qp as w
from wmm_qp.scene import load_scene

def kernels():
    return {f"{d.py_func.__module__}.{d.py_func.__qualname__}": len(d.overloads) for d in gc.get_objects()
            if isinstance(d, Dispatcher) and d.py_func.__module__.startswith("wmm_qp")}

model = w.WmmModel(w.load_robot_config(sys.argv[1]))
ctl = w.make_controller("qp", model, w.load_controller_config())
ctl.set_scene(load_scene(None))
ctl.warm_up()
before = kernels()
q_base, q_arm = np.zeros(3), np.array(model.config.arm.start, dtype=float)
x = model.ee_position(q_base, q_arm)
v_arm = np.full(q_arm.shape, 0.05)
refs = [w.Reference("hold", x_d=x), w.Reference("track", x_d=x + 0.01, xd_d=np.array([0.05, 0.0, 0.0])),
        w.Reference("dm_cartesian"), w.Reference("dm_nullspace", x_d=x), w.Reference("track", x_d=x - 0.2)]
for ref in refs:
    for _ in range(3):
        ctl.step(w.RobotState(q_base, q_arm, v_arm=v_arm), ref)
after = kernels()
print(json.dumps({k: (before.get(k, 0), n) for k, n in after.items() if n != before.get(k, 0)}))
"""


@pytest.mark.parametrize("robot", ["gen3_mecanum", "fr3"])
def test_after_its_warm_up_no_tick_compiles_a_kernel(robot: str) -> None:
    """``warm_up`` loads every kernel a tick runs: in a fresh process, after it, ticks of every
    mode with and without a target, moving, with the default rows, add no compiled signature to
    any of the package's kernels. (A kernel first compiled in the loop costs ~0.25 s on a
    machine's first run: the position task's reference velocity did, at a daemon's first
    setpoint, before the warm-up ticked the modes with a target too.)"""
    import json
    import subprocess
    import sys

    from wmm_qp.config import default_config_dir

    # -P: the package the suite imports (the installed one), not the checkout's root on sys.path,
    # whose numba cache CI's warm-up did not fill (its first process compiled every kernel: ~50 s)
    out = subprocess.run([sys.executable, "-P", "-c", _NO_COMPILE_AFTER_WARM_UP,
                          str(default_config_dir() / "robots" / f"{robot}.toml")],
                         capture_output=True, text=True, timeout=600, check=True)
    compiled = json.loads(out.stdout.strip().splitlines()[-1])
    assert compiled == {}, f"compiled after the warm-up (overloads before, after): {compiled}"
