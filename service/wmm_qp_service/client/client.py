"""The client of one robot's daemon: the session's lifecycle, the commands (setpoints, modes,
the box, the gripper, live obstacles) and the faults (notice them, resume deliberately).

What it reads and waits for is :class:`~.reader.Reader`'s.
"""

from __future__ import annotations

import secrets
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from types import TracebackType
from typing import Any

import zenoh

from ..config import ServiceConfig, load_service_config
from ..protocol import BoxMsg, GripperMsg, ModeMsg, ObstaclesMsg, SetpointMsg, StatusMsg, encode
from ..transport import ROLE_CLIENT, open_session
from .reader import Reader
from .robot_id import robot_id

FOLLOWING = ("track", "dm_nullspace")
"""The modes in which the daemon follows setpoints."""


class Client(Reader):
    """A Zenoh client of one robot's daemon (use as a context manager).

    What it reads (the robot's streams, the daemon's queries, :meth:`~.reader.Reader.wait_ready`)
    is :class:`~.reader.Reader`'s. Faults: the daemon's status (10 Hz) feeds :attr:`fault_active`,
    :meth:`resume_needed` and the ``on_fault`` callback; :meth:`send_setpoint` returns False
    while the daemon does not follow setpoints; :meth:`resume` is the deliberate act that makes
    it follow them again after a fault (``watchdog.resume = "manual"``, docs/protocol.md "Faults in a client").

    Args:
        svc: service config (prefix, robot id, endpoints); None: ``configs/service.toml``. An
            open robot id (``""``) is the default robot file's name
            (:meth:`~.config.ServiceConfig.resolved`).
        name: this client's name (its liveliness token is ``alive/<name>``). Its setpoints
            carry ``source = "<name>-<random>"`` (:attr:`source`): one operator holds the
            daemon's setpoint stream at a time.
        telemetry: also subscribe to per-tick telemetry (see :meth:`~.reader.Reader.telemetry`).
        robot: the robot to talk to, overriding ``svc``'s id: a robot id (``"ur5_omni"``) or a
            robot file (a :class:`~pathlib.Path` or a ``.toml`` path: its ``name``), as
            :func:`robot_id`.
        on_fault: called with the status each time the daemon reports a new fault (one that
            holds the robot, or any new entry of ``status.faults``); it runs in the caller's
            thread, inside whichever of this client's calls read the status first
            (:meth:`send_setpoint`, :meth:`latest_status`, :attr:`fault_active`, …).
    """

    def __init__(self, svc: ServiceConfig | None = None, name: str = "client", telemetry: bool = False,
                 *, robot: str | Path | None = None,
                 on_fault: Callable[[StatusMsg], None] | None = None) -> None:
        svc = svc if svc is not None else load_service_config()
        if robot is not None:
            svc = svc.with_(robot=robot_id(robot, svc))
        super().__init__(svc.resolved(), telemetry)
        self.name = name
        self.source = f"{name}-{secrets.token_hex(4)}"
        self._seq = 0
        self.on_fault = on_fault
        self._fault_active = False  # as the last status said
        self._faults_seen = -1  # faults counted by the daemon at the last status (-1: none yet)
        self.faults_seen = 0  # faults reported to this client (each one an on_fault call)

    @classmethod
    def for_robot(cls, robot: str | Path, svc: ServiceConfig | None = None, name: str = "client",
                  telemetry: bool = False, on_fault: Callable[[StatusMsg], None] | None = None) -> Client:
        """A client of the daemon that drives ``robot``: a robot file (its ``name`` is the id, as
        ``wmm-qp sim --robot-config FILE`` uses it) or a robot id; ``svc`` gives the prefix and
        endpoints (None: ``configs/service.toml``).

        Raises:
            ConfigError: the robot file is unreadable or its name is not a key segment.
        """
        return cls(svc, name=name, telemetry=telemetry, robot=robot, on_fault=on_fault)

    # ------------------------------------------------------------------ lifecycle
    def open(self) -> Client:
        """Open the session and declare publishers, subscribers and the liveliness token."""
        k = self.keys
        s = self.session = self._open_session()
        self._pub_sp = s.declare_publisher(k.setpoint, express=True,
                                           congestion_control=zenoh.CongestionControl.DROP)
        self._pub_mode = s.declare_publisher(k.mode, congestion_control=zenoh.CongestionControl.BLOCK,
                                             reliability=zenoh.Reliability.RELIABLE)
        self._pub_box = s.declare_publisher(k.sim_box, congestion_control=zenoh.CongestionControl.BLOCK,
                                            reliability=zenoh.Reliability.RELIABLE)
        self._pub_obstacles = s.declare_publisher(k.obstacles, congestion_control=zenoh.CongestionControl.BLOCK,
                                                  reliability=zenoh.Reliability.RELIABLE)
        self._pub_gripper = s.declare_publisher(k.gripper, congestion_control=zenoh.CongestionControl.BLOCK,
                                                reliability=zenoh.Reliability.RELIABLE)
        self._declare_subscribers(s)
        self._token = s.liveliness().declare_token(k.alive(self.name))
        return self

    def _open_session(self) -> zenoh.Session:
        """The Zenoh session :meth:`open` declares everything on (a subclass may open another kind)."""
        return open_session(self.svc, ROLE_CLIENT)

    def close(self) -> None:
        """Close the session (always do: an open session can hang the process at exit)."""
        if self.session is not None:
            self.session.close()
            self.session = None

    def __enter__(self) -> Client:
        return self.open()

    def __exit__(self, et: type[BaseException] | None, e: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    def _next(self) -> int:
        self._seq += 1
        return self._seq

    # ------------------------------------------------------------------ commands
    def send_setpoint(self, x: Sequence[float] | Any, xd: Sequence[float] | Any | None = None,
                      q: Sequence[float] | Any | None = None, w: Sequence[float] | Any | None = None) -> bool:
        """Stream an EE target x [m] (world); xd [m/s] its velocity (None: the daemon estimates);
        with the pose task, q the target orientation (quaternion [x, y, z, w], world; None: keep
        the daemon's) and w [rad/s] its angular velocity (None: 0).

        Returns:
            whether the daemon follows setpoints, as its last status said (a mode that follows
            them, no fault active; True before any status): False after a fault, until
            :meth:`resume`. The setpoint is sent either way.
        """
        msg = SetpointMsg(robot=self.svc.robot, seq=self._next(), stamp=time.time(),
                          x=[float(v) for v in x], xd=None if xd is None else [float(v) for v in xd],
                          source=self.source, q=None if q is None else [float(v) for v in q],
                          w=None if w is None else [float(v) for v in w])
        self._pub_sp.put(encode(msg))
        st = self.latest_status()
        return st is None or (st.mode in FOLLOWING and not st.fault_active)

    def set_mode(self, mode: str, direction: Sequence[float] | None = None) -> None:
        """Change mode: hold | track | dm_cartesian | dm_nullspace (direction: DM u, base frame)."""
        msg = ModeMsg(robot=self.svc.robot, seq=self._next(), stamp=time.time(), mode=mode,
                      direction=None if direction is None else [float(v) for v in direction])
        self._pub_mode.put(encode(msg))

    # ------------------------------------------------------------------ faults
    @property
    def fault_active(self) -> bool:
        """A fault holds the robot now, or the daemon waits for a resume (the last status's
        ``fault_active``; False before any status)."""
        self.latest_status()
        return self._fault_active

    def resume_needed(self) -> bool:
        """The daemon holds after a fault until a mode message: call :meth:`resume`."""
        st = self.latest_status()
        return st is not None and st.resume_needed

    def resume(self, mode: str = "track", direction: Sequence[float] | None = None,
               timeout: float = 5.0) -> bool:
        """Resume after a fault, deliberately: wait until the fault has cleared (no safe stop,
        the robot follows the daemon's commands again; a mode message during the stop itself is
        overruled), then send ``mode`` until the status shows it with no fault active.

        After it returns True the daemon has re-latched its target at the EE's position: stream
        setpoints from where the robot is (``latest_status().x``) or accept that it moves, at
        ``smoothing.v_max``, to the next setpoint.

        Args:
            mode: the mode to resume in (``track``, ``dm_nullspace``, ``dm_cartesian``, ``hold``).
            direction: the DM direction, as :meth:`set_mode`.
            timeout: [s] give up after this long.

        Returns:
            True when the status shows ``mode`` and no active fault; False after ``timeout``
            (the fault did not clear: see ``latest_status().last_fault``).
        """
        end = time.monotonic() + timeout
        sent_at = -float("inf")
        seen = self._status_count
        while time.monotonic() < end:
            st = self.latest_status()
            fresh = self._status_count > seen  # a status published after the last mode message
            if st is not None and fresh and st.mode == mode and not st.fault_active:
                return True
            if st is not None and not st.safe_stop and time.monotonic() - sent_at > 0.3:
                self.set_mode(mode, direction)  # (status at 10 Hz: again if none showed it)
                sent_at = time.monotonic()
                seen = self._status_count
            time.sleep(0.01)
        return False

    def _on_status(self, st: StatusMsg) -> None:
        """Fault bookkeeping of a new status; calls ``on_fault`` for a new fault."""
        total = sum(st.faults.values())
        new = (st.fault_active and not self._fault_active) or (0 <= self._faults_seen < total)
        self._fault_active = st.fault_active
        self._faults_seen = total
        if new:
            self.faults_seen += 1
            if self.on_fault is not None:
                self.on_fault(st)

    def place_box(self, mass: float, mu: float, face_x: float, center_y: float,
                  width: float = 0.4, height: float = 0.6) -> None:
        """Place a box in the sim's scene now: mass [kg], friction μ, face x and centre y [m] (world)."""
        msg = BoxMsg(robot=self.svc.robot, seq=self._next(), stamp=time.time(), mass=float(mass),
                     mu=float(mu), face_x=float(face_x), center_y=float(center_y),
                     width=float(width), height=float(height))
        self._pub_box.put(encode(msg))

    def gripper(self, action: str, width: float = 0.0, speed: float = 0.05, force: float = 0.0) -> None:
        """Send a gripper command (``open``, ``close``, ``move``, ``grasp``; see
        :class:`~.protocol.GripperMsg`): width [m], speed [m/s], force [N]."""
        self._pub_gripper.put(encode(GripperMsg(
            robot=self.svc.robot, seq=self._next(), stamp=time.time(), action=action, width=float(width),
            speed=float(speed), force=float(force), source=self.source)))

    def gripper_open(self, speed: float = 0.05) -> None:
        """Open the gripper fully at ``speed`` [m/s]."""
        self.gripper("open", speed=speed)

    def gripper_close(self, speed: float = 0.05) -> None:
        """Close the gripper fully at ``speed`` [m/s]."""
        self.gripper("close", speed=speed)

    def gripper_move(self, width: float, speed: float = 0.05) -> None:
        """Move the fingers to ``width`` [m] at ``speed`` [m/s]."""
        self.gripper("move", width=width, speed=speed)

    def gripper_grasp(self, width: float, force: float, speed: float = 0.05) -> None:
        """Close to ``width`` [m] at ``speed`` [m/s] and hold with ``force`` [N]."""
        self.gripper("grasp", width=width, speed=speed, force=force)

    def put_obstacles(self, obstacles: Sequence[dict[str, Any]]) -> None:
        """Replace the live obstacle set (daemon and sim): tables with the keys of a scene file's
        ``[[obstacles]]`` (world frame), e.g. ``{"id": "ball", "kind": "sphere", "radius": 0.1,
        "xyz": [1, 0, 0.3]}``; an empty list clears it (docs/protocol.md, ObstaclesMsg)."""
        msg = ObstaclesMsg(robot=self.svc.robot, seq=self._next(), stamp=time.time(), source=self.source,
                           obstacles=[dict(o) for o in obstacles])
        self._pub_obstacles.put(encode(msg))

    def put_raw(self, key: str, payload: bytes) -> None:
        """Publish raw bytes on ``<prefix>/<robot>/<key>`` (tests of the validation)."""
        assert self.session is not None
        self.session.put(f"{self.keys.root}/{key}", payload)
