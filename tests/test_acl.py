"""Access control: loopback-only defaults, and the Zenoh ACL configs keep rogue sessions out.

The integration test starts the real sim and daemon with ``configs/zenoh/acl_{sim,daemon}.json5``
and shows that an authenticated client without rights (``viewer``) can read but its mode
changes, setpoints, robot commands and boxes are not delivered, and that a session without
credentials (or with a wrong password) cannot connect at all.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import msgspec
import numpy as np
import pytest
import zenoh
from wmm_qp_service.client import Client
from wmm_qp_service.config import ServiceConfig, load_service_config
from wmm_qp_service.protocol import CommandMsg, StateMsg, encode
from wmm_qp_service.transport import ROLE_CLIENT, ROLE_DAEMON, ROLE_SIM, session_config

from wmm_qp import default_config_dir

ZENOH_DIR = default_config_dir() / "zenoh"
ACL_FILES = sorted(ZENOH_DIR.glob("acl_*.json5"))
TIMEOUT = 30.0


def _get(zc: zenoh.Config, key: str) -> Any:
    return json.loads(zc.get_json(key))


def _configs() -> list[tuple[str, ServiceConfig]]:
    svc = load_service_config()
    out = [("default", svc)]
    out += [(p.name, svc.with_(zenoh={"config": p})) for p in ACL_FILES]
    return out


def test_acl_files_exist() -> None:
    names = {p.name for p in ACL_FILES}
    assert {"acl_sim.json5", "acl_daemon.json5", "acl_operator.json5", "acl_viewer.json5"} <= names


@pytest.mark.parametrize(("name", "svc"), _configs(), ids=[n for n, _ in _configs()])
@pytest.mark.parametrize("role", [ROLE_DAEMON, ROLE_SIM, ROLE_CLIENT])
def test_sessions_bind_loopback_only_and_do_not_scout(name: str, svc: ServiceConfig, role: str) -> None:
    zc = session_config(svc, role)
    assert _get(zc, "mode") == "peer"
    assert _get(zc, "scouting/multicast/enabled") is False
    eps = _get(zc, "listen/endpoints") + _get(zc, "connect/endpoints")
    for ep in eps:
        assert ep.startswith("tcp/127.0.0.1:"), ep
    if role == ROLE_CLIENT:
        assert _get(zc, "listen/endpoints") == []  # a client listens nowhere
    assert _get(zc, "transport/link/tx/lease") <= 1000  # a hung peer is dropped within ~1 s


@pytest.mark.parametrize("path", ACL_FILES, ids=[p.name for p in ACL_FILES])
def test_acl_configs_authenticate_and_default_deny(path: Path) -> None:
    zc = session_config(load_service_config().with_(zenoh={"config": path}), ROLE_DAEMON)
    usr = _get(zc, "transport/auth/usrpwd")
    assert usr["user"] and usr["password"]
    assert Path(usr["dictionary_file"]).is_file()  # resolved relative to the config file
    acl = _get(zc, "access_control")
    assert acl["default_permission"] == "deny"
    if path.name in ("acl_sim.json5", "acl_daemon.json5"):
        assert acl["enabled"] is True


def _until(pred: Callable[[], Any], timeout: float = TIMEOUT) -> Any:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if v := pred():
            return v
        time.sleep(0.05)
    raise AssertionError(f"condition not met within {timeout} s")


@pytest.mark.integration
def test_rogue_session_cannot_command(tmp_path: Path) -> None:
    from wmm_qp_service.processes import Stack, isolated_config

    svc = isolated_config()
    stack = Stack(svc, rate_hz=500.0, log_dir=tmp_path,
                  extra_sim_args=["--zenoh-config", str(ZENOH_DIR / "acl_sim.json5")],
                  extra_daemon_args=["--zenoh-config", str(ZENOH_DIR / "acl_daemon.json5")])
    operator = svc.with_(zenoh={"config": ZENOH_DIR / "acl_operator.json5"})
    viewer = svc.with_(zenoh={"config": ZENOH_DIR / "acl_viewer.json5"})
    with stack, Client(operator, name="operator") as op, Client(viewer, name="viewer") as rogue:
        # the operator is accepted: the stack runs and obeys its mode change
        assert op.wait_for_daemon(TIMEOUT) is not None
        info = _until(lambda: (i := op.info()) is not None and i.status.state_ok and i)
        op.set_mode("track")
        _until(lambda: op.info().status.mode == "track")
        # the viewer may read (query the daemon, receive the state) ...
        assert rogue.wait_for_daemon(TIMEOUT) is not None
        assert rogue.wait_state(TIMEOUT) is not None
        before = rogue.info()
        assert before is not None
        # ... but its mode changes, setpoints and robot commands go nowhere
        x0 = np.array(info.status.x)
        assert op.session is not None
        states = op.session.declare_subscriber(op.keys.state, zenoh.handlers.FifoChannel(100_000))
        forged = encode(CommandMsg(robot=svc.robot, seq=10**9, wheel_speeds=[5.0] * 4, arm_rates=[0.5] * 7))
        for k in range(100):
            rogue.set_mode("dm_cartesian")
            rogue.send_setpoint(x0 + np.array([0.1, 0.0, 0.0]))
            rogue.put_raw("cmd", forged)
            rogue.put_raw("state", b"\xc1garbage")
            if k % 10 == 0:
                time.sleep(0.02)
        rogue.place_box(26.0, 0.65, x0[0] + 0.5, x0[1])  # far ahead: harmless if it got through
        time.sleep(1.0)
        after = op.info()
        assert after is not None and after.status.mode == "track"
        assert after.status.accepted["mode"] == before.status.accepted["mode"]
        assert after.status.accepted["setpoint"] == before.status.accepted["setpoint"]
        assert sum(after.status.rejected.values()) == sum(before.status.rejected.values())
        seen = []  # every state the sim published meanwhile: the forged command never applied
        while (smp := states.try_recv()) is not None:
            seen.append(msgspec.msgpack.decode(smp.payload.to_bytes(), type=StateMsg))
        assert len(seen) > 100
        assert max(m.cmd_seq for m in seen) < 10**9 and not any(m.stale_stop for m in seen)
        assert all(math.isnan(m.box_position) for m in seen)  # nor the forged box
        # the operator's own setpoints still get through
        n0 = after.status.accepted["setpoint"]
        for _ in range(20):
            op.send_setpoint(x0)
            time.sleep(0.01)
        _until(lambda: op.info().status.accepted["setpoint"] > n0)
        # ... and so does its box (sim/box)
        op.place_box(26.0, 0.65, x0[0] + 0.5, x0[1])
        _until(lambda: (st := op.wait_state(0.5)) is not None and math.isfinite(st.box_position))
        # no credentials, or a wrong password: no session at all
        anonymous = svc  # configs/zenoh/peer.json5: no credentials
        with Client(anonymous, name="anonymous") as anon:
            assert anon.wait_for_daemon(3.0) is None
            assert anon.wait_state(1.0) is None
        assert stack.procs["sim"].poll() is None and stack.procs["daemon"].poll() is None


def test_an_invalid_zenoh_config_is_a_config_error(tmp_path: Path) -> None:
    from wmm_qp import ConfigError

    bad = tmp_path / "bad.json5"
    bad.write_text("{ mode: 'peer', no_such_section: 1 }")
    with pytest.raises(ConfigError, match="not a valid Zenoh config"):
        session_config(load_service_config().with_(zenoh={"config": bad}), ROLE_DAEMON)


@pytest.mark.integration
def test_acl_stack_connects_whichever_process_starts_first(tmp_path: Path) -> None:
    """The daemon up first (its connect to the sim retried): with gossip on, the sim learned the
    daemon from the client, dialled it, and the daemon's own connect was then refused for good."""
    from wmm_qp_service.processes import Stack, isolated_config

    svc = isolated_config()
    stack = Stack(svc, rate_hz=500.0, log_dir=tmp_path,
                  extra_sim_args=["--zenoh-config", str(ZENOH_DIR / "acl_sim.json5")],
                  extra_daemon_args=["--zenoh-config", str(ZENOH_DIR / "acl_daemon.json5")])
    operator = svc.with_(zenoh={"config": ZENOH_DIR / "acl_operator.json5"})
    try:
        stack.start_daemon()
        with Client(operator, name="operator") as op:
            assert op.wait_for_daemon(TIMEOUT) is not None  # the daemon is up, the sim is not
            assert not op.info().status.sim_alive
            stack.start_sim()
            _until(lambda: (i := op.info()) is not None and i.status.state_ok and i.status.sim_alive)
    finally:
        stack.stop()
