"""Remote operation on a real network: two hosts made of network namespaces and a veth pair
(iproute2, as root). The robot host runs two robot stacks (sim + daemon, each under the ACL of
`wmm-qp acl init`) and a Zenoh router (a zenoh-python session in router mode) listening on TLS;
the console host runs consoles with the remote users' own credentials: the operator's console
lists both robots and drives the one it chose; a viewer's console cannot move the robot.

Skips, saying why, where namespaces cannot be made (not root, no `ip`, no openssl)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import uuid
from pathlib import Path

import pytest
from support.console_helpers import wait_for
from wmm_qp_service.processes import CLI

pytestmark = [pytest.mark.integration, pytest.mark.slow]

TESTS = Path(__file__).resolve().parents[1]  # the folder that holds the package support


def _run(*cmd: str, check: bool = True) -> subprocess.CompletedProcess[str]:
    return subprocess.run(list(cmd), capture_output=True, text=True, timeout=60, check=check, stdin=subprocess.DEVNULL)


def _netns_unavailable() -> str | None:
    if os.geteuid() != 0:
        return "network namespaces need root"
    for tool in ("ip", "openssl"):
        if shutil.which(tool) is None:
            return f"{tool} missing (iproute2, openssl)"
    probe = f"wmmprobe{uuid.uuid4().hex[:6]}"
    r = _run("ip", "netns", "add", probe, check=False)
    if r.returncode != 0:
        return f"cannot make a network namespace here: {r.stderr.strip()}"
    _run("ip", "netns", "del", probe, check=False)
    return None


def _certs(d: Path, ip: str) -> None:
    """A CA and the router's certificate for ``ip`` (subjectAltName), with openssl."""
    d.mkdir(mode=0o700)
    ossl = ["openssl"]
    _run(*ossl, "req", "-x509", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:P-256", "-nodes", "-days", "2",
         "-subj", "/CN=wmm-test-ca", "-keyout", str(d / "ca.key"), "-out", str(d / "ca.crt"))
    _run(*ossl, "req", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:P-256", "-nodes", "-subj", "/CN=router.wmm",
         "-keyout", str(d / "router.key"), "-out", str(d / "router.csr"))
    ext = d / "san.ext"
    ext.write_text(f"subjectAltName=IP:{ip}\nextendedKeyUsage=serverAuth\n")
    _run(*ossl, "x509", "-req", "-in", str(d / "router.csr"), "-CA", str(d / "ca.crt"), "-CAkey", str(d / "ca.key"),
         "-CAcreateserial", "-days", "2", "-extfile", str(ext), "-out", str(d / "router.crt"))


def _copy_secret(src: Path, dst: Path) -> None:
    shutil.copy(src, dst)
    dst.chmod(0o600)


def _json5_with(template: Path, out: Path, replace: dict[str, str]) -> None:
    text = template.read_text()
    for a, b in replace.items():
        assert a in text, a
        text = text.replace(a, b)
    out.write_text(text)


