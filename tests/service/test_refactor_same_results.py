"""``benchmarks/refactor/same_results.py`` without running a command: the verdict, the noise recheck,
the run list and its user errors (the runs themselves: benchmarks/README.md)."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks" / "refactor"))

import same_results as sr
from results_runs import EXCLUDED, RUNS

ROOT = Path(__file__).resolve().parents[2]
RUN = next(r for r in RUNS if r.name == "circle_qp")


def out(vx: float, rc: int = 0) -> sr.Output:
    return sr.Output(rc, doc={"base_velocity": {"vx": {"max": vx}}, "violations": {"position": 0}})


def test_equal_outputs_pass_and_a_difference_fails_naming_the_command_path_and_values() -> None:
    assert sr.verdict_line([sr.judge(RUN, out(0.0039), out(0.0039 + 1e-13))], 1) == "PASS 1 commands equal"
    v = sr.judge(RUN, out(0.0039), out(0.0040))
    line = sr.verdict_line([v], 1)
    assert line == "FAIL 1 of 1 commands differ; first: circle_qp: base_velocity.vx.max: before 0.0039, after 0.004"


def test_other_exit_codes_or_a_command_without_json_fail() -> None:
    assert sr.judge(RUN, out(0.0039, rc=0), out(0.0039, rc=1)).diffs[0].path == "<exit code>"
    v = sr.judge(RUN, out(0.0039), sr.Output(2, error="exit 2, no JSON on stdout: bad flag"))
    assert "the after tree's command failed: exit 2" in sr.verdict_line([v], 1)
    assert sr.verdict_line([], 1) == "FAIL only 0 of 1 commands ran"


def out2(vx: float, position: int) -> sr.Output:
    o = out(vx)
    o.doc["violations"]["position"] = position
    return o


def test_a_difference_the_before_tree_shows_on_rerun_is_called_noisy() -> None:
    noisy = sr.judge(RUN, out(0.0039083677), out(0.0039083655))
    noisy.reruns = [out(0.0039083677), out(0.0039083655)]  # the before tree alone moves there too
    assert noisy.noise == "noisy" and "noisy here: a rerun of the before tree gave 0.0039083655" in noisy.reason()
    real = sr.judge(RUN, out(0.0039), out(0.0040))
    real.reruns = [out(0.0039), out(0.0039)]
    assert real.noise == "not noisy" and "gave this value again in 2 reruns" in real.reason()
    partly = sr.judge(RUN, out2(0.0039083677, 0), out2(0.0039083655, 3))  # the count is the change's doing
    partly.reruns = [out2(0.0039083655, 0)]
    assert partly.noise == "partly noisy" and "differs from itself at 1 of 2 differing paths" in partly.reason()
    line = sr.verdict_line([noisy, partly, real], 3)
    assert line.startswith("FAIL 3 of 3 commands differ (1 not noisy, 1 partly noisy, 1 noisy); first not noisy: ")
    assert sr.verdict_line([noisy, partly], 2).startswith("FAIL 2 of 2 commands differ (1 partly noisy, 1 noisy); "
                                                          "first partly noisy: circle_qp")  # fmt: skip
    assert sr.verdict_line([sr.judge(RUN, out(0.0039), out(0.0040))], 1).startswith("FAIL 1 of 1 commands differ; ")


def test_the_run_list_has_unique_names_placeholders_and_no_realtime_run() -> None:
    names = [r.name for r in RUNS]
    assert len(names) == len(set(names))
    assert not any("--realtime" in r.argv or "--plots" in r.argv for r in RUNS)
    assert all(a.startswith("{tree}/configs/") for r in RUNS for a in r.argv if "configs/" in a)
    assert any("--realtime" in cmd for cmd, _ in EXCLUDED)
    assert [r.name for r in sr.select(["circle_r1*_qp"])] == ["circle_r170_qp", "circle_r100_qp"]


def test_this_tree_is_read_from_its_pyproject() -> None:
    tree = sr.Tree.load("--before", ROOT)
    assert tree.pythonpath == (ROOT, ROOT / "robot", ROOT / "sim", ROOT / "service", ROOT / "tools")
    assert tree.entry == "wmm_qp_tools.cli:main"
    argv = tree.argv(RUN, "python")
    assert argv[:2] == ["python", "-c"] and argv[3:] == ["experiment", "circle", "--controller", "qp", "--json"]


@pytest.mark.parametrize(
    ("argv", "says"),
    [
        (["--before", "/nonexistent", "--after", str(ROOT)], "--before /nonexistent: not a source tree of wmm-qp"),
        (["--before", str(ROOT)], "--before DIR and --after DIR are required"),
        (["--before", str(ROOT), "--after", str(ROOT), "--only", "no_such_run"], "--only no_such_run: no such run"),
        (["--before", str(ROOT), "--after", str(ROOT), "--jobs", "0"], "--jobs 0: must be at least 1"),
    ],
)
def test_bad_arguments_are_one_line_and_exit_2(argv: list[str], says: str, capsys: Any) -> None:
    assert sr.main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("same_results.py: error: ") and says in err
