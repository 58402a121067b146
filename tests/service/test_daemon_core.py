"""The daemon's logic without transport (ControlCore), driven with a fake clock."""

from __future__ import annotations

import math

import numpy as np
import pytest
from support.daemon_drive import DT, Plant, max_step_ratio, rotated, send, tick
from wmm_qp_service.config import ServiceConfig
from wmm_qp_service.daemon import ControlCore, reports
from wmm_qp_service.protocol import ModeMsg, SetpointMsg

import wmm_qp as w


@pytest.fixture(scope="module")
def robot() -> w.RobotConfig:
    return w.load_robot_config()


def make(robot: w.RobotConfig, ctl: w.ControllerConfig | None = None) -> tuple[ControlCore, Plant]:
    core = ControlCore(ServiceConfig(), ctl or w.load_controller_config(), robot)
    return core, Plant(core.model)


def run(core: ControlCore, plant: Plant, t: float, n: int,
        setpoint: np.ndarray | None = None) -> tuple[float, list[w.Command]]:
    cmds = []
    for _ in range(n):
        core.on_state(plant.msg(), t)
        if setpoint is not None:
            core.on_setpoint(SetpointMsg(robot="wmm", seq=1, stamp=t, x=setpoint.tolist(), source="op"), t)
        cmds.append(tick(core, plant, t))  # numbered, sent, applied: the state names it
        t += DT
    return t, cmds


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
    for _ in range(400):  # no state any more (the commands still go out)
        c = core.tick(t)
        assert c is not None
        send(core, t)
        stops.append(c)
        t += DT
    assert core.safe and core.fault_record.last_code == "state_stale"
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
    core.on_robot_alive(True)
    core.on_robot_alive(False)
    assert core.state_time == -math.inf
    core.tick(t)
    assert core.safe and core.fault_record.last_code == "robot_lost"


# ---------------------------------------------------------------- any robot
def other_robots() -> list[object]:
    return ["gen3_diff_drive", "gen3_omni", "gen3_fixed", "ur5_omni", "panda_diffdrive", "tiago"]


def load_other(name: str, folder) -> w.RobotConfig:  # type: ignore[no-untyped-def]
    from support.service_robots import gen3_file, shipped

    if name.startswith("gen3_"):
        return w.load_robot_config(gen3_file(folder, name.removeprefix("gen3_")))
    return shipped(name)


@pytest.mark.parametrize("name", other_robots())
def test_any_robot_tracks_and_changes_modes_inside_the_bounds(tmp_path, name: str) -> None:  # type: ignore[no-untyped-def]
    robot = load_other(name, tmp_path)
    core, plant = make(robot)
    assert (len(plant.q_arm), len(plant.wheels)) == (robot.n_arm, robot.n_wheels)
    x0 = core.model.ee_position(plant.q_base, plant.q_arm)
    target = x0 + np.array([0.03, 0.02, -0.01])
    core.on_mode(ModeMsg(robot="wmm", seq=1, stamp=0.0, mode="track"))
    t, cmds = run(core, plant, 0.0, 750, setpoint=target)
    assert all(c.status != w.Status.SAFE_STOP for c in cmds), cmds[-1].reason
    assert np.linalg.norm(core.model.ee_position(plant.q_base, plant.q_arm) - target) < 3e-3
    for mode in ("hold", "dm_nullspace", "dm_cartesian", "hold"):
        core.on_mode(ModeMsg(robot="wmm", seq=1, stamp=0.0, mode=mode))
        t, more = run(core, plant, t, 100, setpoint=target)
        cmds += more
    assert all(c.status != w.Status.SAFE_STOP for c in cmds), [c.reason for c in cmds if c.reason][:3]
    assert max_step_ratio(robot, cmds) <= 1.0 + 1e-6
    assert all((np.abs(c.arm_rates) <= robot.arm.velocity_max + 1e-9).all() for c in cmds)