def test_console_drives_the_chosen_robot_through_a_tls_router_and_a_viewer_cannot(tmp_path: Path) -> None:
    why = _netns_unavailable()
    if why:
        pytest.skip(why)
    pytest.importorskip("viser")
    from wmm_qp_service.acl import init

    import wmm_qp as w

    tag = uuid.uuid4().hex[:6]
    robot_ns, console_ns = f"wmmR{tag}", f"wmmC{tag}"
    sub = 200 + int(tag[:2], 16) % 50
    robot_ip, console_ip = f"10.{sub}.77.1", f"10.{sub}.77.2"
    procs: list[subprocess.Popen[bytes]] = []
    _run("ip", "netns", "add", robot_ns)
    _run("ip", "netns", "add", console_ns)
    try:
        _run("ip", "link", "add", f"vr{tag}", "type", "veth", "peer", "name", f"vc{tag}")
        _run("ip", "link", "set", f"vr{tag}", "netns", robot_ns)
        _run("ip", "link", "set", f"vc{tag}", "netns", console_ns)
        for ns, dev, ip in ((robot_ns, f"vr{tag}", robot_ip), (console_ns, f"vc{tag}", console_ip)):
            _run("ip", "-n", ns, "addr", "add", f"{ip}/24", "dev", dev)
            _run("ip", "-n", ns, "link", "set", dev, "up")
            _run("ip", "-n", ns, "link", "set", "lo", "up")
        assert _run("ip", "netns", "exec", console_ns, "ping", "-c", "1", "-W", "5", robot_ip,
                    check=False).returncode == 0 or shutil.which("ping") is None

        # credentials: the stacks' (one acl init, the second stack a copy: its own sim socket),
        # the remote users' (another acl init: operator and viewer with their own secrets), TLS
        stacks = tmp_path / "s1"
        init(stacks)
        shutil.copytree(stacks, tmp_path / "s2", symlinks=True)
        remote = tmp_path / "remote"
        init(remote)
        _certs(tmp_path / "tls", robot_ip)
        rdir = tmp_path / "router"
        rdir.mkdir(mode=0o700)
        _copy_secret(stacks / "operator" / "operator.secret", rdir / "operator.secret")
        _copy_secret(remote / "daemon" / "daemon_users.txt", rdir / "remote_users.txt")
        zdir = w.default_config_dir() / "zenoh"
        _json5_with(zdir / "router_tls.json5", rdir / "router.json5", {
            '"tls/0.0.0.0:7450"': f'"tls/{robot_ip}:7450"',
            '"router.crt"': json.dumps(str(tmp_path / "tls" / "router.crt")),
            '"router.key"': json.dumps(str(tmp_path / "tls" / "router.key"))})
        for user in ("operator", "viewer"):
            _json5_with(zdir / "remote_console.json5", remote / user / "remote.json5", {
                "ROUTER_ADDRESS": robot_ip, '"ca.crt"': json.dumps(str(tmp_path / "tls" / "ca.crt")),
                'user: "operator", password: "file:operator.secret"':
                    f'user: "{user}", password: "file:{user}.secret"'})

        py = list(CLI)
        # (no empty entry: an empty PYTHONPATH entry is the working directory, the checkout's root,
        # whose wmm_qp would shadow the installed one, with another numba cache, cold in CI)
        path = os.pathsep.join(p for p in (str(TESTS), os.environ.get("PYTHONPATH", "")) if p)
        env = dict(os.environ, PYTHONUNBUFFERED="1", PYTHONPATH=path)
        prefix = f"wmmremote{tag}"

        def spawn(name: str, ns: str, argv: list[str]) -> subprocess.Popen[bytes]:
            log = open(tmp_path / f"{name}.log", "wb")  # noqa: SIM115
            p = subprocess.Popen(["ip", "netns", "exec", ns, *argv], stdin=subprocess.DEVNULL, stdout=log,
                                 stderr=log, env=env)
            procs.append(p)
            return p

        connect = []
        for k, folder in ((1, stacks), (2, tmp_path / "s2")):
            sp, dp = 17500 + 10 * k, 17501 + 10 * k
            svc = ["--prefix", prefix, "--robot", f"r{k}", "--sim-endpoint", f"tcp/127.0.0.1:{sp}",
                   "--daemon-endpoint", f"tcp/127.0.0.1:{dp}"]
            # at half the shipped rates: two stacks at 1 kHz / 500 Hz, each sim and daemon
            # SCHED_FIFO at ~45 % of a core, took both cores from the consoles' start (28 s, 35 s)
            spawn(f"sim{k}", robot_ns, [*py, "sim", *svc, "--rate", "500",
                                         "--zenoh-config", str(folder / "sim" / "acl_sim.json5")])
            spawn(f"daemon{k}", robot_ns, [*py, "serve", *svc, "--rate", "250", "--zenoh-config",
                                            str(folder / "daemon" / "acl_daemon.json5")])
            connect += ["--connect", f"tcp/127.0.0.1:{sp}", "--connect", f"tcp/127.0.0.1:{dp}"]
        router = spawn("router", robot_ns, [sys.executable, "-P", "-m", "wmm_qp_service.console.router",
                                            "--zenoh-config", str(rdir / "router.json5"), *connect])
        wait_for("the router up", lambda: "up" in (tmp_path / "router.log").read_text() or router.poll() is not None)
        assert router.poll() is None, (tmp_path / "router.log").read_text()

        r = subprocess.run(["ip", "netns", "exec", console_ns, sys.executable, "-P", "-m", "support.remote_scenario",
                            prefix, str(remote / "operator" / "remote.json5"), str(remote / "viewer" / "remote.json5"),
                            str(tmp_path)], capture_output=True, text=True, timeout=600, env=env,
                           stdin=subprocess.DEVNULL)
        print(r.stderr[-3000:])  # the scenario's progress, each step's time (shown with -s or on failure)
        assert r.returncode == 0, r.stderr[-3000:]
        out = json.loads(r.stdout.strip().splitlines()[-1])
        assert f"{prefix}/r1" in out["robots_seen_by_probe"] and f"{prefix}/r2" in out["robots_seen_by_probe"]
        assert "robot r2" in out["console_line"] and "r1, r2" in out["console_line"], out["console_line"]
        assert out["operator_drove_r2"] and out["r2_operator"].startswith("console-")
        assert out["r1_moved_mm"] < 2.0                      # the other robot was not driven
        assert out["viewer_console_attached"]
        assert out["viewer_setpoints_accepted"] == 0         # the router's ACL dropped the viewer's setpoints
        assert out["viewer_moved_r1_mm"] < 2.0
    finally:
        for p in procs:
            if p.poll() is None:
                p.send_signal(2)
        for p in procs:
            try:
                p.wait(timeout=15)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait(timeout=5)
        _run("ip", "netns", "del", robot_ns, check=False)
        _run("ip", "netns", "del", console_ns, check=False)
