"""Access control: loopback-only defaults, per-role credentials, and the Zenoh ACLs.

``wmm-qp acl init DIR`` writes each role's config and only its own credentials. The mesh tests
open real Zenoh sessions on loopback from those configs — a sim's and a daemon's (they enforce
the ACLs) and clients' — and show who can authenticate and what each may publish; the
integration tests start the real sim and daemon with them.
"""

from __future__ import annotations

import json
import math
import shutil
import subprocess
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import zenoh
from support.zenoh_acl import config_value, peers, until
from wmm_qp_service import acl
from wmm_qp_service.client import Client
from wmm_qp_service.config import ServiceConfig, load_service_config
from wmm_qp_service.keys import Keys
from wmm_qp_service.processes import isolated_config
from wmm_qp_service.transport import ROLE_CLIENT, ROLE_DAEMON, ROLE_EMBEDDED, ROLE_SIM, session_config
from wmm_qp_tools.cli import main as cli_main

from wmm_qp import ConfigError, default_config_dir

ZENOH_DIR = default_config_dir() / "zenoh"
TEMPLATES = sorted(ZENOH_DIR.glob("acl_*.json5"))
FOLDERS = [r.folder for r in acl.ROLES]
ROLE_OF = {"sim": ROLE_SIM, "daemon": ROLE_DAEMON, "embedded": ROLE_EMBEDDED, "operator": ROLE_CLIENT,
           "viewer": ROLE_CLIENT}
TIMEOUT = 30.0
WAIT = 10.0  # [s] patience for a link, a declaration or a message that must arrive


