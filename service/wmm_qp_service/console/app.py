"""The operator's console: a viser web page that shows one robot live and drives it.

One thread polls the robot's link (``state``, ``status``) at ``rate_hz`` and updates the page;
viser's own threads run the callbacks of the buttons and of the target gizmo. A gizmo move
streams setpoints (position; orientation too with the pose task) for ``stream_s`` after the
operator's last move, then the console falls silent and the daemon holds its last target.
"""

from __future__ import annotations

import math
import sys
import threading
import time
from functools import partial
from typing import TYPE_CHECKING, Any

import numpy as np

from wmm_qp import Scene

from .geometry import Series, wxyz_to_xyzw, xyzw_to_wxyz
from .link import Attached, ConsoleError, RobotLink
from .playback import PlaybackPanel, RecordingLink
from .status_text import status_markdown
from .view import RobotView

if TYPE_CHECKING:
    import viser

GRIPPER_SLIDER_MAX = 0.1
"""[m] the width slider's range (a robot clamps a width past its own ``[gripper] width_max``)."""
DM_MIN_SPAN, ERR_MIN_SPAN = 0.05, 0.01
"""The smallest y spans of the DM and tracking-error plots (DM: dimensionless; error: m)."""
MODES = ("hold", "track", "dm_cartesian", "dm_nullspace")
MODE_LABELS = {"hold": "Hold", "track": "Track", "dm_cartesian": "DM Cartesian", "dm_nullspace": "DM null space"}
TRACKING_MODES = ("track", "dm_nullspace")


