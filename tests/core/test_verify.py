"""The referee of ``wmm-qp verify`` (wmm_qp/verify.py) must be able to fail."""

from __future__ import annotations

import numpy as np
import pytest
from support.core_fixtures import Q0, config, model

import wmm_qp as w
from wmm_qp.verify import check_command, verify_controller

ARM = model().config.arm
DT = config().dt


def cmd(arm: np.ndarray) -> w.Command:
    return w.Command(wheel_speeds=np.zeros(4), arm_rates=arm)


def test_a_command_that_cannot_brake_before_the_limit_is_a_position_violation() -> None:
    q = Q0.copy()
    q[1] = ARM.position_upper[1] - 0.01  # 10 mrad before joint 2's limit
    v0 = np.zeros(7)
    v0[1] = 0.5
    state = w.RobotState(np.zeros(3), q, v_arm=v0)
    fast = v0.copy()  # one step stays inside (5 mrad/s·dt ≪ 10 mrad) but braking needs 24 mrad
    assert check_command(model().config, DT, state, cmd(fast))["position"] == 1
    brake = v0 - ARM.acceleration_max * DT  # braking now: always legal
    assert check_command(model().config, DT, state, cmd(brake))["position"] == 0


def test_verify_catches_a_controller_without_the_braking_bound(monkeypatch: pytest.MonkeyPatch) -> None:
    """Drop the braking-distance part of bounds (13): the referee must notice."""
    from wmm_qp.limits import intersect_by_priority

    N_WHEELS = model().n_wheels
    # without the collision rows, which would stop some of these motions for their own reasons
    ctl = w.QpController(model(), config().with_(qp={"solver": "daqp"}, collision={"enabled": False}))
    arm, wheels = model().config.arm, ctl.bounds

    def one_step_only(q, v_prev):  # type: ignore[no-untyped-def]
        lo, hi = wheels(q, v_prev)  # the wheels' bounds as they are; the arm's without braking
        a, qa, va = arm.acceleration_max * DT, q[N_WHEELS:], v_prev[N_WHEELS:]
        alo, ahi = intersect_by_priority(va - a, va + a, -arm.velocity_max, arm.velocity_max)
        lo[N_WHEELS:], hi[N_WHEELS:] = intersect_by_priority(
            alo, ahi, np.minimum((arm.position_lower - qa) / DT, 0), np.maximum((arm.position_upper - qa) / DT, 0)
        )
        return lo, hi

    monkeypatch.setattr(ctl, "bounds", one_step_only)
    assert verify_controller(ctl, model(), 150, 0).by_kind["position"] > 0


# The EE box of DM_CARTESIAN, eq. (17) (the review's attack: relaxed, never re-checked) ----------
BOX_LO, BOX_HI = config().ee_box_lower, config().ee_box_upper


def box_state(z_offset: float, v_z: float) -> tuple[w.RobotState, np.ndarray]:
    """The paper's start, arm moving so that the EE moves at v_z along z; the box's floor lies
    z_offset below the EE. Returns the state and the box's lower corner."""
    kin = model().kinematics(np.zeros(3), Q0)
    v = np.linalg.pinv(kin.J_m) @ np.array([0.0, 0.0, v_z])  # the arm alone
    lower = np.array([-np.inf, -np.inf, kin.x[2] - z_offset])
    return w.RobotState(np.zeros(3), Q0, v_arm=v), lower


def braking(state: w.RobotState) -> np.ndarray:
    a = ARM.acceleration_max * DT
    return state.v_arm - np.clip(state.v_arm, -a, a)


def ee_box_count(state: w.RobotState, arm: np.ndarray, lower: np.ndarray) -> int:
    c = w.Command(wheel_speeds=np.zeros(4), arm_rates=arm)
    return check_command(model().config, DT, state, c, model=model(), ee_box=(lower, BOX_HI))["ee_box"]


def test_the_referee_counts_an_ee_box_crossing_and_asks_only_what_is_possible() -> None:
    kin = model().kinematics(np.zeros(3), Q0)
    down = np.linalg.pinv(kin.J_m) @ np.array([0.0, 0.0, -0.01])  # 20 µm down in one tick
    state, lower = box_state(z_offset=10e-6, v_z=-0.01)  # moving down at 1 cm/s, 10 µm above the floor
    assert ee_box_count(state, down, lower) == 1  # keeps going: 10 µm through the floor
    assert ee_box_count(state, 0.4 * down, lower) == 0  # 8 µm: stays above
    assert ee_box_count(state, braking(state), lower) == 0
    # already below the floor: going further down is a violation, staying or going back up is not
    state, lower = box_state(z_offset=-1e-3, v_z=0.0)
    assert ee_box_count(state, 0.01 * down, lower) == 1
    assert ee_box_count(state, np.zeros(7), lower) == 0
    assert ee_box_count(state, -down, lower) == 0
    # moving down too fast to stop inside: no further than full braking takes it
    state, lower = box_state(z_offset=1e-6, v_z=-0.2)
    assert ee_box_count(state, braking(state), lower) == 0
    assert ee_box_count(state, state.v_arm, lower) == 1  # not braking at all


