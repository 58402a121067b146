"""Progress lines of long commands: first at once, then at most one a second, the last always."""

from __future__ import annotations

import io

from wmm_qp_service.progress import ProgressLine


def test_updates_are_throttled_to_one_a_second_and_the_last_is_always_shown() -> None:
    now = [100.0]
    out = io.StringIO()  # not a terminal: one line per update shown
    bar = ProgressLine("verify", stream=out, clock=lambda: now[0])
    for i in range(1, 51):  # 50 updates over 2.5 s
        now[0] += 0.05
        bar.update(f"{i}/50 samples")
    bar.done("50/50 samples")
    lines = out.getvalue().splitlines()
    assert lines[0] == "verify: 1/50 samples, 0 s"
    assert len(lines) == 1 + 2 + 1  # the first, one a second after it (t = 1.05, 2.05), the last
    assert lines[-1] == "verify: 50/50 samples, 2 s"


def test_a_costly_text_is_only_computed_when_shown() -> None:
    now = [0.0]
    calls = []
    bar = ProgressLine("soak", stream=io.StringIO(), clock=lambda: now[0])
    for _ in range(10):
        bar.update(lambda: calls.append(1) or "x")
    assert len(calls) == 1