def y_range(values: Any, min_span: float) -> tuple[float, float] | None:
    """A plot's y range: the data's, widened about its middle to at least ``min_span`` (uPlot's
    auto range of a nearly constant series spans a few 1e-4 and labels every tick alike, e.g. a
    DM held at 1.2057 ... 1.2063 read "1.206" on all three); rounded outward to a 1/4 of the span
    so that it changes seldom. None without a finite value."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    if not v.size:
        return None
    lo, hi = float(v.min()), float(v.max())
    if hi - lo < min_span:
        mid = 0.5 * (lo + hi)
        lo, hi = mid - 0.5 * min_span, mid + 0.5 * min_span
    step = 0.25 * (hi - lo)
    return math.floor(lo / step) * step, math.ceil(hi / step) * step


class Console:
    """The console: a viser server, the robot link, the panel and the scene of the attached robot.

    Args:
        link: the open Zenoh link, or a recording's (:class:`~.playback.RecordingLink`: the page
            plays it back, with playback controls and without the controls that command).
        host, port: where the web server listens.
        scene: obstacles and fence to draw (None: none).
        rate_hz: [Hz] page updates.
        stream_hz: [Hz] setpoints while the operator moves the target.
        stream_s: [s] how long after the last move the target is still streamed.
    """

    def __init__(self, link: RobotLink | RecordingLink, host: str = "127.0.0.1", port: int = 8080,
                 scene: Scene | None = None, rate_hz: float = 20.0, stream_hz: float = 50.0,
                 stream_s: float = 1.0) -> None:
        self.link = link
        self.recording = link if isinstance(link, RecordingLink) else None
        self.player: PlaybackPanel | None = None
        self.host, self.port = host, port
        self.scene = scene
        self.rate_hz, self.stream_hz, self.stream_s = rate_hz, stream_hz, stream_s
        self.server: viser.ViserServer | None = None
        self.view: RobotView | None = None
        self.attached: Attached | None = None
        self._lock = threading.RLock()
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._target: tuple[np.ndarray, np.ndarray] | None = None  # (x, wxyz) the operator set
        self._moved_at = -math.inf
        self.series = Series(("dm", "error"))
        self._y_ranges: dict[int, tuple[float, float]] = {}  # each plot's y range last sent
        self._t0 = time.monotonic()
        self.mode_clicks = 0
        self._dm_key: tuple[Any, ...] | None = None

    # ----------------------------------------------------------------- lifecycle
    def start(self, robot_id: str | None = None, timeout: float = 10.0) -> Console:
        """Attach to ``robot_id`` (None: the service config's robot when its daemon is alive, else
        the first robot seen), start the web server and the update threads.

        Raises:
            ConsoleError: no daemon answers (the message says which robots are seen).
        """
        import viser

        rid = robot_id or self._first_robot(timeout)
        attached = self.link.attach(rid, timeout=timeout)
        self.server = viser.ViserServer(host=self.host, port=self.port, label="wmm-qp console", verbose=False)
        self.port = self.server.get_port()
        self.server.initial_camera.up = (0.0, 0.0, 1.0)
        # no shadows: the page stays light for a browser without a GPU (software WebGL)
        self.server.scene.configure_default_lights(cast_shadow=False)
        self._build_panel()
        self._attach_view(attached)
        for fn in (self._update_loop, self._stream_loop):
            t = threading.Thread(target=fn, name=f"console-{fn.__name__}", daemon=True)
            t.start()
            self._threads.append(t)
        return self

    def _first_robot(self, timeout: float) -> str:
        start = time.monotonic()
        while True:
            seen = self.link.robots()
            waited = time.monotonic() - start
            if self.link.svc.robot in seen:
                return self.link.svc.robot
            if seen and waited > timeout / 2:
                return seen[0]
            if waited > timeout:
                raise ConsoleError(f"no daemon found under {self.link.svc.prefix}/* within {timeout:g} s "
                                   f"(is `wmm-qp serve` running, and --zenoh-config/--daemon-endpoint right?)")
            time.sleep(0.2)

    @property
    def url(self) -> str:
        host = self.host if self.host not in ("0.0.0.0", "") else "127.0.0.1"
        return f"http://{host}:{self.port}"

    def close(self) -> None:
        self._stop.set()
        for t in self._threads:
            t.join(timeout=2.0)
        if self.server is not None:
            self.server.stop()
        self.link.close()

    # ----------------------------------------------------------------- panel
    def _build_panel(self) -> None:
        assert self.server is not None
        gui = self.server.gui
        gui.configure_theme(control_width="large")
        if self.recording is not None:
            self.player = PlaybackPanel(gui, self.recording)
        with gui.add_folder("Robot"):
            self.robot_dropdown = gui.add_dropdown("Robot", [self.link.svc.robot],
                                                   initial_value=self.link.svc.robot,
                                                   hint="every robot whose daemon this console sees")
            self.robot_md = gui.add_markdown("")
            self.robot_dropdown.on_update(self._on_robot_chosen)
        with gui.add_folder("Mode", expand_by_default=self.recording is None):  # playback: folded
            self.mode_buttons: dict[str, Any] = {}
            for m in MODES[1:]:
                b = gui.add_button(MODE_LABELS[m], hint=f"mode {m}")
                b.on_click(partial(self._mode_clicked, m))
                self.mode_buttons[m] = b
            self.direction = gui.add_vector3("DM direction", (1.0, 0.0, 0.0), step=0.1,
                                             hint="u of eq. (8), base frame (used by the DM modes)")
            self.stop_button = gui.add_button("STOP (hold)", color="red", icon=None, hint="mode hold, at once")
            self.stop_button.on_click(partial(self._mode_clicked, "hold"))
        with gui.add_folder("Gripper", expand_by_default=self.recording is None):
            self.gripper_buttons: dict[str, Any] = {}
            for action in ("open", "close"):
                b = gui.add_button(f"{action.capitalize()} gripper", hint=f"{action} the gripper fully")
                b.on_click(partial(self._gripper_clicked, action))
                self.gripper_buttons[action] = b
            self.gripper_width = gui.add_slider("Width [m]", min=0.0, max=GRIPPER_SLIDER_MAX, step=0.001,
                                                initial_value=GRIPPER_SLIDER_MAX,
                                                hint="move the fingers to this width (the robot clamps it)")
            self.gripper_width.on_update(self._gripper_width_moved)
        if self.recording is not None:  # a recording is watched, not driven
            for h in (self.robot_dropdown, *self.mode_buttons.values(), self.direction, self.stop_button,
                      *self.gripper_buttons.values(), self.gripper_width):
                h.disabled = True
        with gui.add_folder("Status"):
            self.status_md = gui.add_markdown("**daemon**: no status yet")
        with gui.add_folder("Last 30 s"):
            empty = (np.zeros(1), np.zeros(1))
            self.plot_dm = gui.add_uplot(empty, ({"label": "t [s]"}, {"label": "DM", "stroke": "purple"}),
                                         title="directional manipulability", aspect=2.0,
                                         scales={"x": {"time": False}})
            self.plot_err = gui.add_uplot(empty, ({"label": "t [s]"}, {"label": "‖ee − x_d‖ [m]", "stroke": "blue"}),
                                          title="tracking error [m]", aspect=2.0,
                                          scales={"x": {"time": False}})

    def _on_robot_chosen(self, _: Any = None) -> None:
        rid = str(self.robot_dropdown.value)
        if self.attached is not None and rid == self.attached.robot_id:
            return
        try:
            self.attach(rid)
        except ConsoleError as e:
            self.robot_md.content = f"**cannot attach** {rid}: {e}"

    def attach(self, robot_id: str, timeout: float = 5.0) -> Attached:
        """Attach to another robot (its daemon must answer within ``timeout`` [s])."""
        attached = self.link.attach(robot_id, timeout=timeout)
        self._attach_view(attached)
        return attached

    def _attach_view(self, attached: Attached) -> None:
        assert self.server is not None
        with self._lock:
            if self.view is not None:
                self.view.remove()
            self.attached = attached
            self._target = None
            self._moved_at = -math.inf
            self.series = Series(("dm", "error"))
            self.view = RobotView(self.server, attached.robot, attached.W, self.scene, attached.pose_task)
            if self.recording is None:
                self.view.gizmo.on_update(self._on_gizmo)
            else:  # the recorded target, not one to drag
                g = self.view.gizmo
                g.disable_axes = g.disable_sliders = g.disable_rotations = True
            d = attached.direction
            self.direction.value = (float(d[0]), float(d[1]), float(d[2]))  # type: ignore[misc]
            st = attached.info.status
            ee = np.asarray(st.x or [0.5, 0.0, 0.5], float)
            self.server.initial_camera.look_at = (float(ee[0]) * 0.6, float(ee[1]) * 0.6, float(ee[2]) * 0.5)
            self.server.initial_camera.position = (float(ee[0]) + 1.0, float(ee[1]) - 1.3, float(ee[2]) + 0.7)
            if st.x:
                self.view.gizmo.position = np.asarray(st.x_d or st.x, float)
        info = attached.info
        self.robot_md.content = (f"attached to **{attached.robot_id}** · {info.base_kind} base, {info.n_arm} "
                                 f"joints, {info.task} task  \ndrawn: {self.view.drawn}  \n"
                                 f"file `{attached.robot.path}`"
                                 + (f"  \nplaying {self.recording.summary()}" if self.recording else ""))
        if self.robot_dropdown.value != attached.robot_id:
            self.robot_dropdown.options = sorted({*self.robot_dropdown.options, attached.robot_id})
            self.robot_dropdown.value = attached.robot_id  # type: ignore[misc]

    # ----------------------------------------------------------------- commands
    def _mode_clicked(self, mode: str, _event: Any) -> None:
        self.set_mode(mode)

    def _gripper_clicked(self, action: str, _event: Any) -> None:
        self.link.gripper(action)

    def _gripper_width_moved(self, _event: Any) -> None:
        self.link.gripper("move", width=float(self.gripper_width.value))

    def set_mode(self, mode: str) -> None:
        """A mode button: the mode, with the panel's DM direction for the DM modes."""
        d = np.asarray(self.direction.value, float)
        direction = list(d / np.linalg.norm(d)) if mode.startswith("dm_") and np.linalg.norm(d) > 1e-9 else None
        self.link.set_mode(mode, direction)
        self.mode_clicks += 1
        print(f"console: mode {mode} sent (click {self.mode_clicks})", file=sys.stderr, flush=True)
        with self._lock:
            self._target = None  # the daemon latches the target where the EE is

    def _on_gizmo(self, event: Any) -> None:
        h = event.target
        x, wxyz = np.asarray(h.position, float), np.asarray(h.wxyz, float)
        with self._lock:
            self._target = (x, wxyz)
            self._moved_at = time.monotonic()
        self._send_target()

    def _send_target(self) -> None:
        with self._lock:
            if self._target is None or self.attached is None:
                return
            x, wxyz = self._target
            pose = self.attached.pose_task
        self.link.send_setpoint(x.tolist(), q=wxyz_to_xyzw(wxyz) if pose else None)

    # ----------------------------------------------------------------- loops
    def _stream_loop(self) -> None:
        period = 1.0 / self.stream_hz
        while not self._stop.wait(period):
            if time.monotonic() - self._moved_at < self.stream_s:
                self._send_target()

    def _update_loop(self) -> None:
        period = 1.0 / self.rate_hz
        k = 0
        last_robots = -math.inf
        while not self._stop.wait(period):
            k += 1
            try:
                self._update(plots=k % max(1, int(self.rate_hz / 4)) == 0)
                if time.monotonic() - last_robots > 2.0:
                    last_robots = time.monotonic()
                    self._refresh_robots()
            except Exception as e:  # a page update must never end the console
                if self.status_md is not None:
                    self.status_md.content = f"**console error** {type(e).__name__}: {e}"

    def _refresh_robots(self) -> None:
        seen = self.link.robots(timeout=0.3)
        current = self.attached.robot_id if self.attached is not None else None
        opts = sorted({*seen, *([current] if current else [])})
        if tuple(opts) != tuple(self.robot_dropdown.options):
            self.robot_dropdown.options = opts
            if current is not None:
                self.robot_dropdown.value = current  # type: ignore[misc]

    def _update(self, plots: bool) -> None:
        view = self.view
        st, state, truth = self.link.status(), self.link.state(), self.link.truth()
        if view is None:
            return
        with self._lock:
            idle = time.monotonic() - self._moved_at > self.stream_s + 0.5
        if truth is not None and (truth.instance != getattr(state, "instance", "")
                                  or not np.all(np.isfinite(truth.ee_true + truth.base_true))):
            truth = None  # another robot's, or a robot without ground truth: draw odometry and the model
        if state is not None:
            q_arm, q_base = np.asarray(state.q_arm), np.asarray(state.q_base)
            base_true = np.asarray(truth.base_true) if truth is not None else q_base
            ee_true = (np.asarray(truth.ee_true) if truth is not None
                       else np.asarray(st.x if st is not None and st.x else [math.nan] * 3, float))
            moved = view.set_robot(q_arm, base_true, q_base)
            view.set_ee(ee_true, base_true)
            show_arrow = st is not None and st.mode.startswith("dm_")
            d = np.asarray(self.direction.value, float)
            key = (show_arrow, tuple(d))
            if moved or key != self._dm_key:  # the ellipsoid and arrow change with the joints only
                self._dm_key = key
                view.set_dm(q_arm, q_base, ee_true, d if np.linalg.norm(d) > 1e-9 else None,
                            show_arrow)
        if st is not None and st.x_d and idle:
            x_d = np.asarray(st.x_d, float)
            if not np.array_equal(x_d, np.asarray(view.gizmo.position, float)):
                view.gizmo.position = x_d  # follow the daemon's target when the operator is idle
            if st.quat_d:
                view.gizmo.wxyz = xyzw_to_wxyz(st.quat_d)
        if st is not None:
            err = (float(np.linalg.norm(np.asarray(truth.ee_true) - np.asarray(st.x_d)))
                   if truth is not None and st.x_d else math.nan)
            self.series.add(time.monotonic() - self._t0, st.dm, err)
        if plots:
            width = state.gripper_width if state is not None else math.nan
            text = status_markdown(st, truth, self.link.source, width)
            if text != self.status_md.content:
                self.status_md.content = text
            if self.recording is not None:  # the recording's last 30 s up to the playback time
                (t_dm, dm_s), (t_err, err_s) = self.recording.history()
                if self.player is not None:
                    self.player.update()
            elif len(self.series) >= 2:
                t_dm, dm_s, err_s = self.series.arrays(time.monotonic() - self._t0)
                t_err = t_dm
            else:
                return
            self.plot_dm.data = (t_dm, dm_s)
            self.plot_err.data = (t_err, err_s)
            # a recording: its whole range (a uPlot whose scales change often while paused shows no line)
            dm_r, err_r = self.recording.extent() if self.recording is not None else (dm_s, err_s)
            for plot, values, span in ((self.plot_dm, dm_r, DM_MIN_SPAN), (self.plot_err, err_r, ERR_MIN_SPAN)):
                rng = y_range(values, span)
                if rng is not None and rng != self._y_ranges.get(id(plot)):
                    self._y_ranges[id(plot)] = rng
                    plot.scales = {"x": {"time": False}, "y": {"auto": False, "range": list(rng)}}
