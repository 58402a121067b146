"""``wmm-qp contract`` against running drivers: the reference sim passes every check; each mutant
driver (``tests/support/contract_mutants.py``: the sim with exactly one duty of docs/drivers.md
broken) fails exactly the check of that duty, exit 1; a wrong robot id or prefix, a running
daemon and bad arguments get one line naming the problem."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest
from wmm_qp_service.processes import CLI, isolated_config
from wmm_qp_tools.contract import NAMES

import wmm_qp as w

pytestmark = pytest.mark.integration

MUTANTS = Path(__file__).resolve().parents[1] / "support" / "contract_mutants.py"
TOOLS = (sys.executable, "-P", "-m", "wmm_qp_tools.cli")


def _endpoints(svc: Any) -> list[str]:
    return ["--daemon-endpoint", svc.zenoh.daemon_endpoint, "--sim-endpoint", svc.zenoh.sim_endpoint]


@contextmanager
def driver(tmp: Path, mutant: str | None = None) -> Iterator[Any]:
    """``wmm-qp sim`` (or a mutant of it) on an isolated prefix; yields its service config."""
    svc = isolated_config(robot=w.load_robot_config())
    prefix = [sys.executable, str(MUTANTS), mutant] if mutant else [*CLI]
    with open(tmp / f"driver-{mutant or 'sim'}.log", "w") as err:
        p = subprocess.Popen([*prefix, "sim", "--prefix", svc.prefix, "--robot", svc.robot, *_endpoints(svc)],
                             stdin=subprocess.DEVNULL, stdout=err, stderr=err)
    try:
        yield svc
    finally:
        p.send_signal(signal.SIGINT)
        try:
            p.wait(20)
        except subprocess.TimeoutExpired:
            p.kill()


def contract(svc: Any, *args: str, wait: float = 120.0, prefix: str | None = None) -> subprocess.CompletedProcess[str]:
    """``wmm-qp contract`` for the driver of ``svc`` (its prefix unless ``prefix``)."""
    argv = [*TOOLS, "contract", "--prefix", prefix or svc.prefix, *_endpoints(svc), "--wait", f"{wait:g}", *args]
    return subprocess.run(argv, capture_output=True, text=True, timeout=600, stdin=subprocess.DEVNULL)


def verdicts(out: subprocess.CompletedProcess[str]) -> dict[str, Any]:
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.fixture(scope="module")
def sim(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Any]:
    with driver(tmp_path_factory.mktemp("contract")) as svc:
        yield svc


def test_the_reference_sim_passes_every_check_with_a_line_each(sim: Any) -> None:
    out = contract(sim)
    assert out.returncode == 0, out.stdout + out.stderr
    lines = [ln.split() for ln in out.stdout.splitlines() if ln.startswith("  ")]
    assert [(ln[0], ln[1]) for ln in lines] == [("PASS", name) for name in NAMES]
    assert f"{len(NAMES)} of {len(NAMES)} checks passed" in out.stdout


def test_json_gives_each_checks_verdict_and_skip_leaves_a_check_out(sim: Any) -> None:
    out = contract(sim, "--json", "--skip", "position_limit", "--skip", "stopped_stream")
    assert out.returncode == 0, out.stdout + out.stderr
    v = verdicts(out)
    assert v["passed"] is True and v["robot"] == f"{sim.prefix}/{sim.robot}"
    assert list(v["checks"]) == [n for n in NAMES if n not in ("position_limit", "stopped_stream")]
    assert all(c["passed"] is True and c["detail"] for c in v["checks"].values())


def test_every_mutant_still_patches_code_that_exists() -> None:
    out = subprocess.run([sys.executable, str(MUTANTS), "--check"], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr


@pytest.mark.parametrize("mutant", NAMES)
def test_a_mutant_driver_fails_exactly_the_check_of_its_broken_duty(mutant: str, tmp_path: Path) -> None:
    with driver(tmp_path, mutant) as svc:
        out = contract(svc, "--json")
    assert out.returncode == 1, out.stdout + out.stderr
    v = verdicts(out)
    failed = [name for name, c in v["checks"].items() if not c["passed"]]
    assert failed == [mutant], json.dumps(v["checks"], indent=1)
    assert list(v["checks"]) == list(NAMES)
    assert f"FAILED: {mutant}" in out.stderr


def test_a_wrong_prefix_or_robot_id_is_named_with_the_keys_that_do_carry_states(sim: Any) -> None:
    out = contract(sim, wait=3.0, prefix="nosuchprefix")
    assert out.returncode == 1
    err = out.stderr.strip().splitlines()
    assert len(err) == 1 and "Traceback" not in out.stderr
    assert f"no state on nosuchprefix/{sim.robot}/state within 3 s" in err[0]
    assert f"{sim.prefix}/{sim.robot}/state" in err[0] and "wrong --robot-config, --robot or --prefix?" in err[0]
    out = contract(sim, "--robot", "gen3", wait=3.0)
    assert out.returncode == 1
    assert f"no state on {sim.prefix}/gen3/state" in out.stderr and f"{sim.prefix}/{sim.robot}/state" in out.stderr


def test_a_daemon_holding_the_robot_is_named_and_nothing_is_sent() -> None:
    """A daemon's token (and its lease) on the robot's keys: the kit names them, exit 1, no check
    runs. The test's session stands where the driver would (it listens on the sim's endpoint),
    so the kit reaches it as it reaches a daemon connected to the driver."""
    from wmm_qp_service.keys import Keys
    from wmm_qp_service.transport import ROLE_SIM, open_session

    svc = isolated_config(robot=w.load_robot_config())
    keys = Keys.of(svc.prefix, svc.robot)
    with open_session(svc, ROLE_SIM) as s:
        tokens = [s.liveliness().declare_token(keys.alive("daemon")), s.liveliness().declare_token(keys.lease("d1"))]
        try:
            out = contract(svc, "--json", wait=3.0)
        finally:
            for t in tokens:
                t.undeclare()
    assert out.returncode == 1, out.stdout + out.stderr
    assert (f"{keys.alive('daemon')}, {keys.lease('d1')} alive: a daemon (or another controller) holds {keys.root}; "
            f"stop it first") in out.stderr
    assert verdicts(out)["checks"] == {} and "PASS" not in out.stderr


def test_a_daemon_on_the_daemons_endpoint_is_named() -> None:
    """The daemon's endpoint taken (a daemon of the default endpoints runs): one line, exit 1."""
    import socket

    svc = isolated_config(robot=w.load_robot_config())
    host, port = svc.zenoh.daemon_endpoint.split("/", 1)[1].rsplit(":", 1)
    with socket.socket() as sock:
        sock.bind((host, int(port)))
        sock.listen()
        out = contract(svc, wait=3.0)
    assert out.returncode == 1, out.stdout + out.stderr
    err = out.stderr.strip().splitlines()
    assert len(err) == 1 and f"cannot open a session listening on {svc.zenoh.daemon_endpoint}" in err[0]
    assert "is a daemon running there?" in err[0] and "Traceback" not in out.stderr


