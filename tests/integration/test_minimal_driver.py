"""A third driver, written from docs/drivers.md and docs/protocol.md alone
(``examples/minimal_driver/driver.py``: a kinematic robot of its own), passes every check of
``wmm-qp contract``: the contract is enough to write a driver the kit accepts."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from wmm_qp_service.processes import isolated_config
from wmm_qp_tools.contract import NAMES

import wmm_qp as w

pytestmark = pytest.mark.integration

DRIVER = Path(__file__).resolve().parents[2] / "examples" / "minimal_driver" / "driver.py"
TOOLS = (sys.executable, "-P", "-m", "wmm_qp_tools.cli")


def test_the_minimal_driver_passes_every_check_of_the_contract(tmp_path: Path) -> None:
    svc = isolated_config(robot=w.load_robot_config())
    endpoints = ["--daemon-endpoint", svc.zenoh.daemon_endpoint, "--sim-endpoint", svc.zenoh.sim_endpoint]
    with open(tmp_path / "driver.log", "w") as log:
        driver = subprocess.Popen([sys.executable, str(DRIVER), "--prefix", svc.prefix, "--robot", svc.robot,
                                   *endpoints], stdin=subprocess.DEVNULL, stdout=log, stderr=log)
    try:
        out = subprocess.run([*TOOLS, "contract", "--prefix", svc.prefix, "--robot", svc.robot, *endpoints,
                              "--json", "--wait", "20"],
                             capture_output=True, text=True, timeout=120, stdin=subprocess.DEVNULL)
    finally:
        driver.send_signal(signal.SIGINT)
        try:
            code = driver.wait(20)
        except subprocess.TimeoutExpired:
            driver.kill()
            code = None
    log_text = (tmp_path / "driver.log").read_text()
    assert out.returncode == 0, out.stdout + out.stderr + log_text
    verdict = json.loads(out.stdout.strip().splitlines()[-1])
    assert verdict["passed"] is True and list(verdict["checks"]) == list(NAMES)
    failed = {name: c["detail"] for name, c in verdict["checks"].items() if not c["passed"]}
    assert not failed, json.dumps(failed, indent=1)
    assert code == 0, log_text                       # SIGINT: brake to rest, exit 0
    assert "stopped at t = " in log_text and "Traceback" not in log_text
