"""The one-line verdict that ``wmm-qp demo``, ``verify`` and ``soak`` end with, and their exit codes.

FAIL is a broken bound: a violation counted by a referee (``position``, ``velocity``,
``acceleration``, ``wheel_speed``, ``wheel_acceleration``, ``collision``, and ``ee_box`` in
``verify``), or a run that could not be judged (the processes did not come up, one crashed or
did not stop). Deadline misses, faults (the daemon's watchdogs: a safe stop each) and protective
stops (the robot's firmware) are the system doing its job on a loaded host or a broken link:
the line reports and explains them, but they are no FAIL.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

EXIT_PASS = 0
EXIT_FAIL = 1
EXIT_USAGE = 2

EXIT_CODES_HELP = (
    "Ends with one line: PASS or FAIL, why, and where the logs are. Exit status: 0 PASS (no violation); "
    "1 FAIL (a referee counted a violation: a position, velocity, acceleration, wheel speed or wheel "
    "acceleration bound broken, or a collision; or the run could not be judged); 2 bad input or usage. "
    "Deadline misses, faults and protective stops are reported on the line, not a FAIL."
)
"""The epilog of each judged command's ``--help`` (README.md "Exit codes")."""


@dataclass(frozen=True)
class Verdict:
    """PASS or FAIL, and why.

    Attributes:
        passed: no violation and nothing that prevented judging the run.
        reason: the rest of the line (counts, explanation, where the logs are).
    """

    passed: bool
    reason: str

    @property
    def word(self) -> str:
        """``PASS`` or ``FAIL``."""
        return "PASS" if self.passed else "FAIL"

    @property
    def exit_code(self) -> int:
        """0 for PASS, 1 for FAIL."""
        return EXIT_PASS if self.passed else EXIT_FAIL

    def line(self) -> str:
        """The verdict line, e.g. ``PASS: 0 violations; 3 deadline misses — …; logs: /tmp/…``."""
        return f"{self.word}: {self.reason}"

    def json_fields(self) -> dict[str, str]:
        """``{"verdict": "PASS"|"FAIL", "verdict_reason": ...}`` for a command's JSON."""
        return {"verdict": self.word, "verdict_reason": self.reason}


def _counts(counts: Mapping[str, int], codes: bool = False) -> str:
    """``kind n, …``, most first; ``codes``: the keys are fault codes, shown as they are (to grep for)."""
    return ", ".join(f"{k if codes else k.replace('_', ' ')} {v}"
                     for k, v in sorted(counts.items(), key=lambda kv: -kv[1]) if v)


def _plural(n: int, word: str, plural: str = "") -> str:
    return f"{n} {word if n == 1 else plural or word + 's'}"


def judge(
    violations: Mapping[str, int],
    *,
    failures: Sequence[str] = (),
    deadline_misses: int = 0,
    faults: Mapping[str, int] | None = None,
    protective_stops: int = 0,
    also: str = "",
    logs: str | Path | None = None,
) -> Verdict:
    """The verdict of a run.

    Args:
        violations: the referee's counts by kind (zeros allowed).
        failures: other reasons the run fails (a process that crashed, a stack that did not come up).
        deadline_misses: the control loop's missed deadlines (reported).
        faults: the daemon's faults by code, each a safe stop (reported).
        protective_stops: the robot firmware's protective stops (reported).
        also: more context for the line (e.g. how many commands were judged).
        logs: where the processes' logs are (None: the line says there are none).

    Returns:
        FAIL when any violation or failure, else PASS; the reason names the counts and the logs.
    """
    total = int(sum(violations.values()))
    head = _plural(total, "violation") + (f" ({_counts(violations)})" if total else "")
    if also:
        head += f" {also}"
    parts = [head, *failures]
    acted = []
    if deadline_misses:
        acted.append(_plural(deadline_misses, "deadline miss", "deadline misses"))
    n_faults = int(sum((faults or {}).values()))
    if n_faults:
        acted.append(_plural(n_faults, "fault") + f" ({_counts(faults or {}, codes=True)})")
    if protective_stops:
        acted.append(_plural(protective_stops, "protective stop"))
    if acted:
        why = []
        if deadline_misses:
            why.append("the host was loaded")
        if n_faults:
            why.append("the watchdogs stopped the robot safely")
        if protective_stops:
            why.append("the robot's firmware braked")
        parts.append(", ".join(acted) + " — " + ", ".join(why) + " (reported, not a failure)")
    parts.append(f"logs: {logs}" if logs is not None else "logs: none (an in-process run)")
    return Verdict(passed=total == 0 and not failures, reason="; ".join(parts))
