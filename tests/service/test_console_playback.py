"""``wmm-qp console --play FILE.mcap``: a recording played back in the console, without a browser.

The recordings are written here by the recording's own writer (``McapSink``, as the host's writer
process and ``wmm-qp record`` write them) from ticks whose every value is known: the arm's joints,
the base's pose, the target and DM differ from tick to tick, so a state shown at the wrong time
is seen. The playback clock is a fake one the tests move: nothing depends on timing.
"""

from __future__ import annotations

import math
import shutil
import socket
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.importorskip("mcap")
pytest.importorskip("rosbags")

import msgspec
from wmm_qp_service.console.playback import RecordingLink
from wmm_qp_service.console.timeline import load_timeline
from wmm_qp_service.protocol import StatusMsg

import wmm_qp as w

RATE = 100.0
T0 = 1_700_000_000.0  # [s] the first tick's wall clock
SWITCH = 100  # the tick at which the mode goes from hold to track


def q_arm_at(k: int, n: int) -> np.ndarray:
    return 0.1 * np.arange(n) + 0.5 * math.sin(0.02 * k)


def q_base_at(k: int) -> np.ndarray:
    return np.array([0.001 * k, -0.0005 * k, 0.002 * k])


def x_d_at(k: int) -> np.ndarray:
    return np.array([0.5 + 0.001 * k, 0.1, 0.5])


def dm_at(k: int) -> float:
    return 1.0 + 0.001 * k


def mode_at(k: int) -> str:
    return "hold" if k < SWITCH else "track"


def write_recording(path: Path, ticks: int, host: str = "serve", states: bool = True,
                    **meta_extra: str) -> dict[str, Any]:
    """A recording of ``ticks`` ticks at :data:`RATE`: the host's (``serve``: one ``/wmm/tick`` row
    a tick, its status every 10th) or a client's (``record``: what ``wmm-qp record`` writes from the
    robot's keys); ``states=False``: statuses only; ``meta_extra``: metadata to change."""
    from wmm_qp_service.recording.layout import MODES, Layout, config_to_dict
    from wmm_qp_service.recording.writer import McapSink

    robot = w.load_robot_config()
    n, nw = robot.n_arm, robot.n_wheels
    meta = {"format": "wmm-qp recording 1", "recording_id": "test", "host": host, "robot": "wmm",
            "robot_name": robot.name, "robot_file": str(robot.path),
            "arm_joints": msgspec.json.encode(list(robot.arm.joints)).decode(),
            "wheels": msgspec.json.encode([f"w{i}" for i in range(nw)]).decode(), "rate_hz": repr(RATE),
            "started": "2026-01-01T00:00:00Z", **meta_extra}
    if host == "serve":
        meta["controller_config"] = msgspec.json.encode(config_to_dict(w.load_controller_config())).decode()
    lay = Layout(n, nw)
    sink = McapSink(path, meta, lay, None, None)
    sink.open(0)
    mode = None
    for k in range(ticks):
        t = T0 + k / RATE
        ns = int(t * 1e9)
        status = msgspec.to_builtins(StatusMsg(robot="wmm", mode=mode_at(k), state_ok=True, safe_stop=False,
                                               dm=dm_at(k), loop={"ticks": k}))  # type: ignore[arg-type]
        if host == "serve" and states:
            row = np.full(lay.width, math.nan)
            sl, ix = lay.slices, lay.index
            for key, v in (("t_wall", t), ("t", k / RATE), ("tick", k), ("seq", k), ("call", 1), ("latches", 0),
                           ("latency", 0.0), ("mode", MODES.index(w.Mode(mode_at(k)))), ("status", 0),
                           ("state_seq", k),
                           ("dm", dm_at(k))):
                row[ix[key]] = v
            for prefix in ("meas", "ctl"):
                row[sl[f"{prefix}_q_base"]] = q_base_at(k)
                row[sl[f"{prefix}_q_arm"]] = q_arm_at(k, n)
                row[sl[f"{prefix}_v_arm"]] = 0.01 * k
                row[sl[f"{prefix}_wheels"]] = 0.0
            row[sl["x_d"]] = x_d_at(k)
            row[sl["cmd_wheels"]], row[sl["cmd_arm"]] = 0.0, 0.0
            sink.tick(row)
        elif states:  # as wmm-qp record: the state, the telemetry's target, the status with its mode
            sink.measured(ns, q_base_at(k), q_arm_at(k, n), np.full(n, 0.01 * k), np.zeros(nw))
            sink.target(ns, x_d_at(k), np.full(4, math.nan))
            sink.json("/wmm/telemetry", ns, {"tick": k, "dm": dm_at(k)})
        if k % 10 == 0:
            if host != "serve" and mode_at(k) != mode:
                sink.json("/wmm/mode", ns, {"tick": k, "mode": mode_at(k), "previous": mode})
                mode = mode_at(k)
            sink.event(1, k, status, ns)
    sink.close_file({"ticks": str(ticks)})
    return {"path": path, "n_arm": n, "robot": robot}


