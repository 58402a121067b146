"""The sim's gripper (``wmm_qp_sim.gripper``): the robot file's ``[gripper]`` limits, a width
that moves at the commanded speed, commands clamped to the limits, NaN without a gripper."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from wmm_qp_sim import SimRobot, load_sim_config

import wmm_qp as w
from wmm_qp.config import GripperConfig, default_config_dir

FR3 = default_config_dir() / "robots" / "fr3.toml"


def test_the_fr3_file_declares_the_franka_hand() -> None:
    assert w.load_robot_config(FR3).gripper == GripperConfig(width_max=0.08, speed_max=0.1, force_max=70.0)
    assert w.load_robot_config().gripper is None  # the Gen3's file declares none


def test_a_bad_gripper_key_names_the_file_and_key(tmp_path: Path) -> None:
    p = tmp_path / "fr3_bad.toml"
    p.write_text(FR3.read_text().replace("width_max = 0.08", "width_max = -0.08"))
    with pytest.raises(w.ConfigError) as e:
        w.load_robot_config(p)
    assert e.value.key == "gripper.width_max" and str(p) in str(e.value)


def _sim(path: Path | None) -> SimRobot:
    return SimRobot(w.WmmModel(w.load_robot_config(path)), load_sim_config())


def test_the_gripper_closes_and_opens_at_its_speed() -> None:
    sim = _sim(FR3)
    dt = 1e-3
    assert sim.state().gripper_width == pytest.approx(0.08)  # starts open
    assert sim.command_gripper("close", speed=0.05)
    for _ in range(800):  # 0.8 s at 0.05 m/s: 0.04 m
        sim.step(None, dt)
    assert sim.state().gripper_width == pytest.approx(0.04, abs=1e-9)
    for _ in range(900):
        sim.step(None, dt)
    assert sim.state().gripper_width == 0.0
    assert sim.command_gripper("move", width=0.03, speed=1.0)  # clamped to speed_max 0.1 m/s
    for _ in range(100):
        sim.step(None, dt)
    assert sim.state().gripper_width == pytest.approx(0.01, abs=1e-9)
    assert sim.command_gripper("open", speed=0.1)
    for _ in range(1000):
        sim.step(None, dt)
    assert sim.state().gripper_width == pytest.approx(0.08)
    assert sim.command_gripper("grasp", width=0.5, force=500.0)  # width clamped to width_max, force to 70 N
    assert sim.gripper is not None and sim.gripper.target == 0.08 and sim.gripper.force == 70.0


def test_without_a_gripper_the_width_is_nan_and_commands_are_refused() -> None:
    sim = _sim(None)
    assert math.isnan(sim.state().gripper_width)
    assert not sim.command_gripper("close")


@pytest.mark.integration
def test_the_client_opens_and_closes_the_sims_gripper(tmp_path: Path) -> None:
    """``wmm-qp sim`` with the FR3's file, driven by ``Client.gripper_*`` over Zenoh."""
    import time

    from wmm_qp_service.client import Client
    from wmm_qp_service.processes import Stack, isolated_config

    robot = w.load_robot_config(FR3)
    stack = Stack(isolated_config(robot=robot), log_dir=tmp_path, robot_file=FR3)
    stack.start_sim()
    try:
        with Client(stack.svc, name="test") as c:

            def width_until(pred: object, timeout: float = 30.0) -> float:
                end = time.monotonic() + timeout
                while time.monotonic() < end:
                    st = c.wait_state(1.0)
                    if st is not None and pred(st.gripper_width):  # type: ignore[operator]
                        return st.gripper_width
                raise AssertionError(f"gripper width {c.latest_state()}")

            assert width_until(lambda x: x == pytest.approx(0.08), 60.0)  # a first start compiles
            c.gripper_close(speed=0.1)
            assert width_until(lambda x: x == 0.0) == 0.0
            c.gripper_move(0.05, speed=0.1)
            assert width_until(lambda x: x == pytest.approx(0.05)) == pytest.approx(0.05)
            c.gripper_open()
            assert width_until(lambda x: x == pytest.approx(0.08)) == pytest.approx(0.08)
            c.gripper("crush")  # rejected on receipt: the width stays
            time.sleep(0.2)
            st = c.wait_state(1.0)
            assert st is not None and st.gripper_width == pytest.approx(0.08)
    finally:
        assert stack.stop() == {"sim": 0}


@pytest.mark.integration
def test_the_consoles_gripper_buttons_move_the_sims_gripper(tmp_path: Path) -> None:
    """The console's own buttons (a real viser server and the console's link to the robot, their
    click callbacks as a browser's click runs them) close and open the gripper of ``wmm-qp sim``."""
    import socket
    import time
    from types import SimpleNamespace

    viser = pytest.importorskip("viser")
    from wmm_qp_service.client import Client
    from wmm_qp_service.console import Console
    from wmm_qp_service.console.link import RobotLink
    from wmm_qp_service.processes import Stack, isolated_config

    robot = w.load_robot_config(FR3)
    stack = Stack(isolated_config(robot=robot), log_dir=tmp_path, robot_file=FR3)
    stack.start_sim()
    link = RobotLink(stack.svc).open()
    c = Console(link)
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    c.server = viser.ViserServer(host="127.0.0.1", port=port, verbose=False)
    try:
        c._build_panel()
        with Client(stack.svc, name="observer") as obs:

            def width_until(pred: object, timeout: float = 60.0) -> float:
                end = time.monotonic() + timeout
                while time.monotonic() < end:
                    st = obs.wait_state(1.0)
                    if st is not None and pred(st.gripper_width):  # type: ignore[operator]
                        return st.gripper_width
                raise AssertionError(f"gripper width {obs.latest_state()}")

            def click(action: str) -> None:
                for cb in c.gripper_buttons[action]._impl.update_cb:
                    cb(SimpleNamespace(target=c.gripper_buttons[action]))

            width_until(lambda x: x == pytest.approx(0.08))
            end = time.monotonic() + 30.0
            while link.state() is None and time.monotonic() < end:  # the link's session reaches the sim
                time.sleep(0.05)
            click("close")
            assert width_until(lambda x: x == 0.0) == 0.0
            click("open")
            assert width_until(lambda x: x == pytest.approx(0.08)) == pytest.approx(0.08)
    finally:
        c.server.stop()
        link.close()
        stack.stop()
