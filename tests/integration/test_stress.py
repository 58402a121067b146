"""Safety under load: the real sim and daemon (``wmm-qp demo``) while CPU hogs load every core, a
writer fsyncs files, and both processes are frozen (SIGSTOP/SIGCONT) at random. It asserts
safety only, whatever the timing: the sim's referee counts 0. Faults, misses and safe stops are
the watchdogs doing their job and are not asserted (``benchmarks/reliability/drill.py`` runs the
same for minutes per condition; docs/reliability.md "The stress drill")."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from wmm_qp_service.processes import CLI
from wmm_qp_tools.stress import CpuHogs, Freezer, child_pid, stressed

pytestmark = [pytest.mark.integration, pytest.mark.slow]


def test_the_demo_under_cpu_hogs_disk_writes_and_random_freezes_counts_no_violation(tmp_path: Path) -> None:
    argv = [*CLI, "demo", "--json", "--duration", "12",
            "--logs", str(tmp_path)]
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, stdin=subprocess.DEVNULL)
    with stressed("all", parent=lambda: proc.pid, seed=7) as applied:
        out, _ = proc.communicate(timeout=600)
    summary = json.loads(out.decode())
    sim_log = (tmp_path / "sim.log").read_text(errors="replace")
    referee = [ln for ln in sim_log.splitlines() if "sim: referee:" in ln]
    assert summary["violations_total"] == 0, (summary["violations"], referee[:5])
    assert not referee, referee[:5]
    assert summary["loop"]["ticks"] > 0
    # the drill did what it says: both processes were frozen while the demo ran
    assert applied["freezes_sim"] and applied["freezes_daemon"], applied


def test_the_embedded_demo_under_cpu_hogs_disk_writes_and_random_freezes_counts_no_violation(tmp_path: Path) -> None:
    """``wmm-qp demo --embedded``: one process, the robot and its controller in one cycle, frozen
    at random (the robot runs every step it missed when continued: its firmware brakes past the
    command timeout), under CPU hogs and a disk writer: the referee counts 0."""
    argv = [*CLI, "demo", "--embedded", "--json", "--duration", "10",
            "--logs", str(tmp_path)]
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, stdin=subprocess.DEVNULL)
    with stressed("all", parent=lambda: proc.pid, seed=11) as applied:
        out, _ = proc.communicate(timeout=600)
    summary = json.loads(out.decode())
    referee = [ln for ln in (tmp_path / "embedded.log").read_text(errors="replace").splitlines()
               if "sim: referee:" in ln]
    assert summary["violations_total"] == 0, (summary["violations"], referee[:5])
    assert not referee, referee[:5]
    assert summary["embedded"] and summary["exit_codes"] == {"embedded": 0}
    assert summary["loop"]["trigger"] == "embedded" and summary["loop"]["ticks"] > 0
    assert applied["freezes_sim"] and not applied["freezes_daemon"], applied  # the one process was frozen


def test_the_freezer_stops_and_continues_a_process() -> None:
    """The drill's freezer really freezes (the process's state is 'T' while frozen) and always
    continues what it froze."""
    proc = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    try:
        seen = set()
        with Freezer(lambda: proc.pid, 0.2, 0.2, gap_s=(0.05, 0.05)) as f:
            import time
            end = time.monotonic() + 1.0
            while time.monotonic() < end:
                seen.add(Path(f"/proc/{proc.pid}/stat").read_text().rsplit(")", 1)[1].split()[0])
                time.sleep(0.01)
        assert "T" in seen and f.freezes
        state = Path(f"/proc/{proc.pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
        assert state != "T"
    finally:
        proc.kill()
        proc.wait()


def test_child_pid_finds_the_demo_s_processes_by_role() -> None:
    assert child_pid(1, "no-such-role") is None
    with CpuHogs(1) as hogs:
        assert hogs.n == 1
