"""Smoke tests of ``wmm-qp bench``: tiny tick counts, the result's keys, no timing asserts."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from wmm_qp_tools.bench import controller, oneshot, pink_race, scaling
from wmm_qp_tools.bench.stats import PieceTimer, summarize_ns
from wmm_qp_tools.cli import main

import wmm_qp as w

REPO = Path(__file__).resolve().parents[2]  # this checkout (CI installs the packages, not the tree)


def test_summarize_ns_percentiles() -> None:
    s = summarize_ns(np.arange(1, 101) * 1000)  # 1..100 µs
    assert s["n"] == 100
    assert s["p50"] == pytest.approx(50.5)
    assert s["max"] == pytest.approx(100.0)
    assert np.isnan(summarize_ns([])["p50"])


def test_piece_timer_accumulates_within_a_tick() -> None:
    t = PieceTimer(["a", "b"])
    t.add("a", 1000)
    t.add("a", 2000)
    t.flush()
    t.flush()
    assert t.samples == {"a": [3000, 0], "b": [0, 0]}


def test_controller_case_keys_and_breakdown_restores_the_controller() -> None:
    robot, cfg = w.load_robot_config(), w.load_controller_config()
    r = controller.run_case(robot, cfg, "daqp", "dm_nullspace", ticks=20)
    assert r["tick_us"]["n"] == 20 and r["breakdown_tick_us"]["n"] == 20
    assert set(r["pieces_us"]) == set(controller.PIECES)
    assert r["pieces_us"]["kinematics"]["p50"] > 0 and r["pieces_us"]["solve"]["p50"] > 0
    assert r["max_rate_excess"] <= 1e-9
    import wmm_qp.controllers.base as base

    assert base.dm_gradient.__module__ == "wmm_qp.manipulability.directional"  # unpatched


def test_oneshot_agrees_with_persistent() -> None:
    r = oneshot.run(w.load_robot_config(), w.load_controller_config(), ["daqp"], 5)
    assert r["n_problems"] > 0
    assert r["daqp"]["max_abs_diff"] < 1e-6
    assert r["daqp"]["failures_persistent"] == 0


def test_scaling_models_have_the_right_sizes(tmp_path) -> None:  # type: ignore[no-untyped-def]
    robot, cfg = w.load_robot_config(), w.load_controller_config()
    models = scaling.build_models(robot, tmp_path)
    assert {n: m.n for n, m in models.items()} == {6: 6, 7: 7, 14: 14}
    assert len(models[14].frames) == 2
    r = scaling.run_one(models[14], cfg, "daqp", ticks=5, max_seconds=10)
    assert r["n_vars"] == 4 + 14 + 6 and r["failures"] == 0


def test_pink_race_runs_and_is_checked() -> None:
    pytest.importorskip("pink")
    r = pink_race.run(w.load_robot_config(), w.load_controller_config(), ticks=10)
    assert r["available"]
    for k in ("ours", "pink", "pink_accel"):
        assert r[k]["tick_us"]["n"] == 10
        assert r[k]["failures"] == 0
        assert r[k]["max_limit_excess"] <= 1e-3
    assert r["ratio_p50"] > 0


def test_cli_json_has_the_required_keys(capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("pink")
    rc = main(
        ["bench", "--json", "--ticks", "5", "--solver", "daqp", "--mode", "track", "--no-breakdown",
         "--skip", "e2e", "--skip", "daemon", "--skip", "default"]
    )  # fmt: skip
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out["tick_us"]["daqp"]) >= {"p50", "p99"}
    assert set(out["pink_tick_us"]) == {"p50", "p99"}
    assert "e2e" not in out and "daemon" not in out  # skipped
    assert out["machine"]["nproc"] >= 1


@pytest.mark.integration
@pytest.mark.slow
def test_e2e_over_zenoh(capsys: pytest.CaptureFixture[str]) -> None:
    """Every case through real processes, briefly: the figures exist (no timing asserts)."""
    assert main(["bench", "--json", "--only", "e2e", "--ticks", "1000"]) == 0
    e2e = json.loads(capsys.readouterr().out)["e2e"]
    assert e2e["available"] is True
    for case in ("rate 500", "rate 1000", "state 1000"):
        r = e2e[case]
        assert r["exit_codes"] == {"sim": 0, "daemon": 0}
        assert r["ticks"] > 100 and r["achieved_hz"] > 0
        for k in ("tick_us", "step_us", "state_to_cmd_us", "state_transport_us", "daemon_us", "cmd_to_applied_us"):
            assert set(r[k]) == {"p50", "p99", "p999", "max", "n"} and r[k]["n"] > 0, k
        assert r["state_to_cmd_us"]["p50"] > r["daemon_us"]["p50"] > 0  # causal: state, receipt, command
        assert r["misses_per_10k"] is not None and sum(r["violations"].values()) == 0
        assert 0.0 <= r["applied_next_step"] <= 1.0 and r["tick_over_step_p50"] > 1.0
        assert set(r["cpu_pct"]) == {"sim", "daemon", "client"}
        assert r["daemon_loop_end"]["trigger"] == case.split()[0]
    # the embedded stack in the same run, its keys mirroring the split's rates; the machine's floor
    for rate in ("500", "1000"):
        r = e2e["embedded"][rate]
        assert r["available"] and r["exit_codes"] == {"embedded": 0}
        assert r["daemon_loop_end"]["trigger"] == "embedded" and r["daemon_loop_end"]["rate_hz"] == float(rate)
        for k in ("tick_us", "step_us", "state_to_cmd_us"):
            assert set(r[k]) == {"p50", "p99", "p999", "max", "n"} and r[k]["n"] > 0, k
        assert r["state_to_cmd_us"]["p50"] > 0 and r["misses_per_10k"] is not None
        assert set(r["cpu_pct"]) == {"embedded", "client"} and sum(r["violations"].values()) == 0
        assert r["cycle"]["decimation"] == 1000 // int(rate) and r["cycle"]["ticks"] > 0
    plain = e2e["embedded_plain"]["1000"]  # without the cycle's cost cuts, beside it
    assert plain["available"] and not plain["cycle"]["cuts"] and e2e["embedded"]["1000"]["cycle"]["cuts"]
    assert plain["cycle"]["gc"]["enabled"] is False and plain["state_to_cmd_us"]["n"] > 0
    f = e2e["floor"]["1000"]
    assert f["ticks"] == 1000 and f["misses_per_10k"] is not None and f["spin_us"] == 200.0


@pytest.mark.integration
@pytest.mark.slow
def test_daemon_breakdown_over_zenoh(capsys: pytest.CaptureFixture[str]) -> None:
    """The daemon's per-stage breakdown from its real loop: every stage, both triggers."""
    from wmm_qp_service.tick_stages import STAGES

    assert main(["bench", "--json", "--only", "daemon", "--ticks", "1000"]) == 0
    d = json.loads(capsys.readouterr().out)["daemon"]
    assert d["available"] is True
    for case in ("rate 1000", "state 1000"):
        b = d[case]["breakdown"]
        assert b["trigger"] == case.split()[0] and b["ticks"] > 100
        assert set(b["stages"]) == set(STAGES)
        assert b["stages"]["step"]["p50"] > 0 and b["tick"]["p50"] >= b["stages"]["step"]["p50"]
        assert b["tick_over_step_p50"] >= 1.0


