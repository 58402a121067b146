"""Protocol round trips and validation on receipt: every rejection reason."""

from __future__ import annotations

import math

import msgspec
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from wmm_qp_service.config import ValidationConfig
from wmm_qp_service.keys import Keys
from wmm_qp_service.protocol import (
    PROTOCOL_VERSION,
    CommandMsg,
    ModeMsg,
    SetpointMsg,
    StateMsg,
    encode,
)
from wmm_qp_service.validation import Reject, Rejected, Validator

LIM = ValidationConfig()


def state(**kw: object) -> StateMsg:
    d: dict[str, object] = dict(robot="r1", t=0.0, q_base=[0.0] * 3, q_arm=[0.1] * 7, v_arm=[0.0] * 7,
                                wheel_speeds=[0.0] * 4, base_true=[0.0] * 3, ee_true=[0.6, 0, 0.5],
                                tau=[0.0] * 7, contact_force=[0.0] * 3, box_position=0.0,
                                instance="sim-1", seq=1, stamp=1.0)
    d.update(kw)
    return StateMsg(**d)  # type: ignore[arg-type]


def sp(**kw: object) -> SetpointMsg:
    d: dict[str, object] = dict(robot="r1", seq=1, stamp=1.0, x=[0.6, 0.0, 0.5], source="op-1")
    d.update(kw)
    return SetpointMsg(**d)  # type: ignore[arg-type]


def cmd(**kw: object) -> CommandMsg:
    d: dict[str, object] = dict(robot="r1", seq=1, stamp=1.0, wheel_speeds=[0.0] * 4, arm_rates=[0.1] * 7,
                                lease="daemon-1", instance="sim-1", period=0.002, stream=1)
    d.update(kw)
    return CommandMsg(**d)  # type: ignore[arg-type]


def check(cls: type, data: bytes) -> Reject | None:
    try:
        Validator(cls, "r1", LIM).check(data)
    except Rejected as e:
        return e.reason
    return None


def test_valid_messages_round_trip() -> None:
    for cls, msg in [
        (StateMsg, state()),
        (SetpointMsg, sp(robot="r1", x=[0.6, 0.0, 0.5])),
        (SetpointMsg, sp(robot="r1", x=[0.6, 0.0, 0.5], xd=[0.01, 0.0, 0.0])),
        (ModeMsg, ModeMsg(robot="r1", mode="dm_nullspace", direction=[0, 0, 1.0])),
        (CommandMsg, cmd()),
    ]:
        v = Validator(cls, "r1", LIM)
        assert v(encode(msg)) == msg
        assert v.accepted == 1 and not v.rejected


@pytest.mark.parametrize(
    ("cls", "payload", "reason"),
    [
        (SetpointMsg, b"\xc1garbage", Reject.DECODE),
        (SetpointMsg, b"", Reject.DECODE),
        (SetpointMsg, encode(ModeMsg(robot="r1", mode="hold")), Reject.SCHEMA),
        (SetpointMsg, msgspec.msgpack.encode({"type": "setpoint", "robot": "r1"}), Reject.SCHEMA),
        (SetpointMsg, msgspec.msgpack.encode([1, 2, 3]), Reject.SCHEMA),
        (SetpointMsg, msgspec.msgpack.encode({"type": "setpoint", "v": PROTOCOL_VERSION, "robot": "r1",
                                              "seq": 1, "stamp": 1.0, "source": "op",
                                              "x": [0.6, 0.0, 0.5], "evil": 1}), Reject.SCHEMA),
        (SetpointMsg, encode(sp(robot="r1", v=PROTOCOL_VERSION + 1, x=[0.6, 0, 0.5])),
         Reject.VERSION),
        (SetpointMsg, msgspec.msgpack.encode({"type": "setpoint", "v": 99, "robot": "r1",
                                              "x": "new-format"}), Reject.VERSION),
        (SetpointMsg, encode(sp(robot="other", x=[0.6, 0, 0.5])), Reject.ROBOT),
        (SetpointMsg, encode(sp(robot="r1", x=[0.6, 0.5])), Reject.SIZE),
        (SetpointMsg, encode(sp(robot="r1", x=[0.6, 0, 0.5], xd=[0.0] * 4)), Reject.SIZE),
        (SetpointMsg, encode(sp(robot="r1", x=[math.nan, 0, 0.5])), Reject.NON_FINITE),
        (SetpointMsg, encode(sp(robot="r1", x=[0.6, math.inf, 0.5])), Reject.NON_FINITE),
        (SetpointMsg, encode(sp(robot="r1", x=[1e9, 0, 0.5])), Reject.RANGE),
        (SetpointMsg, encode(sp(robot="r1", x=[0.6, 0, 50.0])), Reject.RANGE),
        (SetpointMsg, encode(sp(robot="r1", x=[0.6, 0, 0.5], xd=[10.0, 0, 0])), Reject.RANGE),
        (ModeMsg, encode(ModeMsg(robot="r1", mode="dance")), Reject.MODE),
        (ModeMsg, encode(ModeMsg(robot="r1", mode="track", direction=[0.0, 0.0, 0.0])), Reject.RANGE),
        (ModeMsg, encode(ModeMsg(robot="r1", mode="track", direction=[1.0, math.nan, 0.0])),
         Reject.NON_FINITE),
        (StateMsg, encode(state(q_arm=[0.0] * 6)), Reject.SIZE),
        (StateMsg, encode(state(v_arm=[math.nan] * 7)), Reject.NON_FINITE),
        (StateMsg, encode(state(wheel_speeds=[1e12] * 4)), Reject.RANGE),
        (StateMsg, encode(state(tau=[0.0] * 3)), Reject.SIZE),
        (StateMsg, encode(state(robot="r2")), Reject.ROBOT),
        (CommandMsg, encode(cmd(arm_rates=[1e6] * 7)), Reject.RANGE),
        (CommandMsg, encode(cmd(lease="")), Reject.SCHEMA),
        (CommandMsg, encode(cmd(instance="")), Reject.SCHEMA),
        (CommandMsg, encode(cmd(period=0.0)), Reject.RANGE),
        (CommandMsg, encode(cmd(period=5.0)), Reject.RANGE),
        (CommandMsg, encode(cmd(period=math.nan)), Reject.NON_FINITE),
        (SetpointMsg, encode(sp(source="")), Reject.SCHEMA),
        (StateMsg, encode(state(instance="")), Reject.SCHEMA),
    ],
)
def test_rejections(cls: type, payload: bytes, reason: Reject) -> None:
    assert check(cls, payload) == reason


