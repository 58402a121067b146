"""``wmm-qp demo --driver franka --robot-ip IP --json``: the demo's scenario through the Franka
driver against franky-sim (a running robot, in a child process of the test: libfranka's connect
holds the GIL), with the demo's JSON keys and the driver's referee as ``violations``."""

from __future__ import annotations

import json
import re
import subprocess
from pathlib import Path

import pytest

pytest.importorskip("pylibfranka", reason="needs pylibfranka (pip install 'wmm-qp[franka]')")
pytest.importorskip("franky_sim", reason="needs franky-sim (pip install franky-sim)")

from support.franky_rig import FR3, start_franky_sim
from wmm_qp_service.processes import CLI

import wmm_qp as w

pytestmark = [pytest.mark.integration, pytest.mark.slow]


@pytest.mark.parametrize("embedded", [False, True], ids=["driver+daemon", "embedded"])
def test_the_demo_runs_through_the_franka_driver_against_franky_sim(tmp_path: Path, embedded: bool) -> None:
    """Through the driver and a daemon, or (``--embedded``) the driver alone with the control core
    in libfranka's cycle."""
    sim = start_franky_sim(w.load_robot_config(FR3))
    try:
        p = subprocess.run([*CLI, "demo", "--robot-config", str(FR3),
                            "--driver", "franka", "--robot-ip", sim.host, "--duration", "8",
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
        assert out["physics"] == "the robot's own (driver franka)"  # no plant of ours ran
        m = re.match(r"collision rows on \((\d+) self pairs, (\d+) bodies vs the floor", out["collision_summary"])
        assert m is not None and int(m[1]) > 0 and int(m[2]) > 0, out["collision_summary"]  # the FR3's and the table
        assert out["dm_end"] > out["dm_start"], out
        assert sim.shared[15] == 0 and sim.shared[16] == 0, "franky-sim saw a joint past a limit"
    finally:
        sim.close()


def test_driver_and_robot_ip_go_together() -> None:
    p = subprocess.run([*CLI, "demo", "--driver", "franka"],
                       capture_output=True, text=True, timeout=120, stdin=subprocess.DEVNULL)
    assert p.returncode == 2 and "--driver and --robot-ip go together" in p.stderr and "Traceback" not in p.stderr
