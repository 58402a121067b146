"""The comparison of ``benchmarks/refactor/same_results.py`` (``json_diff``): numbers within 1e-9,
absolute or relative; everything else equal; only the skipped keys ignored; a missing key fails."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks" / "refactor"))

from json_diff import MISSING, TOL, Difference, differences, max_deviation

DOC: dict[str, Any] = {
    "experiment": "push",
    "completed": True,
    "with_dm": {"max_abs_torque": [2.655663568271435, 28.662902551333087, 9.850624499508037e-16], "stall_ticks": 0},
    "base_motion_window": [0.0, 15.884],
    "saturated_joint": None,
}


def diffs(a: Any, b: Any, **kw: Any) -> list[Difference]:
    return list(differences(a, b, **kw))


def changed(path: tuple[str | int, ...], value: Any) -> dict[str, Any]:
    """A deep copy of DOC with the value at ``path`` replaced."""
    import copy

    doc = copy.deepcopy(DOC)
    node: Any = doc
    for p in path[:-1]:
        node = node[p]
    node[path[-1]] = value
    return doc


def test_a_document_equals_itself() -> None:
    assert diffs(DOC, DOC) == []


@pytest.mark.parametrize("scale", [0.5, 0.99])
def test_numbers_within_1e_9_relative_or_absolute_are_equal(scale: float) -> None:
    big = DOC["with_dm"]["max_abs_torque"][1]  # 28.66 N·m: 1e-9 relative is 2.9e-8 absolute
    assert diffs(DOC, changed(("with_dm", "max_abs_torque", 1), big * (1 + scale * TOL))) == []
    tiny = DOC["with_dm"]["max_abs_torque"][2]  # 1e-15: judged by the absolute 1e-9
    assert diffs(DOC, changed(("with_dm", "max_abs_torque", 2), tiny + scale * TOL)) == []
    assert diffs(DOC, changed(("base_motion_window", 0), scale * TOL)) == []  # 0 against 1e-9


def test_a_difference_of_1e_6_fails_and_names_the_path_and_both_values() -> None:
    big = DOC["with_dm"]["max_abs_torque"][1]
    after = changed(("with_dm", "max_abs_torque", 1), big * (1 + 1e-6))
    (d,) = diffs(DOC, after)
    assert d == Difference("with_dm.max_abs_torque[1]", big, big * (1 + 1e-6))
    assert str(d).startswith("with_dm.max_abs_torque[1]: before 28.66")
    assert max_deviation([d])[1] == pytest.approx(1e-6, rel=1e-5)  # relative to the larger value
    (d,) = diffs(DOC, changed(("base_motion_window", 1), 15.884 + 1e-6))  # absolute 1e-6 on 15.9: 6e-8 rel
    assert d.path == "base_motion_window[1]"


def test_strings_bools_and_null_must_be_identical() -> None:
    assert [d.path for d in diffs(DOC, changed(("experiment",), "circle"))] == ["experiment"]
    assert [d.path for d in diffs(DOC, changed(("completed",), 1))] == ["completed"]  # True is not 1
    assert [d.path for d in diffs(DOC, changed(("saturated_joint",), 0))] == ["saturated_joint"]
    assert [d.path for d in diffs(DOC, changed(("with_dm", "stall_ticks"), 1))] == ["with_dm.stall_ticks"]


def test_a_missing_or_extra_key_fails() -> None:
    after = changed(("with_dm",), {"max_abs_torque": DOC["with_dm"]["max_abs_torque"]})
    assert diffs(DOC, after) == [Difference("with_dm.stall_ticks", 0, MISSING)]
    assert diffs(after, DOC) == [Difference("with_dm.stall_ticks", MISSING, 0)]


def test_a_list_of_another_length_fails() -> None:
    (d,) = diffs(DOC, changed(("base_motion_window",), [0.0]))
    assert d.path == "base_motion_window (length)" and (d.before, d.after) == (2, 1)


def test_skipped_keys_are_ignored_wherever_they_occur_and_only_they() -> None:
    skip = {"wall_s": "timing"}
    before = {"wall_s": 1.0, "run": {"wall_s": 2.0, "dm": 5.79}}
    after = {"run": {"wall_s": 9.0, "dm": 5.79}}  # different, and missing at the top
    assert diffs(before, after, skip=skip) == []
    assert [d.path for d in diffs(before, after)] == ["wall_s", "run.wall_s"]  # not skipped by default
    after["run"]["dm"] = 5.80
    assert [d.path for d in diffs(before, after, skip=skip)] == ["run.dm"]


def test_keys_with_dots_are_quoted_in_the_path() -> None:
    (d,) = diffs({"reasons": {"sigma_min # below 0.08": 3}}, {"reasons": {"sigma_min # below 0.08": 4}})
    assert d.path == "reasons['sigma_min # below 0.08']"
