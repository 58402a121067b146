"""Joint motion bounds, eq. (13): never empty, contain the braking command, never overshoot."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from support.core_fixtures import robot

import wmm_qp as w
from wmm_qp.limits import braking_command, braking_velocity, joint_motion_bounds, wheel_bounds

DT = 0.002
ARM = robot().arm


def bounds(q: np.ndarray, v: np.ndarray, dt: float = DT) -> tuple[np.ndarray, np.ndarray]:
    return joint_motion_bounds(q, v, ARM.position_lower, ARM.position_upper, ARM.velocity_max, ARM.acceleration_max, dt)


floats = st.floats(min_value=-1.0, max_value=1.0, allow_nan=False)


@settings(max_examples=300, deadline=None)
@given(
    st.lists(floats, min_size=7, max_size=7),
    st.lists(floats, min_size=7, max_size=7),
    st.floats(min_value=0.0, max_value=1.6),
    st.sampled_from([0.001, 0.002, 0.01]),
)
def test_bounds_are_never_empty_and_contain_the_braking_command(
    qs: list[float], vs: list[float], speed: float, dt: float
) -> None:
    # positions anywhere from far inside to 0.2 rad beyond the limits; rates up to 1.6× the limit
    lo_q = np.where(np.isfinite(ARM.position_lower), ARM.position_lower, -np.pi)
    hi_q = np.where(np.isfinite(ARM.position_upper), ARM.position_upper, np.pi)
    q = (lo_q + hi_q) / 2 + np.array(qs) * ((hi_q - lo_q) / 2 + 0.2)
    v = np.array(vs) * ARM.velocity_max * speed
    lo, hi = bounds(q, v, dt)
    assert np.isfinite(lo).all() and np.isfinite(hi).all()
    assert (lo <= hi).all()
    b = braking_command(v, ARM.acceleration_max, dt)
    assert (lo - 1e-12 <= b).all() and (b <= hi + 1e-12).all()
    # inside the acceleration interval, always
    assert (lo >= v - ARM.acceleration_max * dt - 1e-12).all()
    assert (hi <= v + ARM.acceleration_max * dt + 1e-12).all()


def test_at_and_beyond_a_limit_no_motion_further_out() -> None:
    q = np.zeros(7)
    q[1] = ARM.position_upper[1]  # at the limit
    lo, hi = bounds(q, np.zeros(7))
    assert hi[1] == 0.0 and lo[1] < 0
    q[1] = ARM.position_upper[1] + 0.1  # beyond
    lo, hi = bounds(q, np.zeros(7))
    assert hi[1] == 0.0 and lo[1] < 0


def test_continuous_joints_have_no_position_bound() -> None:
    q = np.full(7, 100.0)  # far "beyond" any limit: irrelevant for continuous joints
    _, hi = bounds(q, np.zeros(7))
    a = ARM.acceleration_max * DT
    np.testing.assert_allclose(hi[[0, 2, 4, 6]], a[[0, 2, 4, 6]])


def test_braking_velocity_tends_to_the_continuous_bound() -> None:
    d, a = np.array([0.5]), np.array([5.0])
    assert abs(braking_velocity(d, a, 1e-5)[0] - np.sqrt(2 * a[0] * d[0])) < 1e-3


@settings(max_examples=200, deadline=None)
@given(
    st.floats(min_value=0.0, max_value=0.5),
    st.floats(min_value=0.0, max_value=1.0),
    st.sampled_from([0.001, 0.002, 0.005]),
)
def test_following_the_upper_bound_then_braking_never_passes_the_limit(start: float, frac: float, dt: float) -> None:
    """Drive joint 2 at its upper bound (13) towards the limit, then brake: never beyond."""
    q = np.zeros(7)
    q[1] = ARM.position_upper[1] - start
    v = np.zeros(7)
    steps = int(frac * 400)
    for k in range(steps + 400):
        lo, hi = bounds(q, v, dt)
        v = hi.copy() if k < steps else braking_command(v, ARM.acceleration_max, dt)
        v = np.clip(v, lo, hi)
        q = q + v * dt
        assert q[1] <= ARM.position_upper[1] + 1e-12


def test_wheel_bounds_acceleration_wins_beyond_speed_limit() -> None:
    base = robot().base
    w = np.full(4, base.wheel_speed_max * 1.5)
    lo, hi = wheel_bounds(w, base, DT)
    np.testing.assert_allclose(lo, hi)
    np.testing.assert_allclose(lo, w - base.wheel_acceleration_max * DT)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.floats(min_value=0.0, max_value=2.0), min_size=7, max_size=7), st.sampled_from([0.001, 0.002]))
def test_the_upper_bound_is_the_braking_velocity_when_that_is_reachable(dist: list[float], dt: float) -> None:
    """bounds (13) fuse the braking formula; from v_prev = braking_velocity(d) the bound is exactly it."""
    d = np.array(dist)
    q = ARM.position_upper - d
    q = np.where(np.isfinite(q), q, 0.0)
    v = np.where(np.isfinite(ARM.position_upper), braking_velocity(d, ARM.acceleration_max, dt), 0.0)
    _, hi = joint_motion_bounds(q, v, ARM.position_lower, ARM.position_upper, np.full(7, 1e9), ARM.acceleration_max, dt)
    limited = np.isfinite(ARM.position_upper)
    np.testing.assert_allclose(hi[limited], v[limited], rtol=1e-12, atol=1e-12)


def _numpy_bounds(q, v, dt, latency):  # type: ignore[no-untyped-def]
    """Eq. (13) written as plain numpy (the form before the compiled kernel): the reference."""
    a, vmax = ARM.acceleration_max, ARM.velocity_max
    lo, hi = np.minimum(np.maximum(-vmax, v - a * dt), v + a * dt), np.minimum(np.maximum(vmax, v - a * dt), v + a * dt)
    ahead, slack = v * latency, 0.5 * a * latency * latency
    up = braking_velocity(ARM.position_upper - q - np.maximum(ahead + slack, 0.0), a, dt)
    down = braking_velocity(q - ARM.position_lower - np.maximum(slack - ahead, 0.0), a, dt)
    return np.minimum(np.maximum(-down, lo), hi), np.minimum(np.maximum(up, lo), hi)


@settings(max_examples=300, deadline=None)
@given(
    st.lists(floats, min_size=7, max_size=7),
    st.lists(st.floats(min_value=-1.6, max_value=1.6), min_size=7, max_size=7),
    st.sampled_from([0.001, 0.002]),
    st.sampled_from([0.0, 0.003, 0.03]),
)
def test_the_compiled_bounds_equal_the_numpy_formula(qs: list[float], vs: list[float], dt: float, lat: float) -> None:
    lo_q = np.where(np.isfinite(ARM.position_lower), ARM.position_lower, -np.pi)
    hi_q = np.where(np.isfinite(ARM.position_upper), ARM.position_upper, np.pi)
    q = (lo_q + hi_q) / 2 + np.array(qs) * ((hi_q - lo_q) / 2 + 0.2)
    v = np.array(vs) * ARM.velocity_max
    lo, hi = joint_motion_bounds(
        q, v, ARM.position_lower, ARM.position_upper, ARM.velocity_max, ARM.acceleration_max, dt, lat
    )
    ref_lo, ref_hi = _numpy_bounds(q, v, dt, lat)
    np.testing.assert_allclose(lo, ref_lo, rtol=0, atol=1e-15)
    np.testing.assert_allclose(hi, ref_hi, rtol=0, atol=1e-15)


@settings(max_examples=100, deadline=None)
@given(st.lists(st.floats(min_value=-2.0, max_value=2.0), min_size=4, max_size=4))
def test_the_controllers_bounds_on_the_wheels_are_the_wheel_bounds(speeds: list[float]) -> None:
    from support.core_fixtures import config, model

    base = robot().base
    wh = np.array(speeds) * base.wheel_speed_max
    ctl = w.QpController(model(), config())
    lo, hi = ctl.bounds(np.zeros(11), np.concatenate([wh, np.zeros(7)]))
    wlo, whi = wheel_bounds(wh, base, ctl.dt)
    np.testing.assert_array_equal(lo[:4], wlo)
    np.testing.assert_array_equal(hi[:4], whi)


def _drive_to_limit_with_stale_state(latency: float, age_ticks: int, dt: float = 0.002) -> float:
    """Drive joint 2 at its bound (13) towards the limit, seeing a state ``age_ticks`` old; max overshoot."""
    q, v = np.zeros(7), np.zeros(7)
    q[1] = ARM.position_upper[1] - 0.3
    history = [q.copy()] * (age_ticks + 1)
    worst = -np.inf
    for _ in range(3000):
        seen = history[-1 - age_ticks]  # the controller's (stale) view of the position
        _, hi = joint_motion_bounds(
            seen, v, ARM.position_lower, ARM.position_upper, ARM.velocity_max, ARM.acceleration_max, dt, latency
        )
        v = hi.copy()
        q = q + v * dt
        history.append(q.copy())
        worst = max(worst, q[1] - ARM.position_upper[1])
    return worst


def test_latency_margin_keeps_a_stale_state_from_overshooting() -> None:
    assert _drive_to_limit_with_stale_state(latency=0.0, age_ticks=1) > 1e-5  # the failure it fixes
    assert _drive_to_limit_with_stale_state(latency=0.002, age_ticks=1) <= 1e-12
    assert _drive_to_limit_with_stale_state(latency=0.006, age_ticks=2) <= 1e-12


def _drive_to_limit_with_lagging_rates(anchor_on_command: bool, age_ticks: int, latency: float) -> float:
    """Drive joint 4 at its upper bound (13) into its limit through a drive that ramps the executed
    rate towards each command at A (two sub-steps a tick), seeing a state (q, rate) ``age_ticks``
    old; bounds anchored on the measured rate or on the last command. Max overshoot [rad]."""
    dt, sub, a = 0.002, 2, ARM.acceleration_max
    q, e, u = np.zeros(7), np.zeros(7), np.zeros(7)
    q[3] = ARM.position_upper[3] - 0.4
    history = [(q.copy(), e.copy())] * (age_ticks + 1)
    worst = -np.inf
    for _ in range(1500):
        seen_q, seen_v = history[-1 - age_ticks]
        anchor = u if anchor_on_command else seen_v
        _, hi = joint_motion_bounds(
            seen_q, anchor, ARM.position_lower, ARM.position_upper, ARM.velocity_max, a, dt, latency
        )
        u = hi.copy()  # the task pulls the joint into its limit
        for _ in range(sub):
            e = e + np.clip(u - e, -a * dt / sub, a * dt / sub)
            q = q + e * dt / sub
            worst = max(worst, q[3] - ARM.position_upper[3])
        history.append((q.copy(), e.copy()))
    return worst


def test_bounds_anchored_on_a_lagging_measured_rate_overshoot_anchored_on_the_command_do_not() -> None:
    """The drill's pushed base, driven back past a joint limit. A measured rate lags the command:
    the acceleration bound (which wins) then lets each command drop A·dt below an old rate only,
    the joint brakes at a fraction of A and passes the limit by ~0.1 rad whatever the latency
    margin; anchored on the last command it brakes at A and the margin covers the lag."""
    for age in (1, 2, 3):
        assert _drive_to_limit_with_lagging_rates(False, age, (age + 1) * 0.002) > 0.1
        assert _drive_to_limit_with_lagging_rates(True, age, (age + 1) * 0.002) <= 1e-12
    assert _drive_to_limit_with_lagging_rates(False, 2, 0.03) > 0.1  # the daemon's 30 ms do not help
    assert _drive_to_limit_with_lagging_rates(True, 2, 0.03) <= 1e-12
