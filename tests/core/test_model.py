"""Kinematics: FK (2), Mecanum base (3), (20), Jacobians (5), checked by finite differences."""

from __future__ import annotations

import numpy as np
import pytest
from support.core_fixtures import Q0, model, random_arm_q, robot

from wmm_qp.model.wmm import rot_z

EPS = 1e-6


def test_paper_start_configuration_ee_matches_paper() -> None:
    x = model().ee_position(np.zeros(3), Q0)
    assert x[0] == pytest.approx(0.650, abs=1e-3)  # paper: x0 = [0.65, 0.0246, 0.4921]
    assert x[2] == pytest.approx(0.492, abs=1e-3)
    assert abs(x[1]) == pytest.approx(0.0246, abs=5e-4)


def test_zero_configuration_matches_reference_fk() -> None:
    # Kinova's kinematics (the URDF's sources): q = 0 → end_effector_link at (0, -0.024860, 1.187385),
    # computed with the rounded rpy 3.1416 / 1.5708; our URDF uses pi and pi/2 exactly, which moves
    # y by 1e-5 m (the offsets add up to 0.02485 exactly).
    x = model().arm.position(np.zeros(7))
    np.testing.assert_allclose(x, [0.0, -0.024860, 1.187385], atol=2e-5)


def test_mount_offset_and_base_pose_compose_as_eq_2() -> None:
    rng = np.random.default_rng(3)
    q = random_arm_q(rng)
    qb = np.array([0.3, -1.2, 0.7])
    x = model().ee_position(qb, q)
    expected = np.array([qb[0], qb[1], 0.0]) + rot_z(qb[2]) @ model().arm.position(q)
    np.testing.assert_allclose(x, expected, atol=1e-12)


@pytest.mark.parametrize("seed", range(5))
def test_arm_jacobian_matches_finite_differences(seed: int) -> None:
    rng = np.random.default_rng(seed)
    q = random_arm_q(rng)
    _, J = model().arm.position_jacobian(q)
    fd = np.zeros((3, 7))
    for k in range(7):
        e = np.zeros(7)
        e[k] = EPS
        fd[:, k] = (model().arm.position(q + e) - model().arm.position(q - e)) / (2 * EPS)
    assert np.linalg.norm(J - fd) / np.linalg.norm(fd) < 1e-6


@pytest.mark.parametrize("seed", range(5))
def test_whole_robot_jacobian_matches_finite_differences(seed: int) -> None:
    """J = [J_b P, J_m] (eq. (5)): the EE velocity of wheel and joint rates, by integration."""
    rng = np.random.default_rng(seed)
    q = random_arm_q(rng)
    qb = np.array([*rng.uniform(-1, 1, 2), rng.uniform(-np.pi, np.pi)])
    kin = model().kinematics(qb, q)
    fd = np.zeros((3, 11))
    for k in range(11):
        v = np.zeros(11)
        v[k] = 1.0

        def x_at(h: float, v: np.ndarray = v) -> np.ndarray:
            # q̇_b = P(ψ) v_b is constant over a tiny step to first order
            return model().ee_position(qb + h * (kin.P @ v[:4]), q + h * v[4:])

        fd[:, k] = (x_at(EPS) - x_at(-EPS)) / (2 * EPS)
    assert np.linalg.norm(kin.J - fd) / np.linalg.norm(fd) < 1e-6


@pytest.mark.parametrize("seed", range(5))
def test_jacobian_derivative_from_kinematic_hessian_matches_finite_differences(seed: int) -> None:
    rng = np.random.default_rng(seed)
    q = random_arm_q(rng)
    arm = model().arm
    arm.position_jacobian(q)
    D = arm.jacobian_derivatives(q)
    fd = np.zeros((7, 3, 7))
    for k in range(7):
        e = np.zeros(7)
        e[k] = EPS
        fd[k] = (arm.position_jacobian(q + e)[1] - arm.position_jacobian(q - e)[1]) / (2 * EPS)
    assert np.linalg.norm(D - fd) / np.linalg.norm(fd) < 1e-6


class TestMecanum:
    """Eqs. (3), (20), wheels FL, FR, RL, RR."""

    R = robot().base.wheel_radius
    L = robot().base.l1 + robot().base.l2

    def test_all_wheels_forward_drive_forward(self) -> None:
        np.testing.assert_allclose(model().base.body_twist(np.ones(4)), [self.R, 0, 0], atol=1e-15)

    def test_sideways_pattern_drives_left(self) -> None:
        np.testing.assert_allclose(model().base.body_twist(np.array([-1.0, 1, 1, -1])), [0, self.R, 0], atol=1e-15)

    def test_spin_pattern_turns_counter_clockwise(self) -> None:
        np.testing.assert_allclose(
            model().base.body_twist(np.array([-1.0, 1, -1, 1])), [0, 0, self.R / self.L], atol=1e-15
        )

    def test_P_rotates_body_twist_into_world(self) -> None:
        yaw = 0.8
        w = np.array([1.0, 1, 1, 1])  # forward in the body frame
        np.testing.assert_allclose(model().base.P(yaw) @ w, [self.R * np.cos(yaw), self.R * np.sin(yaw), 0])

    def test_wheel_speeds_invert_the_twist(self) -> None:
        twist = np.array([0.3, -0.2, 0.5])
        np.testing.assert_allclose(model().base.body_twist(model().base.wheel_speeds(twist)), twist, atol=1e-12)
