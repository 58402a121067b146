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
    GripperMsg,
    ModeMsg,
    SetpointMsg,
    StateMsg,
    TruthMsg,
    encode,
)
from wmm_qp_service.validation import Reject, Rejected, Validator

LIM = ValidationConfig()
N_ARM, N_WHEELS = 7, 4  # the messages below are the Gen3's (7 joints, 4 Mecanum wheels)


def validator(cls: type, robot: str = "r1", n_arm: int = N_ARM, n_wheels: int = N_WHEELS) -> Validator:
    return Validator(cls, robot, LIM, n_arm=n_arm, n_wheels=n_wheels)


def state(**kw: object) -> StateMsg:
    d: dict[str, object] = dict(robot="r1", t=0.0, q_base=[0.0] * 3, q_arm=[0.1] * 7, v_arm=[0.0] * 7,
                                wheel_speeds=[0.0] * 4, tau=[0.0] * 7, gripper_width=0.04, instance="sim-1",
                                seq=1, stamp=1.0)
    d.update(kw)
    return StateMsg(**d)  # type: ignore[arg-type]


def truth(**kw: object) -> TruthMsg:
    d: dict[str, object] = dict(robot="r1", t=0.0, instance="sim-1", state_seq=1, base_true=[0.0] * 3,
                                ee_true=[0.6, 0, 0.5], contact_force=[0.0] * 3, box_position=0.0, seq=1, stamp=1.0)
    d.update(kw)
    return TruthMsg(**d)  # type: ignore[arg-type]


def grip(**kw: object) -> GripperMsg:
    d: dict[str, object] = dict(robot="r1", action="move", width=0.05, speed=0.1, source="op", seq=1, stamp=1.0)
    d.update(kw)
    return GripperMsg(**d)  # type: ignore[arg-type]


def test_the_state_holds_only_what_a_real_robot_reports() -> None:
    """Ground truth, the box, the contact model and the referee are the sim's truth, not state."""
    fields = set(StateMsg.__struct_fields__)
    assert not fields & {"base_true", "ee_true", "box_position", "stalled_joint", "violations", "contact_force"}
    assert {"base_true", "ee_true", "box_position", "stalled_joint", "violations"} <= set(TruthMsg.__struct_fields__)
    assert math.isnan(state(gripper_width=math.nan).gripper_width)  # nan: no gripper


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
        validator(cls).check(data)
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
        (TruthMsg, truth()),
        (GripperMsg, grip(action="grasp", width=0.02, force=40.0)),
    ]:
        v = validator(cls)
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
        (TruthMsg, encode(truth(ee_true=[0.0] * 2)), Reject.SIZE),
        (GripperMsg, encode(grip(action="crush")), Reject.RANGE),
        (GripperMsg, encode(grip(width=-0.01)), Reject.RANGE),
        (GripperMsg, encode(grip(speed=0.0)), Reject.RANGE),
        (GripperMsg, encode(grip(force=1e6)), Reject.RANGE),
        (GripperMsg, encode(grip(width=math.nan)), Reject.NON_FINITE),
        (GripperMsg, encode(grip(source="")), Reject.SCHEMA),
    ],
)
def test_rejections(cls: type, payload: bytes, reason: Reject) -> None:
    assert check(cls, payload) == reason


def test_rejections_are_counted_by_reason() -> None:
    v = validator(SetpointMsg)
    assert v(b"\xc1junk") is None
    assert v(encode(sp(robot="x", x=[0.6, 0, 0.5]))) is None
    assert v(encode(sp(robot="x", x=[0.6, 0, 0.5]))) is None
    assert dict(v.rejected) == {"decode": 1, "robot": 2}
    assert v.accepted == 0 and "robot" in v.last_rejection


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=200))
def test_random_bytes_never_raise_and_never_pass(data: bytes) -> None:
    v = validator(SetpointMsg)
    out = v(data)  # must not raise
    assert out is None or isinstance(out, SetpointMsg)
    assert v.accepted + sum(v.rejected.values()) == 1


def test_keys_live_under_prefix_and_robot() -> None:
    k = Keys.of("lab/", "r1")
    assert k.state == "lab/r1/state" and k.cmd == "lab/r1/cmd" and k.setpoint == "lab/r1/setpoint"
    assert k.mode == "lab/r1/mode" and k.info == "lab/r1/info" and k.alive("robot") == "lab/r1/alive/robot"


def test_box_message_round_trips_and_is_checked() -> None:
    """The sim's ``sim/box`` request: a valid box passes, robot id and ranges are checked."""
    from wmm_qp_service.protocol import BoxMsg

    ok = BoxMsg(robot="r1", seq=1, stamp=1.0, mass=26.0, mu=0.65, face_x=0.66, center_y=-0.02)
    assert validator(BoxMsg).check(encode(ok)) == ok
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


