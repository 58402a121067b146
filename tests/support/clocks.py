"""Fake clocks for timing logic tested without real time."""

from __future__ import annotations

WALL0 = 1.7e9  # [s] the fake wall clock's epoch


class Clock:
    """A fake monotonic clock; each read advances it 1 ns (a spin on it ends), sleeps jump."""

    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        self.t += 1e-9
        return self.t

    def sleep(self, s: float) -> None:
        self.t += max(0.0, s)

    def wall(self) -> float:
        return WALL0 + self.t


class FakeClock:
    """Advances a microsecond per read (so polling terminates) and by the slept time."""

    def __init__(self) -> None:
        self.t = 100.0
        self.slept = 0.0

    def __call__(self) -> float:
        self.t += 1e-6
        return self.t

    def sleep(self, s: float) -> None:
        assert s >= 0.0
        self.slept += s
        self.t += s
