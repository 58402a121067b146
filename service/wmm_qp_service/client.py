"""A small client API for the daemon: send setpoints and mode changes, read status and state,
notice faults and resume after them.

Example::

    from wmm_qp_service.client import Client

    with Client.for_robot("configs/robots/ur5_omni.toml") as c:   # or Client(robot="ur5_omni")
        c.wait_for_daemon(timeout=5.0)
        c.set_mode("track")
        if not c.send_setpoint([0.65, 0.0, 0.49]):   # False: the daemon does not follow setpoints
            c.resume("track")                        # after a fault: resume deliberately
        print(c.info().status.loop)                  # query: status + config
        st = c.latest_state()                        # the sim's last state (or None)
        tr = c.latest_truth()                        # the sim's ground truth, referee (or None)
"""

from __future__ import annotations

import contextlib
import secrets
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from types import TracebackType
from typing import Any

import msgspec
import zenoh

from wmm_qp import ConfigError
from wmm_qp.config import read_toml

from .config import ServiceConfig, check_name, load_service_config
from .keys import Keys
from .protocol import (
    BoxMsg,
    GripperMsg,
    InfoMsg,
    ModeMsg,
    ObstaclesMsg,
    SetpointMsg,
    StateMsg,
    StatusMsg,
    TelemetryMsg,
    TruthMsg,
    encode,
)
from .transport import ROLE_CLIENT, open_session

FOLLOWING = ("track", "dm_nullspace")
"""The modes in which the daemon follows setpoints."""


def robot_id(robot: str | Path, svc: ServiceConfig | None = None) -> str:
    """The robot id of a robot file or of an id: a path (a :class:`~pathlib.Path`, or a string
    ending in ``.toml``) gives the file's ``name`` (read without resolving its URDF; a file
    without ``name`` gives ``svc``'s robot id), any other string is the id itself.

    Raises:
        ConfigError: the file is unreadable, or the name is not a key segment.
    """
    if isinstance(robot, Path) or robot.endswith(".toml"):
        path = Path(robot)
        name = read_toml(path).get("name")
        if name is None:
            return (svc or load_service_config()).resolved().robot
        if not isinstance(name, str):
            raise ConfigError(path, "name", f"must be a string, got {name!r}")
        try:
            return check_name(name, "name")
        except ConfigError:
            raise ConfigError(path, "name", f"must be a key segment (letters, digits, _ -), got {name!r}") from None
    return check_name(robot, "robot")


