"""Ruckig setpoint smoothing: limits always hold; a moving stream is followed without stopping."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from wmm_qp_service.smoother import SetpointSmoother, VelocityEstimator

DT, V, A, J = 0.002, 0.25, 1.0, 10.0
TOL = 1e-6


def run_and_check(sm: SetpointSmoother, targets: list[tuple[int, np.ndarray, np.ndarray | None]],
                  n: int) -> tuple[np.ndarray, np.ndarray]:
    xs, vs = [], []
    prev_v, prev_a = sm.velocity.copy(), sm.acceleration.copy()
    tmap = {k: (x, v) for k, x, v in targets}
    for k in range(n):
        if k in tmap:
            sm.set_target(*tmap[k])
        x, v = sm.step()
        a = sm.acceleration
        assert np.all(np.abs(v) <= V + TOL), v
        assert np.all(np.abs(a) <= A + TOL), a
        # finite-difference checks of what is handed to the controller
        assert np.all(np.abs(v - prev_v) <= A * DT + TOL)
        assert np.all(np.abs(a - prev_a) <= J * DT + TOL)
        prev_v, prev_a = v, a.copy()
        xs.append(x)
        vs.append(v)
    return np.array(xs), np.array(vs)


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 600),
                          st.lists(st.floats(-2, 2), min_size=3, max_size=3),
                          st.one_of(st.none(), st.lists(st.floats(-1, 1), min_size=3, max_size=3))),
                min_size=1, max_size=20),
       st.booleans())
def test_limits_hold_for_any_jumpy_stream(samples: list, rest: bool) -> None:
    sm = SetpointSmoother(DT, V, A, J)
    sm.reset(np.zeros(3))
    targets = [(k, np.array(x), None if v is None else np.array(v)) for k, x, v in samples]
    run_and_check(sm, targets, 650)
    if rest:
        sm.bring_to_rest()
        _, vs = run_and_check(sm, [], 300)
        assert np.allclose(vs[-1], 0.0, atol=1e-9)  # brought to rest


def test_reset_from_a_moving_state_respects_limits() -> None:
    sm = SetpointSmoother(DT, V, A, J)
    sm.reset(np.array([0.6, 0.0, 0.5]), v=np.array([0.2, -0.2, 0.1]), a=np.array([0.5, 0.0, -0.5]))
    _, vs = run_and_check(sm, [(0, np.array([0.0, 0.0, 0.0]), None)], 5000)
    assert np.linalg.norm(vs[-1]) < 1e-6


def test_steady_stream_is_followed_without_stopping() -> None:
    """100 Hz samples of a target moving at 0.11 m/s, with 0.3 mm jitter, velocity estimated."""
    rng = np.random.default_rng(0)
    sm = SetpointSmoother(DT, V, A, J)
    sm.reset(np.zeros(3))
    est = VelocityEstimator(v_max=V)
    v_true = np.array([0.1, 0.05, 0.0])
    speeds, errors = [], []
    for k in range(4000):
        t = k * DT
        if k % 5 == 0:
            xf, v = est.update(v_true * t + rng.normal(0, 3e-4, 3), t)
            sm.set_target(xf, v)
        x, v = sm.step()
        speeds.append(np.linalg.norm(v))
        errors.append(np.linalg.norm(x - v_true * t))
    s = np.array(speeds[1000:])
    assert s.min() > 0.5 * np.linalg.norm(v_true)  # never stop-and-go
    assert max(errors[1000:]) < 5e-3


def test_feed_forward_circle_is_tracked_closely() -> None:
    from wmm_qp_service.streams import circle

    x0 = np.array([0.65, -0.025, 0.49])
    sm = SetpointSmoother(DT, V, A, J)
    sm.reset(x0)
    errs = []
    for k in range(5000):
        t = k * DT
        if k % 5 == 0:
            sm.set_target(*circle(x0, t))
        x, _ = sm.step()
        errs.append(np.linalg.norm(x - circle(x0, t)[0]))
    assert max(errs[500:]) < 1e-3  # after the start from rest


def test_stale_stream_comes_to_rest_and_holds() -> None:
    sm = SetpointSmoother(DT, V, A, J)
    sm.reset(np.zeros(3))
    sm.set_target(np.array([0.0, 0.0, 0.0]), np.array([0.2, 0.0, 0.0]))
    run_and_check(sm, [], 500)
    sm.bring_to_rest()
    xs, vs = run_and_check(sm, [], 500)
    assert np.allclose(vs[-50:], 0.0) and np.allclose(xs[-1], xs[-50])


def test_velocity_estimator_restarts_on_jumps() -> None:
    est = VelocityEstimator(jump=0.05)
    for k in range(50):
        est.update(np.array([0.1 * k * 0.01, 0, 0]), k * 0.01)
    assert est.v[0] > 0.05
    x, v = est.update(np.array([1.0, 0, 0]), 0.5)
    assert np.allclose(v, 0.0) and np.allclose(x, [1.0, 0, 0])
