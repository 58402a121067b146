"""The recording's hook against the attacks its claims are about: a writer that stops (the control
thread must not wait for it, and the file must say what was lost), a host killed without closing
(the writer must still finish the file), a tick the hook cannot read (it must not raise)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

pytest.importorskip("mcap")
pytest.importorskip("rosbags")

from wmm_qp_service.recording.reader import RecordingReader

import wmm_qp as w

ROWS = 4096  # the smallest ring


def _core():  # type: ignore[no-untyped-def]
    from wmm_qp_service.config import load_service_config
    from wmm_qp_service.daemon import ControlCore

    robot = w.load_robot_config()
    cfg = w.load_controller_config().with_(collision={"enabled": False})
    return ControlCore(load_service_config().with_robot(robot), cfg, robot)


def _read(path: Path) -> tuple[list[dict], list[dict], RecordingReader]:  # type: ignore[type-arg]
    import msgspec

    rd = RecordingReader(path)
    ticks, events = [], []
    for topic, _, data in rd.messages({"/wmm/tick", "/wmm/events"}):
        (ticks if topic == "/wmm/tick" else events).append(msgspec.json.decode(data))
    return ticks, events, rd


def test_a_stopped_writer_never_holds_the_control_thread_and_the_file_counts_the_loss(tmp_path: Path) -> None:
    from wmm_qp_service.recording.journal import TickJournal, recording_meta

    core = _core()
    path = tmp_path / "stall.mcap"
    j = TickJournal(path, recording_meta(core, "test", "rate"), core.robot.n_arm, core.robot.n_wheels, rows=ROWS)
    n = 3 * ROWS
    os.kill(j._proc.pid, signal.SIGSTOP)  # the writer stalls: a disk that hangs, a machine starved
    try:
        for k in range(n):  # would hang here if the hook waited for the writer
            core.tick(k * 0.001)
            j.tick(core, None, k, k * 0.001, 0.0)
    finally:
        os.kill(j._proc.pid, signal.SIGCONT)
    summary = j.close(n)
    ticks, events, rd = _read(path)
    assert summary["dropped"] > 0 and summary["dropped"] + len(ticks) == n
    assert [t["tick"] for t in ticks] == list(range(n - len(ticks), n))  # the newest kept, in order
    assert any("ticks lost" in e["data"].get("note", "") for e in events)
    assert rd.end is not None and int(rd.end["dropped"]) == summary["dropped"]


def test_a_host_killed_without_closing_still_gets_its_file(tmp_path: Path) -> None:
    path = tmp_path / "killed.mcap"
    code = textwrap.dedent(f"""
        import os, signal, sys
        sys.path.insert(0, {str(Path(__file__).parent)!r})
        from test_recording_journal import _core
        from wmm_qp_service.recording.journal import TickJournal, recording_meta
        core = _core()
        j = TickJournal({str(path)!r}, recording_meta(core, "test", "rate"), core.robot.n_arm, core.robot.n_wheels,
                        rows={ROWS})
        for k in range(300):
            core.tick(k * 0.001)
            j.tick(core, None, k, k * 0.001, 0.0)
        os.kill(os.getpid(), signal.SIGKILL)  # no close(): a crash
    """)
    r = subprocess.run([sys.executable, "-P", "-c", code], capture_output=True, text=True, timeout=300)
    assert r.returncode == -signal.SIGKILL, r.stderr
    end = time.monotonic() + 120
    while time.monotonic() < end:  # the orphaned writer drains the ring and closes the file
        rd = RecordingReader(path)
        list(rd.messages({"/nothing"}))
        if rd.end is not None:
            break
        time.sleep(0.5)
    ticks, _, rd = _read(path)
    assert rd.error is None and rd.end is not None and "without closing" in rd.end["ended"]
    assert [t["tick"] for t in ticks] == list(range(300))


def test_a_tick_the_hook_cannot_read_is_a_note_not_an_exception(tmp_path: Path) -> None:
    from wmm_qp_service.recording.journal import TickJournal, recording_meta

    core = _core()
    path = tmp_path / "odd.mcap"
    j = TickJournal(path, recording_meta(core, "test", "rate"), core.robot.n_arm, core.robot.n_wheels, rows=ROWS)
    core.tick(0.0)
    j.tick(core, None, 0, 0.0, 0.0)

    class Broken:  # a state message with the wrong number of joints
        q_base, q_arm, v_arm, wheel_speeds = [0.0] * 3, [0.0] * 2, [0.0] * 2, [0.0] * 4

    core.state_msg = Broken()  # type: ignore[assignment]
    j.tick(core, None, 1, 0.001, 0.0)  # must not raise
    j.close(2)
    ticks, events, _ = _read(path)
    assert [t["tick"] for t in ticks] == [0]
    assert any("tick 1 not recorded" in e["data"].get("note", "") for e in events)


def test_the_bench_times_the_hook_and_every_tick_reaches_the_file() -> None:
    from wmm_qp_tools.bench.record import journal_cost

    r = journal_cost(300, w.load_robot_config(), w.load_controller_config())
    assert (r["ticks"], r["recorded"], r["dropped"]) == (300, 300, 0)
    assert r["journal_us"]["p50"] > 0 and r["tick_us"]["p50"] > 0
    assert r["journal_over_tick_p50"] == round(r["journal_us"]["p50"] / r["tick_us"]["p50"], 4)


@pytest.mark.parametrize("argv", [
    ["serve", "--record", "/nonexistent/dir/x.mcap"],
    ["serve", "--record", "x.mcap", "--split-size", "-1"],
    ["serve", "--split-time", "5"],
    ["sim", "--record", "x.mcap"],
    ["record", "x.mcap", "--duration", "0"],
    ["replay", "GARBAGE"],
    ["plot", "GARBAGE"],
    ["replay", "/nonexistent.mcap"],
])
def test_bad_input_is_one_line_and_exit_2(argv: list[str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    from wmm_qp_tools import cli as tools_cli

    monkeypatch.chdir(tmp_path)
    (tmp_path / "GARBAGE").write_bytes(b"not an mcap file\n")
    assert tools_cli.main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "error" in err and "Traceback" not in err, err


def test_a_killed_writer_leaves_a_file_readable_up_to_its_last_chunk(tmp_path: Path) -> None:
    from wmm_qp_service.recording.journal import TickJournal, recording_meta

    core = _core()
    path = tmp_path / "writer_killed.mcap"
    j = TickJournal(path, recording_meta(core, "test", "rate"), core.robot.n_arm, core.robot.n_wheels, rows=ROWS)
    for k in range(2000):
        core.tick(k * 0.001)
        j.tick(core, None, k, k * 0.001, 0.0)
    end = time.monotonic() + 120
    while path.stat().st_size < 30_000 and time.monotonic() < end:  # a chunk or two written
        time.sleep(0.05)
    os.kill(j._proc.pid, signal.SIGKILL)
    summary = j.close(2000)
    assert "died" in summary["error"]
    ticks, _, rd = _read(path)
    assert rd.error is not None and rd.end is None  # cut short, said in one line
    assert ticks and [t["tick"] for t in ticks] == list(range(len(ticks)))  # every tick up to the cut
