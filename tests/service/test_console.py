"""The console's pieces without a browser: the force-manipulability ellipsoid against eq. (8)'s
DM, quaternions, trails and plot windows, the status text, the robot file it draws, the CLI's
one-line errors."""

from __future__ import annotations

import math
import subprocess
from typing import Any

import numpy as np
import pytest
from wmm_qp_service.console.geometry import (
    Series,
    Trail,
    force_ellipsoid,
    matrix_to_quat,
    quat_to_matrix,
    rpy_quat,
    wxyz_to_xyzw,
    xyzw_to_wxyz,
)
from wmm_qp_service.processes import CLI

import wmm_qp as w
from wmm_qp.manipulability import directional_manipulability


@pytest.fixture(scope="module")
def model() -> w.WmmModel:
    return w.WmmModel(w.load_robot_config())


def test_the_ellipsoid_radius_along_u_is_the_dm_of_eq_8(model: w.WmmModel) -> None:
    rng = np.random.default_rng(0)
    W = model.config.arm.default_W()
    lo, hi = model.config.arm.position_lower, model.config.arm.position_upper
    for _ in range(20):
        q = np.where(np.isfinite(lo), rng.uniform(np.maximum(lo, -3), np.minimum(hi, 3)), rng.uniform(-3, 3, len(lo)))
        yaw = rng.uniform(-np.pi, np.pi)
        k = model.kinematics(np.array([0.3, -0.2, yaw]), q)
        e = force_ellipsoid(k.J_m[:3], W)
        u_base = rng.normal(size=3)
        u_base /= np.linalg.norm(u_base)
        # eq. (8): u in the base frame with J_arm; the ellipsoid is world-aligned, u turned by Rz(ψ)
        h2 = directional_manipulability(k.J_arm, u_base, W)
        assert e.radius_along(k.R @ u_base) == pytest.approx(h2, rel=1e-6)
        R = quat_to_matrix(e.wxyz)
        assert pytest.approx(np.eye(3), abs=1e-9) == R @ R.T and np.linalg.det(R) == pytest.approx(1.0)


def test_quaternions_round_trip() -> None:
    rng = np.random.default_rng(1)
    for _ in range(50):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        q = q if q[0] >= 0 else -q
        assert matrix_to_quat(quat_to_matrix(q)) == pytest.approx(q, abs=1e-9)
        assert xyzw_to_wxyz(wxyz_to_xyzw(q)) == pytest.approx(q)
    # a URDF rpy is roll about x, then pitch about y, then yaw about z (fixed axes)
    r, p, y = 0.3, -0.5, 1.1
    Rx = np.array([[1, 0, 0], [0, np.cos(r), -np.sin(r)], [0, np.sin(r), np.cos(r)]])
    Ry = np.array([[np.cos(p), 0, np.sin(p)], [0, 1, 0], [-np.sin(p), 0, np.cos(p)]])
    Rz = np.array([[np.cos(y), -np.sin(y), 0], [np.sin(y), np.cos(y), 0], [0, 0, 1]])
    assert quat_to_matrix(rpy_quat(np.array([r, p, y]))) == pytest.approx(Rz @ Ry @ Rx, abs=1e-12)


def test_trail_thins_and_keeps_the_last_points() -> None:
    t = Trail(n=5, step=0.01)
    assert t.add([0, 0, 0]) and not t.add([0.005, 0, 0]) and not t.add([np.nan, 0, 0])
    for k in range(1, 10):
        t.add([0.02 * k, 0, 0])
    seg = t.segments()
    assert seg.shape == (4, 2, 3) and seg[-1, 1, 0] == pytest.approx(0.18)


def test_series_keeps_the_last_30_s() -> None:
    s = Series(("dm", "error"), window=30.0)
    for k in range(100):
        s.add(float(k), float(k), 0.1)
    t, dm, _ = s.arrays(99.0)
    assert t[0] == pytest.approx(-30.0) and t[-1] == 0.0 and len(dm) == 31
    with pytest.raises(ValueError):
        s.add(100.0, 1.0)


