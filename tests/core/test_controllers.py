"""The paper's controllers, eqs. (11)–(19), and the never-raise guarantee of ``step``."""

from __future__ import annotations

import numpy as np
import pytest
from support.core_fixtures import Q0, config, model, random_arm_q

import wmm_qp as w
from wmm_qp.pseudoinverse import damping_factor, weight_matrix_diag, weighted_pinv
from wmm_qp.verify import check_command


@pytest.mark.parametrize("alpha", [0.0, 0.2, 0.5, 0.99])  # α = 1: rank 2, see below
def test_weighted_pseudoinverse_is_a_right_inverse(alpha: float) -> None:
    rng = np.random.default_rng(1)
    kin = model().kinematics(np.array([0.1, 0.2, 0.3]), random_arm_q(rng))
    Jp = weighted_pinv(kin.J, weight_matrix_diag(alpha, 4, 7))  # eq. (11)
    np.testing.assert_allclose(kin.J @ Jp, np.eye(3), atol=1e-10)


def test_alpha_zero_moves_no_wheel_and_alpha_one_moves_no_joint() -> None:
    kin = model().kinematics(np.zeros(3), Q0)
    xdot = np.array([0.05, -0.02, 0.01])
    v0 = weighted_pinv(kin.J, weight_matrix_diag(0.0, 4, 7)) @ xdot
    v1 = weighted_pinv(kin.J, weight_matrix_diag(1.0, 4, 7)) @ xdot
    assert np.abs(v0[:4]).max() == 0.0
    assert np.abs(v1[4:]).max() == 0.0
    # α = 1: the base cannot move the EE vertically, so only x, y are realised
    np.testing.assert_allclose(kin.J @ v0, xdot, atol=1e-12)
    np.testing.assert_allclose((kin.J @ v1)[:2], xdot[:2], atol=1e-12)


def test_paper_alpha_switch_keeps_base_still_while_arm_suffices() -> None:
    ctl = w.PaperController(model(), config())
    x = model().ee_position(np.zeros(3), Q0)
    cmd = ctl.step(w.RobotState(np.zeros(3), Q0), w.Reference("track", x_d=x, xd_d=[1e-3, 0, 0]))
    assert cmd.alpha == 0.0 and np.abs(cmd.wheel_speeds).max() == 0.0
    big = ctl.step(w.RobotState(np.zeros(3), Q0), w.Reference("track", x_d=x, xd_d=[0.5, 0, 0]))
    assert big.alpha == config().alpha and np.abs(big.wheel_speeds).max() > 0


def test_dls_engages_below_threshold_only() -> None:
    assert damping_factor(0.1, 0.08, 0.05) == 0.0
    assert 0.0 < damping_factor(0.07, 0.08, 0.05) < 0.05
    assert damping_factor(0.0, 0.08, 0.05) == 0.05


@pytest.mark.parametrize("kind", ["traditional", "paper", "qp"])
@pytest.mark.parametrize("mode", list(w.Mode))
def test_commands_stay_finite_at_an_exact_singularity(kind: str, mode: w.Mode) -> None:
    q = np.zeros(7)  # arm stretched straight up: σ_min(J_m) = 0
    ctl = w.make_controller(kind, model(), config())
    cmd = ctl.step(w.RobotState(np.zeros(3), q), w.Reference(mode, x_d=[0.3, 0.1, 1.0], xd_d=[0.1, 0, 0]))
    assert cmd.sigma_min < 1e-6 and cmd.status != w.Status.SAFE_STOP, cmd.reason  # no stop needed there
    assert np.isfinite(cmd.v).all()
    if kind == "paper":
        assert cmd.status == w.Status.DAMPED


