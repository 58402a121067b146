"""Stressors for the reliability drill: CPU hogs, a disk writer, and random freezes of a process.

Each is a context manager that starts its load on entry and removes it on exit (a frozen process
is always continued). They load this machine only: the drill (``benchmarks/reliability/drill.py``)
and the stress test run the real sim and daemon under them and count what the sim's referee
counts, which must stay 0 whatever the timing (docs/reliability.md "The stress drill").
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import os
import random
import signal
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path


def _spin(stop: mp.synchronize.Event) -> None:  # pragma: no cover - runs in a child process
    x = 0
    while not stop.is_set():
        for _ in range(100_000):
            x += 1


class CpuHogs:
    """``n`` processes that spin on the CPU (default: one per core)."""

    def __init__(self, n: int | None = None) -> None:
        self.n = n or os.cpu_count() or 1
        self._stop = mp.get_context("spawn").Event()
        self._procs: list[mp.process.BaseProcess] = []

    def _spinners(self) -> list[tuple[Callable[..., None], tuple[object, ...]]]:
        """Each hog process's target and arguments."""
        return [(_spin, (self._stop,))] * self.n

    def __enter__(self) -> CpuHogs:
        ctx = mp.get_context("spawn")
        self._procs = [ctx.Process(target=f, args=args, daemon=True) for f, args in self._spinners()]
        for p in self._procs:
            p.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        for p in self._procs:
            p.join(timeout=5)
            if p.is_alive():
                p.kill()


def _spin_rt(stop: mp.synchronize.Event, core: int, busy: float, idle: float) -> None:  # pragma: no cover
    os.sched_setaffinity(0, {core})
    with contextlib.suppress(PermissionError):  # without the privilege: an ordinary hog on the core
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(50))
    while not stop.is_set():
        t = time.monotonic() + busy
        while time.monotonic() < t:
            pass
        time.sleep(idle)


class RealtimeHogs(CpuHogs):
    """One process per core, pinned, at ``SCHED_FIFO`` 50 (the priority the sim and the daemon
    take): busy ``busy`` [s], then asleep ``idle`` [s], over and over. A second stack's real-time
    threads, as two stacks on one host meet them: the ordinary threads (Zenoh's, franky-sim's)
    get no CPU while a hog runs, the real-time ones share it in turn."""

    def __init__(self, busy: float, idle: float) -> None:
        super().__init__()
        self.busy, self.idle = busy, idle

    def _spinners(self) -> list[tuple[Callable[..., None], tuple[object, ...]]]:
        return [(_spin_rt, (self._stop, c, self.busy, self.idle)) for c in sorted(os.sched_getaffinity(0))]


class DiskWriter:
    """A thread that writes ``chunk_mb`` files and fsyncs them, over and over (page cache and I/O
    pressure: the kind of load a package install or a log rotation puts on a host).

    Args:
        folder: where the files go (a fresh temporary folder, removed on exit, if None).
        chunk_mb: [MiB] size of each file.
    """

    def __init__(self, folder: Path | None = None, chunk_mb: int = 64) -> None:
        self.folder = folder
        self.chunk_mb = chunk_mb
        self.written_mb = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._tmp: tempfile.TemporaryDirectory[str] | None = None

    def _run(self, folder: Path) -> None:
        block = os.urandom(1 << 20)
        i = 0
        while not self._stop.is_set():
            path = folder / f"drill_{i % 2}.bin"
            with open(path, "wb") as f:
                for _ in range(self.chunk_mb):
                    if self._stop.is_set():
                        break
                    f.write(block)
                    self.written_mb += 1
                f.flush()
                os.fsync(f.fileno())
            i += 1

    def __enter__(self) -> DiskWriter:
        if self.folder is None:
            self._tmp = tempfile.TemporaryDirectory(prefix="wmm-qp-drill-")
            folder = Path(self._tmp.name)
        else:
            folder = self.folder
        self._thread = threading.Thread(target=self._run, args=(folder,), daemon=True)
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=30)
        if self._tmp is not None:
            self._tmp.cleanup()


