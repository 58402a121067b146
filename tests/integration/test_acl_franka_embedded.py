"""``wmm-qp driver franka --embedded`` under access control: the FR3's one process (libfranka's
cycle hosting the control core) with the ``embedded`` role's config that ``wmm-qp acl init``
writes, against franky-sim. The operator drives it; the viewer reads but its modes and setpoints
are not delivered and the arm does not move; a session without credentials gets no link; the
driver's referee counts nothing. (``tests/integration/test_acl_embedded.py`` proves the same of
``wmm-qp sim --embedded`` and checks the config key by key.)"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from support.franky_rig import FR3, driver_stack, start_franky_sim
from support.zenoh_acl import drive_to, viewer_attempts
from wmm_qp_service import acl
from wmm_qp_service.client import Client
from wmm_qp_service.config import ServiceConfig

import wmm_qp as w

pytest.importorskip("pylibfranka", reason="needs pylibfranka (pip install 'wmm-qp[franka]')")
pytest.importorskip("franky_sim", reason="needs franky-sim (pip install franky-sim)")

TIMEOUT = 30.0


def _cfg(svc: ServiceConfig, creds: Path, folder: str) -> ServiceConfig:
    return svc.with_(zenoh={"config": creds / folder / f"acl_{folder}.json5"})


def test_the_fr3_s_embedded_process_obeys_the_operator_only(tmp_path: Path) -> None:
    creds = tmp_path / "acl"
    acl.init(creds)
    sim = start_franky_sim(w.load_robot_config(FR3))
    logs = tmp_path / "logs"
    logs.mkdir()
    try:
        args = ["--embedded", "--zenoh-config", str(creds / "embedded" / "acl_embedded.json5")]
        with driver_stack(sim, logs, serve=False, driver_args=args) as (svc, procs), \
                Client(_cfg(svc, creds, "operator"), name="operator") as op, \
                Client(_cfg(svc, creds, "viewer"), name="viewer") as viewer:
            op.wait_ready(90.0, TIMEOUT, exited=lambda: procs["driver"].poll())
            assert op.resume("track", timeout=TIMEOUT)
            # the viewer may read: the process answers it, and it receives the state ...
            assert viewer.wait_for_daemon(TIMEOUT) is not None and viewer.wait_state(TIMEOUT) is not None
            before = op.info()
            assert before is not None and before.status.mode == "track"
            x0, q0 = np.array(before.status.x), sim.q()
            # ... but its mode changes and setpoints (10 cm away) go nowhere
            viewer_attempts(viewer, x0)
            after = op.info()
            assert after is not None and after.status.mode != "dm_cartesian"
            for key in ("mode", "setpoint"):
                assert after.status.accepted.get(key, 0) == before.status.accepted.get(key, 0), key
            assert np.abs(sim.q() - q0).max() < 0.01  # the arm did not move
            # the operator's setpoints (5 cm along x) move it there
            target = x0 + np.array([0.05, 0.0, 0.0])

            drive_to(op, target)
            assert np.abs(sim.q() - q0).max() > 0.02  # the arm moved
            truth = op.wait_truth(TIMEOUT)
            assert truth is not None and sum(truth.violations.values()) == 0, truth.violations
            # no credentials: no link at all
            with Client(svc, name="anonymous") as anonymous:  # configs/zenoh/peer.json5
                assert anonymous.wait_for_daemon(3.0) is None and anonymous.wait_state(1.0) is None
            assert procs["driver"].poll() is None, (logs / "driver.log").read_text()[-2000:]
        assert procs["driver"].returncode == 0, (logs / "driver.log").read_text()[-2000:]
    finally:
        sim.close()
