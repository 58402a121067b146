"""Directional manipulability, eqs. (8)–(10), and Yoshikawa's index."""

from __future__ import annotations

import numpy as np
import pytest
from support.core_fixtures import Q0, config, model, random_arm_q

from wmm_qp.manipulability import (
    directional_manipulability,
    dm_cartesian_gradient,
    dm_gradient,
    torque_norm_per_newton,
    yoshikawa_manipulability,
)

W = np.array([1, 1, 1, 1, 2.5, 2.5, 2.5])  # the paper's, eq. (8)
X = np.array([1.0, 0, 0])
Z = np.array([0.0, 0, 1])


def h2(q: np.ndarray, u: np.ndarray) -> float:
    _, J = model().arm.position_jacobian(q)
    return directional_manipulability(J, u, W)


def test_paper_values_at_start_configuration() -> None:
    # configs/robots/gen3_7dof.urdf: H2 = 3.8239 along x, 1.1242 along z; the paper: 3.825 (x) and 1.125 (z)
    assert h2(Q0, X) == pytest.approx(3.8239, abs=1e-3)
    assert h2(Q0, Z) == pytest.approx(1.1242, abs=1e-3)


def test_ten_newtons_along_z_cost_8_89_Nm_weighted() -> None:
    _, J = model().arm.position_jacobian(Q0)
    assert 10 * torque_norm_per_newton(J, Z, W) == pytest.approx(8.89, abs=0.01)  # the paper's 8.89 N·m
    assert torque_norm_per_newton(J, Z, W) == pytest.approx(1 / directional_manipulability(J, Z, W))


@pytest.mark.parametrize("seed", range(6))
def test_gradient_matches_finite_differences(seed: int) -> None:
    rng = np.random.default_rng(seed)
    q = random_arm_q(rng)
    u = rng.normal(size=3)
    u /= np.linalg.norm(u)
    arm = model().arm
    _, J = arm.position_jacobian(q)
    value, grad = dm_gradient(J, arm.jacobian_derivatives(q), u, W)
    assert value == pytest.approx(h2(q, u), rel=1e-12)
    fd = np.zeros(7)
    for k in range(7):
        e = np.zeros(7)
        e[k] = 1e-6
        fd[k] = (h2(q + e, u) - h2(q - e, u)) / 2e-6
    assert np.linalg.norm(grad - fd) / np.linalg.norm(fd) < 1e-6


def test_cartesian_gradient_is_joint_gradient_through_pseudoinverse() -> None:
    rng = np.random.default_rng(7)
    g = rng.normal(size=7)
    J = rng.normal(size=(3, 7))
    np.testing.assert_allclose(dm_cartesian_gradient(g, J), g @ np.linalg.pinv(J), atol=1e-12)  # eq. (10)
    # the compiled normal-equation path (taken when σ_min is known to be ≥ 1e-4) agrees
    s = float(np.linalg.svd(J, compute_uv=False)[-1])
    np.testing.assert_allclose(dm_cartesian_gradient(g, J, s), g @ np.linalg.pinv(J), atol=1e-12)


def test_cartesian_gradient_near_a_singularity_falls_back_to_least_squares() -> None:
    J = np.array([[1.0, 0, 0, 0, 0, 0, 0], [0, 1.0, 0, 0, 0, 0, 0], [0, 0, 1e-9, 0, 0, 0, 0]])
    g = np.array([0.3, -0.2, 1.0, 0, 0, 0, 0])
    np.testing.assert_allclose(dm_cartesian_gradient(g, J, 1e-9), dm_cartesian_gradient(g, J), atol=0)


def test_cartesian_gradient_predicts_dm_change_along_minimum_norm_motion() -> None:
    kin = model().kinematics(np.zeros(3), Q0, hessian=True)
    assert kin.dJ_arm is not None
    _, g = dm_gradient(kin.J_arm, kin.dJ_arm, X, config().weights_for(model().config))
    gx = dm_cartesian_gradient(g, kin.J_m)
    dx = np.array([0.0, 0.0, -1e-5])
    dq = np.linalg.pinv(kin.J_m) @ dx
    central = (h2(Q0 + dq, X) - h2(Q0 - dq, X)) / 2
    assert central == pytest.approx(gx @ dx, rel=1e-6)


def test_yoshikawa_index_vanishes_at_stretched_arm() -> None:
    _, J0 = model().arm.position_jacobian(np.zeros(7))
    _, J1 = model().arm.position_jacobian(Q0)
    assert yoshikawa_manipulability(J0) < 1e-8
    assert yoshikawa_manipulability(J1) > 1e-3
