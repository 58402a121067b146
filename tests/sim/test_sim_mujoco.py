"""The physics plant (wmm_qp_sim.mujoco_plant, mujoco_model): built from each robot description,
torque-limited servos, traction-limited wheels, and the same firmware and referees around it."""

from __future__ import annotations

from dataclasses import replace
from functools import cache
from pathlib import Path

import numpy as np
import pytest
from wmm_qp_sim import SimCommand, SimConfig, SimRobot, load_sim_config
from wmm_qp_sim.config import BoxConfig

import wmm_qp as w
from wmm_qp import urdf as urdf_io
from wmm_qp.config import default_config_dir
from wmm_qp.exceptions import ConfigError
from wmm_qp.limits import MotionBounds

mujoco = pytest.importorskip("mujoco", reason="the physics plant needs mujoco: pip install 'wmm-qp[physics]'")

from wmm_qp_sim.mujoco_plant import MujocoPlant  # noqa: E402 (after the skip)

DT = 1e-3
ROBOTS = default_config_dir() / "robots"
SHIPPED = sorted(p.name for p in ROBOTS.glob("*.toml"))
PHYSICS = SimConfig(firmware=False).with_(physics={"plant": "mujoco"})


@cache
def model(name: str) -> w.WmmModel:
    return w.WmmModel(w.load_robot_config(ROBOTS / name))


def plant(name: str, **physics: float) -> MujocoPlant:
    return MujocoPlant(model(name), replace(PHYSICS.physics, **physics), DT)


def hold(p: MujocoPlant, steps: int, wheels: np.ndarray | None = None, arm: np.ndarray | None = None) -> None:
    m = p.wmm
    p.write(np.zeros(m.n_wheels) if wheels is None else wheels, np.zeros(m.n_arm) if arm is None else arm)
    for _ in range(steps):
        p.advance(DT)


@pytest.mark.parametrize("name", SHIPPED)
def test_the_model_has_the_urdfs_masses_and_the_robot_files_limits(name: str) -> None:
    m = model(name)
    p = plant(name)
    mj = p.robot.model
    pm = m.arm.model
    for j in range(1, pm.njoints):  # every joint's body: the reduced model's inertia (locked links merged)
        body = mj.body(pm.names[j])
        assert mj.body_mass[body.id] == pytest.approx(max(pm.inertias[j].mass, 1e-4), rel=1e-9)
    full = urdf_io.load_full_model(m.config.path, m.config.arm.urdf)
    arm_mass = float(mj.body_subtreemass[p.robot.base_body]) - PHYSICS.physics.base_mass
    urdf_mass = sum(inertia.mass for inertia in full.inertias)  # every link, the root's (inertias[0]) too
    assert arm_mass == pytest.approx(urdf_mass, rel=1e-6)  # the whole URDF, locked parts too
    arm = m.config.arm
    for k, joint in enumerate(arm.joints):
        if np.isfinite(arm.position_lower[k]):
            np.testing.assert_allclose(mj.joint(joint).range, [arm.position_lower[k], arm.position_upper[k]])
        assert mj.actuator(joint).forcelimited
        np.testing.assert_allclose(mj.actuator(joint).forcerange, [-arm.torque_limit[k], arm.torque_limit[k]])
    assert (mj.body("base").id in mj.jnt_bodyid) == (m.config.base.kind != "fixed")


@pytest.mark.parametrize("name", SHIPPED)
def test_the_physics_ee_is_where_the_controllers_model_puts_it(name: str) -> None:
    m = model(name)
    p = plant(name)
    p.reset(np.array([0.5, -0.3, 0.7]), np.array(m.config.arm.start, dtype=float), None)
    wheels = m.base.wheel_speeds(np.array([0.1, 0.05, 0.2])) if m.n_wheels else np.zeros(0)
    hold(p, 300, wheels=wheels, arm=np.linspace(-0.3, 0.3, m.n_arm))
    st = p.read()
    mujoco.mj_kinematics(p.robot.model, p.data)  # a step leaves the poses of its start
    tip = p.data.geom("ee_tip").xpos
    np.testing.assert_allclose(tip, m.ee_position(st.base_true, st.q_arm), atol=1e-9)
    assert np.abs(st.q_arm - m.config.arm.start).max() > 0.05  # it moved


