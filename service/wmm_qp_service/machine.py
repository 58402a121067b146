"""The machine and library versions the figures were measured on."""

from __future__ import annotations

import os
import platform
from importlib import metadata
from typing import Any

PACKAGES = ("numpy", "numba", "pin", "proxsuite", "osqp", "daqp", "qpsolvers", "pin-pink", "eclipse-zenoh")


def cpu_model() -> str:
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def machine_info() -> dict[str, Any]:
    versions: dict[str, str] = {}
    for p in PACKAGES:
        try:
            versions[p] = metadata.version(p)
        except metadata.PackageNotFoundError:
            versions[p] = "not installed"
    return {
        "nproc": os.cpu_count(),
        "cpu": cpu_model(),
        "python": platform.python_version(),
        "platform": platform.platform(),
        "versions": versions,
        "loadavg": loadavg(),
    }


def loadavg() -> list[float]:
    """The 1, 5 and 15 minute load averages, rounded to 0.01."""
    return [round(x, 2) for x in os.getloadavg()]


_CLK_TCK = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100


def cpu_seconds(pid: int) -> float | None:
    """[s] CPU time (user + system, all threads) a process used so far (Linux ``/proc``);
    None when unknown (no such process, not Linux)."""
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii") as f:
            fields = f.read().rsplit(")", 1)[1].split()  # after the command name (may hold spaces)
    except (OSError, IndexError):
        return None
    return (int(fields[11]) + int(fields[12])) / _CLK_TCK  # utime, stime: fields 14 and 15 of stat(5)


def steal_seconds() -> float | None:
    """[s] CPU time the hypervisor took from this guest since boot, all CPUs (the ``cpu`` line of
    Linux ``/proc/stat``); None when unknown."""
    try:
        with open("/proc/stat", encoding="ascii") as f:
            fields = f.readline().split()
    except OSError:
        return None
    if len(fields) < 9 or fields[0] != "cpu":
        return None
    return int(fields[8]) / _CLK_TCK  # user nice system idle iowait irq softirq steal: the 8th


class CpuMeter:
    """Each process's CPU share over a window: CPU time used (user + system, every thread of
    the process, from ``/proc/<pid>/stat``, resolution 1/``SC_CLK_TCK`` s) divided by the wall
    time, in % of one core (200 % = both cores of this machine).

    Args:
        pids: {name: pid}.
        clock: wall clock [s] (monotonic).
    """

    def __init__(self, pids: dict[str, int], clock: Any = None) -> None:
        import time

        self.pids = dict(pids)
        self._clock = clock or time.monotonic
        self._t0 = self._clock()
        self._cpu0 = {n: cpu_seconds(p) for n, p in self.pids.items()}

    def shares(self) -> dict[str, float | None]:
        """{name: % of one core since the meter started} (None: unknown)."""
        wall = self._clock() - self._t0
        out: dict[str, float | None] = {}
        for n, p in self.pids.items():
            c0, c1 = self._cpu0[n], cpu_seconds(p)
            out[n] = None if c0 is None or c1 is None or wall <= 0 else round(100.0 * (c1 - c0) / wall, 1)
        return out


CPU_HOW = ("CPU time (user + system, all threads) from /proc/<pid>/stat over the window, divided by "
           "the window's wall time: % of one core")
