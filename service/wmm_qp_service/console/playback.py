"""``wmm-qp console --play FILE``: the console on a recording instead of a live robot.

:class:`RecordingLink` has the read side of :class:`~.link.RobotLink` (``state``, ``status``,
``truth``, ``attach``, ``robots``, ``source``) and answers it from a :class:`~.timeline.Timeline`
at the playback time of its :class:`PlaybackClock`; its commands do nothing (a recording is not
driven). :class:`PlaybackPanel` is the page's "Playback" folder: play/pause, a time slider that
seeks, the speed, whether playback loops at the end. No Zenoh session is opened.
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import msgspec
import numpy as np

from ..protocol import InfoMsg, StateMsg, StatusMsg, TruthMsg
from .link import Attached, robot_description
from .timeline import Channel, Timeline

SPEEDS = (0.1, 0.25, 0.5, 1.0, 2.0, 4.0, 10.0)
PLOT_POINTS = 1500
"""A plot's 30 s window is thinned to at most this many points (a 1 kHz recording has 30000)."""
INSTANCE = "recording"


class PlaybackClock:
    """Playback time τ [s] in [0, ``duration``] that runs at ``speed`` × the wall clock while playing.

    At the end it starts again from 0 (``loop``; :attr:`loops` counts the restarts) or stops there
    (not :attr:`playing` any more). ``clock`` is the wall clock [s] (a test passes its own).
    """

    def __init__(self, duration: float, speed: float = 1.0, loop: bool = True,
                 clock: Callable[[], float] = time.monotonic) -> None:
        if not speed > 0:
            raise ValueError(f"a playback speed is > 0, got {speed:g}")
        self.duration, self.speed, self.loop = max(0.0, duration), speed, loop
        self._clock = clock
        self._tau, self._anchor = 0.0, clock()
        self.playing = True
        self.loops = 0

    def now(self) -> float:
        """τ now (at the end: looped back, or stopped at ``duration``)."""
        if not self.playing:
            return self._tau
        tau = self._tau + self.speed * (self._clock() - self._anchor)
        if tau >= self.duration:
            if self.loop and tau == self.duration:
                return tau  # at the end (a seek there): the last state until time moves on
            if self.loop and self.duration > 0:
                self.loops += int(tau // self.duration)
                self._tau, self._anchor = tau % self.duration, self._clock()
                return self._tau
            self._tau, self.playing = self.duration, False
            return self._tau
        return tau

    def seek(self, tau: float) -> None:
        """Go to ``tau`` [s] (clamped into the recording), playing on if it was."""
        self._tau, self._anchor = min(max(0.0, float(tau)), self.duration), self._clock()

    def play(self) -> None:
        """Play from here (from the start when stopped at the end)."""
        if not self.playing:
            self.seek(0.0 if self._tau >= self.duration else self._tau)
            self.playing = True

    def pause(self) -> None:
        self._tau = self.now()
        self.playing = False

    def set_speed(self, speed: float) -> None:
        if not speed > 0:
            raise ValueError(f"a playback speed is > 0, got {speed:g}")
        self.seek(self.now())
        self.speed = speed

    @property
    def at_end(self) -> str:
        """What happens at the end, for the panel."""
        return "loops" if self.loop else "stops"


@dataclass(frozen=True)
class PlaybackService:
    """The two fields of a service config the console shows (``robot``, ``prefix``)."""

    robot: str
    prefix: str


class RecordingLink:
    """The console's link to a recording: what :class:`~.link.RobotLink` reads, at the playback time.

    Args:
        timeline: the recording (:func:`~.timeline.load_timeline`).
        path: its file (shown on the page).
        fallback: the robot file to draw when the recording's is not here (``--robot-config``).
        speed, loop, clock: the :class:`PlaybackClock`'s.
    """

    playback = True
    source = "playback"

    def __init__(self, timeline: Timeline, path: str | Path, fallback: Path | None = None, speed: float = 1.0,
                 loop: bool = True, clock: Callable[[], float] = time.monotonic) -> None:
        self.timeline = tl = timeline
        self.path = Path(path)
        self.fallback = fallback
        self.robot_id = tl.meta.get("robot") or "recording"
        self.svc = PlaybackService(robot=self.robot_id, prefix=f"recording {self.path.name}")
        self.clock = PlaybackClock(tl.duration, speed, loop, clock)
        self.attached: Attached | None = None
        self.ignored = 0
        self._error = tl.tracking_error()
        if len(tl.dm):
            self._dm = tl.dm
        else:  # a client's recording without telemetry: the statuses' DM
            self._dm = Channel(tl.statuses.t, np.array([[_f((s or {}).get("dm"))] for s in tl.statuses.v]))

    # ----------------------------------------------------------------- what RobotLink does
    def open(self) -> RecordingLink:
        return self

    def close(self) -> None:
        self.attached = None

    def robots(self, timeout: float = 0.5) -> list[str]:
        return [self.robot_id]

    def attach(self, robot_id: str | None = None, timeout: float = 10.0) -> Attached:
        """The recorded robot, described as its daemon would (:func:`~.link.robot_description`:
        the recording's robot file where it exists here, else the shipped file of its name, else
        ``fallback``).

        Raises:
            ConsoleError: none of them has the recording's joints.
        """
        if self.attached is not None:
            return self.attached
        meta = self.timeline.meta
        ctl: dict[str, Any] = {}
        if meta.get("controller_config"):
            decoded = msgspec.json.decode(meta["controller_config"])
            ctl = decoded if isinstance(decoded, dict) else {}
        first = self.status(self.timeline.q_arm.t[0])
        st = first or StatusMsg(robot=self.robot_id, mode="hold", state_ok=True, safe_stop=False)
        joints = [str(j) for j in msgspec.json.decode(meta.get("arm_joints", "[]"))]
        wheels = [str(j) for j in msgspec.json.decode(meta.get("wheels", "[]"))]
        task = str((ctl.get("task") or {}).get("kind", "pose" if st.quat_d else "position"))
        info = InfoMsg(robot=self.robot_id, status=st, joints=joints, wheels=wheels, task=task,
                       config={"robot": {"name": meta.get("robot_name", ""), "file": meta.get("robot_file", "")}},
                       n_arm=len(joints), n_wheels=len(wheels))
        robot = robot_description(info, self.fallback)
        info = msgspec.structs.replace(info, base_kind=robot.base.kind)
        W = np.asarray(ctl.get("W") or robot.arm.default_W(), dtype=float)
        direction = np.asarray(ctl.get("direction") or [1.0, 0.0, 0.0], dtype=float)
        self.attached = Attached(robot_id=self.robot_id, info=info, robot=robot, W=W, direction=direction,
                                 pose_task=task == "pose")
        return self.attached

    def now(self) -> float:
        """The playback time [s since the recording's first message]."""
        return self.clock.now()

    def state(self, tau: float | None = None) -> StateMsg | None:
        """The state measured last at or before ``tau`` (None: now; no state yet: None)."""
        tl = self.timeline
        tau = self.now() if tau is None else tau
        i = tl.q_arm.index(tau)
        if i < 0:
            return None
        q_base = tl.q_base.at(tau)
        v_arm = tl.v_arm.v[i] if len(tl.v_arm) == len(tl.q_arm) else tl.v_arm.at(tau)
        wheels = tl.wheels.at(tau)
        return StateMsg(robot=self.robot_id, seq=i, t=tau, q_arm=_list(tl.q_arm.v[i]),
                        q_base=_list(q_base if q_base is not None else tl.q_base.v[0]), v_arm=_list(v_arm),
                        wheel_speeds=_list(wheels), tau=[], instance=INSTANCE)

    def truth(self, tau: float | None = None) -> TruthMsg | None:
        """The recorded EE (forward kinematics of the measured state; a recording holds no
        ground truth) and the base's odometry, as the console draws a truth (None: no EE yet)."""
        tl = self.timeline
        tau = self.now() if tau is None else tau
        ee, base = tl.ee.at(tau), tl.q_base.at(tau)
        if ee is None or base is None:
            return None
        return TruthMsg(robot=self.robot_id, t=tau, instance=INSTANCE, state_seq=tl.q_arm.index(tau),
                        base_true=_list(base), ee_true=_list(ee), contact_force=[math.nan] * 3)

    def status(self, tau: float | None = None) -> StatusMsg | None:
        """The status published last at or before ``tau``, with the mode, EE, target and DM
        recorded last at ``tau`` (those channels are recorded each tick, the status at ~10 Hz)."""
        tl = self.timeline
        tau = self.now() if tau is None else tau
        st, mode = tl.status(tau), tl.modes.at(tau)
        if st is None and mode is None:
            return None
        st = st or StatusMsg(robot=self.robot_id, mode=str(mode), state_ok=tl.q_arm.index(tau) >= 0,
                             safe_stop=False)
        ch: dict[str, Any] = {"mode": str(mode)} if mode else {}
        if (ee := tl.ee.at(tau)) is not None and np.isfinite(ee).all():
            ch["x"] = _list(ee)
        if (x_d := tl.target.at(tau)) is not None and np.isfinite(x_d).all():
            ch["x_d"] = _list(x_d)
            if st.quat_d and (q := tl.quat_d.at(tau)) is not None:
                ch["quat_d"] = _list(q)
        if (dm := self._dm.at(tau)) is not None and math.isfinite(dm[0]):
            ch["dm"] = float(dm[0])
        return msgspec.structs.replace(st, **ch)

    def history(self, tau: float | None = None,
                window: float = 30.0) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]:
        """The plots' data of the ``window`` [s] up to ``tau``: (t − τ, DM), (t − τ, ‖EE − target‖ [m])."""
        tau = self.now() if tau is None else tau
        out = []
        for ch in (self._dm, self._error):
            lo, hi = int(np.searchsorted(ch.t, tau - window, side="left")), ch.index(tau) + 1
            step = max(1, (hi - lo) // PLOT_POINTS)
            v = np.asarray(ch.v, float).reshape(len(ch.t), -1)[:, 0] if len(ch.t) else np.zeros(0)
            out.append((ch.t[lo:hi:step] - tau, np.ascontiguousarray(v[lo:hi:step])))
        return out[0], out[1]

    def extent(self) -> tuple[np.ndarray, np.ndarray]:
        """Every DM and every ‖EE − target‖ of the recording (the plots' y ranges: fixed for the whole playback)."""
        return self._dm.v[:, 0] if len(self._dm) else np.zeros(0), np.asarray(self._error.v, float)

    # ----------------------------------------------------------------- commands: none
    def send_setpoint(self, x: Sequence[float], q: Sequence[float] | None = None) -> None:
        self.ignored += 1

    def gripper(self, action: str, width: float = 0.0) -> None:
        self.ignored += 1

    def set_mode(self, mode: str, direction: Sequence[float] | None = None) -> None:
        self.ignored += 1

    # ----------------------------------------------------------------- for the panel and the CLI
    def summary(self) -> str:
        """One line: the file, its length, states, the end behaviour."""
        tl = self.timeline
        host = tl.meta.get("host", "?")
        return (f"{self.path.name}: {tl.duration:.1f} s, {tl.states} states ({host} recording"
                f"{', ' + str(len(tl.files)) + ' files' if len(tl.files) > 1 else ''}), at the end it "
                f"{self.clock.at_end}")


class PlaybackPanel:
    """The page's "Playback" folder: play/pause, time (a slider that seeks), speed, loop, a line of text."""

    def __init__(self, gui: Any, link: RecordingLink) -> None:
        self.link = link
        c = link.clock
        self._syncing = self._repush = False
        speeds = sorted({*SPEEDS, c.speed})
        with gui.add_folder("Playback"):
            self.play_button = gui.add_button("Pause", hint="pause or play the recording")
            end = max(math.ceil(c.duration * 100) / 100, 0.01)  # the slider's steps are 0.01 s
            self.slider = gui.add_slider("Time [s]", min=0.0, max=end, step=0.01,
                                         initial_value=0.0, hint="seconds since the recording's first message")
            self.speed = gui.add_dropdown("Speed", [f"{s:g}x" for s in speeds], initial_value=f"{c.speed:g}x")
            self.loop = gui.add_checkbox("Loop at the end", initial_value=c.loop,
                                         hint="off: playback stops at the end")
            self.text = gui.add_markdown(self.markdown(0.0))
        self.play_button.on_click(self._toggle)
        self.slider.on_update(self._seek)
        self.speed.on_update(lambda _: c.set_speed(float(str(self.speed.value).rstrip("x"))))
        self.loop.on_update(lambda _: setattr(c, "loop", bool(self.loop.value)))

    def _toggle(self, _: Any = None) -> None:
        c = self.link.clock
        c.pause() if c.playing else c.play()
        self.update()

    def _seek(self, _: Any = None) -> None:
        if not self._syncing:  # the operator moved it (not update())
            self.link.clock.seek(float(self.slider.value))
            self._repush = True

    def markdown(self, tau: float) -> str:
        c, tl = self.link.clock, self.link.timeline
        state = "playing" if c.playing else ("stopped at the end" if tau >= c.duration else "paused")
        lines = [f"**{state}** t = {tau:.2f} / {c.duration:.2f} s · ×{c.speed:g} · at the end: **{c.at_end}**"
                 + (f" (looped {c.loops}×)" if c.loops else ""),
                 f"`{self.link.path.name}` · {tl.meta.get('host', '?')} recording, {tl.states} states"
                 f" · started {tl.meta.get('started', '?')}"]
        if tl.error:
            lines.append(f"**truncated**: plays what was read ({tl.error})")
        return "  \n".join(lines)

    def update(self) -> None:
        """The slider, the button and the text at the playback time."""
        c = self.link.clock
        tau = c.now()
        v = round(min(tau, self.slider.max), 2)
        self._syncing = True
        try:
            if self._repush and self.slider.value == v:
                # the operator's seek can cross an update of ours on the wire (the browser then shows
                # ours, older): say its value again, as viser sends only a value that changed
                self.slider.value = v + 0.001
            self.slider.value = v
        finally:
            self._syncing = self._repush = False
        label = "Pause" if c.playing else "Play"
        if self.play_button.label != label:
            self.play_button.label = label
        text = self.markdown(tau)
        if text != self.text.content:
            self.text.content = text


def _list(v: Any) -> list[float]:
    return [] if v is None else [float(x) for x in np.asarray(v, float).ravel()]


def _f(v: Any) -> float:
    return math.nan if v is None else float(v)


def warn_truncated(timeline: Timeline, command: str = "wmm-qp console") -> None:
    """One line on stderr for a recording cut short or damaged: what is played."""
    if timeline.error:
        print(f"{command}: warning: {timeline.error}; playing the {timeline.duration:.1f} s read before it",
              file=sys.stderr, flush=True)