@pytest.mark.parametrize("name", SHIPPED)
def test_gravity_is_carried_the_arm_holds_its_start(name: str) -> None:
    p = plant(name)
    q0 = p.read().q_arm.copy()
    hold(p, 500)
    st = p.read()
    np.testing.assert_allclose(st.q_arm, q0, atol=1e-6)
    assert st.stalled_joint is None and st.lagging_joint is None
    assert np.all(np.abs(st.tau) <= p.torque_limit)


def test_a_joint_that_needs_more_than_its_torque_limit_does_not_follow() -> None:
    name = "gen3_mecanum.toml"
    m = model(name)
    shoulder = 1  # joint 2 carries the arm's weight at the start
    up = np.zeros(m.n_arm)
    up[shoulder] = -0.2  # [rad/s] lift
    strong = plant(name)
    q0 = strong.read().q_arm.copy()
    hold(strong, 500, arm=up)
    assert strong.read().q_arm[shoulder] == pytest.approx(q0[shoulder] - 0.1, abs=5e-3)  # it follows
    weak_limits = np.array(m.config.arm.torque_limit, dtype=float)
    weak_limits[shoulder] = 5.0  # [N·m] less than the arm's weight needs
    weak = SimRobot(m, PHYSICS, collisions=False, plant=plant(name))
    weak.plant.torque_limit = weak_limits  # type: ignore[attr-defined]
    weak.plant.robot.model.actuator_forcerange[shoulder] = [-5.0, 5.0]  # type: ignore[attr-defined]
    weak.reset()
    for _ in range(500):
        st = weak.step(SimCommand(np.zeros(m.n_wheels), up), DT)
    assert st.q_arm[shoulder] > q0[shoulder]  # it sank instead of lifting
    assert abs(st.tau[shoulder]) == pytest.approx(5.0, rel=1e-6)
    assert st.drives["torque_limit"][shoulder] > 400 and st.drives["tracking"][shoulder] > 400
    assert sum(st.drives["torque_limit"]) == st.drives["torque_limit"][shoulder]


def into_the_limit(physics: SimConfig, seconds: float = 3.0) -> tuple[int, float]:
    """Joint 4 of the Gen3 driven into its upper limit along bounds (13) (the controller config's
    period and ``state_latency``, centred on the last command as the controller's are) while
    joints 1 and 2 swing: their motion loads joint 4 through the arm's inertia, which the drives'
    gravity compensation does not carry. Returns (the referee's position count, [rad] joint 4's
    largest excursion past its limit)."""
    m = model("gen3_mecanum.toml")
    arm, ctl = m.config.arm, w.load_controller_config()
    bounds = MotionBounds(arm.position_lower, arm.position_upper, arm.velocity_max, arm.acceleration_max,
                          ctl.dt, ctl.state_latency)
    sim = SimRobot(m, physics, collisions=False)
    st = sim.reset()
    joint, last, past = 3, np.zeros(m.n_arm), -np.inf
    n_sub = round(ctl.dt / DT)
    for k in range(round(seconds / ctl.dt)):
        t = k * ctl.dt
        want = np.zeros(m.n_arm)
        want[joint] = arm.velocity_max[joint]  # [rad/s] into the limit, and on pushing at it
        want[0], want[1] = np.sin(2 * np.pi * t), 0.5 * np.sin(2 * np.pi * t / 0.7)
        lo, hi = bounds(st.q_arm, last)
        last = np.clip(want, lo, hi)
        st = sim.step(SimCommand(np.zeros(m.n_wheels), last), DT)
        for _ in range(n_sub - 1):
            st = sim.step(None, DT)
        past = max(past, float(st.q_arm[joint] - arm.position_upper[joint]))
    assert st.q_arm[joint] > arm.position_upper[joint] - 1e-3  # it reached the limit
    return st.violations["position"], past


def test_a_joint_driven_into_its_limit_along_bounds_13_stays_inside_under_load() -> None:
    """A velocity servo commanded 0 at the limit drifts under the load (its rate error is load /
    gain) into the limit; the drive's position-aware cap holds it ``limit_margin`` inside."""
    counts, past = into_the_limit(PHYSICS)
    assert counts == 0
    # the cap at the limit itself is not enough: its servo still yields load / gain · Δt past it
    assert into_the_limit(PHYSICS.with_(physics={"limit_margin": 0.0}))[0] > 0
    assert -1e-5 - 1e-6 < past < 0.0  # [rad] at the drive's line (limit_margin), inside the limit


