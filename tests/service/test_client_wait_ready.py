"""One wait for a started stack: ``Client.wait_ready`` with the processes' ``exited`` is the
launcher's wait (``wmm_qp_service.readiness``), one ``NotReady`` for both (the session's
liveliness and ``info`` queries replaced by a fake; no processes)."""

from __future__ import annotations

import time

import pytest
from wmm_qp_service import client, readiness
from wmm_qp_service.client import Client, NotReady
from wmm_qp_service.config import ServiceConfig
from wmm_qp_service.protocol import InfoMsg, StatusMsg, encode


class _Payload:
    def __init__(self, data: bytes) -> None:
        self.data = data

    def to_bytes(self) -> bytes:
        return self.data


class _Sample:
    def __init__(self, key: str, data: bytes = b"") -> None:
        self.key_expr = key
        self.payload = _Payload(data)


class _Reply:
    def __init__(self, key: str, data: bytes = b"") -> None:
        self.ok = _Sample(key, data)


class Session:
    """The robot's liveliness tokens (``nodes``; every one, or one by its key) and the daemon's
    ``info``, its state valid from the ``ok_from``-th query on (None: never)."""

    def __init__(self, nodes: tuple[str, ...], ok_from: int | None = 1) -> None:
        self.nodes, self.ok_from, self.queries = nodes, ok_from, 0

    def liveliness(self) -> Session:
        return self

    def get(self, key: str, timeout: float = 1.0) -> list[_Reply]:
        root, _, leaf = key.rpartition("/")
        if root.endswith("/alive"):
            return [_Reply(f"{root}/{n}") for n in self.nodes if leaf in ("*", n)]
        assert key.endswith("/info"), key
        self.queries += 1
        ok = self.ok_from is not None and self.queries >= self.ok_from
        st = StatusMsg(robot="r", mode="hold", state_ok=ok, safe_stop=not ok, robot_alive="sim" in self.nodes,
                       last_fault="" if ok else "state stale")
        return [_Reply(key, encode(InfoMsg(robot="r", status=st)))]


def on(session: Session) -> Client:
    c = Client(ServiceConfig(robot="r"))
    c.session = session  # type: ignore[assignment]
    return c


def test_the_client_and_the_launcher_raise_one_not_ready() -> None:
    assert client.NotReady is readiness.NotReady


def test_a_started_process_that_exits_ends_the_client_s_wait_at_once_naming_it() -> None:
    t0 = time.monotonic()
    with pytest.raises(NotReady, match=r"^the sim exited with status 2 \(sim\.log: bad plant\)$") as e:
        on(Session(("daemon",))).wait_ready(30.0, exited=lambda: "the sim exited with status 2 (sim.log: bad plant)")
    assert time.monotonic() - t0 < 1.0 and e.value.robot == "wmm/r" and e.value.info is None


def test_with_exited_the_client_waits_for_the_sim_too_and_names_it() -> None:
    """The daemon answers with a valid state, but the sim's token is missing: a started stack is
    not up (without ``exited`` the daemon's answer alone would do)."""
    said: list[str] = []
    with pytest.raises(NotReady, match=r"^the robot did not come up within 0\.3 s \(still running\)$"):
        on(Session(("daemon",))).wait_ready(0.3, exited=lambda: None, say=said.append)
    assert said and all(s.startswith("waiting for the robot to start") for s in said)
    assert on(Session(("daemon",))).wait_ready(0.3).status.state_ok


def test_with_exited_both_up_the_client_returns_the_first_valid_state() -> None:
    session = Session(("daemon", "robot"), ok_from=3)
    said: list[str] = []
    info = on(session).wait_ready(5.0, 5.0, exited=lambda: None, say=said.append)
    assert info.status.state_ok and session.queries == 3
    assert said and all(s.startswith("waiting for the daemon's first valid state") for s in said)


def test_with_exited_no_valid_state_names_the_processes_and_the_last_fault() -> None:
    with pytest.raises(NotReady, match=r"^the robot and the daemon are up, but the daemon had no valid state for "
                                       r"0\.3 s \(last fault: state stale\)$") as e:
        on(Session(("daemon", "robot"), ok_from=None)).wait_ready(5.0, 0.3, exited=lambda: None)
    assert e.value.info is not None and not e.value.info.status.state_ok and 0.3 <= e.value.waited < 2.0