def test_status_text_shows_every_counter_and_clamped_when_present() -> None:
    from wmm_qp_service.console import status_markdown
    from wmm_qp_service.protocol import LoopStats, StatusMsg

    st = StatusMsg(robot="wmm", mode="track", state_ok=True, safe_stop=True, last_fault="state stale (x)",
                   loop=LoopStats(rate_hz=500, measured_hz=499, ticks=1000, deadline_misses=7),
                   rejected={"range": 2}, robot_violations={"velocity": 1}, x=[0.1, 0, 0.4], x_d=[0.1, 0, 0.4],
                   dm=1.5, operator="console-ab")
    text = status_markdown(st, None, "console-ab")
    for part in ("`track`", "SAFE STOP", "499 / 500 Hz", "deadline misses** 7", "state stale (x)",
                 "rejected** 2", "robot violations** 1", "this console"):
        assert part in text, part
    if "clamped" not in StatusMsg.__struct_fields__:  # before the daemon reports it
        assert "clamped" not in text
        return
    import msgspec

    st = msgspec.structs.replace(st, clamped=3, last_clamp="x 20 -> 3.5")
    assert "clamped** 3 (last: x 20 -> 3.5)" in status_markdown(st, None, "x")


def test_status_text_shows_the_grippers_opening_only_for_a_robot_with_a_gripper() -> None:
    from wmm_qp_service.console import status_markdown
    from wmm_qp_service.protocol import StatusMsg

    st = StatusMsg(robot="fr3", mode="hold", state_ok=True, safe_stop=False)
    assert "**gripper** 41.5 mm open" in status_markdown(st, None, "x", gripper_width=0.0415)
    assert "gripper" not in status_markdown(st, None, "x")  # nan: the robot has none


@pytest.fixture
def viser_server() -> Any:
    """A real viser server on a free port."""
    import socket

    viser = pytest.importorskip("viser")
    pytest.importorskip("yourdfpy")
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    server = viser.ViserServer(host="127.0.0.1", port=port, verbose=False)
    yield server
    server.stop()


def test_the_view_draws_the_fr3_from_its_meshes_every_link_that_has_one_and_no_odometry(viser_server: Any) -> None:
    """The FR3's URDF (franky-sim's package, a ``pkg://`` path) with its meshes; a fixed base has no
    odometry frame to draw over the arm's foot."""
    pytest.importorskip("franky_sim", reason="the FR3's URDF ships with franky-sim (pip install franky-sim)")
    from support.console_helpers import urdf_mesh_links
    from wmm_qp_service.console.view import RobotView

    fr3 = w.load_robot_config(w.default_config_dir() / "robots" / "fr3.toml")
    links = urdf_mesh_links(fr3.arm.urdf)
    assert links >= 10  # link0 … link7, the hand, its two fingers
    view = RobotView(viser_server, fr3, fr3.arm.default_W(), None, pose_task=False)
    assert view.drawn == f"the URDF's meshes ({links} links)"
    assert not view.odom.visible


def test_the_view_draws_the_gen3_from_its_collision_shapes_with_its_odometry(viser_server: Any) -> None:
    from wmm_qp_service.console.view import RobotView

    gen3 = w.load_robot_config()
    view = RobotView(viser_server, gen3, gen3.arm.default_W(), None, pose_task=False)
    links = {sh.link for sh in gen3.collision.shapes if sh.link not in ("", "base")}
    assert view.drawn == f"the robot file's collision shapes ({len(links)} links)" and view.odom.visible


def test_the_robot_file_is_the_daemons_else_the_shipped_one_of_that_name(tmp_path) -> None:
    from wmm_qp_service.console import ConsoleError, robot_description
    from wmm_qp_service.protocol import InfoMsg, StatusMsg

    st = StatusMsg(robot="wmm", mode="hold", state_ok=True, safe_stop=False)
    gen3 = w.load_robot_config()
    joints = list(gen3.arm.joints)
    here = InfoMsg(robot="wmm", status=st, joints=joints, config={"robot": {"name": "wmm", "file": str(gen3.path)}})
    assert robot_description(here, None).path == gen3.path
    remote = InfoMsg(robot="wmm", status=st, joints=joints,
                     config={"robot": {"name": "wmm", "file": "/elsewhere/robot.toml"}})
    assert robot_description(remote, None).name == "wmm"
    unknown = InfoMsg(robot="x", status=st, joints=["a", "b"], config={"robot": {"name": "nobody", "file": ""}})
    with pytest.raises(ConsoleError, match="--robot-config"):
        robot_description(unknown, None)


