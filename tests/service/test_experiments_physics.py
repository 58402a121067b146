"""The paper's experiments on the physics plant (``--physics mujoco``): bounds (13) anchored on
the last command, and the JSON saying which plant ran."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest
from wmm_qp_service.processes import CLI
from wmm_qp_tools.cli import main
from wmm_qp_tools.experiments import circle
from wmm_qp_tools.experiments.runner import anchored
from wmm_qp_tools.experiments.setup import make_setup

import wmm_qp as w

pytest.importorskip("mujoco", reason="the physics plant needs mujoco: pip install 'wmm-qp[physics]'")


def test_a_short_circle_in_physics_has_no_acceleration_violation() -> None:
    # the MuJoCo servos lag the command: bounds (13) centred on the measured rates let two
    # consecutive commands differ by more than A·dt (4 s of the circle: 4 counts, when the state
    # carried the measured rates and the runner did not anchor on the last command)
    tr = circle.run_circle(make_setup("qp", physics="mujoco"), 4.0, progress=False)
    assert tr.sim is not None and tr.sim.config.physics.plant == "mujoco"
    assert tr.violations["acceleration"] == 0
    assert tr.violations["wheel_acceleration"] == 0


def test_the_anchor_keeps_the_pose_and_takes_the_rates_of_the_last_command() -> None:
    st = w.RobotState(q_base=np.array([0.1, 0.2, 0.3]), q_arm=np.ones(2), v_arm=np.full(2, 0.5),
                      wheel_speeds=np.full(4, 0.25))
    assert anchored(st, None) is st  # the first tick: the measured rates
    cmd = w.Command(wheel_speeds=np.arange(4.0), arm_rates=np.array([0.1, -0.2]))
    a = anchored(st, cmd)
    np.testing.assert_array_equal(a.q_base, st.q_base)
    np.testing.assert_array_equal(a.q_arm, st.q_arm)
    np.testing.assert_array_equal(a.v_arm, cmd.arm_rates)
    np.testing.assert_array_equal(a.wheel_speeds, cmd.wheel_speeds)


@pytest.mark.parametrize("physics", ["kinematic", "mujoco"])
def test_the_experiment_json_says_which_plant_ran(physics: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["experiment", "circle", "--duration", "0.5", "--physics", physics, "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["physics"] == physics
    assert out["violations"]["acceleration"] == 0


@pytest.mark.parametrize("argv", [["demo"], ["soak"], ["experiment", "circle", "--duration", "0.5"],
                                  ["bench", "--only", "sim", "--ticks", "5"]])
def test_an_uninstalled_plant_is_one_line_and_exit_2(argv: list[str], monkeypatch: pytest.MonkeyPatch,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    import wmm_qp_sim.plants as plants

    monkeypatch.setattr(plants, "available_plants", lambda: ["kinematic"])
    assert main([*argv, "--physics", "mujoco"]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and "plant 'mujoco' is not available" in err and len(err.strip().splitlines()) == 1


@pytest.mark.integration
@pytest.mark.slow
def test_the_demo_in_physics_has_no_violation() -> None:
    out = subprocess.run([*CLI, "demo", "--duration", "6", "--physics",
                          "mujoco", "--json"], capture_output=True, text=True, timeout=180, check=False)
    assert out.returncode == 0, out.stderr[-2000:]
    d = json.loads(out.stdout)
    assert d["physics"] == "mujoco" and d["violations_total"] == 0 and d["verdict"] == "PASS"


@pytest.mark.integration
@pytest.mark.slow
def test_the_demo_in_physics_on_a_robot_file_the_suite_writes(tmp_path: Path) -> None:
    """A robot no file in the repository describes (the Gen3 on a differential drive, written
    here): its MuJoCo model is built from the file, the demo runs with the collision rows on (the
    default) and the referee counts nothing."""
    from support.service_robots import gen3_file

    robot = gen3_file(tmp_path, base="diff_drive", name="gen3_diff_suite")
    out = subprocess.run([*CLI, "demo", "--duration", "6", "--physics",
                          "mujoco", "--robot-config", str(robot), "--json", "--logs", str(tmp_path / "logs")],
                         capture_output=True, text=True, timeout=180, check=False)
    assert out.returncode == 0, out.stderr[-2000:]
    d = json.loads(out.stdout)
    assert d["physics"] == "mujoco" and d["robot"]["name"] == "gen3_diff_suite" and d["collision"]
    assert d["violations_total"] == 0 and d["verdict"] == "PASS"
    assert d["loop"]["ticks"] > 0 and d["ee_error_max"] is not None


def test_max_mass_bisects_to_the_threshold_of_each_run(monkeypatch: pytest.MonkeyPatch) -> None:
    from wmm_qp_tools.experiments import max_mass

    limit = {"with_dm": 47.3, "without_dm": 31.9}  # [kg] what each configuration pushes, faked
    dm = {"with_dm": 5.8, "without_dm": 3.8}
    monkeypatch.setattr(max_mass, "_pushed", lambda _f, run, mass, _d: (mass <= limit[run], dm[run]))
    out = max_mass.max_mass(lambda: None, progress=False)  # type: ignore[arg-type,return-value]
    for run, m in limit.items():
        lo, hi = out["bracket_kg"][run]
        assert lo <= m < hi and hi - lo <= max_mass.TOLERANCE and out["max_mass_kg"][run] == lo
    assert out["dm_ratio"] == pytest.approx(5.8 / 3.8)
    assert out["measured_ratio"] == pytest.approx(out["max_mass_kg"]["with_dm"] / out["max_mass_kg"]["without_dm"])


@pytest.mark.parametrize("argv", [["circle", "--max-mass"], ["push", "--max-mass", "--realtime"],
                                  ["circle", "--frames", "x"], ["push", "--frames", "x", "--physics", "kinematic"]])
def test_max_mass_and_frames_outside_their_use_are_one_line(argv: list[str],
                                                            capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["experiment", *argv]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1


@pytest.mark.integration
@pytest.mark.slow
def test_the_realtime_circle_starts_its_sim_on_the_physics_plant(capsys: pytest.CaptureFixture[str],
                                                                 tmp_path: Path) -> None:
    logs = tmp_path / "logs"
    assert main(["experiment", "circle", "--realtime", "--physics", "mujoco", "--duration", "3",
                 "--process-logs", str(logs), "--json"]) == 0
    r = json.loads(capsys.readouterr().out)
    assert r["physics"] == "mujoco" and sum(r["violations"].values()) == 0
    assert "mujoco plant" in (logs / "sim.log").read_text()


def test_the_referee_sees_the_physics_box_where_it_is_tipped() -> None:
    from wmm_qp_sim import BoxConfig, SimCommand, SimRobot

    s = make_setup("qp", physics="mujoco")
    sim = SimRobot(s.model, s.sim_cfg)
    sim.place_box(BoxConfig(mass=10.0, mu=0.5, face_x=2.0, width=0.4, height=0.6))
    p = sim.plant
    adr = int(p.robot.model.jnt_qposadr[p.robot.model.body_jntadr[p.robot.box_body]])
    pitch = 0.3  # [rad] leaning away from the robot, about y
    p.data.qpos[adr + 3: adr + 7] = [np.cos(pitch / 2), 0.0, np.sin(pitch / 2), 0.0]
    p.data.qpos[adr + 2] += 0.05  # clear of the floor
    sim.step(SimCommand(np.zeros(s.model.n_wheels), np.zeros(s.model.n_arm), period=1e-3, seq=0), 1e-3)
    box = sim.box_obstacle()
    assert box is not None
    assert box.rpy[1] == pytest.approx(pitch, abs=1e-2) and sim.box is not None and sim.box.tilt > 0.29
    np.testing.assert_allclose(box.xyz, p.data.xpos[p.robot.box_body], atol=1e-12)
    assert sim.box.face_x == pytest.approx(box.xyz[0] - 0.2 * np.cos(box.rpy[1]), abs=1e-6)
