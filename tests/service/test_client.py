"""The client API without transport: robot ids, the fault bookkeeping fed by the status stream,
the deliberate resume and the wait until the daemon is ready (the session's subscribers,
publishers and queries replaced by fakes)."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import msgspec
import pytest
from wmm_qp_service.client import Client, NotReady, robot_id
from wmm_qp_service.config import ServiceConfig
from wmm_qp_service.protocol import InfoMsg, ModeMsg, StatusMsg, encode

from wmm_qp import ConfigError


class _Payload:
    def __init__(self, data: bytes) -> None:
        self.data = data

    def to_bytes(self) -> bytes:
        return self.data


class _Sample:
    def __init__(self, data: bytes, key: str = "") -> None:
        self.payload = _Payload(data)
        self.key_expr = key


class FakeSub:
    """A ring channel of depth 1: the newest status wins."""

    def __init__(self) -> None:
        self.box: list[_Sample] = []

    def publish(self, st: StatusMsg) -> None:
        self.box = [_Sample(encode(st))]

    def try_recv(self) -> _Sample | None:
        return self.box.pop() if self.box else None


class FakeDaemon:
    """The daemon's side of a manual resume: a mode message is overruled while the safe stop
    lasts; after it, it sets the mode and clears resume_needed."""

    def __init__(self, sub: FakeSub) -> None:
        self.sub = sub
        self.safe = False
        self.resume_needed = False
        self.mode = "track"
        self.faults: dict[str, int] = {}
        self.modes_received: list[str] = []

    def status(self) -> StatusMsg:
        return StatusMsg(robot="r", mode=self.mode, state_ok=not self.safe, safe_stop=self.safe,
                         resume_needed=self.resume_needed, fault_active=self.safe or self.resume_needed,
                         faults=dict(self.faults),
                         last_fault="state stale (none valid for > 50 ms)" if self.faults else "",
                         last_fault_code="state_stale" if self.faults else "")

    def publish(self) -> None:
        self.sub.publish(self.status())

    def fault(self) -> None:
        self.safe, self.resume_needed, self.mode = True, False, "track"
        self.faults["state_stale"] = self.faults.get("state_stale", 0) + 1
        self.publish()

    def cleared(self) -> None:
        self.safe, self.resume_needed, self.mode = False, True, "hold"
        self.publish()

    def put(self, payload: bytes) -> None:  # the client's mode publisher
        m = msgspec.msgpack.decode(payload, type=ModeMsg)
        self.modes_received.append(m.mode)
        self.mode = m.mode
        if not self.safe:
            self.resume_needed = False
        self.publish()


class FakePub:
    def put(self, payload: bytes) -> None:
        pass


def fake_client(**kw: Any) -> tuple[Client, FakeDaemon]:
    c = Client(ServiceConfig(robot="r"), **kw)
    sub = FakeSub()
    daemon = FakeDaemon(sub)
    c._sub_status = sub  # type: ignore[assignment]
    c._pub_mode = daemon  # type: ignore[assignment]
    c._pub_sp = FakePub()  # type: ignore[assignment]
    return c, daemon


def test_a_fault_is_reported_once_and_setpoints_say_they_are_not_followed() -> None:
    seen: list[StatusMsg] = []
    c, daemon = fake_client(on_fault=seen.append)
    daemon.publish()
    assert c.send_setpoint([0.5, 0.0, 0.5]) and not c.fault_active and not seen
    daemon.fault()
    assert not c.send_setpoint([0.5, 0.0, 0.5])
    assert c.fault_active and len(seen) == 1 and seen[0].safe_stop
    daemon.publish()  # the same fault, a later status: no second call
    c.latest_status()
    daemon.cleared()  # the fault cleared: the daemon holds until a mode message
    assert not c.send_setpoint([0.5, 0.0, 0.5]) and c.resume_needed() and c.fault_active
    assert len(seen) == 1 and c.faults_seen == 1


def test_resume_waits_for_the_fault_to_clear_then_sends_the_mode() -> None:
    c, daemon = fake_client()
    daemon.fault()
    assert not c.resume("track", timeout=0.2)  # the safe stop lasts: nothing sent, no success
    assert daemon.modes_received == []
    daemon.cleared()
    assert c.resume("track", timeout=2.0)
    assert daemon.modes_received == ["track"] and not c.fault_active
    assert c.send_setpoint([0.5, 0.0, 0.5])


def test_a_new_fault_counted_while_another_holds_is_reported_too() -> None:
    """With ``resume = "auto"`` a short fault may come and go between two statuses: the
    daemon's fault counters still show it."""
    seen: list[StatusMsg] = []
    c, daemon = fake_client(on_fault=seen.append)
    daemon.publish()
    c.latest_status()
    daemon.faults["robot_lost"] = 1  # counted, already cleared: fault_active is False again
    daemon.publish()
    c.latest_status()
    assert len(seen) == 1 and not seen[0].fault_active