@pytest.mark.parametrize(("args", "message"), [
    (["--port", "0"], "a port is 1-65535"),
    (["--port", "http"], "not a port number"),
    (["--wait", "0.5", "--prefix", "nobodyhere", "--daemon-endpoint", "tcp/127.0.0.1:9",
      "--sim-endpoint", "tcp/127.0.0.1:9"], "no daemon found"),
])
def test_console_errors_are_one_line(args: list[str], message: str) -> None:
    pytest.importorskip("viser")
    p = subprocess.run([*CLI, "console", *args], capture_output=True,
                       text=True, timeout=120, stdin=subprocess.DEVNULL)
    assert p.returncode in (1, 2)
    assert message in p.stderr and "Traceback" not in p.stderr
    assert len(p.stderr.strip().splitlines()) == 1, p.stderr


def test_console_refuses_a_port_in_use() -> None:
    import socket

    pytest.importorskip("viser")
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        p = subprocess.run([*CLI, "console", "--port", str(port)],
                           capture_output=True, text=True, timeout=120, stdin=subprocess.DEVNULL)
    assert p.returncode == 2 and "choose another --port" in p.stderr and "Traceback" not in p.stderr


def test_a_gizmo_move_streams_position_and_with_the_pose_task_orientation() -> None:
    from types import SimpleNamespace

    from wmm_qp_service.console import Console

    sent: list[tuple[list[float], list[float] | None]] = []
    link = SimpleNamespace(send_setpoint=lambda x, q=None: sent.append((list(x), q)))
    c = Console(link)  # type: ignore[arg-type]
    gizmo = SimpleNamespace(position=(0.6, 0.1, 0.5), wxyz=(np.cos(0.25), 0.0, 0.0, np.sin(0.25)))
    for pose in (False, True):
        c.attached = SimpleNamespace(pose_task=pose)  # type: ignore[assignment]
        c._on_gizmo(SimpleNamespace(target=gizmo))
    assert sent[0] == ([0.6, 0.1, 0.5], None)                     # position task: no orientation
    assert sent[1][0] == [0.6, 0.1, 0.5]
    assert sent[1][1] == pytest.approx([0.0, 0.0, np.sin(0.25), np.cos(0.25)])  # [x, y, z, w]


def test_the_gripper_buttons_and_width_slider_send_gripper_commands() -> None:
    """The panel's "Open gripper"/"Close gripper" buttons and width slider (a real viser server,
    their own click and update callbacks) each send one gripper command through the link."""
    import socket
    from types import SimpleNamespace

    viser = pytest.importorskip("viser")
    from wmm_qp_service.console import Console

    sent: list[tuple[str, float]] = []
    link = SimpleNamespace(gripper=lambda action, width=0.0: sent.append((action, width)),
                           svc=SimpleNamespace(robot="fr3"))
    c = Console(link)  # type: ignore[arg-type]
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    c.server = viser.ViserServer(host="127.0.0.1", port=port, verbose=False)
    try:
        c._build_panel()
        assert set(c.gripper_buttons) == {"open", "close"}
        assert c.gripper_buttons["close"].label == "Close gripper"
        for action in ("close", "open"):
            for cb in c.gripper_buttons[action]._impl.update_cb:
                cb(SimpleNamespace(target=c.gripper_buttons[action]))
        c.gripper_width.value = 0.03  # as the browser's slider moves it
        assert sent == [("close", 0.0), ("open", 0.0), ("move", pytest.approx(0.03))]
    finally:
        c.server.stop()


def test_a_nearly_constant_plot_gets_a_readable_y_range() -> None:
    """A DM held at 1.2057 ... 1.2063: uPlot's own range spans 6e-4 and labels every tick "1.206";
    the console's spans at least the plot's minimum, about the data, and ignores nan."""
    from wmm_qp_service.console.app import DM_MIN_SPAN, y_range

    rng = y_range([1.2057, math.nan, 1.2063], DM_MIN_SPAN)
    assert rng is not None
    lo, hi = rng
    assert hi - lo >= DM_MIN_SPAN and lo <= 1.2057 and hi >= 1.2063
    assert y_range([0.0, 2.0], DM_MIN_SPAN) == (0.0, 2.0)  # a wide series keeps its own range
    assert y_range([math.nan], DM_MIN_SPAN) is None
