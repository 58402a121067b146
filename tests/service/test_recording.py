"""``wmm-qp serve --record``, ``wmm-qp replay``: a recording read back by an independent decoder
(the ``mcap`` reader and ``rosbags``' CDR deserialiser, with the ROS types parsed from the schemas
the file carries — nothing of wmm-qp's writer), replayed bit for bit with the default solver, a
changed config's differences, and a damaged file's one-line error.

One sim + daemon stack records at 1 kHz for a few seconds, rotating its file every 2 s, while a
client drives it through track (a moving setpoint), a live obstacle, null-space DM and hold.
"""

from __future__ import annotations

import json
import math
import re
import signal
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.importorskip("mcap")
pytest.importorskip("rosbags")

from support.live import ready

pytestmark = pytest.mark.integration

RATE = 1000.0


def cli(*argv: str, timeout: float = 300.0) -> subprocess.CompletedProcess[str]:
    """The installed ``wmm-qp`` (the tools' command table) as a child process."""
    return subprocess.run([sys.executable, "-P", "-m", "wmm_qp_tools.cli", *argv], capture_output=True, text=True,
                          timeout=timeout, stdin=subprocess.DEVNULL)


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """A recorded run: its first file, the daemon's log and its final tick count; and a client's
    recording of the same run (``wmm-qp record``)."""
    from wmm_qp_service.client import Client
    from wmm_qp_service.processes import Stack, isolated_config

    d = tmp_path_factory.mktemp("rec")
    path = d / "run.mcap"
    stack = Stack(isolated_config(), rate_hz=RATE, log_dir=d,
                  extra_daemon_args=["--record", str(path), "--split-time", "2"])
    svc = stack.svc
    client = subprocess.Popen(  # a client's recording of the same run, started first (its start is slow)
        [sys.executable, "-P", "-m", "wmm_qp_tools.cli", "record", str(d / "client.mcap"), "--duration", "600",
         "--prefix", svc.prefix, "--robot", svc.robot, "--daemon-endpoint", svc.zenoh.daemon_endpoint,
         "--sim-endpoint", svc.zenoh.sim_endpoint],
        stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert client.stderr is not None
    assert "wmm-qp record: recording" in client.stderr.readline()  # its subscribers are declared
    with stack as st, Client(st.svc) as c:
        info = ready(c)
        x0 = list(info.status.x)
        c.set_mode("track")
        t0 = time.monotonic()
        while (t := time.monotonic() - t0) < 2.5:
            c.send_setpoint([x0[0] + 0.05 * math.sin(2 * t), x0[1] + 0.05 * (1 - math.cos(2 * t)), x0[2]])
            if 1.0 < t < 1.05:
                c.put_obstacles([{"id": "ball", "kind": "sphere", "radius": 0.05, "xyz": [x0[0] + 0.4, 0.0, 0.3]}])
            time.sleep(0.01)
        c.set_mode("dm_nullspace")
        time.sleep(1.0)
        c.set_mode("hold")
        time.sleep(0.5)
        st.kill("daemon", signal.SIGINT)  # its recording drains before it exits: however busy the machine
        daemon_code = st.procs["daemon"].wait(timeout=600)
        client.send_signal(signal.SIGINT)
        _, client_err = client.communicate(timeout=120)
    log = (d / "daemon.log").read_text()
    m = re.search(r"stopped after (\d+) ticks", log)
    assert daemon_code == 0 and m is not None, log[-2000:]
    assert client.returncode == 0, client_err
    return {"path": path, "log": log, "ticks": int(m.group(1)), "dir": d, "client": d / "client.mcap",
            "client_err": client_err}


_DECODED: dict[Path, tuple[dict[str, list[tuple[int, Any]]], dict[str, dict[str, str]]]] = {}


def _decode(path: Path) -> tuple[dict[str, list[tuple[int, Any]]], dict[str, dict[str, str]]]:
    """Every message of ``path`` by topic, decoded without wmm-qp: CDR by rosbags from the file's
    own ros2msg schemas, JSON by the json module; and the metadata records (decoded once a file)."""
    if path not in _DECODED:
        _DECODED[path] = _decode_file(path)
    return _DECODED[path]


def _decode_file(path: Path) -> tuple[dict[str, list[tuple[int, Any]]], dict[str, dict[str, str]]]:
    from mcap.reader import make_reader
    from rosbags.typesys import Stores, get_typestore
    from rosbags.typesys.msg import get_types_from_msg

    ts = get_typestore(Stores.EMPTY)  # no type known up front: each comes from the file
    out: dict[str, list[tuple[int, Any]]] = {}
    with open(path, "rb") as f:
        r = make_reader(f)
        assert r.get_header().profile == "ros2"
        for schema, ch, msg in r.iter_messages(log_time_order=False):
            assert schema is not None
            if ch.message_encoding == "cdr":
                assert schema.encoding == "ros2msg"
                if schema.name not in ts.types:
                    ts.register(get_types_from_msg(schema.data.decode(), schema.name))
                m = ts.deserialize_cdr(msg.data, schema.name)
            else:
                assert (ch.message_encoding, schema.encoding) == ("json", "jsonschema")
                m = json.loads(msg.data)
            out.setdefault(ch.topic, []).append((msg.log_time, m))
        meta = {md.name: dict(md.metadata) for md in r.iter_metadata()}
    return out, meta


def _files(path: Path) -> list[Path]:
    files, k = [path], 1
    while (p := path.with_name(f"{path.stem}.{k:03d}{path.suffix}")).is_file():
        files.append(p)
        k += 1
    return files


def test_every_tick_is_recorded_and_decodes_independently(recording: dict[str, Any]) -> None:
    files = _files(recording["path"])
    assert len(files) >= 2, "the 2 s split made no second file"
    ticks: list[int] = []
    counts: Counter[str] = Counter()
    for f in files:
        msgs, meta = _decode(f)
        assert meta["wmm_qp"]["format"] == "wmm-qp recording 1" and "wmm_qp_end" in meta
        for topic, ms in msgs.items():
            counts[topic] += len(ms)
            stamps = [t for t, _ in ms]
            assert stamps == sorted(stamps), f"{f.name} {topic}: log times go back"
        rows = [m for _, m in msgs["/wmm/tick"]]
        ticks += [r["tick"] for r in rows]
        assert int(meta["wmm_qp"]["first_tick"]) == rows[0]["tick"]
        assert msgs["/wmm/mode"][0][1]["previous"] is None  # each file says its mode
        js = msgs["/arm/joint_states"]
        assert list(js[-1][1].name) == json.loads(meta["wmm_qp"]["arm_joints"])
        assert js[-1][1].position.shape == (7,) and all(math.isfinite(x) for x in js[-1][1].position)
        tf = msgs["/tf"][-1][1]
        assert tf.transforms[0].child_frame_id == "base" and len(tf.transforms) > 7
        # one measured state a tick from the first state on; one command message a command sent
        with_state = sum(1 for r in rows if r["q_base"][0] is not None or r["call"] != "none")
        assert len(js) <= len(rows)
        sent = sum(1 for r in rows if r["seq"] >= 0)
        assert len(msgs["/arm/joint_commands"]) == len(msgs["/base/wheel_commands"]) == sent
        assert len(msgs["/odom"]) == len(msgs["/ee/pose"]) == len(js) and with_state > 0
    n = recording["ticks"]
    assert ticks == list(range(n)), "a tick is missing, repeated or out of order"
    assert counts["/wmm/tick"] == counts["/wmm/telemetry"] == n
    for topic in ("/arm/joint_states", "/base/wheel_states", "/arm/joint_commands", "/base/wheel_commands",
                  "/ee/pose", "/ee/target", "/tf", "/odom", "/wmm/mode", "/wmm/status", "/wmm/events"):
        assert counts[topic] > 0, topic
    modes = [m for f in files for _, m in _decode(f)[0]["/wmm/mode"]]
    assert {"track", "dm_nullspace", "hold"} <= {m["mode"] for m in modes}
    assert f"recorded {n} ticks (0 lost)" in recording["log"]


def test_replay_reproduces_every_command_with_the_default_solver(recording: dict[str, Any]) -> None:
    r = cli("replay", str(recording["path"]), "--json", timeout=300)
    assert r.returncode == 0, r.stderr
    rep = json.loads(r.stdout)
    assert rep["solver"] == "proxsuite" and rep["proxsuite_build"] == rep["proxsuite_recorded"]
    assert rep["ticks_read"] == recording["ticks"] and len(rep["files"]) >= 2
    assert rep["ticks"] > 0.9 * recording["ticks"]
    assert (rep["differing"], rep["first_difference"], rep["error"]) == (0, None, None)
    obstacles = [m for f in _files(recording["path"]) for _, m in _decode(f)[0].get("/wmm/events", [])
                 if m["kind"] == "obstacles" and m["data"]["obstacles"]]
    assert obstacles, "the live obstacle never reached the recording"


def test_replay_with_another_config_shows_its_differences(recording: dict[str, Any], tmp_path: Path) -> None:
    from wmm_qp.config import default_config_dir

    text = (default_config_dir() / "controller.toml").read_text()
    changed = tmp_path / "k_x.toml"
    changed.write_text(re.sub(r"(?m)^K_x = 10\.0", "K_x = 5.0", text, count=1))
    assert changed.read_text() != text
    r = cli("replay", str(recording["path"]), "--controller-config", str(changed), "--json", timeout=300)
    assert r.returncode == 1, r.stderr
    rep = json.loads(r.stdout)
    assert rep["differing"] > 0 and rep["first_difference"]["max_abs_delta"] > 0
    assert 0 <= rep["first_difference"]["tick"] < recording["ticks"]


def test_a_truncated_or_corrupt_file_gives_one_line_and_replays_what_it_can(recording: dict[str, Any],
                                                                           tmp_path: Path) -> None:
    from mcap.reader import make_reader

    files = _files(recording["path"])
    big = max(range(len(files)), key=lambda k: files[k].stat().st_size)
    with open(files[big], "rb") as f:  # a chunk of messages in its middle: the damage falls among ticks
        summary = make_reader(f).get_summary()
    assert summary is not None
    chunks = sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)
    chunk = chunks[len(chunks) // 2]
    mid = chunk.chunk_start_offset + chunk.chunk_length // 2

    def flip(b: bytes) -> bytes:
        return b[:mid] + bytes(x ^ 0xFF for x in b[mid:mid + 64]) + b[mid + 64:]

    cut, bad = tmp_path / "cut", tmp_path / "bad"
    for d, damage in ((cut, lambda b: b[:mid]), (bad, flip)):
        d.mkdir()
        for k, f2 in enumerate(files):  # a copy of the rotated recording, one of its files damaged
            (d / f2.name).write_bytes(damage(f2.read_bytes()) if k == big else f2.read_bytes())
    for d in (cut, bad):
        r = cli("replay", str(d / files[0].name), "--json", timeout=300)
        assert r.returncode == 1, r.stderr
        errors = [ln for ln in r.stderr.splitlines() if "error" in ln]  # the others: progress lines
        assert len(errors) == 1 and errors[0].startswith("wmm-qp replay: error:") and "Traceback" not in r.stderr
        rep = json.loads(r.stdout)
        assert rep["error"] and rep["ticks"] > 0 and rep["ticks_read"] < recording["ticks"]
        assert rep["differing"] == 0  # the readable part replays as recorded
    r = cli("replay", str(tmp_path / "none.mcap"))
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "no such file" in r.stderr


def test_serve_record_without_the_extra_names_it(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
                                               tmp_path: Path) -> None:
    from wmm_qp_tools import cli as tools_cli

    monkeypatch.setitem(sys.modules, "mcap", None)  # import mcap → ImportError, as without the extra
    assert tools_cli.main(["serve", "--record", str(tmp_path / "x.mcap")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "pip install 'wmm-qp[record]'" in err
    assert not (tmp_path / "x.mcap").exists()
    assert tools_cli.main(["serve", "--split-size", "5"]) == 2
    assert "need --record" in capsys.readouterr().err


def test_the_runtime_imports_without_the_extra() -> None:
    code = ("import sys; sys.modules['mcap'] = None; sys.modules['rosbags'] = None; "
            "import wmm_qp_service.daemon, wmm_qp_service.commands.serve, wmm_qp_service.recording.options")
    assert subprocess.run([sys.executable, "-c", code], capture_output=True, timeout=120).returncode == 0


def test_a_client_records_the_robot_keys_and_plot_draws_both(recording: dict[str, Any], tmp_path: Path) -> None:
    msgs, meta = _decode(recording["client"])
    assert meta["wmm_qp"]["host"] == "record" and "wmm_qp_end" in meta
    for topic in ("/arm/joint_states", "/base/wheel_states", "/arm/joint_commands", "/base/wheel_commands",
                  "/odom", "/tf", "/ee/pose", "/wmm/status", "/wmm/telemetry", "/wmm/mode"):
        assert msgs.get(topic), (topic, recording["client_err"])
    assert {"track", "dm_nullspace", "hold"} <= {m["mode"] for _, m in msgs["/wmm/mode"]}
    # every command the daemon recorded went over the wire: the client saw at most as many
    assert len(msgs["/arm/joint_commands"]) <= recording["ticks"]
    r = cli("replay", str(recording["client"]))
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "serve --record" in r.stderr
    for src, out in ((recording["path"], tmp_path / "host"), (recording["client"], tmp_path / "client")):
        r = cli("plot", str(src), "--out", str(out))
        assert r.returncode == 0, r.stderr
        names = {p.name for p in out.glob("*.png")}
        assert {"joints.png", "wheels.png", "ee.png", "dm.png", "timing.png"} <= names, names
        assert all(p.stat().st_size > 10_000 for p in out.glob("*.png"))


def test_the_console_plays_the_hosts_and_the_clients_recording(recording: dict[str, Any]) -> None:
    """``console --play``'s link on both recordings of the run (the rotated host's read as one): every
    mode of the run at its time, the states in time order, the host's states those of its ticks."""
    from wmm_qp_service.console.playback import RecordingLink
    from wmm_qp_service.console.timeline import load_timeline

    host_states: int | None = None
    for src in (recording["path"], recording["client"]):
        tl = load_timeline(src)
        link = RecordingLink(tl, src)
        assert tl.error is None and tl.states > 100 and np.all(np.diff(tl.q_arm.t) >= 0)
        assert link.attach().info.joints == json.loads(tl.meta["arm_joints"])
        seen = {s.mode for tau in np.linspace(0.0, tl.duration, 200) if (s := link.status(float(tau))) is not None}
        assert {"track", "dm_nullspace", "hold"} <= seen, (src, seen)
        st = link.state(tl.duration)
        assert st is not None and len(st.q_arm) == len(json.loads(tl.meta["arm_joints"]))
        if host_states is None:
            host_states = tl.states
            msgs, _ = _decode(src)
            assert len(tl.files) >= 2 and tl.states >= len(msgs["/arm/joint_states"])
        # (no count compared between the two: the client records every state the sim publishes
        # while it runs, the daemon one per tick it made; which is larger depends on the timing)


def test_the_embedded_core_records_every_tick_and_replays(tmp_path: Path) -> None:
    from wmm_qp_service.client import Client
    from wmm_qp_service.processes import Stack, isolated_config

    path = tmp_path / "emb.mcap"
    with Stack(isolated_config(), rate_hz=500.0, log_dir=tmp_path, embedded=True,
               extra_daemon_args=["--record", str(path)]) as st, Client(st.svc) as c:
        x0 = list(ready(c).status.x)
        c.set_mode("track")
        for k in range(150):
            c.send_setpoint([x0[0] + 0.0003 * k, x0[1], x0[2]])
            time.sleep(0.01)
        st.kill("embedded", signal.SIGINT)
        assert st.procs["embedded"].wait(timeout=600) == 0
    log = (tmp_path / "embedded.log").read_text()
    m = re.search(r", (\d+) ticks, ", log)
    assert m is not None and f"recorded {m.group(1)} ticks (0 lost)" in log, log[-1500:]
    msgs, meta = _decode(path)
    assert meta["wmm_qp"]["host"] == "embedded"
    assert [r["tick"] for _, r in msgs["/wmm/tick"]] == list(range(int(m.group(1))))
    r = cli("replay", str(path), "--json")
    rep = json.loads(r.stdout)
    assert r.returncode == 0 and rep["differing"] == 0 and rep["ticks"] > 0, r.stderr