def test_rejections_are_counted_by_reason() -> None:
    v = Validator(SetpointMsg, "r1", LIM)
    assert v(b"\xc1junk") is None
    assert v(encode(sp(robot="x", x=[0.6, 0, 0.5]))) is None
    assert v(encode(sp(robot="x", x=[0.6, 0, 0.5]))) is None
    assert dict(v.rejected) == {"decode": 1, "robot": 2}
    assert v.accepted == 0 and "robot" in v.last_rejection


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=200))
def test_random_bytes_never_raise_and_never_pass(data: bytes) -> None:
    v = Validator(SetpointMsg, "r1", LIM)
    out = v(data)  # must not raise
    assert out is None or isinstance(out, SetpointMsg)
    assert v.accepted + sum(v.rejected.values()) == 1


def test_keys_live_under_prefix_and_robot() -> None:
    k = Keys.of("lab/", "r1")
    assert k.state == "lab/r1/state" and k.cmd == "lab/r1/cmd" and k.setpoint == "lab/r1/setpoint"
    assert k.mode == "lab/r1/mode" and k.info == "lab/r1/info" and k.alive("sim") == "lab/r1/alive/sim"


def test_box_message_round_trips_and_is_checked() -> None:
    """The sim's ``sim/box`` request: a valid box passes, robot id and ranges are checked."""
    from wmm_qp_service.protocol import BoxMsg

    ok = BoxMsg(robot="r1", seq=1, stamp=1.0, mass=26.0, mu=0.65, face_x=0.66, center_y=-0.02)
    assert Validator(BoxMsg, "r1", LIM).check(encode(ok)) == ok
    assert Keys.of("wmm", "r1").sim_box == "wmm/r1/sim/box"
    other = BoxMsg(robot="r2", seq=1, stamp=1.0, mass=26.0, mu=0.65, face_x=0.66, center_y=0.0)
    assert check(BoxMsg, encode(other)) == Reject.ROBOT
    for bad, reason in (({"mass": math.nan}, Reject.NON_FINITE), ({"mass": 0.0}, Reject.RANGE),
                        ({"mass": 1e6}, Reject.RANGE), ({"mu": -0.1}, Reject.RANGE),
                        ({"width": 0.0}, Reject.RANGE), ({"face_x": 1e9}, Reject.RANGE)):
        msg = msgspec.structs.replace(ok, **bad)
        assert check(BoxMsg, encode(msg)) == reason, bad
    assert check(BoxMsg, encode(state())) == Reject.SCHEMA


@pytest.mark.parametrize("field", ["type", "v", "seq", "stamp", "robot", "source"])
def test_a_setpoint_missing_a_required_field_is_rejected(field: str) -> None:
    """docs/protocol.md: missing fields are rejected — the constructors' defaults (type, v) must
    not stand in for what the wire lacks (a blind drill's client sent no stamp, type, v or seq)."""
    data = msgspec.to_builtins(sp())
    assert check(SetpointMsg, msgspec.msgpack.encode(data)) is None  # complete: accepted
    del data[field]
    assert check(SetpointMsg, msgspec.msgpack.encode(data)) == Reject.SCHEMA


@pytest.mark.parametrize("field", ["type", "v", "seq", "stamp", "lease", "instance", "period", "stream"])
def test_a_command_missing_a_required_field_is_rejected(field: str) -> None:
    data = msgspec.to_builtins(cmd())
    del data[field]
    assert check(CommandMsg, msgspec.msgpack.encode(data)) == Reject.SCHEMA


def test_keys_of_the_control_lease() -> None:
    k = Keys.of("wmm", "r1")
    assert k.lease("abc") == "wmm/r1/lease/abc" and k.lease_all == "wmm/r1/lease/*"