# ---------------------------------------------------------------- the robot's vector lengths
@pytest.mark.parametrize("base, n_wheels", [("diff_drive", 2), ("fixed", 0)])
def test_joint_and_wheel_vectors_have_the_robots_lengths(tmp_path, base: str, n_wheels: int) -> None:  # type: ignore[no-untyped-def]
    """A Gen3 on another base: its sizes are accepted, the Mecanum Gen3's are rejected (size)."""
    from support.service_robots import gen3_file

    import wmm_qp as w

    robot = w.load_robot_config(gen3_file(tmp_path, base))
    assert (robot.n_arm, robot.n_wheels) == (7, n_wheels)
    na, nw = robot.n_arm, robot.n_wheels
    ok_state = state(wheel_speeds=[0.0] * nw)
    ok_cmd = cmd(wheel_speeds=[0.1] * nw)
    for cls, good, bad in ((StateMsg, ok_state, state()), (CommandMsg, ok_cmd, cmd())):
        v = validator(cls, n_arm=na, n_wheels=nw)
        assert v.check(encode(good)) == good
        with pytest.raises(Rejected) as e:
            v.check(encode(bad))  # 4 wheels: the Mecanum robot's
        assert e.value.reason == Reject.SIZE and "wheel_speeds has 4 entries, expected" in e.value.detail


def test_a_six_joint_robots_messages(tmp_path) -> None:  # type: ignore[no-untyped-def]
    """The UR5 on an omni base (6 joints, 3 wheels): every joint vector has 6 entries."""
    from support.service_robots import shipped

    robot = shipped("ur5_omni")
    na, nw = robot.n_arm, robot.n_wheels
    assert (na, nw) == (6, 3)
    good = state(q_arm=[0.1] * na, v_arm=[0.0] * na, tau=[0.0] * na, wheel_speeds=[0.0] * nw)
    v = validator(StateMsg, n_arm=na, n_wheels=nw)
    assert v.check(encode(good)) == good
    for field, n in (("q_arm", 7), ("v_arm", 7), ("tau", 7), ("wheel_speeds", 4)):
        assert check_sized(StateMsg, encode(msgspec.structs.replace(good, **{field: [0.0] * n})), na, nw) \
            == Reject.SIZE, field
    c = cmd(arm_rates=[0.1] * na, wheel_speeds=[0.0] * nw)
    assert check_sized(CommandMsg, encode(c), na, nw) is None
    assert check_sized(CommandMsg, encode(cmd()), na, nw) == Reject.SIZE  # the Gen3's 7 + 4


def check_sized(cls: type, data: bytes, n_arm: int, n_wheels: int) -> Reject | None:
    try:
        validator(cls, n_arm=n_arm, n_wheels=n_wheels).check(data)
    except Rejected as e:
        return e.reason
    return None


def test_a_validator_of_joint_vectors_needs_the_robots_sizes() -> None:
    from wmm_qp_service.protocol import TelemetryMsg

    for cls in (StateMsg, CommandMsg, TelemetryMsg):
        with pytest.raises(ValueError, match="n_arm and n_wheels"):
            Validator(cls, "r1", LIM)
    Validator(SetpointMsg, "r1", LIM)  # task-space messages do not
    Validator(ModeMsg, "r1", LIM)


def test_telemetry_is_checked_against_the_robots_sizes() -> None:
    from wmm_qp_service.protocol import TelemetryMsg

    tel = TelemetryMsg(robot="r1", seq=3, stamp=1.0, t=0.1, mode="track", x=[0.6, 0.0, 0.5],
                       x_d=[0.6, 0.0, 0.5], xd_d=[0.0] * 3, ee_true=[math.nan] * 3, ee_error=math.nan,
                       wheel_speeds=[0.0] * 2, arm_rates=[0.0] * 6, status="ok", dm=1.0, task_error=0.0,
                       tick_us=50.0)
    assert check_sized(TelemetryMsg, encode(tel), 6, 2) is None
    assert check_sized(TelemetryMsg, encode(tel), 7, 4) == Reject.SIZE
    assert check_sized(TelemetryMsg, encode(msgspec.structs.replace(tel, mode="fly")), 6, 2) == Reject.MODE


# ---------------------------------------------------------------- the setpoint's orientation
@pytest.mark.parametrize(
    ("fields", "reason"),
    [
        ({"q": [0.0, 0.0, 0.0, 1.0]}, None),
        ({"q": [0.0, 0.0, 0.0, 2.0], "w": [0.0, 0.0, 0.5]}, None),  # normalised by the controller
        ({"w": [0.1, 0.0, 0.0]}, None),
        ({"q": [0.0, 0.0, 1.0]}, Reject.SIZE),
        ({"q": [0.0, 0.0, 0.0, 0.0]}, Reject.RANGE),
        ({"q": [1e-12, 0.0, 0.0, 0.0]}, Reject.RANGE),
        ({"q": [0.0, 0.0, 0.0, math.nan]}, Reject.NON_FINITE),
        ({"q": [0.0, 0.0, 0.0, 1e300]}, Reject.RANGE),
        ({"w": [0.0, 0.0]}, Reject.SIZE),
        ({"w": [0.0, math.inf, 0.0]}, Reject.NON_FINITE),
        ({"w": [20.0, 0.0, 0.0]}, Reject.RANGE),
    ],
)
def test_the_setpoints_orientation_is_checked(fields: dict[str, list[float]], reason: Reject | None) -> None:
    assert check(SetpointMsg, encode(sp(**fields))) == reason


def test_a_setpoint_without_orientation_decodes_as_before() -> None:
    """``q`` and ``w`` are optional fields of version 2: a setpoint of an older sender (no such
    keys on the wire) is accepted, with both None."""
    data = msgspec.to_builtins(sp())
    del data["q"], data["w"]
    out = validator(SetpointMsg).check(msgspec.msgpack.encode(data))
    assert out.q is None and out.w is None and out.x == [0.6, 0.0, 0.5]
