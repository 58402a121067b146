"""The sim's independent limit referee (wmm_qp_robot.referee)."""

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


def bare() -> SimConfig:
    """No slip, no firmware: the referee alone (the firmware's own tests are below)."""
    return SimConfig(firmware=False).with_(slip={"enabled": False})


def run(model: wmm_qp.WmmModel, commands: list[tuple[np.ndarray, np.ndarray]],
        cfg: SimConfig | None = None, ramp: bool = False) -> dict[str, int]:
    sim = SimRobot(model, cfg or bare(), ramp=ramp)
    sim.reset()
    for k, (wheels, arm) in enumerate(commands):
        sim.step(SimCommand(wheels, arm, period=CTRL_DT, seq=k), DT)
        sim.step(None, DT)
    return sim.state().violations


def ramp(model: wmm_qp.WmmModel, fraction: float, n: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """Accelerate every joint and wheel at `fraction` of its limit for n commands, then hold.

    The final repeated command holds the last rate (a change of zero).
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
    wmax = float(model.config.base.wheel_speed_max[0])
    # a step from rest straight above the velocity limit: velocity and acceleration both count
    v = run(model, [(np.array([wmax * 1.1, 0, 0, 0]), np.r_[vmax[0] * 1.1, np.zeros(6)])] * 3)
    assert v["velocity"] == 3
    assert v["wheel_speed"] == 3
    assert v["acceleration"] == 1
    assert v["wheel_acceleration"] == 1


def test_position_violation_is_caught_and_continuous_joints_are_free(
    model: wmm_qp.WmmModel,
) -> None:
    sim = SimRobot(model, bare())
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
    sim = SimRobot(model, bare())
    sim.reset()
    z = np.zeros(4)
    sim.referee.on_command(0.0, vmax * (1 + 1e-12), z, vmax, z, period=1.0)
    assert sim.referee.counts["velocity"] == 0
    sim.referee.on_command(1.0, vmax * (1 + 1e-6), z, vmax, z, period=1.0)
    assert sim.referee.counts["velocity"] == 7


def test_the_referee_judges_the_command_as_received_not_as_ramped(model: wmm_qp.WmmModel) -> None:
    """The drive ramp executes every command within A·dt; a jump in the commands is still
    counted (before the fix the adapter ramped first and the referee saw only the ramp)."""
    a = np.array(model.config.arm.acceleration_max)
    jump = [(np.zeros(4), a * CTRL_DT * 3.0)] * 5  # 3·A·dt from rest in one command
    v = run(model, jump, ramp=True)
    assert v["acceleration"] == 7 and v["position"] == 0
    legal = run(model, ramp(model, 1.0, 50), ramp=True)
    assert legal == dict.fromkeys(legal, 0)


def test_the_drive_ramp_executes_within_the_acceleration_limit(model: wmm_qp.WmmModel) -> None:
    a = np.array(model.config.arm.acceleration_max)
    sim = SimRobot(model, bare(), ramp=True)
    sim.reset()
    prev = sim.state().v_arm
    for k in range(60):  # a 25·A·dt jump, then held, as a daemon at 500 Hz would send it
        cmd = SimCommand(np.zeros(4), a * 0.05, period=CTRL_DT, seq=k) if k % 2 == 0 else None
        st = sim.step(cmd, DT)
        assert np.all(np.abs(st.v_arm - prev) <= a * DT * (1 + 1e-12) + 1e-15)
        prev = st.v_arm
    np.testing.assert_allclose(prev, a * 0.05)


def test_a_lost_command_widens_the_window(model: wmm_qp.WmmModel) -> None:
    """Commands 1 and 3 arrive (2 was lost): their change is judged over two periods."""
    a = np.array(model.config.arm.acceleration_max)
    sim = SimRobot(model, bare())
    sim.reset()
    z = np.zeros(4)
    sim.step(SimCommand(z, a * CTRL_DT, period=CTRL_DT, seq=1), DT)
    sim.step(SimCommand(z, a * CTRL_DT * 3, period=CTRL_DT, seq=3), DT)
    assert sim.state().violations["acceleration"] == 0
    sim.step(SimCommand(z, a * CTRL_DT * 5, period=CTRL_DT, seq=4), DT)  # 2 A·dt in one period
    assert sim.state().violations["acceleration"] == 7


def test_a_stream_late_on_the_way_is_judged_against_itself_a_new_stream_against_the_robot(
    model: wmm_qp.WmmModel,
) -> None:
    """Commands delayed past the robot's timeout (the sim braked meanwhile) are still one legal
    stream; a command of a new stream must start from what the robot executes."""
    a = np.array(model.config.arm.acceleration_max)
    sim = SimRobot(model, bare())
    sim.reset()
    z = np.zeros(4)
    v = np.zeros(7)
    for k in range(100):  # accelerating at A: legal
        v = v + a * CTRL_DT
        sim.step(SimCommand(z, v.copy(), period=CTRL_DT, seq=k, stream=0), DT)
        sim.step(None, DT)
    for _ in range(40):  # nothing arrives: the robot brakes in its stale stop
        st = sim.step(None, DT)
    assert st.stale_stop and np.all(st.v_arm < v)
    v = v + a * CTRL_DT  # the next command of the same stream arrives late
    sim.step(SimCommand(z, v.copy(), period=CTRL_DT, seq=100, stream=0), DT)
    assert sim.state().violations["acceleration"] == 0
    for _ in range(40):
        st = sim.step(None, DT)
    # a new stream that ignores the braked rates is counted
    sim.step(SimCommand(z, v.copy(), period=CTRL_DT, seq=101, stream=101), DT)
    assert sim.state().violations["acceleration"] == 7


def test_an_acceleration_violation_of_a_robot_without_wheels_is_counted() -> None:
    """A fixed base has empty wheel vectors: the event line's ratio must not reduce over them."""
    import dataclasses

    from wmm_qp_robot.config import RefereeConfig
    from wmm_qp_robot.referee import Referee

    r = wmm_qp.load_robot_config()
    fixed = dataclasses.replace(r, base=dataclasses.replace(r.base, wheel_speed_max=np.zeros(0),
                                                            wheel_acceleration_max=np.zeros(0)))
    ref = Referee(fixed, RefereeConfig())
    none = np.zeros(0)
    ref.on_command(0.0, np.full(7, 0.5), none, np.zeros(7), none, period=0.002, seq=1, stream=1)
    assert ref.counts["acceleration"] == 7 and "acceleration" in ref.last_event
