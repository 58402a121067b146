"""The verdict line of demo, verify and soak: FAIL only for violations and unjudgeable runs."""

from __future__ import annotations

from wmm_qp_service.verdict import EXIT_FAIL, EXIT_PASS, judge


def test_misses_faults_and_stops_are_reported_and_explained_but_pass() -> None:
    v = judge({"position": 0, "velocity": 0}, deadline_misses=12, faults={"state_stale": 2, "robot_lost": 1},
              protective_stops=1, logs="/tmp/run")
    assert v.passed and v.exit_code == EXIT_PASS and v.line().startswith("PASS: 0 violations; ")
    for part in ("12 deadline misses", "3 faults (state_stale 2, robot_lost 1)", "1 protective stop",
                 "the host was loaded", "not a failure", "logs: /tmp/run"):
        assert part in v.reason, (part, v.reason)
    assert v.json_fields() == {"verdict": "PASS", "verdict_reason": v.reason}


def test_any_violation_or_failure_is_fail_naming_the_kinds() -> None:
    v = judge({"position": 3, "velocity": 0, "collision": 1}, logs="/tmp/run")
    assert not v.passed and v.exit_code == EXIT_FAIL
    assert v.line() == "FAIL: 4 violations (position 3, collision 1); logs: /tmp/run"
    crashed = judge({"position": 0}, failures=["the daemon exited with status 1"], logs="/tmp/run")
    assert crashed.word == "FAIL" and "the daemon exited with status 1" in crashed.reason
    assert "\n" not in judge({}, deadline_misses=1).line()
