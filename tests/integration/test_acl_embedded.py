"""Access control of the embedded process (``wmm-qp sim --embedded``): its ``acl init`` role.

``wmm-qp acl init DIR`` writes ``DIR/embedded/``: the one process in place of the sim and the
daemon listens for the operator and the viewer (their secrets' dictionary) and connects nowhere.
Real Zenoh sessions on loopback, one from that config enforcing its ACL, show who gets a link
and what each may publish key by key; then the real process with it: the operator drives, the
viewer reads but moves nothing, a session without credentials gets no link.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import zenoh
from support.zenoh_acl import config_value, drive_to, peers, until, viewer_attempts
from wmm_qp_service import acl
from wmm_qp_service.client import Client
from wmm_qp_service.config import ServiceConfig
from wmm_qp_service.keys import Keys
from wmm_qp_service.processes import Stack, isolated_config
from wmm_qp_service.transport import ROLE_CLIENT, ROLE_EMBEDDED, session_config
from wmm_qp_tools.cli import main as cli_main

TIMEOUT = 30.0
WAIT = 10.0  # [s] patience for a link, a declaration or a message that must arrive
CONFIG = "acl_embedded.json5"
USERS = "embedded_users.txt"
ALL_PUTS = ["cmd", "state", "sim/truth", "setpoint", "mode", "obstacles", "sim/box", "gripper", "status",
            "telemetry"]
OPERATOR_PUTS = ["gripper", "mode", "obstacles", "setpoint", "sim/box"]  # sorted


def _cfg(svc: ServiceConfig, creds: Path, folder: str, config: str | None = None) -> ServiceConfig:
    return svc.with_(zenoh={"config": creds / folder / (config or f"acl_{folder}.json5")})


def _secret(creds: Path, user: str, folder: str | None = None) -> str:
    return (creds / (folder or user) / f"{user}.secret").read_text().strip()


@pytest.fixture(scope="module")
def creds(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder written by ``acl init``."""
    d = tmp_path_factory.mktemp("acl")
    acl.init(d)
    return d


# --------------------------------------------------------------------------- its folder and config


def test_acl_init_gives_the_embedded_process_its_clients_secrets_and_no_own(creds: Path) -> None:
    folder = creds / "embedded"
    assert (folder / CONFIG).is_file(), "acl init wrote no config for the embedded process"
    assert folder.stat().st_mode & 0o777 == 0o700
    assert {p.name for p in folder.iterdir()} == {CONFIG, USERS}  # no secret: it connects nowhere
    assert (folder / USERS).stat().st_mode & 0o777 == 0o600
    assert (folder / USERS).read_text().split() == [f"{u}:{_secret(creds, u)}" for u in ("operator", "viewer")]
    assert _secret(creds, "controller", "daemon") not in (folder / USERS).read_text()


def test_the_embedded_config_listens_on_tcp_connects_nowhere_and_names_its_two_users(creds: Path) -> None:
    svc = isolated_config()
    zc = session_config(_cfg(svc, creds, "embedded"), ROLE_EMBEDDED)
    assert config_value(zc, "listen/endpoints") == [svc.zenoh.daemon_endpoint, svc.zenoh.sim_endpoint]
    assert all(ep.startswith("tcp/127.0.0.1:") for ep in config_value(zc, "listen/endpoints"))
    assert config_value(zc, "connect/endpoints") == []  # no sim to dial: the core writes its command in memory
    assert config_value(zc, "scouting/multicast/enabled") is False
    assert config_value(zc, "scouting/gossip/enabled") is False
    usr = config_value(zc, "transport/auth/usrpwd")
    assert usr["user"] is None and usr["password"] is None
    assert Path(usr["dictionary_file"]) == creds / "embedded" / USERS
    ac = config_value(zc, "access_control")
    assert ac["enabled"] is True and ac["default_permission"] == "deny"
    # every subject is a user name it checks: none is taken on its link's protocol or a Zenoh id
    assert all(s["usernames"] and not s.get("link_protocols") and s["zids"] is None for s in ac["subjects"])
    assert {u for s in ac["subjects"] for u in s["usernames"]} == {"operator", "viewer"}