@pytest.mark.parametrize("name", ["gen3_mecanum", "gen3_fixed", "ur5_omni"])
def test_info_names_the_joints_and_wheels(tmp_path, name: str) -> None:  # type: ignore[no-untyped-def]
    from collections import Counter

    from wmm_qp_service.protocol import InfoMsg, decode, encode
    from wmm_qp_service.rate_loop import RateLoop

    robot = w.load_robot_config() if name == "gen3_mecanum" else load_other(name, tmp_path)
    core, _ = make(robot)
    info = decode(InfoMsg, encode(reports.info(core, RateLoop(500.0, 0.0), Counter(), {})))
    assert info.joints == list(robot.arm.joints) and info.n_arm == robot.n_arm == len(info.joints)
    assert info.wheels == list(core.model.base.wheel_names) and info.n_wheels == robot.n_wheels
    assert info.base_kind == robot.base.kind and info.task == "position"
    assert info.robot == robot.name == core.svc.robot  # an open robot id is the robot's name
    assert info.config["controller"]["W"] == robot.arm.default_W().tolist()
    if name == "gen3_mecanum":
        assert info.wheels == ["front_left", "front_right", "rear_left", "rear_right"]
        assert info.config["controller"]["W"] == [1.0, 1.0, 1.0, 1.0, 2.5, 2.5, 2.5]


# ---------------------------------------------------------------- the pose task
def pose_core(robot: w.RobotConfig) -> tuple[ControlCore, Plant]:
    return make(robot, w.load_controller_config().with_(task={"kind": "pose"}))


def orientation_error(core: ControlCore, plant: Plant, quat: np.ndarray) -> float:
    from wmm_qp import tasks

    _, R = core.model.ee_pose(plant.q_base, plant.q_arm)
    return float(np.linalg.norm(tasks.orientation_error(tasks.quat_to_matrix(quat), R)))


def test_pose_task_hold_latches_the_ee_orientation(robot: w.RobotConfig) -> None:
    from wmm_qp.tasks import rotation_to_quat

    core, plant = pose_core(robot)
    _, R0 = core.model.ee_pose(plant.q_base, plant.q_arm)
    q0 = rotation_to_quat(R0)
    _, cmds = run(core, plant, 0.0, 200)
    assert core.mode == w.Mode.HOLD and core.pose
    assert core.ref.quat_d is not None and np.allclose(core.ref.quat_d, q0, atol=1e-12)
    assert np.allclose(core.ref.omega_d, 0.0)
    assert orientation_error(core, plant, q0) < 1e-6 and np.abs(cmds[-1].v).max() < 1e-6
    from collections import Counter

    from wmm_qp_service.rate_loop import RateLoop

    st = reports.status(core, RateLoop(500.0, 0.0), Counter(), {})
    assert np.allclose(st.quat_d, q0)


def test_pose_task_reaches_a_streamed_orientation_and_hold_relatches(robot: w.RobotConfig) -> None:
    core, plant = pose_core(robot)
    t, cmds = run(core, plant, 0.0, 20)
    q_start = core.orient.quat.copy()
    x0 = core.model.ee_position(plant.q_base, plant.q_arm)
    core.on_mode(ModeMsg(robot="wmm", seq=1, stamp=0.0, mode="track"))
    target = rotated(q_start, [0.0, 0.3, 1.0], 0.3)
    for _ in range(1500):  # 3 s: 0.3 rad at the saturated recovery speed (0.5 rad/s) and K_R
        core.on_state(plant.msg(), t)
        core.on_setpoint(SetpointMsg(robot="wmm", seq=1, stamp=t, x=x0.tolist(), source="op",
                                     q=target.tolist()), t)
        cmd = tick(core, plant, t)
        assert cmd.status != w.Status.SAFE_STOP, cmd.reason
        cmds.append(cmd)
        t += DT
    assert orientation_error(core, plant, target) < 1e-3
    assert np.linalg.norm(core.model.ee_position(plant.q_base, plant.q_arm) - x0) < 2e-3
    assert max_step_ratio(robot, cmds) <= 1.0 + 1e-6
    assert core.setpoints.orientation_ignored == 0
    # hold: the orientation target is the EE's own again (latched), not the streamed one
    core.on_mode(ModeMsg(robot="wmm", seq=1, stamp=0.0, mode="hold"))
    _, R = core.model.ee_pose(plant.q_base, plant.q_arm)
    t, more = run(core, plant, t, 200)
    from wmm_qp.tasks import rotation_to_quat

    assert abs(abs(float(np.dot(core.orient.quat, rotation_to_quat(R)))) - 1.0) < 1e-9
    assert max_step_ratio(robot, cmds + more) <= 1.0 + 1e-6


