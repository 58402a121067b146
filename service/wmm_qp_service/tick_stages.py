"""Where a daemon tick's time goes: a stopwatch that splits each tick into named stages.

The daemon (``wmm-qp serve --breakdown FILE``, run by ``wmm-qp bench --only daemon``) calls
:meth:`TickStages.lap` after each stage of its real loop; the time since the previous lap goes
to that stage. Off (the default), the loop calls nothing: each lap is behind one ``is None``
test. A lap costs one clock read and two list operations (~0.2 µs here).
"""

from __future__ import annotations

import json
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

CALL_NONE, CALL_STEP, CALL_SAFE_STOP, CALL_REPEAT = 0, 1, 2, 3
"""What a control tick asked of the controller (``ControlCore.ctl_call``): nothing, ``step``,
``safe_stop``, or nothing but its last command again."""

STAGES: tuple[str, ...] = (
    "poll", "validation", "watchdogs", "ruckig", "step", "publish", "telemetry", "status", "queries",
)
"""The daemon's stages, in tick order: poll and decode of every input (state, modes,
setpoints, liveliness), validation and acceptance (``on_state`` …), the watchdogs and the
stream's bookkeeping (hazards, latch, prediction), Ruckig (smoother and reference),
``ctl.step``, command encode + publish, telemetry, status (its message, 10 Hz), queries."""
POLL, VALIDATION, WATCHDOGS, RUCKIG, STEP, PUBLISH, TELEMETRY, STATUS, QUERIES = range(len(STAGES))
"""Each stage's index in :data:`STAGES` (:meth:`TickStages.lap`'s argument)."""


class TickStages:
    """Accumulates time per stage within a tick; :meth:`end` stores the tick's figures.

    Args:
        names: stage names, in the order of their index in :meth:`lap`.
        capacity: ticks kept (the first ones; later ticks are counted, not stored).
        clock: [ns] monotonic clock.
    """

    def __init__(self, names: Sequence[str] = STAGES, capacity: int = 200_000,
                 clock: Any = time.perf_counter_ns) -> None:
        self.names = tuple(names)
        self.index = {n: i for i, n in enumerate(self.names)}
        self._clock = clock
        self._acc = [0] * len(self.names)
        self._t = 0
        self._t_begin = 0
        self._rows = np.zeros((capacity, len(self.names) + 1), dtype=np.int64)  # + the whole tick
        self.n = 0
        self.dropped = 0

    def begin(self, t_ns: int | None = None) -> None:
        """A tick starts now (or at ``t_ns``, the loop's own start time of it)."""
        self._t = self._t_begin = self._clock() if t_ns is None else t_ns

    def lap(self, i: int) -> None:
        """The time since the previous lap (or :meth:`begin`) was spent in stage ``i``."""
        t = self._clock()
        self._acc[i] += t - self._t
        self._t = t

    def lap_at(self, i: int, t_ns: int) -> None:
        """:meth:`lap` with the time taken elsewhere (``t_ns``, the same clock)."""
        self._acc[i] += t_ns - self._t
        self._t = t_ns

    def discard(self) -> None:
        """Forget this tick (one that published nothing)."""
        self._acc = [0] * len(self.names)

    def end(self) -> None:
        """The tick ended at the last lap: store its stages and its whole time."""
        if self.n < self._rows.shape[0]:
            row = self._rows[self.n]
            row[:-1] = self._acc
            row[-1] = self._t - self._t_begin
            self.n += 1
        else:
            self.dropped += 1
        self._acc = [0] * len(self.names)

    def summary(self) -> dict[str, Any]:
        """{"ticks", "stages": {name: {p50, p99, max, mean} [µs]}, "tick": …, "sum_of_p50"}."""
        rows = self._rows[: self.n].astype(float) / 1e3
        out: dict[str, Any] = {"ticks": self.n, "dropped": self.dropped, "stages": {}}
        for j, name in enumerate((*self.names, "tick")):
            col = rows[:, j]
            s = _summary(col)
            if name == "tick":
                out["tick"] = s
            else:
                out["stages"][name] = s
        out["sum_of_p50"] = round(sum(s["p50"] for s in out["stages"].values() if s["n"]), 2)
        return out

    def write(self, path: str | Path, extra: dict[str, Any] | None = None) -> None:
        """Write :meth:`summary` (and ``extra``) as JSON."""
        data = self.summary() | (extra or {})
        Path(path).write_text(json.dumps(data, indent=1, default=str) + "\n", encoding="utf-8")


def _summary(a: np.ndarray) -> dict[str, float]:
    if a.size == 0:
        return {"p50": float("nan"), "p99": float("nan"), "max": float("nan"), "mean": float("nan"), "n": 0}
    p50, p99 = np.percentile(a, [50.0, 99.0])
    return {"p50": round(float(p50), 2), "p99": round(float(p99), 2), "max": round(float(a.max()), 2),
            "mean": round(float(a.mean()), 2), "n": int(a.size)}
