"""Plots of a recording (``wmm-qp plot FILE.mcap --out DIR``): what each tick did, against its limits.

Each figure shares the time axis [s since the recording's first message], with the modes as shaded
spans and each new fault or command reason as a red line:

* ``joints.png``: each arm joint's position (measured), velocity (commanded; measured dotted) and
  acceleration (the change between consecutive commands × the control rate) against the robot
  file's limits of (13);
* ``wheels.png``: each wheel's speed (commanded; measured dotted) and acceleration against its limits;
* ``ee.png``: the EE (forward kinematics of the measured state) against its target, per axis, and
  the distance between them;
* ``dm.png``: DM (eq. (8)) and σ_min of the arm's Jacobian, with the floor σ_f;
* ``timing.png``: each tick's work and the controller's step [µs] against the period, the ticks
  past it (misses).

It reads the ROS 2 channels with ``rosbags``' own type store and the JSON channels as JSON.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import msgspec
import numpy as np

CDR = {"/arm/joint_states", "/arm/joint_commands", "/base/wheel_states", "/base/wheel_commands", "/ee/pose",
       "/ee/target"}
JSON = {"/wmm/telemetry", "/wmm/mode", "/wmm/status", "/wmm/events"}
MODE_COLOURS = {"hold": "#dddddd", "track": "#cfe8ff", "dm_cartesian": "#ffe7c2", "dm_nullspace": "#d9f2d0"}


class Series:
    """A recording's data as arrays over time [s]."""

    def __init__(self) -> None:
        self.t0: float | None = None
        self.raw: dict[str, list[tuple[float, Any]]] = {}
        self.meta: dict[str, str] = {}
        self.error: str | None = None

    def arrays(self, topic: str, pick: Callable[[Any], Any]) -> tuple[np.ndarray, np.ndarray]:
        rows = self.raw.get(topic, [])
        if not rows:
            return np.empty(0), np.empty((0, 0))
        t = np.array([r[0] for r in rows])
        return t, np.array([pick(r[1]) for r in rows], dtype=float)


def load(path: str | Path, progress: Callable[[int], None] | None = None) -> Series:
    """Every message of the plotted channels of the recording at ``path`` (and its rotated files)."""
    from rosbags.typesys import Stores, get_typestore
    from wmm_qp_service.recording.reader import RecordingReader, chain

    ts = get_typestore(Stores.ROS2_HUMBLE)
    names = {"/arm/joint_states": "sensor_msgs/msg/JointState", "/arm/joint_commands": "sensor_msgs/msg/JointState",
             "/base/wheel_states": "sensor_msgs/msg/JointState", "/base/wheel_commands": "sensor_msgs/msg/JointState",
             "/ee/pose": "geometry_msgs/msg/PoseStamped", "/ee/target": "geometry_msgs/msg/PoseStamped"}
    s = Series()
    n = 0
    for f in chain(path):
        rd = RecordingReader(f)
        for topic, ns, data in rd.messages(CDR | JSON):
            if s.t0 is None:
                s.t0 = ns * 1e-9
            m = ts.deserialize_cdr(data, names[topic]) if topic in CDR else msgspec.json.decode(data)
            s.raw.setdefault(topic, []).append((ns * 1e-9 - s.t0, m))
            n += 1
            if progress is not None and n % 20000 == 0:
                progress(n)
        if not s.meta:
            s.meta = rd.meta
        if rd.error is not None:
            s.error = rd.error
            break
    return s


def _spans(s: Series, axes: list[Any]) -> None:
    """The modes as shaded spans, new faults and command reasons as red lines, on every axis."""
    modes = s.raw.get("/wmm/mode", [])
    end = max((rows[-1][0] for rows in s.raw.values() if rows), default=0.0)
    for i, (t, m) in enumerate(modes):
        t1 = modes[i + 1][0] if i + 1 < len(modes) else end
        for ax in axes:
            ax.axvspan(t, t1, color=MODE_COLOURS.get(m["mode"], "#eeeeee"), alpha=0.6, lw=0, zorder=0)
    faults = []
    last = ""
    for t, st in s.raw.get("/wmm/status", []):
        code = st["status"].get("last_fault_code", "")
        if code and code != last:
            faults.append(t)
        last = code
    faults += [t for t, e in s.raw.get("/wmm/events", []) if e["kind"] == "reason" and e["data"].get("reason")]
    for t in faults:
        for ax in axes:
            ax.axvline(t, color="red", lw=0.8, alpha=0.7, zorder=1)