@pytest.fixture(scope="module")
def creds(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder written by ``acl init`` (short path: it holds the sim's unix socket)."""
    d = tmp_path_factory.mktemp("acl")
    acl.init(d)
    return d


def _cfg(svc: ServiceConfig, creds: Path, folder: str) -> ServiceConfig:
    role = next(r for r in acl.ROLES if r.folder == folder)
    return svc.with_(zenoh={"config": creds / folder / role.config})


def _secrets(creds: Path) -> dict[str, str]:
    return {r.user: (creds / r.folder / r.secret).read_text().strip()
            for r in acl.ROLES if r.user is not None and r.secret is not None}


# --------------------------------------------------------------------------- credentials


def test_acl_templates_exist() -> None:
    assert {p.name for p in TEMPLATES} == {r.config for r in acl.ROLES}


def test_acl_init_gives_each_role_only_its_own_credentials(creds: Path) -> None:
    secret = _secrets(creds)
    assert set(secret) == {"controller", "operator", "viewer"}  # the sim connects nowhere: no secret
    assert len(set(secret.values())) == 3
    assert creds.stat().st_mode & 0o777 == 0o700
    for r in acl.ROLES:
        folder = creds / r.folder
        assert folder.stat().st_mode & 0o777 == 0o700
        names = {p.name for p in folder.iterdir()}
        assert names == {r.config} | {n for n in (r.secret, r.dictionary) if n}
        for name in names - {r.config}:
            assert (folder / name).stat().st_mode & 0o777 == 0o600
        # whose secrets the folder holds: its own, and those of who may connect to it
        held = {u for u, s in secret.items() for p in folder.iterdir() if s in p.read_text()}
        assert held == ({r.user} if r.user else set()) | set(r.admits), r.folder
        if r.dictionary:
            lines = (folder / r.dictionary).read_text().split()
            assert lines == [f"{u}:{secret[u]}" for u in r.admits]
    # the viewer's folder: the viewer's secret and nothing of the controller, operator or sim
    assert {p.name for p in (creds / "viewer").iterdir()} == {"acl_viewer.json5", "viewer.secret"}


@pytest.mark.parametrize("folder", ["sim", "daemon", "embedded"])
def test_a_listener_admits_exactly_the_users_its_acl_names(creds: Path, folder: str) -> None:
    """A user in the dictionary but not in the ACL could connect (default deny, but still); one in
    the ACL but not in the dictionary could not connect at all."""
    role = next(r for r in acl.ROLES if r.folder == folder)
    zc = session_config(_cfg(load_service_config(), creds, folder), ROLE_OF[folder])
    named = {u for s in config_value(zc, "access_control")["subjects"] for u in s.get("usernames") or []}
    assert named == set(role.admits)


def test_acl_init_secrets_are_fresh_and_never_overwritten(tmp_path: Path) -> None:
    acl.init(tmp_path / "a")
    acl.init(tmp_path / "b")
    a, b = _secrets(tmp_path / "a"), _secrets(tmp_path / "b")
    assert all(len(v) >= 43 for v in (*a.values(), *b.values()))  # token_urlsafe(32)
    assert not set(a.values()) & set(b.values())
    with pytest.raises(ConfigError, match="not empty"):
        acl.init(tmp_path / "a")
    assert _secrets(tmp_path / "a") == a


def test_the_repository_ships_no_working_secret() -> None:
    """The configs are templates: every one names a credential file that is not there, and no
    password (or sample dictionary) is tracked or installed."""
    svc = load_service_config()
    for path in TEMPLATES:
        with pytest.raises(ConfigError, match="no such credential file"):
            session_config(svc.with_(zenoh={"config": path}), ROLE_CLIENT)
        usrpwd = json.loads(zenoh.Config.from_file(str(path)).get_json("transport/auth/usrpwd"))
        assert usrpwd["password"] is None or usrpwd["password"].startswith(acl.FILE_PREFIX)
    root = Path(__file__).resolve().parents[2]
    tracked = subprocess.run(["git", "ls-files", "configs"], cwd=root, capture_output=True, text=True,
                             check=True).stdout.split()
    assert tracked and not [f for f in tracked if f.endswith((".secret", ".txt"))]
    pyproject = (root / "pyproject.toml").read_text()
    assert '"share/wmm-qp/configs/zenoh" = ["configs/zenoh/*.json5"]' in pyproject


def _run_cli(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, list[str]]:
    rc = cli_main(list(argv))
    return rc, capsys.readouterr().err.splitlines()


def test_a_missing_or_placeholder_credential_is_a_one_line_cli_error(
        creds: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    viewer = tmp_path / "viewer"
    shutil.copytree(creds / "viewer", viewer)
    cfg, secret = viewer / "acl_viewer.json5", viewer / "viewer.secret"
    argv = ("status", "--zenoh-config", str(cfg), "--timeout", "0.1", *_endpoints(isolated_config()))
    secret.unlink()
    rc, err = _run_cli(capsys, *argv)
    assert rc == 2 and len(err) == 1 and str(secret) in err[0] and "no such credential file" in err[0]
    secret.write_text("change-me-viewer\n")
    secret.chmod(0o600)
    rc, err = _run_cli(capsys, *argv)
    assert rc == 2 and len(err) == 1 and str(secret) in err[0] and "placeholder" in err[0]
    secret.write_text("too-short\n")
    rc, err = _run_cli(capsys, *argv)
    assert rc == 2 and len(err) == 1 and "too short" in err[0]
    secret.write_text((creds / "viewer" / "viewer.secret").read_text())
    secret.chmod(0o644)
    rc, err = _run_cli(capsys, *argv)
    assert rc == 2 and len(err) == 1 and str(secret) in err[0] and "chmod 600" in err[0]
    # a listener's dictionary: the same checks, naming the dictionary file and line (not the secret)
    sim = tmp_path / "sim"
    shutil.copytree(creds / "sim", sim)
    users = sim / "sim_users.txt"
    users.write_text(users.read_text() + "intruder:change-me-intruder\n")
    with pytest.raises(ConfigError, match=r"sim_users\.txt: line 4 \(intruder\): a placeholder") as e:
        session_config(load_service_config().with_(zenoh={"config": sim / "acl_sim.json5"}), ROLE_SIM)
    assert "change-me-intruder" not in str(e.value)
    # an inline sample password (the old configs' kind) is refused too
    inline = tmp_path / "inline.json5"
    inline.write_text('{ transport: { auth: { usrpwd: { user: "viewer", password: "change-me-viewer" } } } }')
    with pytest.raises(ConfigError, match=r"transport\.auth\.usrpwd\.password: a placeholder"):
        session_config(load_service_config().with_(zenoh={"config": inline}), ROLE_CLIENT)


def _endpoints(svc: ServiceConfig) -> tuple[str, ...]:
    return ("--daemon-endpoint", svc.zenoh.daemon_endpoint, "--sim-endpoint", svc.zenoh.sim_endpoint)


def test_acl_init_cli_writes_the_folders(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert cli_main(["acl", "init", str(tmp_path / "d")]) == 0
    out = capsys.readouterr().out
    assert f"wmm-qp serve --zenoh-config {tmp_path / 'd' / 'daemon' / 'acl_daemon.json5'}" in out
    assert sorted(p.name for p in (tmp_path / "d").iterdir()) == sorted(FOLDERS)
    rc, err = _run_cli(capsys, "acl", "init", str(tmp_path / "d"))
    assert rc == 2 and len(err) == 1 and "not empty" in err[0]


# --------------------------------------------------------------------------- session configs


CASES = [(None, r) for r in (ROLE_DAEMON, ROLE_SIM, ROLE_CLIENT)] + [(f, ROLE_OF[f]) for f in FOLDERS]


@pytest.mark.parametrize(("folder", "role"), CASES, ids=[f"{f or 'default'}-{r}" for f, r in CASES])
def test_sessions_bind_loopback_only_and_do_not_scout(creds: Path, folder: str | None, role: str) -> None:
    svc = load_service_config() if folder is None else _cfg(load_service_config(), creds, folder)
    zc = session_config(svc, role)
    assert config_value(zc, "mode") == "peer"
    assert config_value(zc, "scouting/multicast/enabled") is False
    for ep in config_value(zc, "listen/endpoints") + config_value(zc, "connect/endpoints"):
        assert ep.startswith("tcp/127.0.0.1:") or ep == f"unixsock-stream/{creds / acl.SIM_SOCKET}", ep
    if role == ROLE_CLIENT:
        assert config_value(zc, "listen/endpoints") == []  # a client listens nowhere
    assert config_value(zc, "transport/link/tx/lease") <= 1000  # a hung peer is dropped within ~1 s
    # every link an explicit connect: with gossip on, the sim dialled the daemon that had dialled it
    # (two links in one transport); after a frozen sim's one-sided lease expiry the pair can stay
    # split for good (docs/reliability.md, "Gossip is off")
    assert config_value(zc, "scouting/gossip/enabled") is False


@pytest.mark.parametrize("folder", FOLDERS)
def test_acl_configs_authenticate_and_default_deny(creds: Path, folder: str) -> None:
    role = next(r for r in acl.ROLES if r.folder == folder)
    zc = session_config(_cfg(load_service_config(), creds, folder), ROLE_OF[folder])
    usr = config_value(zc, "transport/auth/usrpwd")
    assert usr["user"] == role.user
    if role.user is not None:  # the secret itself, read from its file
        assert usr["password"] == _secrets(creds)[role.user]
    if role.dictionary is None:
        assert usr["dictionary_file"] is None
        assert config_value(zc, "access_control")["enabled"] is False  # a client: listens nowhere
    else:
        assert Path(usr["dictionary_file"]) == creds / folder / role.dictionary
        ac = config_value(zc, "access_control")
        assert ac["enabled"] is True and ac["default_permission"] == "deny"
        assert all(s["zids"] is None for s in ac["subjects"])  # nobody is named by a (public) Zenoh id
    assert config_value(zc, "id") is None  # no fixed Zenoh id


def test_a_daemon_may_not_listen_where_its_acl_trusts_any_peer(creds: Path) -> None:
    """The daemon's ACL takes its unix-socket link for the sim: listening on one would let anyone
    connect there as the sim."""
    svc = _cfg(load_service_config(), creds, "daemon")
    svc = svc.with_(zenoh={"daemon_endpoint": f"unixsock-stream/{creds / 'daemon.sock'}"})
    with pytest.raises(ConfigError, match="may not listen"):
        session_config(svc, ROLE_DAEMON)


def test_an_invalid_zenoh_config_is_a_config_error(tmp_path: Path) -> None:
    bad = tmp_path / "bad.json5"
    bad.write_text("{ mode: 'peer', no_such_section: 1 }")
    with pytest.raises(ConfigError, match="not a valid Zenoh config"):
        session_config(load_service_config().with_(zenoh={"config": bad}), ROLE_DAEMON)


# --------------------------------------------------------------------------- a mesh of sessions


@dataclass
class Mesh:
    """A sim session and a daemon session from the ``acl init`` configs (they enforce the ACLs),
    each with subscribers on every key, a liveliness subscriber and a barrier queryable."""

    svc: ServiceConfig
    creds: Path
    keys: Keys
    sim: zenoh.Session
    daemon: zenoh.Session
    subs: dict[str, Any]
    tokens: dict[str, Any]

    def client(self, folder: str, user: str | None = None) -> zenoh.Session:
        zc = session_config(_cfg(self.svc, self.creds, folder), ROLE_CLIENT)
        if user is not None:
            zc.insert_json5("transport/auth/usrpwd/user", json.dumps(user))
        return zenoh.open(zc)

    def received(self, at: str) -> list[tuple[str, bytes]]:
        out = []
        while (s := self.subs[at].try_recv()) is not None:
            out.append((str(s.key_expr).removeprefix(self.keys.root + "/"), s.payload.to_bytes()))
        return out

    def seen_tokens(self, at: str) -> set[str]:
        out = set()
        while (s := self.tokens[at].try_recv()) is not None:
            if s.kind == zenoh.SampleKind.PUT:
                out.add(str(s.key_expr).removeprefix(self.keys.root + "/"))
        return out


@pytest.fixture(scope="module")
def mesh(creds: Path) -> Iterator[Mesh]:
    svc = isolated_config()
    keys = Keys.of(svc.prefix, svc.robot)
    with zenoh.open(session_config(_cfg(svc, creds, "sim"), ROLE_SIM)) as sim, \
            zenoh.open(session_config(_cfg(svc, creds, "daemon"), ROLE_DAEMON)) as daemon:
        subs, tokens, keep = {}, {}, []
        for name, s in (("sim", sim), ("daemon", daemon)):
            subs[name] = s.declare_subscriber(f"{keys.root}/**", zenoh.handlers.FifoChannel(10_000))
            tokens[name] = s.liveliness().declare_subscriber(f"{keys.root}/**", zenoh.handlers.FifoChannel(1000))
            keep.append(s.declare_queryable(f"{keys.root}/barrier/{name}", lambda q: q.reply(q.key_expr, b"")))
        until(lambda: str(sim.info.zid()) in peers(daemon), WAIT, "the daemon's link to the sim")
        yield Mesh(svc, creds, keys, sim, daemon, subs, tokens)
        for q in keep:
            q.undeclare()


def _barrier(m: Mesh, client: zenoh.Session, at: str) -> None:
    """After a reply from ``at``, everything ``client`` sent there before has been handled (one
    link, one priority, in order), and ``client`` has the declarations ``at`` made at link set-up."""

    def answered() -> bool:
        return any(r.ok is not None for r in client.get(f"{m.keys.root}/barrier/{at}", timeout=1.0))

    until(answered, WAIT, f"a reply from the {at}")


def _put_where_heard(m: Mesh, client: zenoh.Session, tag: str, keys: list[str]) -> None:
    """Put ``<tag>:<key>`` on each key once ``client`` knows the sim's and the daemon's subscribers
    (a message missing at a listener was then dropped by its ACL, not for want of a subscriber),
    then wait until both listeners have handled them."""
    want = {str(m.sim.info.zid()), str(m.daemon.info.zid())}
    until(lambda: want <= peers(client), WAIT, "the client's links")
    for at in ("sim", "daemon"):
        _barrier(m, client, at)
    for k in keys:
        p = client.declare_publisher(f"{m.keys.root}/{k}")
        until(lambda p=p: p.matching_status.matching, WAIT, f"a subscriber known for {k}")
        p.put(f"{tag}:{k}".encode())
        p.undeclare()
    for at in ("sim", "daemon"):
        _barrier(m, client, at)


def _from(got: list[tuple[str, bytes]], tag: str) -> list[str]:
    return sorted(k for k, v in got if v.startswith(f"{tag}:".encode()))


def _tokens_until(m: Mesh, at: str, key: str) -> set[str]:
    """The tokens ``at`` sees until ``key`` is among them."""
    seen: set[str] = set()

    def done() -> bool:
        seen.update(m.seen_tokens(at))
        return key in seen

    until(done, WAIT, f"the token {key} at the {at}")
    return seen


ALL_PUTS = ["cmd", "state", "setpoint", "mode", "sim/box", "obstacles", "status", "telemetry"]


def test_a_viewer_cannot_authenticate_as_the_controller(mesh: Mesh) -> None:
    """The controller's (or operator's) user name with the viewer's secret is refused by the sim (the
    one listener that admits the controller) and by the daemon; the viewer's own gets two links."""
    with mesh.client("viewer") as viewer, mesh.client("viewer", user="controller") as impostor, \
            mesh.client("viewer", user="operator") as impostor2:
        both = {str(mesh.sim.info.zid()), str(mesh.daemon.info.zid())}
        until(lambda: peers(viewer) == both, WAIT, "the viewer's links")
        _barrier(mesh, viewer, "sim")  # the impostors opened together with it and had the same time
        assert peers(impostor) == set() and peers(impostor2) == set()


def test_a_viewer_can_read_but_publish_nothing(mesh: Mesh) -> None:
    with mesh.client("viewer") as viewer:
        _put_where_heard(mesh, viewer, "viewer", ALL_PUTS)
        assert _from(mesh.received("sim"), "viewer") == []
        assert _from(mesh.received("daemon"), "viewer") == []
        # ... while it may read: it receives the state the sim publishes
        states = viewer.declare_subscriber(mesh.keys.state, zenoh.handlers.FifoChannel(100))
        until(lambda: (mesh.sim.put(mesh.keys.state, b"sim:state"), states.try_recv())[1], WAIT, "a state")


def test_the_operator_may_put_setpoint_mode_and_scene_but_not_cmd_or_state(mesh: Mesh) -> None:
    with mesh.client("operator") as op:
        _put_where_heard(mesh, op, "operator", ALL_PUTS)
        assert _from(mesh.received("sim"), "operator") == ["obstacles", "sim/box"]
        assert _from(mesh.received("daemon"), "operator") == ["mode", "obstacles", "setpoint"]


def test_only_the_controller_commands_the_sim_and_only_the_sim_states_the_daemon(mesh: Mesh) -> None:
    """The daemon's cmd reaches the sim (by its user name); the sim's state reaches the daemon over
    the unix socket the daemon dialled (the sim has no user name there); nothing else of theirs."""
    for k in ALL_PUTS:
        mesh.daemon.put(f"{mesh.keys.root}/{k}", f"daemon:{k}".encode())
        mesh.sim.put(f"{mesh.keys.root}/{k}", f"sim:{k}".encode())
    _barrier(mesh, mesh.daemon, "sim")  # the daemon-sim link, both ways
    _barrier(mesh, mesh.sim, "daemon")
    assert _from(mesh.received("sim"), "daemon") == ["cmd"]
    assert _from(mesh.received("daemon"), "sim") == ["state"]


def test_only_their_owners_hold_the_sim_daemon_and_lease_tokens(mesh: Mesh) -> None:
    forged = {"alive/robot", "alive/daemon", "lease/forged"}
    root = mesh.keys.root
    for folder in ("viewer", "operator"):
        with mesh.client(folder) as c:
            first = c.liveliness().declare_token(f"{root}/alive/{folder}-1")
            for at in ("sim", "daemon"):  # the listeners' interest has reached the client
                _tokens_until(mesh, at, f"alive/{folder}-1")
            tokens = [c.liveliness().declare_token(f"{root}/{k}") for k in sorted(forged)]
            last = c.liveliness().declare_token(f"{root}/alive/{folder}-2")
            for at in ("sim", "daemon"):  # declarations on one link arrive in order
                assert not _tokens_until(mesh, at, f"alive/{folder}-2") & forged, (folder, at)
            for t in (first, *tokens, last):
                t.undeclare()
    # the controller's lease and daemon tokens reach the sim ...
    owned = [mesh.daemon.liveliness().declare_token(f"{root}/{k}") for k in ("alive/daemon", "lease/ctl")]
    assert {"alive/daemon", "lease/ctl"} <= _tokens_until(mesh, "sim", "lease/ctl")
    for t in owned:
        t.undeclare()
    # ... the sim's own reaches the daemon, but the sim may not claim the lease or the daemon's
    mesh.seen_tokens("daemon")  # (the daemon's own, just declared, seen locally)
    owned = [mesh.sim.liveliness().declare_token(f"{root}/{k}") for k in ("alive/daemon", "lease/sim", "alive/robot")]
    assert not _tokens_until(mesh, "daemon", "alive/robot") & {"alive/daemon", "lease/sim"}
    for t in owned:
        t.undeclare()


# --------------------------------------------------------------------------- real processes


@pytest.mark.integration
def test_rogue_session_cannot_command(tmp_path_factory: pytest.TempPathFactory, tmp_path: Path) -> None:
    """The real sim and daemon with the ``acl init`` configs: the operator drives them; a viewer
    (valid credentials, no rights) can read, but its mode changes, setpoints and boxes are not
    delivered; a session without credentials gets no link. (Which keys each role may put, cmd and
    state included, is shown key by key by the mesh tests above.)"""
    from wmm_qp_service.processes import Stack

    creds = tmp_path_factory.mktemp("acl")  # its own sim socket (the mesh's sim holds the module's)
    acl.init(creds)
    svc = isolated_config()
    stack = Stack(svc, rate_hz=500.0, log_dir=tmp_path,
                  extra_sim_args=["--zenoh-config", str(creds / "sim" / "acl_sim.json5")],
                  extra_daemon_args=["--zenoh-config", str(creds / "daemon" / "acl_daemon.json5")])
    with stack, Client(_cfg(svc, creds, "operator"), name="operator") as op, \
            Client(_cfg(svc, creds, "viewer"), name="viewer") as rogue:
        # the operator is accepted: the stack runs and obeys its mode change
        assert op.wait_for_daemon(TIMEOUT) is not None
        info = until(lambda: (i := op.info()) is not None and i.status.state_ok and i)
        # (the operator's mode message also resumes a daemon that a fault of a cold first start,
        # kernels still compiling, moved to hold: sent until the daemon tracks)
        until(lambda: op.set_mode("track") or ((i := op.info()) is not None and i.status.mode == "track"))
        # the viewer may read (query the daemon, receive the state) ...
        assert rogue.wait_for_daemon(TIMEOUT) is not None
        assert rogue.wait_state(TIMEOUT) is not None
        before = rogue.info()
        assert before is not None
        # ... but its mode changes, setpoints and boxes go nowhere
        x0 = np.array(info.status.x)
        for k in range(100):
            rogue.set_mode("dm_cartesian")
            rogue.send_setpoint(x0 + np.array([0.1, 0.0, 0.0]))
            if k % 10 == 0:
                time.sleep(0.02)
        rogue.place_box(26.0, 0.65, x0[0] + 0.5, x0[1])  # far ahead: harmless if it got through
        time.sleep(1.0)
        after = op.info()
        assert after is not None and after.status.mode != "dm_cartesian"  # (a fault may hold: not the viewer's)
        assert after.status.accepted["mode"] == before.status.accepted["mode"]
        assert after.status.accepted["setpoint"] == before.status.accepted["setpoint"]
        assert sum(after.status.rejected.values()) == sum(before.status.rejected.values())
        st = op.wait_truth(TIMEOUT)
        assert st is not None and math.isnan(st.box_position)  # nor the box
        # the operator's own setpoints still get through
        n0 = after.status.accepted["setpoint"]
        for _ in range(20):
            op.send_setpoint(x0)
            time.sleep(0.01)
        until(lambda: op.info().status.accepted["setpoint"] > n0)
        # ... and so does its box (sim/box)
        op.place_box(26.0, 0.65, x0[0] + 0.5, x0[1])
        until(lambda: (st := op.wait_truth(0.5)) is not None and math.isfinite(st.box_position))
        # no credentials: no session at all
        with Client(svc, name="anonymous") as anon:  # configs/zenoh/peer.json5: no credentials
            assert anon.wait_for_daemon(3.0) is None
            assert anon.wait_state(1.0) is None
        assert stack.procs["sim"].poll() is None and stack.procs["daemon"].poll() is None


@pytest.mark.integration
def test_acl_stack_connects_whichever_process_starts_first(tmp_path_factory: pytest.TempPathFactory,
                                                          tmp_path: Path) -> None:
    """The daemon up first (its connect to the sim retried): with gossip on, the sim learned the
    daemon from the client, dialled it, and the daemon's own connect was then refused for good."""
    from wmm_qp_service.processes import Stack

    creds = tmp_path_factory.mktemp("acl")  # its own sim socket (the mesh's sim holds the module's)
    acl.init(creds)
    svc = isolated_config()
    stack = Stack(svc, rate_hz=500.0, log_dir=tmp_path,
                  extra_sim_args=["--zenoh-config", str(creds / "sim" / "acl_sim.json5")],
                  extra_daemon_args=["--zenoh-config", str(creds / "daemon" / "acl_daemon.json5")])
    try:
        stack.start_daemon()
        with Client(_cfg(svc, creds, "operator"), name="operator") as op:
            assert op.wait_for_daemon(TIMEOUT) is not None  # the daemon is up, the sim is not
            assert not op.info().status.robot_alive
            stack.start_sim()
            until(lambda: (i := op.info()) is not None and i.status.state_ok and i.status.robot_alive)
    finally:
        stack.stop()
