"""The console's side of Zenoh: one :class:`~wmm_qp_service.client.Client` of the robot it is
attached to, the robots it sees, and the robot description it draws.

The console is a client of the daemon like any other (docs/protocol.md): it reads ``state``
(ring of one) and ``status``, queries ``info`` once when it attaches, and sends ``setpoint`` and
``mode`` only when the operator acts. It never subscribes to the per-tick telemetry: its plots
are drawn from the 10 Hz status and the sim's state.
"""

from __future__ import annotations

import threading
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

import wmm_qp as w
from wmm_qp import ConfigError, RobotConfig

from ..client import Client
from ..config import ServiceConfig
from ..protocol import InfoMsg, StateMsg, StatusMsg, TruthMsg


class ConsoleError(w.WmmQpError):
    """Something the console cannot do (no daemon, an unknown robot): one line for the user."""


@dataclass(frozen=True)
class Attached:
    """The robot the console is attached to, as its daemon describes it.

    Attributes:
        robot_id: its id (``<robot>`` in ``<prefix>/<robot>``).
        info: the daemon's ``info`` reply at attach time.
        robot: the robot description the console draws (the daemon's file where it exists on
            this machine, else the shipped file of the same name, else ``--robot-config``).
        W: the diagonal of eq. (8)'s torque weights the daemon uses.
        direction: the DM direction u the daemon's controller config gives (base frame).
        pose_task: the daemon runs the pose task (setpoints carry orientations).
    """

    robot_id: str
    info: InfoMsg
    robot: RobotConfig
    W: np.ndarray
    direction: np.ndarray
    pose_task: bool


def file_mode(svc: ServiceConfig) -> str:
    """The ``mode`` the service config's Zenoh file asks for (``peer`` when none)."""
    import json

    import zenoh

    if svc.zenoh.config is None:
        return "peer"
    try:
        return str(json.loads(zenoh.Config.from_file(str(svc.zenoh.config)).get_json("mode")) or "peer")
    except Exception:  # zenoh.ZError: session_config reports a bad file as one line
        return "peer"


class RouterClient(Client):
    """A :class:`~wmm_qp_service.client.Client` whose session is a Zenoh **client** when its
    config file says ``mode: "client"`` (``remote_console.json5``): behind a router, a peer is
    taken for a member of the robot's peer mesh and the router forwards it nothing of the other
    peers; a client is routed. Otherwise the same session as every wmm-qp client."""

    def _open_session(self) -> Any:
        import zenoh

        from ..transport import ROLE_CLIENT, session_config

        if file_mode(self.svc) != "client":
            return super()._open_session()
        zc = session_config(self.svc, ROLE_CLIENT)
        zc.insert_json5("mode", '"client"')
        return zenoh.open(zc)


def robot_description(info: InfoMsg, fallback: Path | None) -> RobotConfig:
    """The robot file the console draws for a daemon's ``info``.

    Looked up in order: the file the daemon names, when it exists here (same machine or same
    install); a shipped ``configs/robots/*.toml`` whose ``name`` is the daemon's robot name;
    ``fallback`` (``--robot-config``). A file whose joints differ from the daemon's is skipped.

    Raises:
        ConsoleError: none fits.
    """
    robot_cfg = info.config.get("robot", {}) if isinstance(info.config, dict) else {}
    name = str(robot_cfg.get("name", ""))
    candidates: list[Path] = []
    f = str(robot_cfg.get("file", ""))
    if f:
        candidates.append(Path(f))
    shipped = sorted((w.default_config_dir() / "robots").glob("*.toml"))
    candidates += [p for p in shipped if _toml_name(p) == name]
    if fallback is not None:
        candidates.append(fallback)
    tried = []
    for p in candidates:
        if not p.is_file():
            continue
        try:
            r = w.load_robot_config(p)
        except ConfigError as e:
            tried.append(f"{p}: {e}")
            continue
        if list(r.arm.joints) == list(info.joints):
            return r
        tried.append(f"{p}: its joints are not the daemon's")
    raise ConsoleError(f"no robot file here for robot {name!r} (joints {', '.join(info.joints)}); "
                       f"give it with --robot-config FILE" + (f" ({'; '.join(tried)})" if tried else ""))


def _toml_name(path: Path) -> str:
    from wmm_qp.config import read_toml

    try:
        return str(read_toml(path).get("name", "wmm"))
    except ConfigError:
        return ""