def _legend(fig: Any, s: Series) -> None:
    import matplotlib.patches as mpatches
    from matplotlib.lines import Line2D

    seen = {m["mode"] for _, m in s.raw.get("/wmm/mode", [])}
    handles: list[Any] = [mpatches.Patch(color=c, label=k) for k, c in MODE_COLOURS.items() if k in seen]
    handles.append(Line2D([], [], color="red", lw=0.8, label="fault / command reason"))
    fig.legend(handles=handles, loc="upper right", ncol=len(handles), fontsize=8, frameon=False)


def plot(s: Series, out: str | Path) -> list[Path]:
    """Write the figures of the module docstring into ``out``; the files written."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    import wmm_qp as w

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    robot = w.load_robot_config(s.meta["robot_file"]) if Path(s.meta.get("robot_file", "")).is_file() else None
    joints = list(msgspec.json.decode(s.meta.get("arm_joints", "[]")))
    wheels = list(msgspec.json.decode(s.meta.get("wheels", "[]")))
    title = f"{s.meta.get('robot', '?')} ({s.meta.get('robot_name', '?')}), {s.meta.get('started', '')}"
    written: list[Path] = []
    # a command's acceleration is its change over the control period, as bounds (13) count it (the
    # messages' wall stamps jitter); a tick that sent nothing makes the next change span two periods
    rate = float(s.meta.get("rate_hz", "nan"))

    def save(fig: Any, name: str) -> None:
        fig.suptitle(f"{name.split('.')[0]}: {title}", fontsize=10, x=0.01, ha="left")
        _legend(fig, s)
        fig.tight_layout(rect=(0, 0, 1, 0.96))
        p = out / name
        fig.savefig(p, dpi=90)
        plt.close(fig)
        written.append(p)

    t_js, q = s.arrays("/arm/joint_states", lambda m: m.position)
    t_jc, qd_cmd = s.arrays("/arm/joint_commands", lambda m: m.velocity)
    _, qd = s.arrays("/arm/joint_states", lambda m: m.velocity)
    if len(joints) and (len(t_js) or len(t_jc)):
        fig, axs = plt.subplots(len(joints), 3, figsize=(13, 1.6 * len(joints) + 1), sharex=True, squeeze=False)
        acc = np.diff(qd_cmd, axis=0) * rate if len(t_jc) > 1 else np.empty((0, len(joints)))
        for j, name in enumerate(joints):
            a_p, a_v, a_a = axs[j]
            if len(t_js):
                a_p.plot(t_js, q[:, j], lw=0.9)
                a_v.plot(t_js, qd[:, j], lw=0.7, ls=":", color="gray", label="measured")
            if len(t_jc):
                a_v.plot(t_jc, qd_cmd[:, j], lw=0.9, label="commanded")
            if len(acc):
                a_a.plot(t_jc[1:], acc[:, j], lw=0.6)
            if robot is not None:
                arm = robot.arm
                for ax, lo, hi in ((a_p, arm.position_lower[j], arm.position_upper[j]),
                                   (a_v, -arm.velocity_max[j], arm.velocity_max[j]),
                                   (a_a, -arm.acceleration_max[j], arm.acceleration_max[j])):
                    for v in (lo, hi):
                        if math.isfinite(v):
                            ax.axhline(v, color="k", ls="--", lw=0.8)
            a_p.set_ylabel(name, fontsize=8)
            _spans(s, [a_p, a_v, a_a])
        axs[0][0].set_title("position [rad | m]", fontsize=9)
        axs[0][1].set_title("velocity [rad/s | m/s]: commanded, measured dotted", fontsize=9)
        axs[0][2].set_title("acceleration of the command [rad/s² | m/s²]", fontsize=9)
        for ax in axs[-1]:
            ax.set_xlabel("t [s]")
        save(fig, "joints.png")

    t_wc, w_cmd = s.arrays("/base/wheel_commands", lambda m: m.velocity)
    t_ws, w_meas = s.arrays("/base/wheel_states", lambda m: m.velocity)
    if len(wheels) and len(t_wc):
        fig, axs = plt.subplots(len(wheels), 2, figsize=(11, 1.6 * len(wheels) + 1), sharex=True, squeeze=False)
        acc = np.diff(w_cmd, axis=0) * rate if len(t_wc) > 1 else np.empty((0, len(wheels)))
        for k, name in enumerate(wheels):
            a_v, a_a = axs[k]
            if len(t_ws):
                a_v.plot(t_ws, w_meas[:, k], lw=0.7, ls=":", color="gray")
            a_v.plot(t_wc, w_cmd[:, k], lw=0.9)
            if len(acc):
                a_a.plot(t_wc[1:], acc[:, k], lw=0.6)
            if robot is not None and len(robot.base.wheel_speed_max):
                for ax, lim in ((a_v, robot.base.wheel_speed_max[k]), (a_a, robot.base.wheel_acceleration_max[k])):
                    for v in (-lim, lim):
                        ax.axhline(v, color="k", ls="--", lw=0.8)
            a_v.set_ylabel(name, fontsize=8)
            _spans(s, [a_v, a_a])
        axs[0][0].set_title("wheel speed [rad/s]: commanded, measured dotted", fontsize=9)
        axs[0][1].set_title("acceleration of the command [rad/s²]", fontsize=9)
        for ax in axs[-1]:
            ax.set_xlabel("t [s]")
        save(fig, "wheels.png")

    def pos(m: Any) -> list[float]:
        p = m.pose.position
        return [p.x, p.y, p.z]

    t_ee, ee = s.arrays("/ee/pose", pos)
    t_tg, tg = s.arrays("/ee/target", pos)
    if len(t_ee):
        fig, axs = plt.subplots(4, 1, figsize=(11, 8), sharex=True)
        for i, axis in enumerate("xyz"):
            axs[i].plot(t_ee, ee[:, i], lw=0.9, label="EE (measured)")
            if len(t_tg):
                axs[i].plot(t_tg, tg[:, i], lw=0.9, ls="--", label="target")
            axs[i].set_ylabel(f"{axis} [m]")
        axs[0].legend(fontsize=8, loc="lower left")
        if len(t_tg):
            err = np.linalg.norm(np.array([np.interp(t_tg, t_ee, ee[:, i]) for i in range(3)]).T - tg, axis=1)
            axs[3].plot(t_tg, err * 1e3, lw=0.8)
        axs[3].set_ylabel("|EE (last state) − target| [mm]", fontsize=8)
        axs[3].set_xlabel("t [s]")
        _spans(s, list(axs))
        save(fig, "ee.png")

    t_tel, tel = s.arrays("/wmm/telemetry", lambda m: [_f(m.get("dm")), _f(m.get("sigma_min")), _f(m.get("tick_us")),
                                                       _f(m.get("step_us"))])
    if len(t_tel):
        fig, axs = plt.subplots(2, 1, figsize=(11, 5), sharex=True)
        axs[0].plot(t_tel, tel[:, 0], lw=0.9)
        axs[0].set_ylabel("DM (H2, eq. (8))")
        axs[1].plot(t_tel, tel[:, 1], lw=0.9)
        floor = _config(s.meta).get("sigma_min_floor")
        if isinstance(floor, (int, float)) and floor > 0:
            axs[1].axhline(floor, color="k", ls="--", lw=0.8, label=f"σ_f = {floor:g}")
            axs[1].legend(fontsize=8, loc="lower left")
        axs[1].set_ylabel("σ_min(J_m) [m/rad]")
        axs[1].set_xlabel("t [s]")
        _spans(s, list(axs))
        save(fig, "dm.png")

        period_us = 1e6 / float(s.meta.get("rate_hz", "nan"))
        fig, ax = plt.subplots(1, 1, figsize=(11, 4))
        ax.plot(t_tel, tel[:, 2], lw=0.6, label="tick's work (the previous tick's)")
        ax.plot(t_tel, tel[:, 3], lw=0.6, label="controller step")
        misses = int(np.sum(tel[:, 2] > period_us)) if math.isfinite(period_us) else 0
        if math.isfinite(period_us):
            ax.axhline(period_us, color="k", ls="--", lw=0.8,
                       label=f"period {period_us:.0f} µs ({misses} ticks past it)")
        ax.set_yscale("log")
        ax.set_ylabel("[µs]")
        ax.set_xlabel("t [s]")
        ax.legend(fontsize=8, loc="upper left")
        _spans(s, [ax])
        save(fig, "timing.png")
    return written


def _f(v: Any) -> float:
    return math.nan if v is None else float(v)


def _config(meta: dict[str, str]) -> dict[str, Any]:
    try:
        d = msgspec.json.decode(meta.get("controller_config", "{}"))
        return d if isinstance(d, dict) else {}
    except msgspec.DecodeError:
        return {}