def test_robot_ids_from_a_robot_file_or_an_id(tmp_path: Path) -> None:
    f = tmp_path / "mine.toml"
    f.write_text('name = "my_robot"\n[arm]\n')
    assert robot_id(f) == robot_id(str(f)) == "my_robot"
    assert robot_id("z1_omni") == "z1_omni"
    assert Client.for_robot(f, ServiceConfig(robot="wmm")).svc.robot == "my_robot"
    assert Client(ServiceConfig(robot="wmm"), robot="other").svc.robot == "other"
    nameless = tmp_path / "nameless.toml"
    nameless.write_text("[arm]\n")
    assert robot_id(nameless, ServiceConfig(robot="wmm")) == "wmm"
    bad = tmp_path / "bad.toml"
    bad.write_text('name = "a b"\n')
    with pytest.raises(ConfigError, match=r"bad\.toml: name: must be a key segment"):
        robot_id(bad)
    with pytest.raises(ConfigError, match="robot"):
        robot_id("a b")


class _Reply:
    def __init__(self, key: str, data: bytes = b"") -> None:
        self.ok = _Sample(data, key)


class FakeSession:
    """The daemon's liveliness token and ``info`` queryable (``answers`` None: no daemon at all).
    Its status says ``state_ok`` from the ``ok_from``-th info query on (None: never)."""

    def __init__(self, answers: bool = True, ok_from: int | None = 1) -> None:
        self.answers = answers
        self.ok_from = ok_from
        self.queries = 0

    def liveliness(self) -> FakeSession:
        return self

    def get(self, key: str, timeout: float = 1.0) -> list[_Reply]:
        if not self.answers:
            return []
        if key.endswith("/alive/daemon"):
            return [_Reply(key)]
        assert key.endswith("/info"), key
        self.queries += 1
        ok = self.ok_from is not None and self.queries >= self.ok_from
        st = StatusMsg(robot="r", mode="hold", state_ok=ok, safe_stop=False, robot_alive=True)
        return [_Reply(key, encode(InfoMsg(robot="r", status=st)))]


def session_client(session: FakeSession) -> Client:
    c = Client(ServiceConfig(robot="r"))
    c.session = session  # type: ignore[assignment]
    return c


def test_wait_ready_returns_the_info_once_the_state_is_valid() -> None:
    session = FakeSession(ok_from=3)  # the daemon answers at once, its robot's state is valid from the 3rd query
    info = session_client(session).wait_ready(timeout=5.0)
    assert info.status.state_ok and session.queries == 3


def test_wait_ready_without_a_daemon_times_out_naming_the_robot() -> None:
    t0 = time.monotonic()
    with pytest.raises(NotReady, match=r"not ready after 0\.\d s: no daemon for robot wmm/r ") as e:
        session_client(FakeSession(answers=False)).wait_ready(timeout=0.3)
    assert e.value.info is None and e.value.robot == "wmm/r" and 0.3 <= e.value.waited < 2.0
    assert "daemons seen: none" in e.value.reason and time.monotonic() - t0 < 2.0


def test_wait_ready_with_a_daemon_but_no_valid_state_times_out_with_its_last_answer() -> None:
    session = FakeSession(ok_from=None)
    t0 = time.monotonic()
    with pytest.raises(NotReady, match="has no valid state from its robot") as e:
        session_client(session).wait_ready(timeout=5.0, state_timeout=0.3)
    assert e.value.info is not None and not e.value.info.status.state_ok
    assert session.queries >= 2 and 0.3 <= time.monotonic() - t0 < 2.0  # state_timeout, not timeout
