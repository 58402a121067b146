"""The simulated robot: Mecanum motion, odometry vs. truth, stale stop (wmm_qp_sim.robot)."""

from __future__ import annotations

import numpy as np
import pytest
from wmm_qp_sim import SimCommand, SimConfig, SimRobot, load_sim_config

import wmm_qp

DT = 1e-3


@pytest.fixture(scope="module")
def model() -> wmm_qp.WmmModel:
    return wmm_qp.WmmModel(wmm_qp.load_robot_config())


def no_slip() -> SimConfig:
    return SimConfig().with_(slip={"enabled": False})


def drive(sim: SimRobot, wheels: np.ndarray, seconds: float, arm: np.ndarray | None = None) -> None:
    cmd = SimCommand(wheels, np.zeros(7) if arm is None else arm)
    for _ in range(round(seconds / DT)):
        sim.step(cmd, DT)


def test_default_config_loads() -> None:
    cfg = load_sim_config()
    assert cfg.rate_hz == 1000.0
    assert cfg.dt == pytest.approx(1e-3)
    assert cfg.slip.enabled


@pytest.mark.parametrize(
    ("wheels", "direction"),
    [
        ((1.0, 1.0, 1.0, 1.0), (1.0, 0.0, 0.0)),  # pure forward
        ((-1.0, 1.0, 1.0, -1.0), (0.0, 1.0, 0.0)),  # pure sideways (left)
        ((-1.0, 1.0, -1.0, 1.0), (0.0, 0.0, 1.0)),  # pure spin (counter-clockwise)
    ],
)
def test_mecanum_pure_motions(
    model: wmm_qp.WmmModel, wheels: tuple[float, ...], direction: tuple[float, ...]
) -> None:
    sim = SimRobot(model, no_slip())
    sim.reset()
    drive(sim, np.array(wheels), 0.5)
    st = sim.state()
    moved = st.base_true
    R = model.config.base.wheel_radius
    L = model.config.base.l1 + model.config.base.l2
    expected_speed = R if direction[2] == 0 else R / L
    np.testing.assert_allclose(moved, np.array(direction) * expected_speed * 0.5, atol=1e-12)
    np.testing.assert_allclose(st.wheel_speeds, wheels)


def test_odometry_equals_truth_without_slip(model: wmm_qp.WmmModel) -> None:
    sim = SimRobot(model, no_slip())
    sim.reset()
    drive(sim, np.array([2.0, 1.0, 3.0, -1.0]), 1.0, arm=np.full(7, 0.1))
    st = sim.state()
    np.testing.assert_array_equal(st.base_odom, st.base_true)
    np.testing.assert_allclose(st.ee_true, model.ee_position(st.base_odom, st.q_arm), atol=1e-12)
    np.testing.assert_allclose(st.q_arm, np.array(wmm_qp.load_robot_config().arm.start) + 0.1, atol=1e-9)


def test_slip_makes_odometry_drift_reproducibly(model: wmm_qp.WmmModel) -> None:
    finals = []
    for _ in range(2):
        sim = SimRobot(model, SimConfig(), seed=7)
        sim.reset()
        drive(sim, np.array([5.0, 5.0, 5.0, 5.0]), 2.0)
        finals.append(sim.state())
    a, b = finals
    np.testing.assert_array_equal(a.base_true, b.base_true)  # seeded: reproducible
    np.testing.assert_allclose(a.base_odom, b.base_odom)
    drift = np.linalg.norm(a.base_true[:2] - a.base_odom[:2])
    assert drift > 1e-3  # ~0.76 m travelled with ~2 % per-wheel scale errors
    assert drift < 0.1
    other = SimRobot(model, SimConfig(), seed=8)
    other.reset()
    drive(other, np.array([5.0, 5.0, 5.0, 5.0]), 2.0)
    assert not np.allclose(other.state().base_true, a.base_true)


def test_reset_restores_rest_and_counts(model: wmm_qp.WmmModel) -> None:
    sim = SimRobot(model, no_slip())
    sim.step(SimCommand(np.full(4, 100.0), np.zeros(7)), DT)
    assert sim.state().violations["wheel_speed"] == 4
    st = sim.reset(q_base=(1.0, 2.0, 0.5))
    assert st.violations == dict.fromkeys(st.violations, 0)
    np.testing.assert_array_equal(st.base_odom, [1.0, 2.0, 0.5])
    rs = sim.robot_state()
    np.testing.assert_array_equal(rs.q_base, [1.0, 2.0, 0.5])
    assert not rs.v_arm.any() and not rs.wheel_speeds.any()


def test_robot_state_reports_odometry_and_executed_rates(model: wmm_qp.WmmModel) -> None:
    sim = SimRobot(model, SimConfig(), seed=1)
    sim.reset()
    drive(sim, np.array([3.0, 3.0, 3.0, 3.0]), 0.3, arm=np.full(7, 0.01))
    rs, st = sim.robot_state(), sim.state()
    np.testing.assert_array_equal(rs.q_base, st.base_odom)
    np.testing.assert_array_equal(rs.v_arm, np.full(7, 0.01))
    np.testing.assert_array_equal(rs.wheel_speeds, np.full(4, 3.0))


def test_stale_commands_brake_to_rest_at_acceleration_limits(model: wmm_qp.WmmModel) -> None:
    cfg = no_slip().with_(stale_timeout=0.05)
    sim = SimRobot(model, cfg)
    sim.reset()
    # reachable from rest within the 50 ms the command is held (legal for the referee)
    v0 = np.array([0.1, -0.1, 0.1, 0.05, -0.2, 0.2, 0.3])
    w0 = np.array([0.8, -0.8, 0.5, 0.2])
    sim.step(SimCommand(w0, v0), DT)
    for _ in range(49):
        st = sim.step(None, DT)
        assert not st.stale_stop
        np.testing.assert_array_equal(st.v_arm, v0)  # held command goes on
    st = sim.step(None, DT)
    assert st.stale_stop
    prev = st
    for _ in range(200):
        st = sim.step(None, DT)
        a_max = np.array(model.config.arm.acceleration_max)
        assert np.all(np.abs(st.v_arm - prev.v_arm) <= a_max * DT + 1e-12)
        prev = st
    assert not st.v_arm.any() and not st.wheel_speeds.any()
    assert st.violations == dict.fromkeys(st.violations, 0)
    # a new command ends the stale stop
    st = sim.step(SimCommand(np.zeros(4), np.zeros(7)), DT)
    assert not st.stale_stop


def test_malformed_command_is_ignored_and_counted(model: wmm_qp.WmmModel) -> None:
    sim = SimRobot(model, no_slip())
    sim.reset()
    sim.step(SimCommand(np.full(4, 0.01), np.zeros(7)), DT)
    st = sim.step(SimCommand(np.full(4, np.nan), np.zeros(7)), DT)
    assert st.rejected_commands == 1
    np.testing.assert_array_equal(st.wheel_speeds, np.full(4, 0.01))
    st = sim.step(SimCommand(np.zeros(3), np.zeros(7)), DT)
    assert st.rejected_commands == 2