def test_pose_task_turns_at_the_streamed_angular_velocity(robot: w.RobotConfig) -> None:
    """A setpoint's ``w`` is feed-forward: between samples the target turns at it."""
    core, plant = pose_core(robot)
    t, _ = run(core, plant, 0.0, 20)
    x0 = core.model.ee_position(plant.q_base, plant.q_arm)
    core.on_mode(ModeMsg(robot="wmm", seq=1, stamp=0.0, mode="track"))
    run(core, plant, t, 1)
    t += DT
    q1 = core.orient.quat.copy()
    core.on_setpoint(SetpointMsg(robot="wmm", seq=1, stamp=t, x=x0.tolist(), source="op",
                                 q=q1.tolist(), w=[0.0, 0.0, 0.2]), t)
    for _ in range(50):  # 0.1 s without a new sample
        core.on_state(plant.msg(), t)
        tick(core, plant, t)
        t += DT
    expected = rotated(q1, [0.0, 0.0, 1.0], 0.2 * 50 * DT)
    assert abs(abs(float(np.dot(core.orient.quat, expected))) - 1.0) < 1e-9
    assert np.allclose(core.ref.omega_d, [0.0, 0.0, 0.2])
    for _ in range(200):  # past setpoint_timeout (0.25 s): the target stops turning
        core.on_state(plant.msg(), t)
        tick(core, plant, t)
        t += DT
    assert core.orient.resting and np.allclose(core.ref.omega_d, 0.0)


def test_position_task_ignores_a_setpoints_orientation_and_counts_it(robot: w.RobotConfig) -> None:
    """docs/protocol.md: with the position task a setpoint carrying ``q`` is followed in position;
    its orientation is ignored and counted (``status.orientation_ignored``)."""
    core, plant = make(robot)
    t, _ = run(core, plant, 0.0, 5)
    x0 = core.model.ee_position(plant.q_base, plant.q_arm)
    target = x0 + np.array([0.02, 0.0, 0.0])
    core.on_mode(ModeMsg(robot="wmm", seq=1, stamp=0.0, mode="track"))
    for _ in range(600):
        core.on_state(plant.msg(), t)
        assert core.on_setpoint(SetpointMsg(robot="wmm", seq=1, stamp=t, x=target.tolist(), source="op",
                                            q=[0.0, 0.0, 0.38, 0.92], w=[0.0, 0.0, 1.0]), t)
        tick(core, plant, t)
        t += DT
    assert core.ref.quat_d is None and np.allclose(core.ref.omega_d, 0.0)
    assert np.linalg.norm(core.model.ee_position(plant.q_base, plant.q_arm) - target) < 2e-3
    assert core.setpoints.orientation_ignored == 600
    from collections import Counter

    from wmm_qp_service.rate_loop import RateLoop

    st = reports.status(core, RateLoop(500.0, 0.0), Counter(), {})
    assert st.orientation_ignored == 600 and st.quat_d == []


def test_the_status_position_is_finite_during_a_safe_stop(robot: w.RobotConfig) -> None:
    """Clients start their streams at ``status.x``: a safe stop's command has no EE position
    (NaN), so the status gives the state's (a demo once streamed NaN setpoints from it)."""
    from collections import Counter

    from wmm_qp_service.rate_loop import RateLoop

    core, plant = make(robot)
    assert reports.status(core, RateLoop(500.0, 0.0), Counter(), {}).x == []
    t, _ = run(core, plant, 0.0, 10)
    for _ in range(40):  # no state any more: safe stop
        cmd = core.tick(t)
        t += DT
    assert cmd is not None and cmd.status == w.Status.SAFE_STOP and not np.isfinite(cmd.x).all()
    x = reports.status(core, RateLoop(500.0, 0.0), Counter(), {}).x
    assert np.allclose(x, core.model.ee_position(plant.q_base, plant.q_arm))


