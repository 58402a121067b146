"""The service's own configuration (``configs/service.toml``), loaded into frozen dataclasses.

Every check names the file and the dotted key (:class:`wmm_qp.ConfigError`).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

from wmm_qp import ConfigError, RobotConfig, default_config_dir, default_robot_file
from wmm_qp.config import TomlTable, read_toml

_NAME = re.compile(r"^[A-Za-z0-9_\-]+(/[A-Za-z0-9_\-]+)*$")


@dataclass(frozen=True)
class ZenohConfig:
    """Transport settings.

    Attributes:
        config: path of the base Zenoh JSON5 session config.
        daemon_endpoint: where the daemon listens (clients connect here).
        sim_endpoint: where the sim listens (the daemon and clients connect here).
    """

    config: Path | None = None
    daemon_endpoint: str = "tcp/127.0.0.1:7448"
    sim_endpoint: str = "tcp/127.0.0.1:7447"


@dataclass(frozen=True)
class LoopConfig:
    """The daemon's fixed-rate loop.

    Attributes:
        rate_hz: [Hz] control rate.
        spin_us: [µs] the loop sleeps until this long before the deadline, then spins.
        status_hz: [Hz] status publication rate.
        telemetry_every: publish telemetry every N ticks (0 = never).
        rt_priority: SCHED_FIFO priority of the control thread (1–99; 0 = normal scheduling).
            Needs CAP_SYS_NICE (root); without it the daemon says so and runs normally.
        queries_per_tick: ``info`` queries answered per tick at most (the others wait in
            their FIFO for the next ticks), so a burst of queries cannot stall the loop.
        trigger: what starts a tick. ``rate``: the fixed-rate clock (absolute deadlines).
            ``state``: a new state from the robot (the robot's cycle is the clock: the command
            for state k is out well before the robot's next cycle); without one for 1.5
            periods, a tick on the prediction path, and after ``watchdog.state_timeout`` the
            safe stop, as in ``rate``. ``rate_hz`` must then be the robot's cycle rate (the
            commands' Δt): ticks are never closer than half a period.
    """

    rate_hz: float = 500.0
    spin_us: float = 200.0
    status_hz: float = 10.0
    telemetry_every: int = 1
    rt_priority: int = 0
    queries_per_tick: int = 1
    trigger: str = "rate"


@dataclass(frozen=True)
class WatchdogConfig:
    """Timeouts.

    Attributes:
        state_timeout: [s] no valid state for this long → safe stop.
        setpoint_timeout: [s] no setpoint for this long → the smoothed target comes to rest.
        command_hold: [s] the longest a command can act: the robot's own command timeout
            (sim.toml ``stale_timeout``) plus the state's age. The controller's bounds (13)
            brake from where the joints can be by then (its ``state_latency``), so a stalled
            daemon cannot push a joint past a position limit.
        state_age_max: [s] the state age bounds (13) allow for: ``command_hold`` minus the
            robot's command timeout. The daemon measures the age without shared clocks, as the
            round trip from publishing command k to reading a state that applied it (the
            smallest of the last ``ROUND_TRIPS`` ticks, so jitter does not count); above this
            it is a fault and a safe stop (a slow link, a constant delay).
        resume: after a safe stop ends (the fault cleared), ``manual``: hold where the robot
            is until a mode message resumes (``status.resume_needed``); ``auto``: go on with
            the last mode by itself.
        operator_timeout: [s] one operator holds the setpoint stream while its setpoints keep
            arriving; another source is refused (counted, reported) until the holder has been
            silent this long.
        obstacles_timeout: [s] the live obstacle set is stale when no obstacles message came
            for this long: it is kept (a silent perception does not make obstacles vanish) and
            the status says ``obstacles_stale``.
    """

    state_timeout: float = 0.05
    setpoint_timeout: float = 0.25
    command_hold: float = 0.035
    state_age_max: float = 0.01
    resume: str = "manual"
    operator_timeout: float = 0.5
    obstacles_timeout: float = 1.0


@dataclass(frozen=True)
class SmoothingConfig:
    """Ruckig limits of the smoothed Cartesian setpoint, per axis.

    Attributes:
        v_max: [m/s] velocity limit.
        a_max: [m/s²] acceleration limit.
        j_max: [m/s³] jerk limit.
    """

    v_max: float = 0.25
    a_max: float = 1.0
    j_max: float = 10.0


@dataclass(frozen=True)
class ValidationConfig:
    """Ranges incoming messages are checked against (beyond sizes and finiteness).

    Attributes:
        position_abs_max: [m] max |x|, |y| of a setpoint.
        z_min, z_max: [m] range of a setpoint's z.
        speed_max: [m/s] max norm of a setpoint's feed-forward velocity.
        angular_speed_max: [rad/s] max norm of a setpoint's angular velocity ``w`` (pose task).
        state_abs_max: max |value| of any entry of a state message.
        command_abs_max: [rad/s] max |entry| of a command message.
        payload_max_bytes: larger payloads are rejected (``size``) before they are decoded
            (the largest valid message, a state, is < 1 KiB; a 20k-entry vector costs ~0.4 ms).
        obstacles_max: the most obstacles one live obstacles message may carry.
        obstacles_payload_max_bytes: ``payload_max_bytes`` for an obstacles message.
        obstacle_size_max: [m] the largest edge, radius or length of a live obstacle.

    A setpoint inside these ranges can still be outside the scene's fence or below the floor:
    the daemon clamps it (``status.clamped``); these ranges only refuse nonsense.
    """

    position_abs_max: float = 100.0
    z_min: float = -10.0
    z_max: float = 10.0
    speed_max: float = 2.0
    angular_speed_max: float = 10.0
    state_abs_max: float = 1e3
    command_abs_max: float = 1e2
    payload_max_bytes: int = 4096
    obstacles_max: int = 32
    obstacles_payload_max_bytes: int = 16384
    obstacle_size_max: float = 100.0


@dataclass(frozen=True)
class ServiceConfig:
    """Everything the daemon, the sim's adapter and clients agree on.

    Attributes:
        robot: robot id carried by every message; "" (the default) = the robot description's
            ``name`` (:meth:`with_robot`), so each robot file has its own keys. The command line
            resolves it with :func:`resolve_robot_id` (``--robot``, else the robot file's
            ``name``, else this), so this is the id of a robot file that sets no ``name``.
        prefix: first segment(s) of every key expression (``<prefix>/<robot>/...``).
    """

    robot: str = ""
    prefix: str = "wmm"
    zenoh: ZenohConfig = field(default_factory=ZenohConfig)
    loop: LoopConfig = field(default_factory=LoopConfig)
    watchdog: WatchdogConfig = field(default_factory=WatchdogConfig)
    smoothing: SmoothingConfig = field(default_factory=SmoothingConfig)
    validation: ValidationConfig = field(default_factory=ValidationConfig)

    def with_(self, **changes: Any) -> ServiceConfig:
        """A copy with some fields changed; nested sections may be given as dicts."""
        for name in ("zenoh", "loop", "watchdog", "smoothing", "validation"):
            if isinstance(changes.get(name), dict):
                changes[name] = replace(getattr(self, name), **changes[name])
        return replace(self, **changes)

    def with_robot(self, robot: RobotConfig) -> ServiceConfig:
        """This config with the robot id filled from the robot description when it is open
        (``robot = ""``); an id the service config or ``--robot`` set is kept.

        Raises:
            ConfigError: the robot's name is not a key segment (letters, digits, _ -).
        """
        if self.robot:
            return self
        if not _NAME.match(robot.name):
            raise ConfigError(robot.path or "<robot config>", "name",
                              f"must be a key segment (letters, digits, _ -), got {robot.name!r}")
        return replace(self, robot=robot.name)

    def resolved(self) -> ServiceConfig:
        """This config with an open robot id filled from the default robot file's ``name``
        (what a client uses when it is given no robot description)."""
        return self if self.robot else replace(self, robot=default_robot_id())


def default_robot_id() -> str:
    """The ``name`` of the default robot file (:func:`wmm_qp.default_robot_file`), read without
    resolving its URDF; "wmm" when it sets none (the default of :func:`wmm_qp.load_robot_config`)."""
    return robot_file_name(default_robot_file()) or "wmm"


def robot_file_name(path: Path) -> str | None:
    """The ``name`` a robot file sets (read without resolving its URDF), or None when it sets none.

    Raises:
        ConfigError: the file cannot be read, or its ``name`` is not a key segment.
    """
    name = read_toml(path).get("name")
    if name is None:
        return None
    if not isinstance(name, str) or not _NAME.match(name):
        raise ConfigError(path, "name", f"must be a non-empty key segment (letters, digits, _ -), got {name!r}")
    return name


def resolve_robot_id(service: ServiceConfig, robot: str | None = None, robot_file: Path | None = None) -> str:
    """The robot id a command uses, the same for every command (docs/protocol.md "Keys"):

    1. ``robot`` (``--robot``) when given;
    2. else the ``name`` of the robot file (``robot_file``, ``--robot-config``; None: the default
       robot file) when it sets one — so a sim started with a robot file is found by a client
       given the same file, or ``--robot <its name>``;
    3. else the service config's ``robot``; else "wmm".

    Raises:
        ConfigError: an id that is not a key segment (naming the flag or the file's ``name``).
    """
    if robot:
        return check_name(robot, "--robot")
    name = robot_file_name(robot_file if robot_file is not None else default_robot_file())
    return name or service.robot or "wmm"


def _section(root: TomlTable, name: str, cls: Any, base: Any) -> Any:
    """One table of service.toml, typed by the dataclass's defaults (numbers > 0 but z_min)."""
    t = root.table(name, required=False)
    t.unknown({f.name for f in fields(cls)})
    out: dict[str, Any] = {}
    for k in t.data:
        default = getattr(base, k)
        if k == "config":
            p = Path(t.string(k))
            out[k] = p if p.is_absolute() else root.path.parent / p
        elif isinstance(default, str):
            out[k] = t.string(k)
            if not out[k]:
                raise ConfigError(root.path, f"{name}.{k}", "must be a non-empty string")
        elif isinstance(default, int):
            out[k] = t.integer(k, lo=0)
        else:
            out[k] = t.number(k, positive=k != "z_min")
    return replace(base, **out)


def load_service_config(path: Path | str | None = None) -> ServiceConfig:
    """Load and validate ``service.toml`` (default: the config folder's, else built-in defaults).

    Raises:
        ConfigError: unreadable file, unknown key or invalid value (names file and key).
    """
    if path is None:
        p = default_config_dir() / "service.toml"
        if not p.is_file():
            return ServiceConfig()
    else:
        p = Path(path)
    root = TomlTable(p, read_toml(p))
    root.unknown({"zenoh", "loop", "watchdog", "smoothing", "validation", "robot", "prefix"})
    data = root.data
    base = ServiceConfig()
    for k in ("robot", "prefix"):
        if k not in data:
            continue
        v = data[k]
        if not isinstance(v, str) or not _NAME.match(v):
            raise ConfigError(p, k, "must be a non-empty key segment (letters, digits, _ -)")
    cfg = ServiceConfig(
        robot=data.get("robot", base.robot),
        prefix=data.get("prefix", base.prefix),
        zenoh=_section(root, "zenoh", ZenohConfig, base.zenoh),
        loop=_section(root, "loop", LoopConfig, base.loop),
        watchdog=_section(root, "watchdog", WatchdogConfig, base.watchdog),
        smoothing=_section(root, "smoothing", SmoothingConfig, base.smoothing),
        validation=_section(root, "validation", ValidationConfig, base.validation),
    )
    if cfg.validation.z_min >= cfg.validation.z_max:
        raise ConfigError(p, "validation.z_min", "must be < validation.z_max")
    if cfg.watchdog.resume not in ("manual", "auto"):
        raise ConfigError(p, "watchdog.resume", f"must be \"manual\" or \"auto\", got {cfg.watchdog.resume!r}")
    if cfg.loop.trigger not in ("rate", "state"):
        raise ConfigError(p, "loop.trigger", f"must be \"rate\" or \"state\", got {cfg.loop.trigger!r}")
    if cfg.loop.queries_per_tick < 1:
        raise ConfigError(p, "loop.queries_per_tick", "must be >= 1")
    return cfg


def check_name(value: str, what: str) -> str:
    """Validate a robot id or prefix given on the command line.

    Raises:
        ConfigError: not a valid key segment.
    """
    if not _NAME.match(value):
        raise ConfigError("<command line>", what, "must be letters, digits, _ or - (segments split by /)")
    return value
