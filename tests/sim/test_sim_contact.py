"""The quasi-static box push and the joint torques τ = J_mᵀ F (wmm_qp_sim.contact)."""

from __future__ import annotations

import numpy as np
import pytest
from wmm_qp_sim import BoxConfig, SimCommand, SimConfig, SimRobot

import wmm_qp

DT = 1e-3


@pytest.fixture(scope="module")
def model() -> wmm_qp.WmmModel:
    return wmm_qp.WmmModel(wmm_qp.load_robot_config())


def push_forward(model: wmm_qp.WmmModel, box: BoxConfig, seconds: float) -> SimRobot:
    """Drive the base straight forward (the EE leads the robot into the box)."""
    sim = SimRobot(model, SimConfig().with_(slip={"enabled": False}))
    sim.reset(box=box)
    w = 0.1 / model.config.base.wheel_radius  # 0.1 m/s forward
    for k in range(round(seconds / DT)):
        ramp = min(1.0, (k + 1) * DT / 0.1)  # 13 rad/s² < 20
        sim.step(SimCommand(np.full(4, w * ramp), np.zeros(7)), DT)
    return sim


def test_no_box_no_contact(model: wmm_qp.WmmModel) -> None:
    sim = SimRobot(model, SimConfig())
    st = sim.reset()
    assert np.isnan(st.box_position)
    assert not st.tau.any()


def test_light_box_slides_with_the_ee_and_torques_equal_jt_f(model: wmm_qp.WmmModel) -> None:
    box = BoxConfig(mass=26.0, mu=0.3, face_x=0.70)
    sim = push_forward(model, box, 1.5)
    st = sim.state()
    assert st.stalled_joint is None
    assert st.box_displacement > 0.05
    assert st.box_position == pytest.approx(st.ee_true[0], abs=1e-9)
    F = np.array([0.3 * 26.0 * 9.81, 0.0, 0.0])
    np.testing.assert_allclose(st.contact_force, F)
    J_m = model.kinematics(st.base_true, st.q_arm).J_m
    np.testing.assert_allclose(st.tau, J_m.T @ F, atol=1e-9)
    assert st.violations == dict.fromkeys(st.violations, 0)


def test_before_contact_no_force(model: wmm_qp.WmmModel) -> None:
    sim = push_forward(model, BoxConfig(face_x=0.70), 0.2)  # the EE has moved ~0.02 m
    st = sim.state()
    assert st.box_displacement == 0.0
    assert not st.contact_force.any() and not st.tau.any()


def test_heavy_box_stalls_at_the_torque_limit(model: wmm_qp.WmmModel) -> None:
    box = BoxConfig(mass=200.0, mu=0.8, face_x=0.70)  # needs ~1570 N: far beyond the arm
    sim = push_forward(model, box, 1.5)
    st = sim.state()
    assert st.box_displacement == 0.0
    assert st.stalled_joint is not None
    j = st.stalled_joint
    limit = np.array(model.config.arm.torque_limit)
    assert abs(st.tau[j]) == pytest.approx(limit[j])
    assert np.all(np.abs(st.tau) <= limit * (1 + 1e-12))
    assert st.ee_true[0] <= 0.70 + 1e-12  # the EE is stopped at the face
    # the wheels spin in place: odometry runs ahead of the blocked true base
    assert st.base_odom[0] > st.base_true[0] + 0.05


def test_contact_only_inside_the_face(model: wmm_qp.WmmModel) -> None:
    box = BoxConfig(face_x=0.70, center_y=1.0, width=0.4)  # face off to the side
    sim = push_forward(model, box, 1.0)
    st = sim.state()
    assert st.box_displacement == 0.0 and not st.tau.any()
