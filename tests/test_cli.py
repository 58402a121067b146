"""The ``wmm-qp`` CLI: inspect, verify, and its error handling (one line, exit 2)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest
from wmm_qp_service.cli import main

from wmm_qp.config import default_config_dir
from wmm_qp.solvers import available_solvers

START = "0,0.5235987755982988,0,1.5707963267948966,0,-0.5235987755982988,0"


def run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    try:
        code = main(list(argv))
    except SystemExit as e:  # argparse errors
        code = int(e.code or 0)
    out, err = capsys.readouterr()
    return code, out, err


def test_inspect_json_at_the_paper_start(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run(capsys, "inspect", "--arm-q", START, "--direction", "0,0,1", "--json")
    assert code == 0
    d = json.loads(out)
    assert d["ee_position"][0] == pytest.approx(0.650, abs=1e-3)
    assert d["ee_position"][2] == pytest.approx(0.492, abs=1e-3)
    assert d["dm"] == pytest.approx(1.124, abs=2e-3)
    assert len(d["dm_gradient"]) == 7 and len(d["dm_cartesian_gradient"]) == 3
    assert 10 * d["torque_norm_per_newton"] == pytest.approx(8.89, abs=0.01)
    assert d["sigma_min"] > 0.08


def test_inspect_text_output(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run(capsys, "inspect", "--arm-q", START)
    assert code == 0 and "DM H2" in out and "eq. (9)" in out


@pytest.mark.parametrize(
    "argv",
    [
        ["inspect", "--arm-q", "1,2,3"],
        ["inspect", "--arm-q", "a,b,c,d,e,f,g"],
        ["inspect", "--arm-q", "nan,0,0,0,0,0,0"],
        ["inspect", "--arm-q", START, "--direction", "0,0,0"],
        ["inspect", "--arm-q", "0,0,0,0,0,0"],
        ["verify", "--samples", "-3"],
        ["verify", "--solver", "cplex"],
        ["inspect", "--arm-q", START, "--robot-config", "/nonexistent/robot.toml"],
    ],
)
def test_bad_arguments_get_one_line_and_exit_2(capsys: pytest.CaptureFixture[str], argv: list[str]) -> None:
    code, _, err = run(capsys, *argv)
    assert code == 2
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err


def test_bad_config_names_file_and_key(tmp_path, capsys: pytest.CaptureFixture[str]) -> None:  # type: ignore[no-untyped-def]
    bad = tmp_path / "controller.toml"
    bad.write_text("[gains]\nk_N = 'fast'\n")
    code, _, err = run(capsys, "inspect", "--arm-q", START, "--controller-config", str(bad))
    assert code == 2 and str(bad) in err and "gains.k_N" in err


@pytest.mark.parametrize("solver", available_solvers())
def test_verify_reports_zero_violations_for_every_qp_solver(solver: str, capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run(capsys, "verify", "--solver", solver, "--samples", "2000", "--json")
    d = json.loads(out)
    assert d["samples"] == 2000 and d["steps"] == 8000
    assert d["violations"] == 0 and code == 0, d["by_kind"]


@pytest.mark.parametrize("controller", ["traditional", "paper"])
def test_verify_finds_violations_in_the_baselines(controller: str, capsys: pytest.CaptureFixture[str]) -> None:
    scene = str(default_config_dir() / "scenes" / "default.toml")
    code, out, _ = run(capsys, "verify", "--controller", controller, "--samples", "100", "--scene", scene, "--json")
    d = json.loads(out)
    assert code == 1 and d["violations"] > 0 and d["by_kind"]["acceleration"] > 0
    assert d["by_kind"]["collision"] > 0  # no collision rows: the referee sees them collide
    assert d["scene"].endswith("default.toml")


def test_verify_referees_collisions_by_default(capsys: pytest.CaptureFixture[str]) -> None:
    """Without --scene, verify still referees self and floor collisions and the default scene's
    fence (the paper's controller, which has no rows, is caught colliding); --no-collision
    referees the bounds only."""
    code, out, _ = run(capsys, "verify", "--controller", "paper", "--samples", "30", "--json")
    d = json.loads(out)
    assert d["collision"] is True and d["scene"].endswith("default.toml")
    assert code == 1 and d["by_kind"]["collision"] > 0 and d["by_case"].get("near_self", 0) > 0
    code, out, _ = run(capsys, "verify", "--controller", "paper", "--samples", "30", "--no-collision", "--json")
    d = json.loads(out)
    assert d["collision"] is False and d["scene"] is None and d["by_kind"]["collision"] == 0


def test_verify_has_the_qp_controllers_rows_on_by_default(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run(capsys, "verify", "--samples", "10", "--solver", "daqp", "--json")
    d = json.loads(out)
    assert d["collision"] is True and d["collision_rows"] is True and code == 0, d["by_kind"]
    _, out, _ = run(capsys, "verify", "--samples", "10", "--solver", "daqp", "--no-collision", "--json")
    assert json.loads(out)["collision_rows"] is False


def test_verify_scene_and_no_collision_exclude_each_other(capsys: pytest.CaptureFixture[str]) -> None:
    scene = str(default_config_dir() / "scenes" / "default.toml")
    code, _, err = run(capsys, "verify", "--samples", "1", "--scene", scene, "--no-collision")
    assert code == 2 and "--no-collision" in err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err


def test_console_script_runs_without_traceback() -> None:
    r = subprocess.run(
        [sys.executable, "-m", "wmm_qp_service.cli", "inspect", "--arm-q", "1"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode == 2 and "Traceback" not in r.stderr


def test_inspect_defaults_to_the_robots_start(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run(capsys, "inspect", "--json")
    d = json.loads(out)
    assert code == 0 and d["robot"] == "wmm" and len(d["joints"]) == 7
    assert d["ee_position"][0] == pytest.approx(0.650, abs=1e-3)


def test_inspect_another_robot(tmp_path, capsys: pytest.CaptureFixture[str]) -> None:  # type: ignore[no-untyped-def]
    from service_robots import gen3_file, shipped

    code, out, _ = run(capsys, "inspect", "--json", "--robot-config", str(gen3_file(tmp_path, "fixed")))
    d = json.loads(out)
    assert code == 0 and d["robot"] == "gen3_fixed" and d["ee_position"][0] == pytest.approx(0.650, abs=1e-3)
    ur5 = shipped("ur5_omni")
    code, out, _ = run(capsys, "inspect", "--json", "--robot-config", str(ur5.path))
    d = json.loads(out)
    assert code == 0 and len(d["dm_gradient"]) == 6 and d["joints"] == list(ur5.arm.joints)
    code, _, err = run(capsys, "inspect", "--arm-q", START, "--robot-config", str(ur5.path))
    assert code == 2 and "needs 6" in err and len(err.strip().splitlines()) == 1


# ---------------------------------------------------------------- bad robot files
BAD_ROBOTS = {
    # case: (what to change in the Gen3's file, the key the error names)
    "frame_missing": ({"ee_frame": '"no_such_link"'}, "arm.ee_frame"),
    "not_one_chain": ({"ee_frame": '"forearm_link"'}, "arm.joints"),  # joints 5-7 lie past it
    "unknown_base_kind": ({}, "base.kind"),
    "no_acceleration_limit": ({}, "arm.acceleration_max"),
    "urdf_does_not_parse": ({}, "arm.urdf"),
    "missing_package": ({"urdf": '"package://no-such-package/x.urdf"'}, "arm.urdf"),
}


def bad_robot_file(folder, case: str):  # type: ignore[no-untyped-def]
    from service_robots import gen3_text

    changes, key = BAD_ROBOTS[case]
    text = gen3_text(**changes)
    if case == "unknown_base_kind":
        text = text.replace('kind = "mecanum"', 'kind = "hovercraft"')
    elif case == "no_acceleration_limit":
        text = "\n".join(line for line in text.splitlines() if not line.startswith("acceleration_max"))
    elif case == "urdf_does_not_parse":
        broken = folder / "broken.urdf"
        broken.write_text('<robot name="x"><link name="a"><joint name="j"')
        text = gen3_text(urdf=f'"{broken}"')
    p = folder / f"{case}.toml"
    p.write_text(text)
    return p, key


ROBOT_COMMANDS = {
    "sim": [], "serve": [], "status": ["--timeout", "0.1"], "mode": ["hold", "--timeout", "0.1"],
    "teleop": ["--duration", "0.1"], "inspect": [], "demo": [], "soak": [],
}


@pytest.mark.parametrize("case", list(BAD_ROBOTS))
def test_a_bad_robot_file_is_one_line_naming_file_and_key(tmp_path, capsys: pytest.CaptureFixture[str],  # type: ignore[no-untyped-def]
                                                           case: str) -> None:
    """Every command that takes a robot: one line naming the file and the key, exit 2, before
    it opens a session or starts a process."""
    path, key = bad_robot_file(tmp_path, case)
    for command, extra in ROBOT_COMMANDS.items():
        code, _, err = run(capsys, command, *extra, "--robot-config", str(path))
        assert code == 2, (command, err)
        assert "Traceback" not in err and len(err.strip().splitlines()) == 1, (command, err)
        assert f"{path}: {key}:" in err, (command, err)
        assert err.startswith(f"wmm-qp {command}: error: "), err
    if case == "missing_package":
        assert "no-such-package" in err and "not installed" in err


@pytest.mark.parametrize("case", [
    "missing_package",
    "urdf_does_not_parse",  # urdfdom writes its own errors to fd 2: load_full_model silences them
])
def test_a_bad_robot_file_through_the_console_script(tmp_path, case: str) -> None:  # type: ignore[no-untyped-def]
    """The whole process's stderr (a C++ parser may write to it directly): one line."""
    path, key = bad_robot_file(tmp_path, case)
    r = subprocess.run([sys.executable, "-m", "wmm_qp_service.cli", "sim", "--robot-config", str(path)],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "Traceback" not in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert f"{path}: {key}:" in r.stderr
