"""Input devices: the keyboard's key latch, the gamepad driver on a recorded event stream, the
target integrator at its set speed, and the teleop loop against a fake client."""

from __future__ import annotations

import numpy as np
import pytest
from wmm_qp_service.devices import (
    DeviceSample,
    GamepadDevice,
    KeyboardDevice,
    RecordedEvents,
    TargetIntegrator,
)
from wmm_qp_service.devices.gamepad import (
    ABS_HAT0X,
    ABS_RX,
    ABS_RY,
    ABS_X,
    ABS_Y,
    BTN_NORTH,
    BTN_SOUTH,
    BTN_START,
    EV_ABS,
    EV_KEY,
    AxisRange,
)

PAD_RANGES = {c: AxisRange(-32768, 32767) for c in (ABS_X, ABS_Y, ABS_RX, ABS_RY)} | {ABS_HAT0X: AxisRange(-1, 1)}


def test_a_key_drives_its_axis_for_the_latch_and_the_opposite_key_reverses_it() -> None:
    kb = KeyboardDevice(latch=0.2)
    assert kb.press("w", 0.0)
    assert kb.read(0.1).twist.tolist() == [1, 0, 0, 0, 0, 0]
    assert not kb.read(0.25).twist.any()           # let go: stops one latch later
    kb.press("w", 1.0)
    kb.press("s", 1.05)
    assert kb.read(1.1).twist[0] == -1.0
    kb.press("r", 2.0)
    kb.press("a", 2.0)
    assert kb.read(2.1).twist.tolist() == [0, 1, 1, 0, 0, 0]


def test_rotation_keys_only_with_the_pose_task_and_the_buttons_latch_once() -> None:
    assert not KeyboardDevice(rotations=False).press("u", 0.0)
    kb = KeyboardDevice(rotations=True)
    kb.press("u", 0.0)
    assert kb.read(0.05).twist[5] == 1.0
    kb.press(" ", 0.1)
    s = kb.read(0.11)
    assert s.hold and not s.twist.any()            # hold stops every axis at once
    assert not kb.read(0.12).hold                  # reported once
    kb.press("t", 0.2)
    kb.press("q", 0.2)
    s = kb.read(0.21)
    assert s.resume and s.quit
    assert not kb.press("z", 0.3)


def test_the_gamepad_driver_maps_a_recorded_stream() -> None:
    rec = RecordedEvents([
        (0.0, EV_ABS, ABS_Y, -32768),       # left stick fully forward → +x
        (0.0, EV_ABS, ABS_X, 1000),         # inside the dead zone → 0
        (0.1, EV_ABS, ABS_RY, 16384),       # right stick half back → −z
        (0.2, EV_ABS, ABS_RX, -32768),      # yaw, only with rotations
        (0.3, EV_KEY, BTN_SOUTH, 1),        # A: hold
        (0.4, EV_KEY, BTN_SOUTH, 0),
        (0.5, EV_KEY, BTN_NORTH, 1),        # Y: resume
        (0.6, EV_ABS, ABS_Y, 0),            # stick released
        (0.7, EV_KEY, BTN_START, 1),        # START: quit
    ], PAD_RANGES)
    pad = GamepadDevice(rec, rotations=False)
    pad.feed(rec.poll_at(0.05))
    s = pad.read_state()
    assert s.twist[0] == pytest.approx(1.0) and s.twist[1] == 0.0
    pad.feed(rec.poll_at(0.25))
    s = pad.read_state()
    assert s.twist[2] == pytest.approx(-0.5, abs=1e-3) and s.twist[5] == 0.0
    pad.feed(rec.poll_at(0.45))
    assert pad.read_state().hold
    pad.feed(rec.poll_at(0.75))
    s = pad.read_state()
    assert s.resume and s.quit and s.twist[0] == 0.0
    pad_rot = GamepadDevice(RecordedEvents([(0.0, EV_ABS, ABS_RX, -32768)], PAD_RANGES), rotations=True)
    pad_rot.feed(pad_rot.source.poll_at(1.0))  # type: ignore[attr-defined]
    assert pad_rot.read_state().twist[5] == pytest.approx(1.0)


