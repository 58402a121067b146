"""Zenoh's I/O threads at the loop's real-time priority: a process whose loop is SCHED_FIFO opens
its session so that every Zenoh thread (those the open starts, and the ones started later for a
link) runs one priority below the loop, and its own thread gets its scheduling back; the FR3
driver asks for the sim config's priority (libfranka sets none under RealtimeConfig.kIgnore).

The Zenoh runtime is one per process: each case runs in a fresh interpreter.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

# A peer session opened with the given priority, a second process's session that connects to it
# and publishes (so links and their rx/tx threads start after the open), then every thread's
# policy and priority by name, and the opening thread's own.
PROBE = textwrap.dedent("""
    import json, os, subprocess, sys, time
    from wmm_qp_service.config import load_service_config
    from wmm_qp_service.processes import free_port
    from wmm_qp_service.transport import ROLE_SIM, open_session

    prio = int(sys.argv[1])
    port = free_port()
    svc = load_service_config(None).with_(zenoh={"sim_endpoint": f"tcp/127.0.0.1:{port}"})
    got = []
    with open_session(svc, ROLE_SIM, prio) as s:
        sub = s.declare_subscriber("probe/x", lambda sample: got.append(1))
        peer = subprocess.Popen([sys.executable, "-c", (
            "import time, zenoh, json; c = zenoh.Config(); "
            "c.insert_json5('scouting/multicast/enabled', 'false'); "
            f"c.insert_json5('connect/endpoints', json.dumps(['tcp/127.0.0.1:{port}'])); "
            "s = zenoh.open(c); p = s.declare_publisher('probe/x'); "
            "[(p.put(b'x'), time.sleep(0.01)) for _ in range(300)]; s.close()")])
        t_end = time.monotonic() + 20
        while len(got) < 20 and time.monotonic() < t_end:
            time.sleep(0.05)
        threads = {}
        for tid in os.listdir("/proc/self/task"):
            name = open(f"/proc/self/task/{tid}/comm").read().strip()
            if int(tid) != os.getpid():
                threads.setdefault(name, []).append(
                    [os.sched_getscheduler(int(tid)), os.sched_getparam(int(tid)).sched_priority])
        peer.kill()
        sub.undeclare()
    print(json.dumps({"received": len(got), "threads": threads,
                      "caller": [os.sched_getscheduler(0), os.sched_getparam(0).sched_priority]}))
""")


def _fifo_permitted() -> bool:
    try:
        before = os.sched_getscheduler(0), os.sched_getparam(0)
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))
        os.sched_setscheduler(0, *before)
        return True
    except (AttributeError, OSError):
        return False


def _probe(priority: int) -> dict:
    r = subprocess.run([sys.executable, "-c", PROBE, str(priority)], capture_output=True, text=True, timeout=60,
                       cwd=Path(__file__).resolve().parents[2])
    assert r.returncode == 0, r.stderr[-2000:]
    return json.loads(r.stdout.strip().splitlines()[-1])


def _zenoh_threads(out: dict) -> dict[str, list[list[int]]]:
    # Zenoh's runtime pools: app, acc, net, rx, tx (named "<pool>-<n>")
    return {n: p for n, p in out["threads"].items() if n.split("-")[0] in ("app", "acc", "net", "rx", "tx")}


@pytest.mark.skipif(not _fifo_permitted(), reason="SCHED_FIFO not permitted here (needs root or CAP_SYS_NICE)")
def test_a_session_opened_at_a_priority_runs_every_zenoh_thread_there_and_gives_the_caller_its_own_back() -> None:
    out = _probe(7)
    assert out["received"] >= 20, out  # the link came up: its rx thread exists
    zt = _zenoh_threads(out)
    assert any(n.startswith("rx-") for n in zt), zt  # a thread started for the link, after the open
    for name, policies in zt.items():
        assert all(p == [os.SCHED_FIFO, 7] for p in policies), (name, policies)
    assert out["caller"] == [os.SCHED_OTHER, 0]


def test_a_session_opened_without_a_priority_leaves_zenoh_threads_at_normal_scheduling() -> None:
    out = _probe(0)
    zt = _zenoh_threads(out)
    assert zt and all(p == [os.SCHED_OTHER, 0] for ps in zt.values() for p in ps), zt


def test_io_priority_is_one_below_the_loop_and_never_raises_a_normal_loop() -> None:
    from wmm_qp_service.transport import io_priority

    assert [io_priority(p) for p in (0, 1, 2, 50, 99)] == [0, 1, 1, 49, 98]


class _Started(Exception):
    """Raised by the fake FrankaDriver: what ``wmm-qp driver franka`` asked for, without a robot."""


@pytest.mark.parametrize(("flags", "expected"), [([], 50), (["--rt-priority", "0"], 0), (["--rt-priority", "7"], 7)])
def test_driver_franka_asks_for_the_sim_configs_priority_or_the_flags(
        monkeypatch: pytest.MonkeyPatch, flags: list[str], expected: int) -> None:
    import wmm_qp_service.drivers.franka as franka
    from wmm_qp_service.commands import driver
    from wmm_qp_tools.cli import build_parser

    def fake_driver(*args: object, rt_priority: int = 0, **kw: object) -> None:
        raise _Started(rt_priority)

    monkeypatch.setattr(franka, "FrankaDriver", fake_driver)
    args = build_parser("driver").parse_args(["driver", "franka", "--robot-ip", "127.0.0.1", *flags])
    with pytest.raises(_Started) as e:
        driver.run(args)
    assert e.value.args == (expected,)


def test_driver_franka_refuses_a_priority_out_of_range_in_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    from wmm_qp_service.commands import driver
    from wmm_qp_tools.cli import build_parser

    args = build_parser("driver").parse_args(["driver", "franka", "--robot-ip", "127.0.0.1", "--rt-priority", "100"])
    assert driver.run(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["wmm-qp driver franka: error: --rt-priority must be in [0, 99]"]