@pytest.mark.parametrize("kind", ["paper", "traditional"])
def test_the_baselines_leave_the_box_and_the_referee_sees_it(kind: str) -> None:
    """The paper's controller and the traditional one do not respect the box (v = J# v_c), so with a
    Cartesian DM gain large enough for a tick to reach a face, verify must count ee_box violations;
    the QP with the same gain must not."""
    cfg = config().with_(k_C=1e3)
    assert verify_controller(w.make_controller(kind, model(), cfg), model(), 100, 0).by_kind["ee_box"] > 0
    assert verify_controller(w.make_controller("qp", model(), cfg), model(), 100, 0).by_kind["ee_box"] == 0


@pytest.mark.parametrize("solver", ["osqp", "daqp"])
def test_verify_catches_the_qp_without_its_ee_box_recheck(solver: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """OSQP and DAQP meet the EE box rows only to their primal tolerance (~1e-6 m per tick): without
    the re-check after the solve the referee finds the EE past the box; with it, nothing."""
    import wmm_qp.controllers.qp.controller as qp_module

    ctl = w.QpController(model(), config().with_(qp={"solver": solver}))
    assert verify_controller(ctl, model(), 300, 0).by_kind["ee_box"] == 0
    monkeypatch.setattr(qp_module, "_hold_ee_box", lambda *a: 0.0)
    assert verify_controller(ctl, model(), 300, 0).by_kind["ee_box"] > 0


# The command: any robot, either task kind ------------------------------------------------
@pytest.mark.parametrize("robot_file, task", [("ur5_omni.toml", "pose"), ("tiago.toml", "position")])
def test_verify_command_on_any_robot_and_task(robot_file: str, task: str, capsys: pytest.CaptureFixture[str]) -> None:
    import json

    from wmm_qp_tools.cli import main

    path = w.default_robot_file().parent / robot_file
    argv = ["verify", "--robot-config", str(path), "--task", task, "--solver", "daqp", "--samples", "30", "--json"]
    assert main(argv) == 0
    out = json.loads(capsys.readouterr().out)
    assert (out["robot"], out["task"], out["samples"], out["violations"]) == (path.stem, task, 30, 0)
    assert out["steps"] == 4 * 30 and out["examples"] == []


def test_verify_on_a_robot_file_without_collision_shapes_passes_and_says_so(
        tmp_path: pytest.TempPathFactory, capsys: pytest.CaptureFixture[str]) -> None:
    """A robot file with no [collision] table: no self pair to sample near, no traceback (the
    near-self sampler took min() of no distances), and every place rows are reported says why
    there are none."""
    import json
    from pathlib import Path

    from wmm_qp_tools.cli import main

    text = (w.default_robot_file().parent / "gen3_mecanum.toml").read_text()
    urdf = w.default_robot_file().parent / "gen3_7dof.urdf"
    bare = text[: text.index("[collision]")].replace('urdf = "gen3_7dof.urdf"', f'urdf = "{urdf}"')
    bare = bare.replace("body = {", "# body = {")  # no base box either: no bodies at all
    path = Path(str(tmp_path)) / "bare.toml"
    path.write_text(bare)
    assert main(["verify", "--robot-config", str(path), "--samples", "40", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["violations"] == 0 and out["collision_rows"] and out["steps"] == 4 * 40
    assert sum(out["cut_by"].values()) == out["statuses"].get("saturated", 0)
    rows_on = config().with_(collision={"enabled": True})
    ctl = w.make_controller("qp", w.WmmModel(w.load_robot_config(path)), rows_on)
    assert ctl.collision_summary().startswith(
        "collision rows on (no self pairs — this robot file has no [collision] shapes")


def test_the_fr3_file_has_self_pairs_and_the_table() -> None:
    """The FR3's file takes its URDF's collision meshes: self pairs, the hand, the table below."""
    pytest.importorskip("franky_sim")
    robot = w.load_robot_config(w.default_robot_file().parent / "fr3.toml")
    ctl = w.make_controller("qp", w.WmmModel(robot), config().with_(collision={"enabled": True}))
    summary = ctl.collision_summary()
    import re

    m = re.match(r"collision rows on \((\d+) self pairs, (\d+) bodies vs the floor", summary)
    assert m is not None and int(m[1]) >= 20 and int(m[2]) >= 8, summary