def test_cartesian_dm_velocity_is_zero_outside_the_box() -> None:
    ctl = w.PaperController(model(), config())
    st_in = w.RobotState(np.zeros(3), Q0)  # z = 0.492 inside [0.36, 0.56]
    cmd = ctl.step(st_in, w.Reference("dm_cartesian"))
    assert np.abs(cmd.v).max() > 0
    q_high = Q0.copy()
    q_high[3] = 0.5  # folds less: EE above 0.56 m
    assert model().ee_position(np.zeros(3), q_high)[2] > 0.56
    cmd = ctl.step(w.RobotState(np.zeros(3), q_high), w.Reference("dm_cartesian"))
    np.testing.assert_allclose(cmd.v, 0.0, atol=1e-15)


@pytest.mark.parametrize("kind", ["traditional", "paper", "qp"])
def test_nan_input_gives_a_safe_stop_not_an_exception(kind: str) -> None:
    ctl = w.make_controller(kind, model(), config())
    v = np.full(7, 0.5)
    st = w.RobotState(np.zeros(3), np.r_[np.nan, Q0[1:]], v_arm=v)
    cmd = ctl.step(st, w.Reference("track"))
    assert cmd.status == w.Status.SAFE_STOP and "NaN" in cmd.reason
    np.testing.assert_allclose(cmd.arm_rates, v - config().dt * np.array(model().config.arm.acceleration_max))
    cmd = ctl.step(w.RobotState(np.zeros(3), Q0), w.Reference("track", x_d=[np.inf, 0, 0]))
    assert cmd.status == w.Status.SAFE_STOP


def test_an_exception_inside_a_controller_becomes_a_safe_stop(monkeypatch: pytest.MonkeyPatch) -> None:
    ctl = w.PaperController(model(), config())

    def boom(*_: object, **__: object) -> None:
        raise RuntimeError("kaboom")

    monkeypatch.setattr(ctl, "context", boom)
    cmd = ctl.step(w.RobotState(np.zeros(3), Q0), w.Reference("track"))
    assert cmd.status == w.Status.SAFE_STOP and "kaboom" in cmd.reason


def test_closed_form_sigma_min_matches_the_svd() -> None:
    from wmm_qp.pseudoinverse import sigma_min

    rng = np.random.default_rng(5)
    for i in range(300):
        J = model().kinematics(np.zeros(3), random_arm_q(rng)).J_m
        if i % 3 == 0:
            J[2] = 0.3 * J[0] - 0.7 * J[1] + rng.normal(scale=1e-4, size=7)  # near rank 2
        assert abs(sigma_min(J) - np.linalg.svd(J, compute_uv=False)[-1]) < 1e-7


def test_closed_form_sigma_min_near_the_straight_pose() -> None:
    """Next to the straight (singular) arm the trigonometric form loses digits: the documented
    bounds (pseudoinverse.sigma_min) hold, far below the 0.08 threshold it is compared with."""
    from wmm_qp.pseudoinverse import sigma_min

    rng = np.random.default_rng(3)
    worst = {1e-3: 0.0, 1e-4: 0.0, 0.0: 0.0}
    for _ in range(1000):
        J = model().kinematics(np.zeros(3), rng.normal(size=7) * 10.0 ** rng.uniform(-5, -1)).J_m
        s = np.linalg.svd(J, compute_uv=False)[-1]
        band = 1e-3 if s >= 1e-3 else 1e-4 if s >= 1e-4 else 0.0
        worst[band] = max(worst[band], abs(sigma_min(J) - s))
    assert worst[1e-3] < 1e-7 and worst[1e-4] < 1e-5 and worst[0.0] < 1e-4, worst