def test_acl_init_says_how_to_run_the_embedded_process(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert cli_main(["acl", "init", str(tmp_path / "d")]) == 0
    out = capsys.readouterr().out
    assert f"wmm-qp sim --embedded --zenoh-config {tmp_path / 'd' / 'embedded' / CONFIG}" in out


# --------------------------------------------------------------------------- sessions on loopback


@dataclass
class Embedded:
    """A session from the embedded config (it enforces the ACL) with a subscriber on every key, a
    liveliness subscriber and a barrier queryable."""

    svc: ServiceConfig
    creds: Path
    keys: Keys
    session: zenoh.Session
    sub: Any
    tokens: Any

    def client(self, folder: str | None, user: str | None = None, password: str | None = None) -> zenoh.Session:
        """A client session from ``folder``'s config (None: no credentials), user and password
        replaced if given."""
        svc = self.svc if folder is None else _cfg(self.svc, self.creds, folder)
        zc = session_config(svc, ROLE_CLIENT)
        if user is not None:
            zc.insert_json5("transport/auth/usrpwd/user", json.dumps(user))
        if password is not None:
            zc.insert_json5("transport/auth/usrpwd/password", json.dumps(password))
        return zenoh.open(zc)

    def received(self, tag: str) -> list[str]:
        """The keys of the samples received so far whose payload ``tag`` sent, sorted."""
        out = []
        while (s := self.sub.try_recv()) is not None:
            if s.payload.to_bytes().startswith(f"{tag}:".encode()):
                out.append(str(s.key_expr).removeprefix(self.keys.root + "/"))
        return sorted(out)

    def tokens_until(self, key: str) -> set[str]:
        """The tokens seen until ``key`` is among them."""
        seen: set[str] = set()

        def done() -> bool:
            while (s := self.tokens.try_recv()) is not None:
                if s.kind == zenoh.SampleKind.PUT:
                    seen.add(str(s.key_expr).removeprefix(self.keys.root + "/"))
            return key in seen

        until(done, WAIT, f"the token {key}")
        return seen

    def barrier(self, client: zenoh.Session) -> None:
        """After a reply, everything ``client`` sent before has been handled (one link, one
        priority, in order), and ``client`` has the declarations made at link set-up."""

        def answered() -> bool:
            return any(r.ok is not None for r in client.get(f"{self.keys.root}/barrier", timeout=1.0))

        until(answered, WAIT, "a reply from the embedded session")


@pytest.fixture(scope="module")
def embedded(creds: Path) -> Iterator[Embedded]:
    svc = isolated_config()
    keys = Keys.of(svc.prefix, svc.robot)
    with zenoh.open(session_config(_cfg(svc, creds, "embedded"), ROLE_EMBEDDED)) as s:
        sub = s.declare_subscriber(f"{keys.root}/**", zenoh.handlers.FifoChannel(10_000))
        tokens = s.liveliness().declare_subscriber(f"{keys.root}/**", zenoh.handlers.FifoChannel(1000))
        q = s.declare_queryable(f"{keys.root}/barrier", lambda q: q.reply(q.key_expr, b""))
        yield Embedded(svc, creds, keys, s, sub, tokens)
        q.undeclare()


def test_only_the_operator_and_the_viewer_get_a_link(embedded: Embedded) -> None:
    """A split daemon's credentials (the controller's real secret), the viewer's secret under the
    operator's name, and no credentials at all: no link; the viewer's own: one."""
    controller = _secret(embedded.creds, "controller", "daemon")
    with embedded.client("viewer") as viewer, embedded.client(None) as anonymous, \
            embedded.client("operator", user="controller", password=controller) as daemon, \
            embedded.client("viewer", user="operator") as impostor:
        zid = str(embedded.session.info.zid())
        until(lambda: peers(viewer) == {zid}, WAIT, "the viewer's link")
        embedded.barrier(viewer)  # the others opened together with it and had the same time
        assert peers(anonymous) == set() and peers(daemon) == set() and peers(impostor) == set()


def _put_where_heard(e: Embedded, client: zenoh.Session, tag: str) -> None:
    """Put ``<tag>:<key>`` on each key of :data:`ALL_PUTS` once ``client`` knows the embedded
    session's subscriber (a message missing there was dropped by its ACL, not for want of a
    subscriber), then wait until it has handled them."""
    until(lambda: str(e.session.info.zid()) in peers(client), WAIT, "the client's link")
    e.barrier(client)
    for k in ALL_PUTS:
        p = client.declare_publisher(f"{e.keys.root}/{k}")
        until(lambda p=p: p.matching_status.matching, WAIT, f"a subscriber known for {k}")
        p.put(f"{tag}:{k}".encode())
        p.undeclare()
    e.barrier(client)


def test_the_operator_puts_its_inputs_the_viewer_nothing_and_nobody_cmd_or_state(embedded: Embedded) -> None:
    """The operator's setpoint, mode, obstacles, box and gripper get through; its cmd, state,
    sim/truth, status and telemetry do not; nothing of the viewer's does."""
    with embedded.client("operator") as op:
        _put_where_heard(embedded, op, "operator")
        assert embedded.received("operator") == OPERATOR_PUTS
    with embedded.client("viewer") as viewer:
        _put_where_heard(embedded, viewer, "viewer")
        assert embedded.received("viewer") == []


def test_nobody_brings_in_the_sim_daemon_or_lease_token(embedded: Embedded) -> None:
    forged = {"alive/robot", "alive/daemon", "lease/forged"}
    root = embedded.keys.root
    for folder in ("viewer", "operator"):
        with embedded.client(folder) as c:
            first = c.liveliness().declare_token(f"{root}/alive/{folder}-1")
            embedded.tokens_until(f"alive/{folder}-1")  # the listener's interest has reached the client
            tokens = [c.liveliness().declare_token(f"{root}/{k}") for k in sorted(forged)]
            last = c.liveliness().declare_token(f"{root}/alive/{folder}-2")
            # declarations on one link arrive in order
            assert not embedded.tokens_until(f"alive/{folder}-2") & forged, folder
            for t in (first, *tokens, last):
                t.undeclare()


# --------------------------------------------------------------------------- the real process


@pytest.mark.integration
def test_the_embedded_process_obeys_the_operator_only(creds: Path, tmp_path: Path) -> None:
    """``wmm-qp sim --embedded --zenoh-config DIR/embedded/acl_embedded.json5``: the operator puts it
    in track and its setpoints move the robot; the viewer can read, but its mode changes and
    setpoints are not delivered (the counters do not move, the mode stays, the robot stays where
    it is); a session without credentials gets no link; the referee counts nothing."""
    svc = isolated_config()
    stack = Stack(svc, rate_hz=500.0, log_dir=tmp_path, embedded=True,
                  extra_sim_args=["--zenoh-config", str(creds / "embedded" / CONFIG)])
    with stack, Client(_cfg(stack.svc, creds, "operator"), name="operator") as op, \
            Client(_cfg(stack.svc, creds, "viewer"), name="viewer") as viewer:
        op.wait_ready(90.0, TIMEOUT, exited=stack.exited)  # a process that exits ends the wait at once
        assert op.resume("track", timeout=TIMEOUT)
        # the viewer may read: query the process, receive the state and the truth ...
        assert viewer.wait_for_daemon(TIMEOUT) is not None and viewer.wait_state(TIMEOUT) is not None
        before, truth = op.info(), viewer.wait_truth(TIMEOUT)
        assert before is not None and before.status.mode == "track" and truth is not None
        x0, ee0 = np.array(before.status.x), np.array(truth.ee_true)
        # ... but its mode changes and setpoints (10 cm away) go nowhere
        viewer_attempts(viewer, x0)
        after, truth = op.info(), op.wait_truth(TIMEOUT)
        assert after is not None and truth is not None
        assert after.status.mode != "dm_cartesian"  # (a fault may hold it: not the viewer's doing)
        for key in ("mode", "setpoint"):
            assert after.status.accepted.get(key, 0) == before.status.accepted.get(key, 0), key
        assert sum(after.status.rejected.values()) == sum(before.status.rejected.values())
        assert np.linalg.norm(np.array(truth.ee_true) - ee0) < 0.005  # the robot did not move
        # the operator's setpoints (5 cm along x) move it there
        target = x0 + np.array([0.05, 0.0, 0.0])

        drive_to(op, target)
        truth = op.wait_truth(TIMEOUT)
        assert truth is not None and truth.ee_true[0] - ee0[0] > 0.04  # the robot moved
        assert sum(truth.violations.values()) == 0, truth.violations
        # no credentials: no link at all
        with Client(stack.svc, name="anonymous") as anonymous:  # configs/zenoh/peer.json5
            assert anonymous.wait_for_daemon(3.0) is None and anonymous.wait_state(1.0) is None
        assert stack.exited() is None
    assert stack.stop() == {"embedded": 0}