class RobotLink:
    """The Zenoh link of the console: attach to one robot, read it, command it.

    Args:
        svc: the service config (prefix, endpoints, the Zenoh config with the operator's or the
            viewer's credentials, or the router's endpoint).
        fallback: the robot file to draw when the daemon's cannot be found (``--robot-config``).
        name: the client's liveliness name (``alive/<name>``).
    """

    def __init__(self, svc: ServiceConfig, fallback: Path | None = None, name: str = "console") -> None:
        self.svc = svc.resolved()
        self.fallback = fallback
        self.name = name
        self._lock = threading.Lock()
        self._client: Client | None = None
        self.attached: Attached | None = None
        self.setpoints_sent = 0

    # ----------------------------------------------------------------- lifecycle
    def open(self) -> RobotLink:
        """Open a session on the service config's robot (it need not be alive yet)."""
        self._client = RouterClient(self.svc, name=self.name).open()
        return self

    def close(self) -> None:
        with self._lock:
            if self._client is not None:
                self._client.close()
                self._client = None
            self.attached = None

    def __enter__(self) -> RobotLink:
        return self.open()

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def client(self) -> Client:
        if self._client is None:
            raise ConsoleError("the console's Zenoh session is closed")
        return self._client

    # ----------------------------------------------------------------- robots
    def robots(self, timeout: float = 0.5) -> list[str]:
        """The ids of every robot whose daemon this session sees (liveliness), sorted."""
        prefix = self.svc.prefix.strip("/") + "/"
        return [r.removeprefix(prefix) for r in self.client.robots(timeout=timeout)]

    def attach(self, robot_id: str | None = None, timeout: float = 10.0) -> Attached:
        """Attach to ``robot_id`` (None: the service config's): a session on its keys, its
        ``info``, the robot description to draw.

        Raises:
            ConsoleError: its daemon does not answer within ``timeout`` [s] (the message lists the
                robots that are seen), or no robot file fits it.
        """
        rid = robot_id or self.svc.robot
        with self._lock:
            if self._client is None or self._client.svc.robot != rid:
                if self._client is not None:
                    self._client.close()
                self._client = RouterClient(self.svc.with_(robot=rid), name=self.name).open()
            c = self._client
        info = c.wait_for_daemon(timeout=timeout)
        if info is None:
            raise ConsoleError(c.no_daemon_reason())
        robot = robot_description(info, self.fallback)
        ctl: dict[str, Any] = info.config.get("controller", {}) if isinstance(info.config, dict) else {}
        W = np.asarray(ctl.get("W") or robot.arm.default_W(), dtype=float)
        direction = np.asarray(ctl.get("direction") or [1.0, 0.0, 0.0], dtype=float)
        self.attached = Attached(robot_id=rid, info=info, robot=robot, W=W, direction=direction,
                                 pose_task=info.task == "pose")
        return self.attached

    # ----------------------------------------------------------------- reading
    def state(self) -> StateMsg | None:
        with self._lock:
            return self._client.latest_state() if self._client is not None else None

    def truth(self) -> TruthMsg | None:
        """The sim's last evaluation data (None: none, e.g. a real robot's driver without one)."""
        with self._lock:
            return self._client.latest_truth() if self._client is not None else None

    def status(self) -> StatusMsg | None:
        with self._lock:
            return self._client.latest_status() if self._client is not None else None

    @property
    def source(self) -> str:
        """This console's setpoint source id (the daemon's ``status.operator`` when it holds the stream)."""
        return self.client.source

    # ----------------------------------------------------------------- commands
    def send_setpoint(self, x: Sequence[float], q: Sequence[float] | None = None) -> None:
        """One EE target x [m] (world); with the pose task q = [x, y, z, w] too."""
        with self._lock:
            if self._client is None:
                return
            self._client.send_setpoint(x, q=q)
            self.setpoints_sent += 1

    def gripper(self, action: str, width: float = 0.0) -> None:
        """A gripper command (``open``, ``close``, ``move`` to ``width`` [m]) at 0.05 m/s."""
        with self._lock:
            if self._client is not None:
                self._client.gripper(action, width=width, speed=0.05)

    def set_mode(self, mode: str, direction: Sequence[float] | None = None) -> None:
        """hold | track | dm_cartesian | dm_nullspace (direction: DM u, base frame)."""
        with self._lock:
            if self._client is not None:
                self._client.set_mode(mode, direction)