class Client:
    """A Zenoh client of one robot's daemon (use as a context manager).

    Faults: the daemon's status (10 Hz) feeds :attr:`fault_active`, :meth:`resume_needed` and
    the ``on_fault`` callback; :meth:`send_setpoint` returns False while the daemon does not
    follow setpoints; :meth:`resume` is the deliberate act that makes it follow them again
    after a fault (``watchdog.resume = "manual"``, docs/protocol.md "Faults in a client").

    Args:
        svc: service config (prefix, robot id, endpoints); None: ``configs/service.toml``. An
            open robot id (``""``) is the default robot file's name
            (:meth:`~.config.ServiceConfig.resolved`).
        name: this client's name (its liveliness token is ``alive/<name>``). Its setpoints
            carry ``source = "<name>-<random>"`` (:attr:`source`): one operator holds the
            daemon's setpoint stream at a time.
        telemetry: also subscribe to per-tick telemetry (see :meth:`telemetry`).
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
        svc = svc.resolved()
        self.svc = svc
        self.name = name
        self.source = f"{name}-{secrets.token_hex(4)}"
        self.keys = Keys.of(svc.prefix, svc.robot)
        self._want_telemetry = telemetry
        self._seq = 0
        self.session: zenoh.Session | None = None
        self._last_state: StateMsg | None = None
        self._last_truth: TruthMsg | None = None
        self._last_status: StatusMsg | None = None
        self._status_count = 0  # statuses received
        self._dec_state = msgspec.msgpack.Decoder(StateMsg)
        self._dec_truth = msgspec.msgpack.Decoder(TruthMsg)
        self._dec_status = msgspec.msgpack.Decoder(StatusMsg)
        self._dec_tel = msgspec.msgpack.Decoder(TelemetryMsg)
        self._dec_info = msgspec.msgpack.Decoder(InfoMsg)
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
        self._sub_state = s.declare_subscriber(k.state, zenoh.handlers.RingChannel(1))
        self._sub_truth = s.declare_subscriber(k.sim_truth, zenoh.handlers.RingChannel(1))
        self._sub_status = s.declare_subscriber(k.status, zenoh.handlers.RingChannel(1))
        self._sub_tel = (s.declare_subscriber(k.telemetry, zenoh.handlers.FifoChannel(100_000))
                         if self._want_telemetry else None)
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

    # ------------------------------------------------------------------ reading
    def daemon_alive(self, timeout: float = 0.5) -> bool:
        """The daemon's liveliness token for this robot is present."""
        assert self.session is not None
        replies = self.session.liveliness().get(self.keys.alive("daemon"), timeout=timeout)
        return any(r.ok is not None for r in replies)

    def robots(self, timeout: float = 0.5) -> list[str]:
        """``<prefix>/<robot>`` of every robot whose daemon this session can see (liveliness)."""
        assert self.session is not None
        prefix = self.svc.prefix.strip("/")
        out = set()
        for r in self.session.liveliness().get(f"{prefix}/*/alive/daemon", timeout=timeout):
            if r.ok is not None:
                out.add(str(r.ok.key_expr).removesuffix("/alive/daemon"))
        return sorted(out)

    def no_daemon_reason(self) -> str:
        """Why no daemon answers: "no daemon for robot X" and the robots that are seen."""
        seen = self.robots()
        return (f"no daemon for robot {self.keys.root} (no liveliness token {self.keys.alive('daemon')}); "
                f"daemons seen: {', '.join(seen) if seen else 'none'}")

    def info(self, timeout: float = 2.0) -> InfoMsg | None:
        """Query the daemon's status and configuration (None: no daemon answered)."""
        assert self.session is not None
        for reply in self.session.get(self.keys.info, timeout=timeout):
            if reply.ok is not None:
                try:
                    return self._dec_info.decode(reply.ok.payload.to_bytes())
                except msgspec.DecodeError:
                    return None
        return None

    def wait_for_daemon(self, timeout: float = 10.0) -> InfoMsg | None:
        """Query until the daemon answers (None after ``timeout`` [s]; then
        :meth:`no_daemon_reason` says why). Queries are sent only while the daemon's liveliness
        token is present, so a mistyped robot id costs no query time-outs."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if not self.daemon_alive(timeout=min(0.5, max(0.05, end - time.monotonic()))):
                time.sleep(0.05)
                continue
            info = self.info(timeout=min(1.0, max(0.1, end - time.monotonic())))
            if info is not None:
                return info
            time.sleep(0.05)
        return None

    def latest_state(self) -> StateMsg | None:
        """The robot's most recent state (kept from earlier calls when nothing new arrived)."""
        s = self._sub_state.try_recv()
        if s is not None:
            with contextlib.suppress(msgspec.DecodeError):
                self._last_state = self._dec_state.decode(s.payload.to_bytes())
        return self._last_state

    def latest_truth(self) -> TruthMsg | None:
        """The sim's most recent evaluation data (``sim/truth``; None: none yet, or a robot that
        publishes none). Nothing on the control path needs it."""
        s = self._sub_truth.try_recv()
        if s is not None:
            with contextlib.suppress(msgspec.DecodeError):
                self._last_truth = self._dec_truth.decode(s.payload.to_bytes())
        return self._last_truth

    def wait_truth(self, timeout: float = 5.0) -> TruthMsg | None:
        """Wait for fresh evaluation data from the sim (None after ``timeout`` [s])."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            s = self._sub_truth.try_recv()
            if s is not None:
                with contextlib.suppress(msgspec.DecodeError):
                    self._last_truth = self._dec_truth.decode(s.payload.to_bytes())
                    return self._last_truth
            time.sleep(0.005)
        return None

    def latest_status(self) -> StatusMsg | None:
        """The daemon's most recent published status (it also feeds the fault bookkeeping:
        :attr:`fault_active`, ``on_fault``)."""
        s = self._sub_status.try_recv()
        if s is not None:
            with contextlib.suppress(msgspec.DecodeError):
                self._last_status = st = self._dec_status.decode(s.payload.to_bytes())
                self._status_count += 1
                self._on_status(st)
        return self._last_status

    def wait_state(self, timeout: float = 5.0) -> StateMsg | None:
        """Wait for a fresh state from the sim (None after ``timeout`` [s])."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            s = self._sub_state.try_recv()
            if s is not None:
                try:
                    self._last_state = self._dec_state.decode(s.payload.to_bytes())
                    return self._last_state
                except msgspec.DecodeError:
                    pass
            time.sleep(0.005)
        return None

    def telemetry(self) -> list[TelemetryMsg]:
        """Every telemetry message received since the last call (needs ``telemetry=True``)."""
        out: list[TelemetryMsg] = []
        if self._sub_tel is None:
            return out
        while (s := self._sub_tel.try_recv()) is not None:
            with contextlib.suppress(msgspec.DecodeError):
                out.append(self._dec_tel.decode(s.payload.to_bytes()))
        return out

    def alive(self, timeout: float = 1.0) -> list[str]:
        """Names of the live nodes of this robot (daemon, sim, clients)."""
        assert self.session is not None
        names = []
        for reply in self.session.liveliness().get(self.keys.alive_all, timeout=timeout):
            if reply.ok is not None:
                names.append(str(reply.ok.key_expr).rsplit("/", 1)[-1])
        return sorted(names)
