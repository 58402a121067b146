"""Replay: the controller run again on a recording's ticks, its commands compared with the recorded ones.

The recording holds, for every tick, what the host asked of its controller (``/wmm/tick``: ``step``
with the state and the reference it handed over, ``safe_stop`` with the state it braked from, or
nothing) and the command it got, plus everything that changes the controller between ticks: each
re-latch (``latches``: the controller's warm starts reset), the latency margin of bounds (13), the
live obstacle sets (``/wmm/events``). :func:`replay` rebuilds the controller from the recording's
metadata (the robot file, the controller config as the host ran it, the scene), or from another
controller config, and makes the same calls in the same order: the open-loop replay of the
controller (the states are the recorded ones whatever it commands now).

Bit for bit: a float survives the JSON of ``/wmm/tick`` exactly (shortest round-trip decimal), and
the controller is deterministic given its calls — with DAQP and OSQP in any process; with
proxsuite when the same build is loaded (docs/recording.md "Replay": its AVX builds' last bits
depend on where their buffers lie in memory, so the replay loads the build the recording names in
``proxsuite_build`` and reports when it differs).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import msgspec
import numpy as np

import wmm_qp as w
from wmm_qp.config.shapes import ShapeConfig

from . import RecordingError, load_proxsuite, proxsuite_build
from .layout import config_from_dict
from .reader import RecordingReader, chain

TICK_TOPICS = {"/wmm/tick", "/wmm/events"}


class ReplayReport(msgspec.Struct):
    """What :func:`replay` found (``wmm-qp replay --json``).

    Attributes:
        ticks: controller calls replayed (ticks that called ``step`` or ``safe_stop``).
        differing: of them, commands that differ from the recorded ones (any bit).
        first_difference: the first such tick and its max |Δ| over the rates, or None.
        max_abs_delta: the largest |Δ| [rad/s or m/s] over every replayed tick.
        ticks_read: ticks read from the recording (every tick, with or without a call).
        files: the files read.
        config: "recorded" or the controller config file used instead.
        solver: the QP solver of the replayed controller.
        error: why reading stopped before the recording's end (None: read to its end).
        proxsuite_build: proxsuite's build the replay ran ("" when not loaded), and
        proxsuite_recorded: the recording host's (a different build: its last bits may differ).
    """

    ticks: int
    differing: int
    first_difference: dict[str, float] | None
    max_abs_delta: float
    ticks_read: int
    files: list[str]
    config: str
    solver: str
    error: str | None = None
    proxsuite_build: str = ""
    proxsuite_recorded: str = ""


def _vec(v: list[float | None] | None) -> np.ndarray | None:
    """A recorded vector (NaN is null in JSON); None when absent (every entry null)."""
    if v is None:
        return None
    if not v:
        return np.empty(0)
    if all(x is None for x in v):
        return None
    return np.array([math.nan if x is None else x for x in v], dtype=float)


def _shapes(raw: list[dict[str, Any]]) -> tuple[ShapeConfig, ...]:
    out = []
    for d in raw:
        vel = d.get("velocity")
        out.append(ShapeConfig(name=d["name"], link=d["link"], kind=d["kind"], size=np.array(d["size"], dtype=float),
                               xyz=np.array(d["xyz"], dtype=float), rpy=np.array(d["rpy"], dtype=float),
                               exempt=tuple(d.get("exempt", ())),
                               velocity=None if vel is None else np.array(vel, dtype=float)))
    return tuple(out)


def _max_delta(a: np.ndarray, b: np.ndarray | None) -> float:
    """max |a − b|; inf where one is NaN and the other not, or the sizes differ; 0 for the same bits."""
    if b is None or a.shape != b.shape:
        return math.inf
    if np.array_equal(a.view(np.int64), b.view(np.int64)):
        return 0.0
    d = np.abs(a - b)
    d[np.isnan(a) != np.isnan(b)] = math.inf
    d[np.isnan(a) & np.isnan(b)] = 0.0
    return float(d.max()) if d.max() > 0 else 5e-324  # bits differ (e.g. -0.0 and 0.0): a difference


def controller_for(meta: dict[str, str],
                   controller_config: str | Path | None) -> tuple[w.Controller, w.ControllerConfig, Any]:
    """The controller as the recording's host built it (or with ``controller_config``'s settings, at
    the recording's rate and latency margin), warmed up as the host did; and its scene.

    Raises:
        RecordingError: the recording lacks its metadata, or its robot file is gone.
    """
    from wmm_qp.scene import load_scene

    if not meta.get("controller_config"):
        raise RecordingError("not a wmm-qp recording (no wmm_qp metadata with a controller config)")
    robot_file = meta.get("robot_file", "")
    if not robot_file or not Path(robot_file).is_file():
        raise RecordingError(f"the recording's robot file {robot_file!r} is not here "
                             f"(replay rebuilds the model from it)")
    recorded = config_from_dict(msgspec.json.decode(meta["controller_config"]))
    if controller_config is not None:
        cfg = w.load_controller_config(controller_config).with_(rate_hz=recorded.rate_hz,
                                                                  state_latency=recorded.state_latency)
    else:
        cfg = recorded
    load_proxsuite(meta.get("proxsuite_build", ""))  # the recording's build, unless proxsuite is loaded already
    model = w.WmmModel(w.load_robot_config(robot_file))
    ctl = w.make_controller(meta.get("controller", cfg.kind), model, cfg)
    scene = load_scene(meta["scene"] if meta.get("scene") else None)
    ctl.set_scene(scene)  # as ControlCore.__init__: the scene, then the warm-up
    ctl.warm_up()
    return ctl, cfg, scene


def replay(path: str | Path, controller_config: str | Path | None = None,
           progress: Callable[[int], None] | None = None) -> ReplayReport:
    """Replay the recording at ``path`` (and the rotated files that follow it).

    Args:
        path: the recording's (first) file.
        controller_config: another controller config (None: the recorded one).
        progress: told the ticks read so far, now and then.

    Raises:
        RecordingError: not a recording, or nothing of it readable.
    """
    files = chain(path)
    ticks: list[dict[str, Any]] = []
    obstacles: dict[int, list[dict[str, Any]]] = {}
    meta: dict[str, str] = {}
    error = None
    rid = None
    read_files = []
    for f in files:
        rd = RecordingReader(f)
        for topic, _, data in rd.messages(TICK_TOPICS):
            d = msgspec.json.decode(data)
            if topic == "/wmm/tick":
                ticks.append(d)
                if progress is not None and len(ticks) % 5000 == 0:
                    progress(len(ticks))
            elif d.get("kind") == "obstacles":
                obstacles[int(d["tick"])] = d["data"]["obstacles"]
        if rid is not None and rd.meta.get("recording_id") != rid:
            break  # a file of another recording that happens to share the name
        read_files.append(str(f))
        if not meta:
            meta, rid = rd.meta, rd.meta.get("recording_id")
        if rd.error is not None:
            error = rd.error
            break
    if not meta:
        raise RecordingError(error or f"{path}: not a wmm-qp recording (no wmm_qp metadata)")
    if meta.get("host") == "record":
        raise RecordingError(f"{path}: a client's recording (wmm-qp record) holds no controller inputs: replay "
                             f"needs the host's own, wmm-qp serve --record")
    if not ticks:
        raise RecordingError(error or f"{path}: no ticks recorded")
    ctl, cfg, scene = controller_for(meta, controller_config)
    build = proxsuite_build()
    ticks.sort(key=lambda d: int(d["tick"]))
    latches = 0
    n = differing = 0
    first: dict[str, float] | None = None
    worst = 0.0
    pending = sorted(obstacles)
    for d in ticks:
        tick = int(d["tick"])
        while pending and pending[0] <= tick:
            ctl.set_obstacles(scene.obstacles + _shapes(obstacles[pending.pop(0)]))
        if int(d["latches"]) != latches:
            latches = int(d["latches"])
            ctl.reset()
        call = d["call"]
        if call not in ("step", "safe_stop"):
            continue
        ctl.set_latency(float(d["latency"]))
        q_base, q_arm, v_arm, wheels = (_vec(d[k]) for k in ("q_base", "q_arm", "v_arm", "wheel_speeds"))
        state = w.RobotState(q_base=q_base, q_arm=q_arm, v_arm=v_arm, wheel_speeds=wheels)  # type: ignore[arg-type]
        if call == "step":
            ref = w.Reference(mode=w.Mode(d["mode"]), x_d=_vec(d["x_d"]), xd_d=_vec(d["xd_d"]),  # type: ignore[arg-type]
                              direction=_vec(d["direction"]), quat_d=_vec(d["quat_d"]),
                              omega_d=_vec(d["omega_d"]))  # type: ignore[arg-type]
            cmd = ctl.step(state, ref)
        else:
            cmd = ctl.safe_stop(state, "replay")
        n += 1
        delta = max(_max_delta(cmd.wheel_speeds, _vec(d["cmd_wheel_speeds"])),
                    _max_delta(cmd.arm_rates, _vec(d["cmd_arm_rates"])))
        if delta > 0:
            differing += 1
            worst = max(worst, delta)
            if first is None:
                first = {"tick": tick, "max_abs_delta": delta}
    solver = cfg.qp.solver if meta.get("controller", cfg.kind) == "qp" else "none"
    return ReplayReport(ticks=n, differing=differing, first_difference=first, max_abs_delta=worst,
                        ticks_read=len(ticks), files=read_files,
                        config=str(controller_config) if controller_config is not None else "recorded",
                        solver=solver, error=error, proxsuite_build=build,
                        proxsuite_recorded=meta.get("proxsuite_build", ""))
