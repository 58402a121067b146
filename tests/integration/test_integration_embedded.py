"""``wmm-qp sim --embedded`` as a process on loopback: the sim and the control core in one cycle,
with every client speaking the same keys and messages as to a split sim and daemon; the lease
refuses a second controller. No timing asserts."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from support.live import TIMEOUT, cli, until
from wmm_qp_service.client import Client
from wmm_qp_service.processes import Stack, _service_args, free_port, isolated_config
from wmm_qp_service.teleop import stream_circle

pytestmark = pytest.mark.integration


def test_one_process_serves_every_client_and_holds_the_lease(tmp_path: Path) -> None:
    report = tmp_path / "cycle.json"
    stack = Stack(isolated_config(), rate_hz=1000.0, log_dir=tmp_path, embedded=True,
                  extra_sim_args=["--cycle-report", str(report)])
    try:
        stack.start()
        with Client(stack.svc, name="test", telemetry=True) as c:
            assert c.wait_for_daemon(3 * TIMEOUT) is not None, "the embedded process did not answer"
            info = until(lambda: (i := c.info()) is not None and i.status.state_ok and i)
            assert info.status.loop.trigger == "embedded" and info.status.loop.rate_hz == 1000.0
            assert info.status.collision  # the rows are on by default
            st = until(lambda: c.wait_state(2.0))
            assert st.lease == info.status.lease == info.status.lease_holder  # the robot obeys its own core
            # a second controller for the same robot is refused while the embedded core holds the lease
            other = stack.svc.with_(zenoh={"daemon_endpoint": f"tcp/127.0.0.1:{free_port()}"})
            r = cli("serve", *_service_args(other), timeout=120.0)
            assert r.returncode == 3, r.stderr
            assert f"is already controlled by daemon {info.status.lease}" in r.stderr and "Traceback" not in r.stderr
            # the operator's side: mode, setpoints, telemetry, status, as with two processes
            c.set_mode("track")
            until(lambda: (i := c.info()) is not None and i.status.mode == "track")
            x0 = np.array(c.info().status.x)
            stream_circle(c, x0, 3.0)
            tel: list[Any] = c.telemetry()
            # it tracked; a deadline fault on a loaded host may brake it (safe_stop), never an error status
            statuses = {m.status for m in tel}
            assert "ok" in statuses and statuses <= {"ok", "damped", "safe_stop"}, statuses
            assert all(m.state_seq >= 0 for m in tel[-50:])  # every command from a fresh state
            r = cli("status", "--json", *_service_args(stack.svc), timeout=60.0)
            assert r.returncode == 0, r.stderr
            status = json.loads(r.stdout)["status"]
            assert status["loop"]["trigger"] == "embedded" and status["lease"] == info.status.lease
            print("faults under this host's load:", status["faults"])  # a fault may hold it (safe whatever the timing)
            tr = until(lambda: c.wait_truth(2.0))
            assert sum(tr.violations.values()) == 0, tr.violations
    finally:
        codes = stack.stop()
    assert codes == {"embedded": 0}
    rep = json.loads(report.read_text())
    assert rep["ticks"] > 1000 and rep["decimation"] == 1 and rep["gc"]["enabled"]
