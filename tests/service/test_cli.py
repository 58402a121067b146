"""The ``wmm-qp`` CLI: inspect, verify, and its error handling (one line, exit 2)."""

from __future__ import annotations

import json
import subprocess

import pytest
from wmm_qp_service.processes import CLI
from wmm_qp_tools.cli import main

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
    # 400 random states × 4 steps each solver (the 2000-sample runs of record: docs/results.md §5)
    code, out, _ = run(capsys, "verify", "--solver", solver, "--samples", "400", "--json")
    d = json.loads(out)
    assert d["samples"] == 400 and d["steps"] == 1600
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
        [*CLI, "inspect", "--arm-q", "1"],
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
    from support.service_robots import gen3_file, shipped

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
    from support.service_robots import gen3_text

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
    r = subprocess.run([*CLI, "sim", "--robot-config", str(path)],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "Traceback" not in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert f"{path}: {key}:" in r.stderr


# ---------------------------------------------------------------- the robot id
ID_COMMANDS = {  # every command that talks to a robot over Zenoh, with its required arguments
    "sim": [], "serve": [], "teleop": [], "mode": ["hold"], "status": [], "console": [],
}


@pytest.mark.parametrize("command", list(ID_COMMANDS))
def test_every_command_takes_the_robot_id_from_the_robot_files_name(tmp_path, command: str) -> None:  # type: ignore[no-untyped-def]
    """--robot-config F with F's name X: the id is X, whatever configs/service.toml's robot says
    (a sim started with F and a client given F, or --robot X, meet on <prefix>/X); --robot wins."""
    from support.service_robots import gen3_file
    from wmm_qp_service.cli_common import service_config
    from wmm_qp_service.config import load_service_config
    from wmm_qp_tools.cli import build_parser

    assert load_service_config().robot == "wmm"  # the shipped service config names another id
    f = gen3_file(tmp_path, "fixed", name="cell_7")
    extra = ID_COMMANDS[command]

    def robot_id(*argv: str) -> str:
        return service_config(build_parser(command).parse_args([command, *extra, *argv])).robot

    assert robot_id("--robot-config", str(f)) == "cell_7"
    assert robot_id("--robot-config", str(f), "--robot", "other") == "other"
    assert robot_id() == "wmm"  # the default robot file's name
    nameless = tmp_path / "nameless.toml"
    nameless.write_text("\n".join(x for x in f.read_text().splitlines() if not x.startswith("name =")))
    svc = tmp_path / "service.toml"
    svc.write_text('robot = "from_service"\n')
    assert robot_id("--robot-config", str(nameless), "--service-config", str(svc)) == "from_service"
    assert robot_id("--robot-config", str(f), "--service-config", str(svc)) == "cell_7"


def test_demo_and_soak_run_their_robot_under_its_files_name(tmp_path) -> None:  # type: ignore[no-untyped-def]
    """demo and soak start their own sim and daemon: the robot file's name is their id too."""
    from support.service_robots import gen3_file
    from wmm_qp_service.processes import isolated_config

    import wmm_qp as w

    robot = w.load_robot_config(gen3_file(tmp_path, "fixed", name="cell_7"))
    assert isolated_config(robot=robot).robot == "cell_7"


# ---------------------------------------------------------------- verdict line and progress
def test_verify_prints_progress_on_stderr_and_keeps_stdout_json(capsys: pytest.CaptureFixture[str]) -> None:
    """Progress (not a terminal: one line per update) and the verdict line go to stderr; stdout
    is the JSON alone, with the verdict fields."""
    code, out, err = run(capsys, "verify", "--samples", "3", "--json")
    d = json.loads(out)
    assert code == 0 and d["verdict"] == "PASS" and d["verdict_reason"].startswith("0 violations")
    lines = err.strip().splitlines()
    assert "verify: 3/3 samples, 0 violations" in err, err
    assert lines[-1] == "PASS: " + d["verdict_reason"] and "verify:" not in out


def test_verify_ends_with_one_fail_line_naming_the_violations(capsys: pytest.CaptureFixture[str]) -> None:
    """The traditional controller breaks bounds: FAIL, exit 1, the kinds counted on the last line."""
    code, out, _ = run(capsys, "verify", "--controller", "traditional", "--samples", "14")
    last = out.strip().splitlines()[-1]
    assert code == 1 and last.startswith("FAIL: ") and " violations (" in last, last


@pytest.mark.parametrize("command", ["demo", "verify", "soak"])
def test_the_judged_commands_document_their_exit_codes_in_help(capsys: pytest.CaptureFixture[str],
                                                               command: str) -> None:
    code, out, _ = run(capsys, command, "--help")
    text = " ".join(out.split())
    assert code == 0 and "0 PASS" in text and "1 FAIL" in text and "2 bad input or usage" in text, text


def test_experiment_and_bench_print_progress_on_stderr_only(capsys: pytest.CaptureFixture[str]) -> None:
    """Not a terminal, --json: progress lines on stderr, the JSON alone on stdout."""
    code, out, err = run(capsys, "experiment", "circle", "--duration", "0.5", "--json")
    assert code == 0 and json.loads(out)["experiment"] == "circle"
    assert "circle: 100%" in err, err
    code, out, err = run(capsys, "bench", "--only", "oneshot", "--ticks", "5", "--solver", available_solvers()[0],
                         "--json")
    assert code == 0 and "oneshot" in json.loads(out)
    assert "bench: section 1/1: oneshot" in err and "bench: done, 1/1 sections" in err, err


ROBOTS = default_config_dir() / "robots"


@pytest.mark.parametrize(("argv", "names"), [
    (["--robot-config", str(ROBOTS / "gen3_mecanum.toml")], "--robot-config"),  # a mobile base: not a Franka
    (["--stale-timeout", "0"], "--stale-timeout"),
    (["--stale-timeout", "nan"], "--stale-timeout"),
])
def test_driver_franka_bad_input_is_one_line_and_exit_2(capsys: pytest.CaptureFixture[str], argv: list[str],
                                                        names: str) -> None:
    if "--robot-config" not in argv:
        pytest.importorskip("franky_sim", reason="configs/robots/fr3.toml's URDF ships with franky-sim")
    code, _, err = run(capsys, "driver", "franka", "--robot-ip", "127.0.0.1", *argv)
    assert code == 2 and names in err and len(err.strip().splitlines()) == 1, err


def test_driver_franka_without_a_robot_says_so_and_exits_1(tmp_path: object) -> None:
    pytest.importorskip("pylibfranka", reason="needs pylibfranka (pip install 'wmm-qp[franka]')")
    pytest.importorskip("franky_sim", reason="configs/robots/fr3.toml's URDF ships with franky-sim")
    from wmm_qp_service.processes import free_port

    r = subprocess.run([*CLI, "driver", "franka",
                        "--robot-ip", "127.0.0.254", "--prefix", f"wmmnorobot{free_port()}",
                        "--sim-endpoint", f"tcp/127.0.0.1:{free_port()}"],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 1 and "cannot connect to the robot at 127.0.0.254" in r.stderr, r.stderr
    assert "Traceback" not in r.stderr