@dataclass
class Freezer:
    """Freezes a process (SIGSTOP) for random times, then continues it (SIGCONT), in a thread.

    Attributes:
        pid: returns the pid to freeze now (None: not running; skipped).
        min_s, max_s: [s] each freeze lasts uniform(min_s, max_s).
        gap_s: [s] (low, high) of the uniform wait between freezes.
        seed: seed of the draws.
        freezes: the freezes done, as (duration [s]) in order.
    """

    pid: Callable[[], int | None]
    min_s: float = 0.005
    max_s: float = 0.5
    gap_s: tuple[float, float] = (0.3, 1.5)
    seed: int = 0
    freezes: list[float] = field(default_factory=list)

    def __post_init__(self) -> None:
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._rng = random.Random(self.seed)

    def _run(self) -> None:
        while not self._stop.wait(self._rng.uniform(*self.gap_s)):
            pid = self.pid()
            if pid is None:
                continue
            d = self._rng.uniform(self.min_s, self.max_s)
            try:
                os.kill(pid, signal.SIGSTOP)
            except ProcessLookupError:
                continue
            try:
                time.sleep(d)
            finally:
                with contextlib.suppress(ProcessLookupError):
                    os.kill(pid, signal.SIGCONT)
            self.freezes.append(d)

    def __enter__(self) -> Freezer:
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5)


def child_pid(parent: int, role: str) -> int | None:
    """The pid of ``parent``'s child process running ``wmm_qp_service.cli <role>`` (the demo's
    and the soak's sim or daemon), or None."""
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
            ppid = int(stat.rsplit(")", 1)[1].split()[1])
            if ppid != parent:
                continue
            argv = (entry / "cmdline").read_bytes().split(b"\0")
        except (OSError, ValueError, IndexError):
            continue
        if b"wmm_qp_service.cli" in argv and role.encode() in argv:
            return int(entry.name)
    return None


CONDITIONS = ("cpu", "disk", "freeze_sim", "freeze_daemon", "all")
"""The drill's conditions: CPU hogs on every core; a disk writer; the sim frozen at random; the
daemon frozen at random; all of them at once."""


@contextlib.contextmanager
def stressed(condition: str, parent: Callable[[], int | None], seed: int = 0,
             freeze: tuple[float, float] = (0.005, 0.5)) -> Iterator[dict[str, object]]:
    """Run the body under ``condition`` (one of :data:`CONDITIONS`, or "none").

    Args:
        condition: what load to apply.
        parent: the pid of the process whose children are the sim and the daemon (None: not
            started yet).
        seed: seed of the freezes.
        freeze: [s] (min, max) of one freeze.

    Yields:
        a dict filled on exit with what was applied (``freezes_sim``, ``freezes_daemon``: the
        freezes' durations; ``disk_mb``).
    """
    if condition not in (*CONDITIONS, "none"):
        raise ValueError(f"unknown condition {condition!r}; one of {', '.join(CONDITIONS)} or none")
    out: dict[str, object] = {}
    with contextlib.ExitStack() as stack:
        if condition in ("cpu", "all"):
            stack.enter_context(CpuHogs())
        disk = stack.enter_context(DiskWriter()) if condition in ("disk", "all") else None
        freezers: dict[str, Freezer] = {}
        for role in ("sim", "daemon"):
            if condition in (f"freeze_{role}", "all"):
                def pid(role: str = role) -> int | None:
                    p = parent()
                    return child_pid(p, "serve" if role == "daemon" else role) if p is not None else None
                freezers[role] = stack.enter_context(
                    Freezer(pid, freeze[0], freeze[1], seed=seed + (role == "daemon")))
        try:
            yield out
        finally:
            stack.close()
            for role, f in freezers.items():
                out[f"freezes_{role}"] = list(f.freezes)
            if disk is not None:
                out["disk_mb"] = disk.written_mb