class FakeClock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


@pytest.fixture(scope="module")
def host_rec(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    return write_recording(tmp_path_factory.mktemp("play") / "host.mcap", 600)


@pytest.fixture(scope="module")
def client_rec(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    return write_recording(tmp_path_factory.mktemp("play") / "client.mcap", 300, host="record")


def link_of(rec: dict[str, Any], **kw: Any) -> tuple[RecordingLink, FakeClock]:
    clock = FakeClock()
    return RecordingLink(load_timeline(rec["path"]), rec["path"], clock=clock, **kw), clock


@pytest.mark.parametrize("which", ["host_rec", "client_rec"])
def test_seeking_to_a_time_gives_the_state_recorded_then(which: str, request: pytest.FixtureRequest) -> None:
    rec = request.getfixturevalue(which)
    link, _ = link_of(rec)
    tl = link.timeline
    ticks = 600 if which == "host_rec" else 300
    assert tl.states == ticks and tl.error is None
    assert np.all(np.diff(tl.q_arm.t) > 0)  # in time order, one a tick
    assert tl.q_arm.t == pytest.approx(np.arange(ticks) / RATE, abs=1e-6)
    for k in (0, 1, 57, SWITCH - 1, SWITCH, ticks - 1):
        link.clock.seek(k / RATE + 0.004)  # between tick k and k + 1: tick k's
        st, status, truth = link.state(), link.status(), link.truth()
        assert st is not None and status is not None and truth is not None
        assert st.q_arm == pytest.approx(q_arm_at(k, rec["n_arm"]), abs=1e-12)
        assert st.q_base[:2] == pytest.approx(q_base_at(k)[:2], abs=1e-12)
        assert st.q_base[2] == pytest.approx(q_base_at(k)[2], abs=1e-9)  # through /odom's quaternion
        assert status.mode == mode_at(k) and status.x_d == pytest.approx(x_d_at(k))
        assert status.dm == pytest.approx(dm_at(k))
        assert truth.base_true == pytest.approx(st.q_base)
        x, _ = w.WmmModel(rec["robot"]).ee_pose(np.array(st.q_base), np.array(st.q_arm))
        assert truth.ee_true == pytest.approx(x, abs=1e-9)  # /ee/pose: forward kinematics of the state
    a = link.attach()
    assert a.robot.path == rec["robot"].path and a.info.joints == list(rec["robot"].arm.joints)
    assert a.info.base_kind == rec["robot"].base.kind and not a.pose_task


def test_a_robot_file_that_is_not_here_needs_robot_config(tmp_path: Path) -> None:
    from wmm_qp_service.console import ConsoleError

    f = tmp_path / "elsewhere.mcap"
    gen3 = w.load_robot_config()
    write_recording(f, 20, robot_file=str(tmp_path / "gone.toml"), robot_name="nobody")
    with pytest.raises(ConsoleError, match="--robot-config"):
        RecordingLink(load_timeline(f), f).attach()
    assert RecordingLink(load_timeline(f), f, fallback=gen3.path).attach().robot.path == gen3.path


def test_the_clock_plays_at_its_speed_pauses_and_seeks(host_rec: dict[str, Any]) -> None:
    link, clock = link_of(host_rec, speed=2.0)
    assert link.now() == 0.0 and link.clock.playing
    clock.t += 0.5
    assert link.now() == pytest.approx(1.0)
    link.clock.set_speed(0.5)
    clock.t += 0.4
    assert link.now() == pytest.approx(1.2)
    link.clock.pause()
    clock.t += 10.0
    assert link.now() == pytest.approx(1.2) and not link.clock.playing
    link.clock.seek(3.0)
    assert link.now() == 3.0
    link.clock.play()
    clock.t += 1.0
    assert link.now() == pytest.approx(3.5)
    link.clock.seek(-1.0)
    assert link.now() == 0.0


@pytest.mark.parametrize("loop", [True, False])
def test_at_the_end_playback_loops_or_stops(loop: bool, host_rec: dict[str, Any]) -> None:
    link, clock = link_of(host_rec, loop=loop)
    d = link.timeline.duration
    assert d == pytest.approx(599 / RATE, abs=1e-6)
    link.clock.seek(d - 0.5)
    clock.t += 1.0
    st = link.state()
    assert st is not None
    if loop:
        assert link.now() == pytest.approx(0.5) and link.clock.playing and link.clock.loops == 1
        assert st.q_arm == pytest.approx(q_arm_at(50, host_rec["n_arm"]))
    else:
        assert link.now() == d and not link.clock.playing
        assert st.q_arm == pytest.approx(q_arm_at(599, host_rec["n_arm"]))  # the last state, held
        link.clock.play()  # from the start again
        assert link.now() == 0.0 and link.clock.playing


def test_the_plots_hold_the_last_30_s_up_to_the_playback_time(host_rec: dict[str, Any]) -> None:
    link, _ = link_of(host_rec)
    (t_dm, dm), (t_err, err) = link.history(2.0)
    assert t_dm[-1] == pytest.approx(0.0, abs=1e-6) and np.all(t_dm <= 1e-9) and np.all(np.diff(t_dm) > 0)
    assert dm[-1] == pytest.approx(dm_at(200)) and dm[0] == pytest.approx(dm_at(0))
    assert len(t_err) == 201 and np.isfinite(err).all()
    (t_dm, dm), _ = link.history(5.0, window=1.0)
    assert t_dm[0] >= -1.0 and dm[-1] == pytest.approx(dm_at(500))


def test_a_truncated_recording_plays_what_was_read(host_rec: dict[str, Any], tmp_path: Path) -> None:
    cut = tmp_path / "cut.mcap"
    data = host_rec["path"].read_bytes()
    cut.write_bytes(data[: int(len(data) * 0.6)])
    tl = load_timeline(cut)
    assert tl.error is not None and 0 < tl.states < 600
    link = RecordingLink(tl, cut, clock=FakeClock())
    link.clock.seek(tl.duration)
    st = link.state()
    assert st is not None and st.q_arm == pytest.approx(q_arm_at(tl.states - 1, host_rec["n_arm"]))


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _cli(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    from wmm_qp_tools import cli as tools_cli

    code = tools_cli.main(["console", *argv])
    return code, capsys.readouterr().err


@pytest.mark.parametrize(("make", "message"), [
    ("missing", "no such file"),
    ("garbage", "not a valid MCAP file"),
    ("no_states", "no robot states recorded"),
    ("speed", "--speed must be > 0"),
    ("speed_live", "--speed needs --play"),
    ("unknown_robot", "give it with --robot-config"),
])
def test_play_errors_are_one_line_and_exit_2(make: str, message: str, tmp_path: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("viser")
    f = tmp_path / "x.mcap"
    argv = ["--play", str(f), "--port", str(_free_port())]
    if make == "garbage":
        f.write_bytes(b"not an mcap file\n" * 10)
    elif make == "no_states":
        write_recording(f, 30, states=False)
    elif make in ("speed", "speed_live"):
        write_recording(f, 5)
        argv = [*argv, "--speed", "0"] if make == "speed" else ["--speed", "2", "--port", str(_free_port())]
    elif make == "unknown_robot":  # its robot file is not here, no shipped file has its name
        write_recording(f, 5, robot_file=str(tmp_path / "gone.toml"), robot_name="nobody")
    code, err = _cli(argv, capsys)
    assert code == 2 and message in err and "Traceback" not in err, err
    assert err.count("\n") == 1 and err.startswith("wmm-qp console: error: "), err


def test_without_the_record_extra_it_names_it(monkeypatch: pytest.MonkeyPatch, tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("viser")
    import wmm_qp_service.recording as recording

    def missing() -> None:
        raise recording.RecordingUnavailable("mcap")

    monkeypatch.setattr(recording, "require", missing)
    code, err = _cli(["--play", str(tmp_path / "x.mcap"), "--port", str(_free_port())], capsys)
    assert code == 2 and err == "wmm-qp console: error: recording needs the 'mcap' package: " \
                                "pip install 'wmm-qp[record]'\n"


def test_the_cli_plays_a_truncated_file_and_says_so_in_one_line(host_rec: dict[str, Any], tmp_path: Path,
                                                                capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("viser")
    cut = tmp_path / "cut.mcap"
    data = host_rec["path"].read_bytes()
    cut.write_bytes(data[: int(len(data) * 0.6)])
    code, err = _cli(["--play", str(cut), "--port", str(_free_port()), "--duration", "0.3"], capsys)
    assert code == 0, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("wmm-qp console: warning: ") and "playing the" in lines[0], err


def test_the_console_in_play_mode_shows_the_recording_at_the_playback_time(host_rec: dict[str, Any],
                                                                           tmp_path: Path) -> None:
    """The page's view, status and plots at a seek time (a real viser server, no browser); the
    commanding controls disabled; the time slider seeks; the play button pauses."""
    viser = pytest.importorskip("viser")
    pytest.importorskip("yourdfpy")
    from wmm_qp_service.console import Console

    cut = tmp_path / "copy.mcap"
    shutil.copy(host_rec["path"], cut)
    link, clock = link_of({"path": cut})
    c = Console(link)
    c.server = viser.ViserServer(host="127.0.0.1", port=_free_port(), verbose=False)
    try:
        c._build_panel()
        c._attach_view(link.attach())
        assert c.view is not None and c.player is not None
        for h in (*c.mode_buttons.values(), c.stop_button, *c.gripper_buttons.values(), c.gripper_width):
            assert h.disabled
        assert c.view.gizmo.disable_axes and c.view.gizmo.disable_sliders
        k = 432
        link.clock.seek(k / RATE + 0.002)
        link.clock.pause()
        c._update(plots=True)
        n = host_rec["n_arm"]
        joints = [c.view._cfg[c.view._joint_index[j]] for j in host_rec["robot"].arm.joints]
        assert joints == pytest.approx(q_arm_at(k, n), abs=1e-12)
        assert c.view.base_frame.position[:2] == pytest.approx(q_base_at(k)[:2])
        assert np.asarray(c.view.gizmo.position) == pytest.approx(x_d_at(k))
        assert "**mode** `track`" in c.status_md.content
        t_dm, dm = c.plot_dm.data
        assert dm[-1] == pytest.approx(dm_at(k)) and t_dm[-1] == pytest.approx(0.0, abs=0.01)
        lo, hi = c.plot_dm.scales["y"]["range"]  # the whole recording's: fixed while it plays
        assert lo <= dm_at(0) and hi >= dm_at(599)
        assert c.player.slider.value == pytest.approx(round(k / RATE + 0.002, 2))
        assert "**paused**" in c.player.text.content and "at the end: **loops**" in c.player.text.content
        c.player.slider.value = 0.555  # as the browser's slider moves it: a seek
        assert link.now() == pytest.approx(0.555)
        c._update(plots=True)
        assert "**mode** `hold`" in c.status_md.content and c.player.slider.value == pytest.approx(0.555, abs=0.006)
        for cb in c.player.play_button._impl.update_cb:  # the play button
            cb(None)
        assert link.clock.playing and c.player.play_button.label == "Pause"
        clock.t += 0.1
        assert link.now() == pytest.approx(0.655)
        c.set_mode("track")  # a command: nothing goes out
        assert link.ignored == 1
    finally:
        c.server.stop()
