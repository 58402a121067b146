"""A small client API for the daemon: send setpoints and mode changes, read status and state.

Example::

    from wmm_qp_service.client import Client
    from wmm_qp_service.config import load_service_config

    with Client(load_service_config()) as c:
        c.wait_for_daemon(timeout=5.0)
        c.set_mode("track")
        c.send_setpoint([0.65, 0.0, 0.49])          # stream these at any rate
        print(c.info().status.loop)                  # query: status + config
        st = c.latest_state()                        # the sim's last state (or None)
"""

from __future__ import annotations

import contextlib
import secrets
import time
from collections.abc import Sequence
from types import TracebackType
from typing import Any

import msgspec
import zenoh

from .config import ServiceConfig
from .keys import Keys
from .protocol import (
    BoxMsg,
    InfoMsg,
    ModeMsg,
    ObstaclesMsg,
    SetpointMsg,
    StateMsg,
    StatusMsg,
    TelemetryMsg,
    encode,
)
from .transport import ROLE_CLIENT, open_session


class Client:
    """A Zenoh client of one robot's daemon (use as a context manager).

    Args:
        svc: service config (prefix, robot id, endpoints); an open robot id (``""``) is the
            default robot file's name (:meth:`~.config.ServiceConfig.resolved`).
        name: this client's name (its liveliness token is ``alive/<name>``). Its setpoints
            carry ``source = "<name>-<random>"`` (:attr:`source`): one operator holds the
            daemon's setpoint stream at a time.
        telemetry: also subscribe to per-tick telemetry (see :meth:`telemetry`).
    """

    def __init__(self, svc: ServiceConfig, name: str = "client", telemetry: bool = False) -> None:
        svc = svc.resolved()
        self.svc = svc
        self.name = name
        self.source = f"{name}-{secrets.token_hex(4)}"
        self.keys = Keys.of(svc.prefix, svc.robot)
        self._want_telemetry = telemetry
        self._seq = 0
        self.session: zenoh.Session | None = None
        self._last_state: StateMsg | None = None
        self._last_status: StatusMsg | None = None
        self._dec_state = msgspec.msgpack.Decoder(StateMsg)
        self._dec_status = msgspec.msgpack.Decoder(StatusMsg)
        self._dec_tel = msgspec.msgpack.Decoder(TelemetryMsg)
        self._dec_info = msgspec.msgpack.Decoder(InfoMsg)

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
        self._sub_state = s.declare_subscriber(k.state, zenoh.handlers.RingChannel(1))
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
                      q: Sequence[float] | Any | None = None, w: Sequence[float] | Any | None = None) -> None:
        """Stream an EE target x [m] (world); xd [m/s] its velocity (None: the daemon estimates);
        with the pose task, q the target orientation (quaternion [x, y, z, w], world; None: keep
        the daemon's) and w [rad/s] its angular velocity (None: 0)."""
        msg = SetpointMsg(robot=self.svc.robot, seq=self._next(), stamp=time.time(),
                          x=[float(v) for v in x], xd=None if xd is None else [float(v) for v in xd],
                          source=self.source, q=None if q is None else [float(v) for v in q],
                          w=None if w is None else [float(v) for v in w])
        self._pub_sp.put(encode(msg))

    def set_mode(self, mode: str, direction: Sequence[float] | None = None) -> None:
        """Change mode: hold | track | dm_cartesian | dm_nullspace (direction: DM u, base frame)."""
        msg = ModeMsg(robot=self.svc.robot, seq=self._next(), stamp=time.time(), mode=mode,
                      direction=None if direction is None else [float(v) for v in direction])
        self._pub_mode.put(encode(msg))

    def place_box(self, mass: float, mu: float, face_x: float, center_y: float,
                  width: float = 0.4, height: float = 0.6) -> None:
        """Place a box in the sim's scene now: mass [kg], friction μ, face x and centre y [m] (world)."""
        msg = BoxMsg(robot=self.svc.robot, seq=self._next(), stamp=time.time(), mass=float(mass),
                     mu=float(mu), face_x=float(face_x), center_y=float(center_y),
                     width=float(width), height=float(height))
        self._pub_box.put(encode(msg))

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
        """The sim's most recent state (kept from earlier calls when nothing new arrived)."""
        s = self._sub_state.try_recv()
        if s is not None:
            with contextlib.suppress(msgspec.DecodeError):
                self._last_state = self._dec_state.decode(s.payload.to_bytes())
        return self._last_state

    def latest_status(self) -> StatusMsg | None:
        """The daemon's most recent published status."""
        s = self._sub_status.try_recv()
        if s is not None:
            with contextlib.suppress(msgspec.DecodeError):
                self._last_status = self._dec_status.decode(s.payload.to_bytes())
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