def test_paper_controller_switches_to_damped_least_squares_below_the_threshold() -> None:
    """σ_min(J_m) just above 0.08: the plain J#; just below: the damped one (paper's controller)."""
    from wmm_qp.pseudoinverse import sigma_min

    c = config()
    ctl = w.PaperController(model(), c)
    q = Q0.copy()
    found = {}
    for q4 in np.linspace(1.0, 0.0, 400):  # unfold the elbow towards the stretched singularity
        q[3] = q4
        s = sigma_min(model().kinematics(np.zeros(3), q).J_m)
        key = "above" if 0.08 < s < 0.085 else "below" if 0.07 < s < 0.08 else None
        if key and key not in found:
            found[key] = q.copy()
    assert set(found) == {"above", "below"}
    for key, qk in found.items():
        kin = model().kinematics(np.zeros(3), qk)
        xdot = np.array([0.0, 0.0, 1e-3])
        cmd = ctl.step(w.RobotState(np.zeros(3), qk), w.Reference("track", x_d=kin.x, xd_d=xdot))
        lam = damping_factor(sigma_min(kin.J_m), c.sigma_threshold, c.damping_max)
        expected = weighted_pinv(kin.J, weight_matrix_diag(cmd.alpha, 4, 7), lam) @ xdot
        np.testing.assert_allclose(cmd.v, expected, atol=1e-12)
        assert (lam > 0) == (key == "below")
        assert (cmd.status == w.Status.DAMPED) == (key == "below")


# Malformed input (the review's attack: step raised on a state of the wrong shape) ----------------
ROBOT_WHEELS = model().base.M.shape[1]  # the robot's own sizes, from the model and its config
ROBOT_JOINTS = model().config.arm.acceleration_max.shape[0]
FIELDS = {"q_base": 3, "q_arm": ROBOT_JOINTS, "v_arm": ROBOT_JOINTS, "wheel_speeds": ROBOT_WHEELS}
MOVING_V = np.linspace(-1.0, 1.0, ROBOT_JOINTS) * 0.5  # the robot is moving: the stop must brake
MOVING_W = np.full(ROBOT_WHEELS, 3.0)


def malformed(n: int) -> dict[str, object]:
    """Every way a state field can be the wrong thing, for a field of n entries."""
    return {
        "short": np.zeros(n - 1),
        "long": np.zeros(n + 1),
        "2d": np.zeros((2, n)),
        "column": np.zeros((n, 1)),
        "scalar": np.float64(0.5),
        "0d": np.array(0.5),
        "empty": np.zeros(0),
        "None": None,
        "None-array": np.array(None),
        "object-array": np.array([None] * n),
        "list": [0.0] * n,
        "string": "0.0",
        "float32": np.full(n, 0.25, dtype=np.float32),  # the wrong type, but rates one can brake from
    }


USABLE = {"float32"}  # malformed for the controller, usable rates for the safe stop


def moving_state() -> w.RobotState:
    return w.RobotState(np.zeros(3), Q0, v_arm=MOVING_V, wheel_speeds=MOVING_W)


def assert_safe_stop_of_the_robot_s_sizes(cmd: w.Command, state: w.RobotState, bad_field: str, how: str) -> None:
    """A safe stop of the robot's sizes that brakes from the state's usable rates inside the
    acceleration bounds; a malformed rate field is unknown: its part is zero, the reason says so."""
    assert cmd.status == w.Status.SAFE_STOP, cmd.reason
    for got, n in ((cmd.wheel_speeds, ROBOT_WHEELS), (cmd.arm_rates, ROBOT_JOINTS)):
        assert isinstance(got, np.ndarray) and got.dtype == np.float64 and got.shape == (n,)
        assert np.isfinite(got).all()
    arm, base, dt = model().config.arm, model().config.base, config().dt
    unknown = bad_field in ("v_arm", "wheel_speeds") and how not in USABLE
    v0, w0 = (np.asarray(a, dtype=float) for a in (state.v_arm, state.wheel_speeds))
    if unknown:
        v0, w0 = (np.zeros(ROBOT_JOINTS), w0) if bad_field == "v_arm" else (v0, np.zeros(ROBOT_WHEELS))
    a, aw = arm.acceleration_max * dt, base.wheel_acceleration_max * dt
    np.testing.assert_allclose(cmd.arm_rates, np.sign(v0) * np.maximum(np.abs(v0) - a, 0.0), atol=1e-15, rtol=0)
    np.testing.assert_allclose(cmd.wheel_speeds, np.sign(w0) * np.maximum(np.abs(w0) - aw, 0.0), atol=1e-15, rtol=0)
    if unknown:
        assert f"{bad_field} unusable" in cmd.reason and "commanded 0" in cmd.reason
    else:
        assert "unusable" not in cmd.reason
        good = w.RobotState(np.zeros(3), Q0, v_arm=v0, wheel_speeds=w0)
        assert sum(check_command(model().config, dt, good, cmd).values()) == 0