def test_the_status_and_info_say_whether_the_collision_rows_are_on(robot: w.RobotConfig) -> None:
    """The shipped controller config has the rows on (self, floor, the default scene's fence);
    ``[collision] enabled = false`` turns them off, and the status and the info say which."""
    from collections import Counter

    from wmm_qp_service.rate_loop import RateLoop

    core, plant = make(robot)
    run(core, plant, 0.0, 3)
    st = reports.status(core, RateLoop(500.0, 0.0), Counter(), {})
    info = reports.info(core, RateLoop(500.0, 0.0), Counter(), {})
    assert st.collision is True and info.collision is True
    assert st.collision_summary.startswith("collision rows on") and "fence" in st.collision_summary
    assert info.collision_summary == st.collision_summary
    assert st.collision_pair != "" and math.isfinite(st.collision_distance)
    off, plant = make(robot, w.load_controller_config().with_(collision={"enabled": False}))
    run(off, plant, 0.0, 3)
    st = reports.status(off, RateLoop(500.0, 0.0), Counter(), {})
    assert st.collision is False and st.collision_summary == "no collision rows"
    assert reports.info(off, RateLoop(500.0, 0.0), Counter(), {}).collision is False


def test_a_robot_whose_states_never_name_a_command_applied_is_said_once(robot: w.RobotConfig) -> None:
    """A new stream repeats its first command until a state names one of its commands as applied
    (``cmd_seq``). A driver that never reports it would leave the robot still without a word: after
    a second of fresh states naming none, the status says why, once."""
    core, plant = make(robot)
    x0 = core.model.ee_position(plant.q_base, plant.q_arm)
    core.on_mode(ModeMsg(robot="wmm", seq=1, stamp=0.0, mode="track"))
    t, cmds = 0.0, []
    for _ in range(1000):  # 2 s; the commands are numbered and sent, the plant executes them
        core.on_state(plant.msg(cmd_seq=-1), t)  # but its states always say cmd_seq -1
        core.on_setpoint(SetpointMsg(robot="wmm", seq=1, stamp=t, x=(x0 + [0.1, 0.0, 0.0]).tolist(), source="op"), t)
        cmds.append(tick(core, plant, t))
        t += DT
    assert all(c is cmds[0] for c in cmds)  # the first command, again and again
    assert core.fault_record.counts["commands_not_applied"] == 1
    assert "cmd_seq -1" in core.fault_record.last
    assert core.fault_active  # the status says the robot is held, not tracking
    core.on_state(plant.msg(cmd_seq=core.stream.seq), t)  # a state names the stream's command at last
    tick(core, plant, t + DT)
    assert core.stream.confirmed and not core.fault_active


def test_only_a_command_this_daemon_sent_confirms_its_stream(robot: w.RobotConfig) -> None:
    """The attack: a restarted daemon numbers from 1 again, and a late command of the one before
    it (a higher seq, applied just before the robot took the new lease) names a seq at or past
    the new stream's start. It must not confirm the stream: only a seq this daemon sent does."""
    core, plant = make(robot)
    core.on_state(plant.msg(), 0.0)
    first = core.tick(0.0)
    assert first is not None
    send(core, 0.0)  # seq 1, the stream's first
    core.on_state(plant.msg(cmd_seq=50), DT)  # an older daemon's seq 50: never sent by this one
    assert not core.stream.confirmed
    assert core.tick(DT) is first  # still repeating its first command
    send(core, DT)
    core.on_state(plant.msg(cmd_seq=2), 2 * DT)  # this daemon's seq 2: the robot follows
    assert core.stream.confirmed
