"""Percentile summaries of timing samples, and a small stopwatch that accumulates pieces."""

from __future__ import annotations

import time
from collections.abc import Sequence

import numpy as np

Summary = dict[str, float]


def summarize_ns(samples_ns: Sequence[int] | np.ndarray) -> Summary:
    """p50, p99, max and mean [µs] of samples in nanoseconds (NaN when empty).

    Args:
        samples_ns: [ns] one duration per tick.
    """
    a = np.asarray(samples_ns, dtype=float) / 1e3
    if a.size == 0:
        nan = float("nan")
        return {"p50": nan, "p99": nan, "max": nan, "mean": nan, "n": 0}
    p50, p99 = np.percentile(a, [50.0, 99.0])
    return {
        "p50": round(float(p50), 2),
        "p99": round(float(p99), 2),
        "max": round(float(a.max()), 2),
        "mean": round(float(a.mean()), 2),
        "n": int(a.size),
    }


class PieceTimer:
    """Accumulates time per named piece within one tick; :meth:`flush` stores the tick's sums.

    Pieces called several times within a tick (e.g. a solve per QP stage) add up.
    """

    def __init__(self, names: Sequence[str]) -> None:
        self.names = tuple(names)
        self._tick: dict[str, int] = dict.fromkeys(self.names, 0)
        self.samples: dict[str, list[int]] = {n: [] for n in self.names}

    def add(self, name: str, ns: int) -> None:
        self._tick[name] += ns

    def pending(self) -> int:
        """[ns] sum of this tick's pieces so far."""
        return sum(self._tick.values())

    def flush(self) -> None:
        for n in self.names:
            self.samples[n].append(self._tick[n])
            self._tick[n] = 0

    def summaries(self) -> dict[str, Summary]:
        return {n: summarize_ns(v) for n, v in self.samples.items()}


now_ns = time.perf_counter_ns
