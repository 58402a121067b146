"""The daemon's logic without transport (ControlCore), driven with a fake clock."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from wmm_qp_service.config import ServiceConfig
from wmm_qp_service.daemon import ControlCore
from wmm_qp_service.protocol import ModeMsg, SetpointMsg, StateMsg

import wmm_qp as w

DT = 0.002


class Plant:
    """Integrates commands exactly (executed = commanded) and makes StateMsgs."""

    def __init__(self, model: w.WmmModel) -> None:
        self.model = model
        self.q_base = np.zeros(3)
        self.q_arm = np.array(w.load_robot_config().arm.start)
        self.v_arm = np.zeros(7)
        self.wheels = np.zeros(4)
        self.seq = 0
        self.instance = "sim-A"
        self.violations: dict[str, int] = {"position": 0}
        self.cmd_seq = -1

    def apply(self, cmd: w.Command) -> None:
        self.v_arm, self.wheels = cmd.arm_rates.copy(), cmd.wheel_speeds.copy()
        self.q_arm = self.q_arm + DT * self.v_arm
        self.q_base = self.q_base + DT * (self.model.base.P(float(self.q_base[2])) @ self.wheels)

    def msg(self, **kw: object) -> StateMsg:
        self.seq += 1
        d: dict[str, object] = dict(
            robot="wmm", seq=self.seq, stamp=0.0, t=0.0, q_base=self.q_base.tolist(),
            q_arm=self.q_arm.tolist(), v_arm=self.v_arm.tolist(), wheel_speeds=self.wheels.tolist(),
            base_true=self.q_base.tolist(), ee_true=self.model.ee_position(self.q_base, self.q_arm).tolist(),
            tau=[0.0] * 7, contact_force=[0.0] * 3, instance=self.instance, lease="core",
            violations=dict(self.violations), cmd_seq=self.cmd_seq)
        d.update(kw)
        return StateMsg(**d)  # type: ignore[arg-type]


@pytest.fixture(scope="module")
def robot() -> w.RobotConfig:
    return w.load_robot_config()


def make(robot: w.RobotConfig) -> tuple[ControlCore, Plant]:
    core = ControlCore(ServiceConfig(), w.load_controller_config(), robot)
    return core, Plant(core.model)


def run(core: ControlCore, plant: Plant, t: float, n: int,
        setpoint: np.ndarray | None = None) -> tuple[float, list[w.Command]]:
    cmds = []
    for _ in range(n):
        core.on_state(plant.msg(), t)
        if setpoint is not None:
            core.on_setpoint(SetpointMsg(robot="wmm", seq=1, stamp=t, x=setpoint.tolist(), source="op"), t)
        cmd = core.tick(t)
        assert cmd is not None
        plant.apply(cmd)
        cmds.append(cmd)
        t += DT
    return t, cmds


def max_step_ratio(robot: w.RobotConfig, cmds: list[w.Command]) -> float:
    a = np.asarray(robot.arm.acceleration_max) * DT
    wa = robot.base.wheel_acceleration_max * DT
    worst = 0.0
    for p, q in itertools.pairwise(cmds):
        worst = max(worst, float(np.max(np.abs(q.arm_rates - p.arm_rates) / a)),
                    float(np.max(np.abs(q.wheel_speeds - p.wheel_speeds) / wa)))
    return worst


def test_no_command_before_a_state(robot: w.RobotConfig) -> None:
    core, _ = make(robot)
    assert core.tick(0.0) is None


def test_tracks_a_stream_and_mode_changes_never_jump(robot: w.RobotConfig) -> None:
    core, plant = make(robot)
    x0 = core.model.ee_position(plant.q_base, plant.q_arm)
    core.on_mode(ModeMsg(robot="wmm", seq=1, stamp=0.0, mode="track"))
    t, cmds = run(core, plant, 0.0, 600, setpoint=x0 + np.array([0.05, 0.03, -0.02]))
    x = core.model.ee_position(plant.q_base, plant.q_arm)
    assert np.linalg.norm(x - (x0 + np.array([0.05, 0.03, -0.02]))) < 2e-3
    all_cmds = list(cmds)
    for mode in ("hold", "dm_nullspace", "dm_cartesian", "track", "hold"):
        core.on_mode(ModeMsg(robot="wmm", seq=1, stamp=0.0, mode=mode))
        t, cmds = run(core, plant, t, 150, setpoint=x0 + np.array([-0.05, 0.0, 0.0]))
        all_cmds += cmds
    assert max_step_ratio(robot, all_cmds) <= 1.0 + 1e-6  # inside A·dt every tick


def test_setpoints_are_ignored_in_hold(robot: w.RobotConfig) -> None:
    core, plant = make(robot)
    x0 = core.model.ee_position(plant.q_base, plant.q_arm)
    run(core, plant, 0.0, 200, setpoint=x0 + np.array([0.1, 0.0, 0.0]))
    assert np.linalg.norm(core.model.ee_position(plant.q_base, plant.q_arm) - x0) < 1e-6


def test_stale_setpoints_bring_the_target_to_rest(robot: w.RobotConfig) -> None:
    core, plant = make(robot)
    x0 = core.model.ee_position(plant.q_base, plant.q_arm)
    core.on_mode(ModeMsg(robot="wmm", seq=1, stamp=0.0, mode="track"))
    t, _ = run(core, plant, 0.0, 50, setpoint=x0 + np.array([0.3, 0.0, 0.0]))
    assert not core.smoother.resting
    t, _ = run(core, plant, t, 500)  # no more setpoints for 1 s > setpoint_timeout
    assert core.smoother.resting and np.allclose(core.smoother.velocity, 0.0)


def test_stale_state_gives_a_safe_stop_inside_the_bounds(robot: w.RobotConfig) -> None:
    core, plant = make(robot)
    x0 = core.model.ee_position(plant.q_base, plant.q_arm)
    core.on_mode(ModeMsg(robot="wmm", seq=1, stamp=0.0, mode="track"))
    t, cmds = run(core, plant, 0.0, 300, setpoint=x0 + np.array([0.3, 0.2, 0.0]))
    assert np.abs(cmds[-1].v).max() > 1e-3
    stops = []
    for _ in range(400):  # no state any more
        c = core.tick(t)
        assert c is not None
        stops.append(c)
        t += DT
    assert core.safe and "state stale" in core.last_fault
    assert all(c.status == w.Status.SAFE_STOP for c in stops[30:])
    assert max_step_ratio(robot, [cmds[-1], *stops]) <= 1.0 + 1e-6
    assert np.abs(stops[-1].v).max() == 0.0
    # the state comes back: resume from the measured state, still no jump
    plant.v_arm, plant.wheels = stops[-1].arm_rates.copy(), stops[-1].wheel_speeds.copy()
    t, cmds = run(core, plant, t, 50)
    assert not core.safe and all(c.status != w.Status.SAFE_STOP for c in cmds)


def test_sim_lost_is_a_fault(robot: w.RobotConfig) -> None:
    core, plant = make(robot)
    t, _ = run(core, plant, 0.0, 5)
    core.on_sim_alive(True)
    core.on_sim_alive(False)
    assert core.state_time == -math.inf
    core.tick(t)
    assert core.safe and core.last_fault.startswith("sim lost")