@pytest.mark.parametrize("name", ["gen3_mecanum.toml", "panda_diffdrive.toml"])
def test_the_base_holds_below_its_traction_and_slips_beyond(name: str) -> None:
    moved = {}
    for share in (0.8, 1.3):
        p = plant(name)
        cap = p.physics.mu_wheel * p.mass * p.physics.g
        p.data.xfrc_applied[p.robot.base_body, 1] = share * cap  # [N] sideways (a differential drive's hard way)
        hold(p, 1000)
        moved[share] = float(np.linalg.norm(p.read().base_true[:2]))
    assert moved[0.8] < 0.01  # [m] the wheels hold it
    assert moved[1.3] > 0.3  # [m] pushed past its traction in 1 s, it slides away


def test_the_commanded_wheel_speeds_drive_the_base_and_are_measured() -> None:
    m = model("gen3_mecanum.toml")
    p = plant("gen3_mecanum.toml")
    wheels = m.base.wheel_speeds(np.array([0.0, 0.3, 0.0]))  # [m/s] sideways
    hold(p, 1000, wheels=wheels)
    st = p.read()
    assert st.base_true[1] == pytest.approx(0.3, abs=0.02) and abs(st.base_true[0]) < 1e-3
    np.testing.assert_allclose(st.wheel_speeds, wheels, atol=1e-3)


def sideways_drift(mu_wheel: float) -> float:
    """[m] the Panda's differential-drive base's largest sideways offset while its EE moves
    sideways at 0.4 m/s, back and forth (0.2 m, −0.4 m, +0.2 m), the wheels commanded still."""
    name = "panda_diffdrive.toml"
    m = model(name)
    sim = SimRobot(m, PHYSICS, collisions=False, plant=plant(name, mu_wheel=mu_wheel))
    st = sim.reset()
    drift = 0.0
    for k in range(2000):
        J = m.kinematics(st.base_true, st.q_arm).J_m
        v = -0.4 if 500 <= k < 1500 else 0.4  # [m/s] along world y, the base's sideways at yaw 0
        st = sim.step(SimCommand(np.zeros(m.n_wheels), np.linalg.pinv(J) @ np.array([0.0, v, 0.0])), DT)
        drift = max(drift, abs(st.base_true[1]))
    return drift


def test_a_differential_drive_does_not_drift_sideways_while_the_arm_moves_sideways() -> None:
    assert sideways_drift(mu_wheel=0.5) < 0.002  # [m]
    assert sideways_drift(mu_wheel=0.0) > 0.002  # without traction the same task pushes it aside


def test_a_light_box_slides_a_heavy_one_stalls_the_arm_at_its_torque_limit() -> None:
    m = model("gen3_mecanum.toml")
    sim = SimRobot(m, PHYSICS, collisions=False)
    ee = m.ee_position(np.zeros(3), m.config.arm.start)
    result = {}
    for mass in (10.0, 500.0):
        sim.reset(box=BoxConfig(mass=mass, mu=0.5, face_x=ee[0] + 0.03, center_y=ee[1], height=ee[2] + 0.1))
        for _ in range(2000):
            st = sim.state()
            J = m.kinematics(st.base_true, st.q_arm).J_m
            st = sim.step(SimCommand(np.zeros(m.n_wheels), np.linalg.pinv(J) @ np.array([0.05, 0.0, 0.0])), DT)
        result[mass] = st
    light, heavy = result[10.0], result[500.0]
    assert light.box_displacement > 0.04  # [m] 0.1 m commanded, 0.03 m of it to reach the face
    assert light.contact_force[0] > 0.0
    assert heavy.box_displacement < 0.005
    assert heavy.contact_force[0] > light.contact_force[0]
    assert sum(heavy.drives["torque_limit"]) > 1000 and heavy.stalled_joint is not None


def test_the_plant_is_chosen_by_the_config_and_a_bad_name_is_one_line(tmp_path: Path) -> None:
    assert type(SimRobot(model("ur5_omni.toml"), PHYSICS, collisions=False).plant).__name__ == "MujocoPlant"
    assert type(SimRobot(model("ur5_omni.toml"), SimConfig(), collisions=False).plant).__name__ == "KinematicPlant"
    bad = tmp_path / "sim.toml"
    bad.write_text('[physics]\nplant = "bullet"\n')
    with pytest.raises(ConfigError, match=r"physics\.plant: must be one of kinematic, mujoco"):
        load_sim_config(bad)