@pytest.mark.parametrize("kind", ["traditional", "paper", "qp"])
@pytest.mark.parametrize("field", list(FIELDS))
@pytest.mark.parametrize("how", list(malformed(7)))
def test_a_malformed_state_gives_a_safe_stop_of_the_robot_s_sizes(kind: str, field: str, how: str) -> None:
    ctl = w.make_controller(kind, model(), config())
    state = moving_state()
    setattr(state, field, malformed(FIELDS[field])[how])  # RobotState is mutable: a field replaced
    for mode in w.Mode:
        cmd = ctl.step(state, w.Reference(mode))
        assert "wrong shapes" in cmd.reason
        assert_safe_stop_of_the_robot_s_sizes(cmd, state, field, how)


@pytest.mark.parametrize("field", list(FIELDS))
@pytest.mark.parametrize("how", list(malformed(7)))
def test_safe_stop_itself_never_raises_and_has_the_robot_s_sizes(field: str, how: str) -> None:
    ctl = w.make_controller("qp", model(), config())
    state = moving_state()
    setattr(state, field, malformed(FIELDS[field])[how])
    assert_safe_stop_of_the_robot_s_sizes(ctl.safe_stop(state, "test"), state, field, how)


@pytest.mark.parametrize("not_a_state", [None, object(), "state", np.zeros(18)])
def test_safe_stop_of_something_that_is_not_a_state_is_zero(not_a_state: object) -> None:
    ctl = w.make_controller("qp", model(), config())
    for cmd in (ctl.safe_stop(not_a_state, "test"), ctl.step(not_a_state, w.Reference("track"))):  # type: ignore[arg-type]
        assert cmd.status == w.Status.SAFE_STOP
        np.testing.assert_array_equal(cmd.wheel_speeds, np.zeros(ROBOT_WHEELS))
        np.testing.assert_array_equal(cmd.arm_rates, np.zeros(ROBOT_JOINTS))


@pytest.mark.parametrize("kind", ["traditional", "paper", "qp"])
@pytest.mark.parametrize("field", ["x_d", "xd_d", "direction", "mode"])
@pytest.mark.parametrize("how", ["short", "long", "2d", "scalar", "empty", "object-array", "float32", "list", "string"])
def test_a_malformed_reference_gives_a_safe_stop_not_a_broadcast(kind: str, field: str, how: str) -> None:
    """x_d of one entry used to broadcast into a command towards a wrong target, a direction of one
    or five entries reached the (not bounds-checked) DM kernels."""
    ctl = w.make_controller(kind, model(), config())
    x = model().ee_position(np.zeros(3), Q0)
    for mode in w.Mode:
        ref = w.Reference(mode, x_d=x, direction=[1.0, 0.0, 0.0])
        setattr(ref, field, malformed(3)[how])
        cmd = ctl.step(moving_state(), ref)
        assert "reference arrays have the wrong shapes" in cmd.reason
        assert_safe_stop_of_the_robot_s_sizes(cmd, moving_state(), "", how)


@pytest.mark.parametrize("kind", ["traditional", "paper", "qp"])
def test_every_controller_declares_the_host_capabilities(kind: str) -> None:
    """A host calls set_scene / set_obstacles / set_latency / the collision reports on any
    controller without probing it: the baselines answer 'no rows', the QP controller its own."""
    from wmm_qp.scene import Scene

    ctl = w.make_controller(kind, model(), config().with_(collision={"enabled": True}))
    ctl.set_scene(Scene())
    ctl.set_obstacles(())
    ctl.set_latency(0.004)
    assert ctl.bounds.latency == 0.004
    has_rows = kind == "qp"
    assert ctl.collision_on is has_rows
    assert ctl.collision_summary().startswith("collision rows on" if has_rows else "no collision rows")
    assert ctl.last_collision_rows() is None  # no tick yet