def test_the_integrator_moves_at_the_set_speed_and_never_jumps() -> None:
    it = TargetIntegrator([0.5, 0.0, 0.4], speed=0.05, dt_max=0.1)
    s = DeviceSample(twist=np.array([1.0, -1.0, 0.0, 0, 0, 0]))
    for _ in range(50):
        assert it.step(s, 0.02)
    assert it.x == pytest.approx([0.55, -0.05, 0.4])        # 1 s at 0.05 m/s
    it.step(s, 5.0)                                          # a stalled loop: one dt_max at most
    assert it.x == pytest.approx([0.555, -0.055, 0.4])
    assert not it.step(DeviceSample(), 0.02)
    assert it.quaternion() is None


def test_the_integrator_turns_about_world_axes() -> None:
    it = TargetIntegrator([0, 0, 0], R=np.eye(3), angular_speed=0.5)
    yaw = DeviceSample(twist=np.array([0, 0, 0, 0, 0, 1.0]))
    for _ in range(100):
        it.step(yaw, np.pi / 100)                            # π s at 0.5 rad/s: π/2 about z
    assert it.R is not None
    assert it.R @ np.array([1.0, 0, 0]) == pytest.approx([0, 1, 0], abs=1e-9)
    q = it.quaternion()
    assert q is not None and q == pytest.approx([0, 0, np.sin(np.pi / 4), np.cos(np.pi / 4)])


class _FakeClient:
    def __init__(self) -> None:
        self.modes: list[str] = []
        self.setpoints: list[list[float]] = []
        self.grips: list[str] = []

    def set_mode(self, mode: str, direction: object = None) -> None:
        self.modes.append(mode)

    def send_setpoint(self, x: object, q: object = None) -> None:
        self.setpoints.append(list(np.asarray(x, float)))

    def latest_status(self) -> None:
        return None

    def gripper(self, action: str, width: float = 0.0, speed: float = 0.05, force: float = 0.0) -> None:
        self.grips.append(action)


def test_device_teleop_streams_while_moving_and_hold_holds() -> None:
    from wmm_qp_service.teleop import DeviceTeleop

    kb = KeyboardDevice(latch=0.2)
    c = _FakeClient()
    t = DeviceTeleop(c, kb, TargetIntegrator([0.5, 0, 0.4], speed=0.1), stream_s=0.3)  # type: ignore[arg-type]
    t._last = 0.0
    kb.press("w", 0.0)
    for k in range(1, 11):
        t.tick(k * 0.02)
    # 9 ticks inside the 0.2 s latch move it 2 mm each; the 10th streams it standing
    assert len(c.setpoints) == 10 and c.setpoints[-1][0] == pytest.approx(0.518)
    kb.press(" ", 0.25)
    t.tick(0.26)
    assert c.modes == ["hold"] and t.holding
    n = len(c.setpoints)
    kb.press("w", 0.3)
    for k in range(20):
        t.tick(0.3 + k * 0.02)
    assert len(c.setpoints) == n                     # holding: keys move nothing, nothing is sent
    kb.press("t", 1.0)
    kb.press("q", 1.0)
    t.tick(1.02)
    assert t.quit


def test_the_gripper_keys_close_and_open_the_gripper_once_per_press() -> None:
    from wmm_qp_service.teleop import DeviceTeleop

    kb = KeyboardDevice()
    c = _FakeClient()
    t = DeviceTeleop(c, kb, TargetIntegrator([0.5, 0, 0.4], speed=0.1), stream_s=0.3)  # type: ignore[arg-type]
    t._last = 0.0
    assert kb.press("c", 0.0)
    t.tick(0.02)
    t.tick(0.04)  # reported once
    assert kb.press("v", 0.05)
    t.tick(0.06)
    assert c.grips == ["close", "open"] and not c.modes
