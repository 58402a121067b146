"""``wmm-qp demo --driver franka --robot-ip IP --json``: the demo's scenario through the Franka
driver against franky-sim (a running robot, in a child process of the test: libfranka's connect
holds the GIL), with the demo's JSON keys and the driver's referee as ``violations``."""

from __future__ import annotations

import json
import multiprocessing as mp
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytest.importorskip("pylibfranka", reason="needs pylibfranka (pip install 'wmm-qp[franka]')")
pytest.importorskip("franky_sim", reason="needs franky-sim (pip install franky-sim)")

from test_franka_driver import FR3, N_SHARED, _serve

import wmm_qp as w

pytestmark = [pytest.mark.integration, pytest.mark.slow]


@pytest.mark.parametrize("embedded", [False, True], ids=["driver+daemon", "embedded"])
def test_the_demo_runs_through_the_franka_driver_against_franky_sim(tmp_path: Path, embedded: bool) -> None:
    """Through the driver and a daemon, or (``--embedded``) the driver alone with the control core
    in libfranka's cycle."""
    a = w.load_robot_config(FR3).arm
    ctx = mp.get_context("spawn")
    shared, hostname, stop = ctx.Array("d", N_SHARED), ctx.Array("c", 64), ctx.Event()
    sim = ctx.Process(target=_serve, args=(shared, hostname, stop, a.position_lower.tolist(),
                                            a.position_upper.tolist(), a.velocity_max.tolist()), daemon=True)
    sim.start()
    try:
        t0 = time.monotonic()
        while not hostname.value and time.monotonic() - t0 < 60:
            time.sleep(0.1)
        assert hostname.value, "franky-sim did not start"
        p = subprocess.run([sys.executable, "-m", "wmm_qp_service.cli", "demo", "--robot-config", str(FR3),
                            "--driver", "franka", "--robot-ip", hostname.value.decode(), "--duration", "8",
                            "--json", "--logs", str(tmp_path), *(["--embedded"] if embedded else [])],
                           capture_output=True, text=True, timeout=600, stdin=subprocess.DEVNULL)
        assert p.stdout.strip(), p.stderr
        out = json.loads(p.stdout)
        assert {"violations", "violations_total", "loop", "phases", "faults", "verdict", "exit_codes"} <= set(out)
        procs = {"driver": 0} if embedded else {"driver": 0, "daemon": 0}
        assert set(out["exit_codes"]) == set(procs), out["exit_codes"]  # no sim was started
        assert out["exit_codes"] == procs, (out["exit_codes"], p.stderr)
        assert out["loop"]["trigger"] == ("embedded" if embedded else "rate")
        assert out["violations_total"] == 0, out["violations"]
        assert out["ee_error_max"] is None  # no ground truth from a real robot
        assert out["dm_end"] > out["dm_start"], out
        assert shared[15] == 0 and shared[16] == 0, "franky-sim saw a joint past a limit"
    finally:
        stop.set()
        sim.join(10)
        if sim.is_alive():
            sim.kill()


def test_driver_and_robot_ip_go_together() -> None:
    p = subprocess.run([sys.executable, "-m", "wmm_qp_service.cli", "demo", "--driver", "franka"],
                       capture_output=True, text=True, timeout=120, stdin=subprocess.DEVNULL)
    assert p.returncode == 2 and "--driver and --robot-ip go together" in p.stderr and "Traceback" not in p.stderr