def test_jitter_section_the_empty_loop_at_both_rates(capsys: pytest.CaptureFixture[str]) -> None:
    """The machine's floor (what the end-to-end figures are read against): the daemon's loop with
    no work, briefly; the counts are consistent (no timing asserts): a tick that wakes more than a
    period late is a deadline miss at the next wait (but the last tick's), and no tick starts
    before its deadline."""
    assert main(["bench", "--json", "--only", "jitter", "--ticks", "60"]) == 0
    out = json.loads(capsys.readouterr().out)
    j = out["jitter"]
    assert set(j) == {"500", "1000"}
    a = out["step_after_idle"]  # ctl.step after each idle: as many of each, ratios of the p50s
    assert a["ticks_each"] == 60 and a["idle_us"] == 800.0
    for idle in ("none", "sleep", "spin"):
        assert 0.0 < a[idle]["p50"] <= a[idle]["p99"]
    assert a["sleep_over_none_p50"] == pytest.approx(a["sleep"]["p50"] / a["none"]["p50"], abs=0.02)
    for rate, r in j.items():
        assert r["rate_hz"] == float(rate) and r["ticks"] == 60 and r["scheduling"]
        assert 0 <= r["late_over_a_period"] <= r["deadline_misses"] + 1 and r["deadline_misses"] <= 60
        assert r["misses_per_10k"] == pytest.approx(1e4 * r["deadline_misses"] / 60, abs=0.01)
        assert 0.0 <= r["late_us"]["p50"] <= r["late_us"]["p99"] <= r["late_us"]["max"]
        assert r["seconds"] >= 60 / float(rate) * 0.99  # the loop paced its ticks, it did not burst
        assert r["steal_s"] is None or r["steal_s"] >= 0.0


