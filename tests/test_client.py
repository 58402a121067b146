"""The client API without transport: robot ids, the fault bookkeeping fed by the status stream,
and the deliberate resume (the session's subscribers and publishers replaced by fakes)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import msgspec
import pytest
from wmm_qp_service.client import Client, robot_id
from wmm_qp_service.config import ServiceConfig
from wmm_qp_service.protocol import ModeMsg, StatusMsg, encode

from wmm_qp import ConfigError


class _Payload:
    def __init__(self, data: bytes) -> None:
        self.data = data

    def to_bytes(self) -> bytes:
        return self.data


class _Sample:
    def __init__(self, data: bytes) -> None:
        self.payload = _Payload(data)


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
                         faults=dict(self.faults), last_fault="state stale" if self.faults else "")

    def publish(self) -> None:
        self.sub.publish(self.status())

    def fault(self) -> None:
        self.safe, self.resume_needed, self.mode = True, False, "track"
        self.faults["state stale"] = self.faults.get("state stale", 0) + 1
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
    daemon.faults["sim lost"] = 1  # counted, already cleared: fault_active is False again
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