@pytest.mark.parametrize("args, message", [
    (["--robot-config", "/nonexistent.toml"], "nonexistent.toml"),
    (["--rate", "0"], "--rate must be > 0"),
    (["--skip", "nosuchcheck"], "invalid choice"),
    (["--stale-timeout", "-1"], "--stale-timeout must be > 0"),
])
def test_bad_arguments_are_one_line_and_exit_2(args: Sequence[str], message: str) -> None:
    out = subprocess.run([*TOOLS, "contract", *args], capture_output=True, text=True, timeout=120)
    assert out.returncode == 2, out.stdout + out.stderr
    assert len(out.stderr.strip().splitlines()) == 1 and message in out.stderr


def test_the_fr3_driver_on_franky_sim_passes_every_check(tmp_path: Path) -> None:
    """``wmm-qp contract --robot-config fr3.toml`` against ``wmm-qp driver franka`` on franky-sim
    (each in its own process: libfranka's connect holds the GIL)."""
    pytest.importorskip("pylibfranka", reason="needs pylibfranka (pip install 'wmm-qp[franka]')")
    pytest.importorskip("franky_sim", reason="needs franky-sim (pip install franky-sim)")
    from support.franky_rig import FR3, driver_stack, start_franky_sim

    sim = start_franky_sim(w.load_robot_config(FR3))
    try:
        with driver_stack(sim, tmp_path, serve=False) as (svc, _):
            out = contract(svc, "--robot-config", str(FR3), "--json")
    finally:
        sim.close()
    assert out.returncode == 0, out.stdout + out.stderr
    v = verdicts(out)
    assert list(v["checks"]) == list(NAMES) and all(c["passed"] for c in v["checks"].values())
    assert "cannot_stop_before_limit" in v["checks"]["position_limit"]["detail"]