def test_cli_user_errors_exit_2(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "--ticks", "0"]) == 2
    assert main(["bench", "--solver", "nope"]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and "error" in err


def test_fastest_backend_breaks_a_p50_tie_by_p99() -> None:
    from wmm_qp_tools.bench.runner import targets

    ticks = {"osqp": {"p50": 27.60, "p99": 309.9}, "daqp": {"p50": 27.77, "p99": 81.1}}
    assert targets({"tick_us": ticks})["fastest_backend"] == "daqp"  # within 2 %: p99 decides
    ticks["osqp"]["p50"] = 20.0  # clearly faster: p50 decides
    t = targets({"tick_us": ticks})
    assert t["fastest_backend"] == "osqp" and t["fastest_p99_le_250us"] is False


# Any robot ------------------------------------------------------------------------------------------
ROBOTS = w.default_robot_file().parent


@pytest.mark.parametrize("name", ["panda_diffdrive.toml", "ur5_omni.toml", "tiago.toml"])
@pytest.mark.parametrize("task", ["position", "pose"])
def test_controller_case_on_any_robot_and_task(name: str, task: str) -> None:
    robot = w.load_robot_config(ROBOTS / name)
    cfg = w.load_controller_config().with_(task={"kind": task})
    r = controller.run_case(robot, cfg, "daqp", "track", ticks=20, breakdown=False)
    assert r["tick_us"]["n"] == 20 and r["max_rate_excess"] <= 1e-9
    assert r["status"].get("safe_stop", 0) == 0


def test_scaling_follows_the_robot_s_arm(tmp_path) -> None:  # type: ignore[no-untyped-def]
    robot = w.load_robot_config(ROBOTS / "ur5_omni.toml")  # 6 joints, 3 omni wheels
    models = scaling.build_models(robot, tmp_path)
    assert {n: m.n for n, m in models.items()} == {5: 5, 6: 6, 12: 12}
    r = scaling.run_one(models[12], w.load_controller_config(), "daqp", ticks=5, max_seconds=10)
    assert r["n_vars"] == 3 + 12 + 6 and r["failures"] == 0


def test_robots_section_times_every_robot_task_and_solver(tmp_path) -> None:  # type: ignore[no-untyped-def]
    from wmm_qp_tools.bench.runner import run_robots, shipped_robots

    files = shipped_robots()
    assert files[0].name == w.default_robot_file().name and len(files) >= 4
    bad = tmp_path / "broken.toml"
    bad.write_text('name = "broken"\n')
    r = run_robots(w.load_controller_config(), ["daqp"], 3, 10.0, files=[files[0], ROBOTS / "tiago.toml", bad])
    assert set(r) == {"wmm", "tiago", "broken"}
    assert r["broken"]["available"] is False and "broken.toml" in r["broken"]["reason"]
    for name in ("wmm", "tiago"):
        for task in ("position", "pose"):
            assert r[name][task]["daqp"]["tick_us"]["n"] == 3


def test_pink_race_needs_a_holonomic_base() -> None:
    r = pink_race.run(w.load_robot_config(ROBOTS / "panda_diffdrive.toml"), w.load_controller_config(), ticks=5)
    assert r["available"] is False and "diff_drive" in r["reason"]


def test_pink_race_on_the_omni_base() -> None:
    pytest.importorskip("pink")
    r = pink_race.run(w.load_robot_config(ROBOTS / "ur5_omni.toml"), w.load_controller_config(), ticks=10)
    assert r["available"] and r["ours"]["failures"] == 0 and r["pink"]["failures"] == 0


def test_cli_robot_config_and_task(capsys: pytest.CaptureFixture[str]) -> None:
    rc = main(["bench", "--json", "--only", "controller", "--ticks", "5", "--solver", "daqp", "--mode", "track",
               "--no-breakdown", "--robot-config", str(ROBOTS / "tiago.toml"), "--task", "pose"])  # fmt: skip
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    assert out["robot"] == "tiago" and out["task"] == "pose" and set(out["tick_us"]["daqp"]) >= {"p50", "p99"}


def test_compare_commits_interleaves_two_trees() -> None:
    """The same tree twice: both workers follow the same trajectory and agree on every stage."""
    from wmm_qp_tools.bench.compare_commits import HERE, interleave

    r = interleave(HERE, HERE, blocks=2, ticks=20, solvers=["daqp"])
    row = r["solvers"]["daqp"]
    assert r["ticks"] == 20 and row["old"]["n"] == row["new"]["n"] == 20
    assert row["same_run"]["stages"] and row["same_run"]["status"] and row["ratio_p50"] > 0


def test_collision_default_times_every_robot_with_and_without_its_default_rows(tmp_path) -> None:  # type: ignore[no-untyped-def]
    """``wmm-qp bench --only collision_default`` on a short run: each robot's step with the default
    scene's rows and without rows, on the same states (no timing asserted); a broken file is named."""
    from wmm_qp_tools.bench import collision
    from wmm_qp_tools.bench.runner import shipped_robots

    bad = tmp_path / "broken.toml"
    bad.write_text('name = "broken"\n')
    files = [*shipped_robots(), bad]
    r = collision.run_default(w.load_controller_config().with_(qp={"solver": "daqp"}), 150, 60.0, files=files)
    assert set(r) == {"wmm", "panda_diffdrive", "ur5_omni", "tiago", "fr3", "broken"}
    assert r["broken"]["available"] is False
    for name in ("wmm", "panda_diffdrive", "ur5_omni", "tiago"):  # (the FR3 file declares no collision shapes)
        c = r[name]
        assert c["with_rows"]["n"] == c["without_rows"]["n"] > 0 and c["solver"] == "daqp"
        assert c["monitored"]["obstacles"] == 0 and c["monitored"]["self_pairs"] > 0
    assert r["tiago"]["rows"]["max"] >= 1  # its arm_1/arm_3 pair starts within d_i


def test_the_sections_but_collision_default_time_the_controller_without_rows(
        capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    """The shipped config has the rows on; the sections whose figures were taken without them
    (the paper's setting) still time that, collision_default both."""
    from wmm_qp_tools.bench import runner

    seen: list[bool] = []
    real = runner.controller.run

    def spy(robot, cfg, *a, **k):  # type: ignore[no-untyped-def]
        seen.append(cfg.collision.enabled)
        return real(robot, cfg, *a, **k)

    monkeypatch.setattr(runner.controller, "run", spy)
    assert main(["bench", "--json", "--ticks", "3", "--solver", "daqp", "--mode", "track", "--no-breakdown",
                 "--only", "controller"]) == 0
    assert seen == [False] and w.load_controller_config().collision.enabled
    capsys.readouterr()


def test_sim_section_times_every_shipped_robot_on_both_plants(capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("mujoco", reason="the physics plant needs mujoco: pip install 'wmm-qp[physics]'")
    from wmm_qp_tools.bench.runner import shipped_robots

    assert main(["bench", "--json", "--only", "sim", "--ticks", "20"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["physics"] == ["kinematic", "mujoco"]
    names = {w.load_robot_config(f).name for f in shipped_robots()}
    assert set(out["sim"]) == names
    for row in out["sim"].values():
        for plant in ("kinematic", "mujoco"):
            r = row[plant]
            assert r["step_us"]["n"] == 20 and 0.0 < r["step_us"]["p50"] <= r["step_us"]["p99"]
            assert r["realtime_factor"] > 0.0
            assert r["violations"]["velocity"] == 0 and r["violations"]["acceleration"] == 0


def test_sim_section_on_one_plant(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "--json", "--only", "sim", "--ticks", "5", "--physics", "kinematic"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["physics"] == ["kinematic"]
    assert all(set(row) == {"file", "available", "kinematic"} for row in out["sim"].values())


def test_tick_section_times_this_tree_and_a_baseline_tree_in_alternating_rounds(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """``--only tick --baseline-tree DIR`` (DIR: this same tree): each round one worker run per tree,
    the first of a round alternating; the JSON's tick_compare and the report's line (no timing asserted)."""
    from wmm_qp_tools.bench.compare_commits import HERE
    from wmm_qp_tools.bench.tick_compare import round_order
    from wmm_qp_tools.commands.bench import _print_report

    if not (HERE / "pyproject.toml").is_file():  # CI installs the packages, not the tree
        pytest.skip("--baseline-tree times source trees: needs wmm-qp installed editable (pip install -e .)")

    assert [round_order(k) for k in range(3)] == [("this", "baseline"), ("baseline", "this"), ("this", "baseline")]
    argv = ["bench", "--json", "--only", "tick", "--baseline-tree", str(REPO), "--ticks", "5", "--rounds", "2"]
    assert main([*argv, "--solver", "daqp"]) == 0
    r = json.loads(capsys.readouterr().out)
    t = r["tick_compare"]
    assert {"this_us_p50", "baseline_us_p50", "ratio", "rounds"} <= set(t)
    assert t["rounds"] == 2 and len(t["ratio_rounds"]) == 2 and t["solver"] == "daqp" and t["ratio"] > 0
    assert t["same_run"]["stages"] and t["same_run"]["status"]  # the same tree: the same numerics
    _print_report(r)  # the text report: one line with the ratio
    (line,) = [ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("tick ")]
    assert "ratio this/baseline" in line and "over 2 rounds" in line


def test_tick_section_a_bad_baseline_tree_is_one_line_and_exit_2(
    tmp_path, capsys: pytest.CaptureFixture[str]  # type: ignore[no-untyped-def]
) -> None:
    for argv, says in (
        (["--only", "tick", "--baseline-tree", str(tmp_path)], f"--baseline-tree {tmp_path}: not a wmm-qp source tree"),
        (["--only", "tick", "--baseline-tree", str(tmp_path / "nope")], "not a directory"),
        (["--only", "tick"], "--only tick needs --baseline-tree DIR"),
        (["--only", "controller", "--baseline-tree", str(tmp_path)], "--baseline-tree applies to the tick section"),
        (["--only", "tick", "--baseline-tree", str(tmp_path), "--rounds", "0"], "--rounds must be at least 1"),
    ):
        assert main(["bench", *argv]) == 2
        err = capsys.readouterr().err
        assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
        assert err.startswith("wmm-qp bench: error: ") and says in err, err


def test_default_ratios_and_targets_are_computed_from_the_run_s_own_figures() -> None:
    """The default section's ratios come from its figures (not constants): a fabricated run whose
    rows cost 2.5× on one robot, whose in-loop step is 1.2× the isolated one and whose embedded
    loop misses 3× the floor's deadlines fails exactly those targets."""
    from wmm_qp_tools.bench.default import ratios
    from wmm_qp_tools.bench.runner import default_targets

    run = {"robot": "gen3", "in_process": {
        "gen3": {"available": True, "ratio_p50": 1.5, "with_rows": {"p50": 100.0, "p99": 300.0}},
        "tiago": {"available": True, "ratio_p50": 2.5, "with_rows": {"p50": 400.0, "p99": 900.0}},
        "absent": {"available": False, "reason": "not installed"}},
        "loops": {"rate 1000": {"step_us": {"p50": 120.0}, "misses_per_10k": 1.0},
                  "embedded 1000": {"step_us": {"p50": 120.0}, "misses_per_10k": 6.0},
                  "floor 1000": {"misses_per_10k": 2.0}},
        "pink": {"gen3": {"available": True, "ratio_p50": 3.4}, "z1": {"available": False}},
        "paced": {"ticks": 10, "back_to_back": {"p50": 100.0}, "1000": {"p50": 80.0}}}
    r = ratios(run)
    assert r["isolated_step_p50_us"] == 100.0 and set(r["rows"]) == {"gen3", "tiago"}
    assert r["loops"]["embedded 1000"] == {"in_loop_over_isolated_step_p50": 1.2, "in_loop_over_paced_step_p50": 1.5,
                                           "misses_per_10k": 6.0, "floor_misses_per_10k": 2.0,
                                           "misses_over_floor": 3.0}
    assert r["paced_step_p50_us"] == {"back_to_back": 100.0, "1000": 80.0}
    t = default_targets(r)
    assert t["default: rows_p99_under_1ms_every_robot"] is True
    assert t["default: rows_cost_within_2x_p50_every_robot"] is False  # tiago's 2.5×
    assert t["default rate 1000: in_loop_step_within_1_3x"] is True
    assert t["default embedded 1000: misses_within_2x_floor"] is False
    assert t["default: at_least_3x_pink_every_holonomic_robot"] is True
    run["loops"]["floor 1000"]["misses_per_10k"] = 0.0  # an empty loop that missed none: no ratio, still judged
    t = default_targets(ratios(run))
    assert ratios(run)["loops"]["embedded 1000"]["misses_over_floor"] is None
    assert t["default embedded 1000: misses_within_2x_floor"] is False


@pytest.mark.integration
@pytest.mark.slow
def test_default_section_runs_what_users_run(capsys: pytest.CaptureFixture[str]) -> None:
    """``--only default`` briefly: every shipped robot in process, both loops at both rates with
    their floors, the ratios and the targets in the JSON (no timing asserts)."""
    assert main(["bench", "--json", "--only", "default", "--ticks", "400"]) == 0
    out = json.loads(capsys.readouterr().out)
    d = out["default"]
    assert {"wmm", "tiago", "fr3"} <= set(d["in_process"]) and d["ratios"]["isolated_step_p50_us"] > 0
    assert set(d["loops"]) == {"rate 500", "embedded 500", "rate 1000", "embedded 1000", "floor 500", "floor 1000"}
    for key in ("rate 500", "embedded 1000"):
        assert d["loops"][key]["available"] and d["ratios"]["loops"][key]["in_loop_over_isolated_step_p50"] > 0
        assert d["loops"][key]["collision"] is True  # the loops with the default rows, as users run them
        assert d["ratios"]["loops"][key]["in_loop_over_paced_step_p50"] > 0
    assert d["paced"]["back_to_back"]["p50"] > 0 and d["paced"]["500"]["p50"] > 0
    assert "default: rows_p99_under_1ms_every_robot" in out["targets"]


def test_the_kernel_benchmarks_take_the_kernels_arguments_as_the_rows_pass_them() -> None:
    """``benchmarks/collision/passes_tick.py`` and ``rows_parts.py`` time the two kernels on the
    arguments ``_robot_rows`` passes them: split where ``robot_passes``' own end (a kernel that
    gains an argument must not break them)."""
    from wmm_qp_tools.bench.collision import kernel_arguments_at_tick

    from wmm_qp.limits._pair_passes import robot_passes
    from wmm_qp.limits.collision import _rows

    robot, rows = kernel_arguments_at_tick("configs/robots/panda_diffdrive.toml", 5)
    n, left = robot_passes(*robot)
    assert n > 0 and left == 0
    _, _, m, closest, _ = _rows(*rows)
    assert m > 0 and closest >= 0


def test_the_gjk_benchmark_times_a_robots_warm_hull_pairs() -> None:
    """``benchmarks/collision/gjk_calls.py`` finds the FR3's pairs of two hulls that GJK computed
    with a warm start and calls GJK on them (a change to GJK's arguments must not break it)."""
    import importlib.util
    import re

    spec = importlib.util.spec_from_file_location("gjk_calls", "benchmarks/collision/gjk_calls.py")
    assert spec is not None and spec.loader is not None
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    bench.CALLS = 10
    out = bench.one("fr3", 5)
    found = re.match(r"fr3: (\d+) hull pairs, their warm GJK calls ([0-9.]+) µs", out)
    assert found is not None, out
    assert int(found.group(1)) > 0 and float(found.group(2)) > 0