def test_without_mujoco_the_plant_says_what_to_install(monkeypatch: pytest.MonkeyPatch) -> None:
    from wmm_qp_sim import plants

    monkeypatch.setattr(plants, "available_plants", lambda: ["kinematic"])
    with pytest.raises(plants.PlantNotAvailable, match=r"pip install 'wmm-qp\[physics\]'"):
        SimRobot(model("ur5_omni.toml"), PHYSICS, collisions=False)


def test_wmm_qp_sim_physics_flag_chooses_the_plant(monkeypatch: pytest.MonkeyPatch) -> None:
    from types import SimpleNamespace

    import wmm_qp_service.drivers.sim_node as adapter
    from wmm_qp_tools.cli import main

    plants: list[str] = []

    class Node:  # records the config the command builds its node from; runs nothing
        def __init__(self, svc: object, sim_cfg: SimConfig, robot: object, **kw: object) -> None:
            plants.append(sim_cfg.physics.plant)
            self.sim = SimpleNamespace(collision=None)
            self.validate = SimpleNamespace(rejected={})
            self.states_dropped = 0

        def run(self, stop: object) -> SimpleNamespace:
            return SimpleNamespace(t=0.0, violations={}, drives={"torque_limit": [0], "tracking": [0]})

    monkeypatch.setattr(adapter, "SimNode", Node)
    assert main(["sim", "--physics", "mujoco", "--rt-priority", "0"]) == 0
    assert main(["sim", "--rt-priority", "0"]) == 0
    assert plants == ["mujoco", load_sim_config().physics.plant]


def test_the_state_reports_the_executed_rates_exactly_0_at_rest_after_a_stop() -> None:
    """A daemon whose stream broke waits for a state of the robot at rest in its stop, rates exactly
    0 (docs/drivers.md); the physics plant's measured rates never are, so the state carries the
    executed ones, as a real robot's does."""
    from wmm_qp_service.config import ServiceConfig
    from wmm_qp_service.drivers.sim_node import SimNode

    m = model("tiago.toml")
    sim = SimRobot(m, PHYSICS.with_(firmware=True), ramp=True, collisions=False)  # as `wmm-qp sim` runs it
    node = SimNode(ServiceConfig(), PHYSICS, m.config, sim=sim)
    moving = SimCommand(m.base.wheel_speeds(np.array([0.1, 0.0, 0.1])), np.full(m.n_arm, 0.05))
    for _ in range(200):
        st = sim.step(moving, DT)
    for _ in range(500):  # no command: the stale stop brakes the robot to rest
        st = sim.step(None, DT)
    assert st.stale_stop
    measured = sim.plant.read()
    assert np.any(measured.v_arm) and np.any(measured.wheel_speeds)  # the physics never rests exactly
    msg = node.state_msg(st, 1)
    assert not np.any(msg.v_arm) and not np.any(msg.wheel_speeds)
    rs = sim.robot_state()
    assert not np.any(rs.v_arm) and not np.any(rs.wheel_speeds)
    st = sim.step(moving, DT)  # a new command: the executed rates are the drives' (ramped) ones
    np.testing.assert_allclose(st.v_arm, np.minimum(0.05, np.asarray(m.config.arm.acceleration_max) * DT))


def test_the_zenoh_node_drives_the_robot_it_is_given() -> None:
    from wmm_qp_service.config import ServiceConfig
    from wmm_qp_service.drivers.sim_node import SimNode

    m = model("ur5_omni.toml")
    sim = SimRobot(m, PHYSICS, collisions=False)
    node = SimNode(ServiceConfig(), PHYSICS, m.config, sim=sim)
    assert node.sim is sim and node.model is m
    q0 = sim.state().q_arm
    arm = np.full(m.n_arm, 0.1)
    node.take([SimCommand(np.zeros(m.n_wheels), np.full(m.n_arm, 9.0)), SimCommand(np.zeros(m.n_wheels), arm)], DT)
    st = sim.state()
    assert st.commands == 1 and st.violations["velocity"] > 0  # the superseded one: received and judged
    np.testing.assert_array_equal(st.q_arm, q0)  # not executed
    assert sim.step(node.take([SimCommand(np.zeros(m.n_wheels), arm)], DT), DT).q_arm[0] > q0[0]
