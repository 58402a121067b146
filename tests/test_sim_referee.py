"""The sim's independent limit referee (wmm_qp_sim.referee)."""

from __future__ import annotations

import numpy as np
import pytest
from wmm_qp_sim import SimCommand, SimConfig, SimRobot

import wmm_qp

DT = 1e-3
CTRL_DT = 2e-3  # controller at 500 Hz: two sim steps per command


@pytest.fixture(scope="module")
def model() -> wmm_qp.WmmModel:
    return wmm_qp.WmmModel(wmm_qp.load_robot_config())


def run(model: wmm_qp.WmmModel, commands: list[tuple[np.ndarray, np.ndarray]]) -> dict[str, int]:
    sim = SimRobot(model, SimConfig().with_(slip={"enabled": False}))
    sim.reset()
    for wheels, arm in commands:
        sim.step(SimCommand(wheels, arm), DT)
        sim.step(None, DT)
    return sim.state().violations


def ramp(model: wmm_qp.WmmModel, fraction: float, n: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """Accelerate every joint and wheel at `fraction` of its limit for n commands, then hold.

    The final repeated command makes the referee judge the last change (it judges a change
    when the next command arrives).
    """
    a = np.array(model.config.arm.acceleration_max) * fraction
    wa = model.config.base.wheel_acceleration_max * fraction
    cmds = [(np.full(4, wa * CTRL_DT * (k + 1)), a * CTRL_DT * (k + 1)) for k in range(n)]
    return [*cmds, cmds[-1]]


def test_legal_sequence_counts_nothing(model: wmm_qp.WmmModel) -> None:
    # exactly at the acceleration limit: legal
    v = run(model, ramp(model, 1.0, 50))
    assert v == dict.fromkeys(v, 0)


def test_acceleration_violation_is_caught(model: wmm_qp.WmmModel) -> None:
    v = run(model, ramp(model, 1.01, 10))
    assert v["acceleration"] == 7 * 10
    assert v["wheel_acceleration"] == 4 * 10
    assert v["velocity"] == 0 and v["position"] == 0


def test_velocity_violation_is_caught(model: wmm_qp.WmmModel) -> None:
    vmax = np.array(model.config.arm.velocity_max)
    wmax = model.config.base.wheel_speed_max
    # a step from rest straight above the velocity limit: velocity and acceleration both count
    v = run(model, [(np.array([wmax * 1.1, 0, 0, 0]), np.r_[vmax[0] * 1.1, np.zeros(6)])] * 3)
    assert v["velocity"] == 3
    assert v["wheel_speed"] == 3
    assert v["acceleration"] == 1
    assert v["wheel_acceleration"] == 1


def test_position_violation_is_caught_and_continuous_joints_are_free(
    model: wmm_qp.WmmModel,
) -> None:
    sim = SimRobot(model, SimConfig().with_(slip={"enabled": False}))
    upper = np.array(model.config.arm.position_upper)
    q = np.zeros(7)
    q[1] = upper[1] - 0.001
    sim.reset(q_arm=q)
    # joint 2 drives 0.01 rad past its limit; joint 1 (continuous) spins freely
    rates = np.zeros(7)
    rates[0], rates[1] = 1.0, 0.5
    steps = 0
    sim.step(SimCommand(np.zeros(4), rates * 0.0), DT)
    for k in range(1, 300):
        a = k / 300.0  # gentle ramp: 3.3 rad/s² at most
        st = sim.step(SimCommand(np.zeros(4), rates * a), DT)
        steps += int(st.q_arm[1] > upper[1])
    v = sim.state().violations
    assert v["position"] == steps > 0
    assert v["acceleration"] == 0 and v["velocity"] == 0


def test_tolerance_accepts_round_off(model: wmm_qp.WmmModel) -> None:
    vmax = np.array(model.config.arm.velocity_max)
    sim = SimRobot(model, SimConfig().with_(slip={"enabled": False}))
    sim.reset()
    sim.referee.on_new_rates(0.0, vmax, np.zeros(4), vmax * (1 + 1e-12), np.zeros(4))
    assert sim.referee.counts["velocity"] == 0
    sim.referee.on_new_rates(1.0, vmax, np.zeros(4), vmax * (1 + 1e-6), np.zeros(4))
    assert sim.referee.counts["velocity"] == 7
