"""The daemon's service messages: what clients send it (``setpoint``, ``obstacles``, ``mode``) and
what it tells them (``status``, ``telemetry``, the ``info`` reply)."""

from __future__ import annotations

from typing import Any

import msgspec

from .wire import Msg


class SetpointMsg(Msg, tag="setpoint", kw_only=True):
    """client → daemon: an EE target (world frame).

    Attributes:
        x: [m] target EE position.
        xd: [m/s] the target's velocity (feed-forward, e.g. a scripted trajectory);
            None: the daemon estimates it from the stream.
        source: the sending operator's id (one operator holds the stream at a time).
        q: target EE orientation, a quaternion [x, y, z, w] (world; normalised by the
            controller); None: keep the orientation target the daemon has. Used with the pose
            task only: a daemon running the position task accepts the setpoint, ignores its
            orientation and counts it (``StatusMsg.orientation_ignored``).
        w: [rad/s] the orientation target's angular velocity (world; feed-forward); None: 0.
    """

    x: list[float]
    xd: list[float] | None = None
    source: str
    q: list[float] | None = None
    w: list[float] | None = None


class ObstaclesMsg(Msg, tag="obstacles", kw_only=True):
    """client (perception, an operator) → daemon and sim: the live obstacles, world frame.

    Each message replaces the previous live set as a whole (the scene file's obstacles stay); an
    empty list clears it. A set older than ``obstacles.timeout`` (service.toml) is *kept* — a
    stale perception does not make an obstacle vanish — and the status says ``obstacles_stale``.

    Attributes:
        source: the sender's id.
        obstacles: tables with the keys of a scene file's ``[[obstacles]]`` (``wmm_qp.scene``):
            ``id`` (unique), ``kind`` (box | sphere | capsule | cylinder | plane), ``size``
            (box) or ``radius`` (+ ``length``), ``xyz``, ``rpy``, ``normal``/``offset`` (plane),
            ``exempt`` (links that may touch it; "ee": those moving with the EE).
    """

    source: str
    obstacles: list[dict[str, Any]]


class ModeMsg(Msg, tag="mode"):
    """client → daemon: change the mode.

    Attributes:
        mode: hold | track | dm_cartesian | dm_nullspace.
        direction: DM direction u (base, yaw-compensated frame); None: the config's.
    """

    mode: str
    direction: list[float] | None = None


class LoopStats(msgspec.Struct, kw_only=True):
    """Loop timing figures.

    Attributes:
        rate_hz: [Hz] configured rate.
        measured_hz: [Hz] ticks per second since start.
        ticks: ticks run.
        deadline_misses: ticks that started after their deadline.
        tick_p50_us, tick_p99_us, tick_max_us: [µs] work time per tick (recent window; max: ever).
        trigger: ``rate`` (fixed-rate ticks) or ``state`` (a tick per new state, ``loop.trigger``),
            or ``embedded`` (the core ticks in the robot's own cycle, ``--embedded``: a deadline
            miss is a tick whose cycle started after its deadline).
        watchdog_ticks: (state trigger) ticks without a new state for 1.5 periods: the
            prediction path; each is also a deadline miss.
        overruns: ticks whose command came more than a period after their start (rate) or their
            state (state trigger).
    """

    rate_hz: float = 0.0
    measured_hz: float = 0.0
    ticks: int = 0
    deadline_misses: int = 0
    tick_p50_us: float = 0.0
    tick_p99_us: float = 0.0
    tick_max_us: float = 0.0
    trigger: str = "rate"
    watchdog_ticks: int = 0
    overruns: int = 0


class StatusMsg(Msg, tag="status"):
    """daemon → all: what the daemon is doing (~10 Hz, and on the ``info`` query).

    Attributes:
        mode: current mode.
        state_ok: a fresh, valid state is arriving.
        safe_stop: the daemon is commanding a safe stop.
        controller_status, reason: of the last command.
        last_fault: the last fault's message ("" = none), e.g. "state stale (none valid for >
            50 ms)"; it stays after the fault cleared: ``fault_active`` says whether one holds the
            robot now. A note that is not a fault (a failed reply) may replace it.
        last_fault_code: the last fault's code ("" = none), e.g. ``state_stale``, ``robot_lost``.
        fault_active: a fault holds the robot now (a safe stop, a broken command stream, a lost
            lease, a stream whose commands the robot's states have not named applied for 1 s), or
            ``resume_needed``: the robot does not follow setpoints until a client acts.
        last_fault_age: [s] time since ``last_fault`` was recorded (daemon clock; nan: none).
        loop: timing figures.
        rejected: rejected messages, by reason.
        accepted: accepted messages, by key (state, setpoint, mode).
        robot_violations: the referee's counts, by kind (from the last ``sim/truth`` message;
            empty without one).
        x, x_d: [m] EE position (model, odometry: of the last command, or of the last state
            when the command has none, as a safe stop's; never NaN, [] before a state) and
            smoothed target.
        dm: directional manipulability along the active direction.
        robot_alive: the sim's liveliness token is present.
        faults: faults seen since start, by code (``state_stale``, ``stall_braking``, …:
            :class:`wmm_qp.fault_codes.FaultCode`, docs/protocol.md "Fault codes").
        lease: this daemon's control lease id; ``lease_holder``: the holder the sim reports.
        robot_instance: the latched sim instance ("" = none yet).
        operator: the source holding the setpoint stream ("" = none).
        operator_conflicts: setpoints refused because another operator held the stream.
        resume_needed: a safe stop ended, and the daemon holds until a mode message resumes.
        round_trip_ms: [ms] the smallest command → state round trip of the recent window
            (an upper bound of the state's age measured without shared clocks).
        protective_stop: the robot's firmware reports a protective stop.
        quat_d: the orientation target, a quaternion [x, y, z, w] (world), pose task only
            ([] with the position task).
        orientation_error: [rad] angle between the EE's orientation (last state; model,
            odometry) and ``quat_d``; nan with the position task.
        orientation_ignored: setpoints whose orientation was ignored (the position task).
        clamped: setpoints clamped into the scene's fence (its EE box) and above the floor
            margin before they were followed; ``last_clamp``: the last one, e.g. "x 20 -> 3.5".
        obstacles: obstacles the controller keeps away from (the scene's and the live ones);
            ``obstacles_live``: of them, from the last live set; ``obstacles_stale``: that set
            is older than ``obstacles.timeout`` (kept all the same).
        collision_distance, collision_pair: [m] the closest monitored pair of the last tick
            (self, floor, obstacles; nan and "" without collision rows).
        collision: the controller has collision rows (on by default; off with ``--no-collision``,
            ``[collision] enabled = false`` or a controller without rows, paper and traditional).
        collision_summary: one line saying so, e.g. "collision rows on (24 self pairs, 7 bodies
            vs the floor, 0 obstacles, fence)" or "no collision rows".
    """

    mode: str
    state_ok: bool
    safe_stop: bool
    controller_status: str = ""
    reason: str = ""
    last_fault: str = ""
    last_fault_code: str = ""
    fault_active: bool = False
    last_fault_age: float = float("nan")
    loop: LoopStats = msgspec.field(default_factory=LoopStats)
    rejected: dict[str, int] = msgspec.field(default_factory=dict)
    accepted: dict[str, int] = msgspec.field(default_factory=dict)
    robot_violations: dict[str, int] = msgspec.field(default_factory=dict)
    x: list[float] = msgspec.field(default_factory=list)
    x_d: list[float] = msgspec.field(default_factory=list)
    dm: float = float("nan")
    robot_alive: bool = False
    faults: dict[str, int] = msgspec.field(default_factory=dict)
    lease: str = ""
    lease_holder: str = ""
    robot_instance: str = ""
    operator: str = ""
    operator_conflicts: int = 0
    resume_needed: bool = False
    round_trip_ms: float = float("nan")
    protective_stop: bool = False
    quat_d: list[float] = msgspec.field(default_factory=list)
    orientation_ignored: int = 0
    orientation_error: float = float("nan")
    clamped: int = 0
    last_clamp: str = ""
    obstacles: int = 0
    obstacles_live: int = 0
    obstacles_stale: bool = False
    collision_distance: float = float("nan")
    collision_pair: str = ""
    collision: bool = False
    collision_summary: str = ""


class TelemetryMsg(Msg, tag="telemetry"):
    """daemon → all: one tick (every ``loop.telemetry_every`` ticks).

    Attributes:
        t: [s] daemon time since start.
        mode: current mode.
        x: [m] EE position (model, odometry base pose).
        x_d, xd_d: [m], [m/s] the reference handed to the controller.
        ee_true: [m] ground-truth EE position from the last ``sim/truth`` message (nan: none).
        ee_error: [m] ‖ee_true − x_d‖ (tracking modes, with a truth), nan otherwise.
        wheel_speeds, arm_rates: [rad/s] the command (n_wheels, n_arm).
        status: controller status.
        dm: directional manipulability.
        task_error: [m/s] ‖J v − ẋ_ref‖.
        tick_us: [µs] work time of the previous tick, all of it (inputs to status and queries:
            this tick's own ends after its telemetry).
        step_us: [µs] this tick's ``ctl.step`` alone.
        state_seq: seq of the state this tick's command was computed from (-1: a predicted
            state, no new one arrived), as the command's ``state_seq``.
        state_rx: [s] the daemon's ``time.time()`` when it received that state (nan: predicted).
        cmd_stamp: [s] the daemon's ``time.time()`` right after it published the command.
    """

    t: float
    mode: str
    x: list[float]
    x_d: list[float]
    xd_d: list[float]
    ee_true: list[float]
    ee_error: float
    wheel_speeds: list[float]
    arm_rates: list[float]
    status: str
    dm: float
    task_error: float
    tick_us: float
    step_us: float = float("nan")
    state_seq: int = -1
    state_rx: float = float("nan")
    cmd_stamp: float = float("nan")


class InfoMsg(Msg, tag="info"):
    """Reply of the ``info`` queryable: status, the robot the daemon drives, the running configuration.

    Attributes:
        status: the current status.
        config: service, controller and robot settings as plain data.
        joints: the arm's controlled joints, in the order of every arm vector (``q_arm``,
            ``v_arm``, ``tau``, ``arm_rates``).
        wheels: the base's wheels, in the order of every wheel vector (``wheel_speeds``).
        base_kind: ``mecanum``, ``omni``, ``diff_drive`` or ``fixed``.
        task: the task kind, ``position`` (r = 3) or ``pose`` (r = 6: setpoints' ``q`` is used).
        n_arm, n_wheels: the lengths of the arm and wheel vectors (``len(joints)``, ``len(wheels)``).
        collision, collision_summary: as in :class:`StatusMsg`: whether the controller has
            collision rows, and one line saying which.
    """

    status: StatusMsg
    config: dict[str, Any] = msgspec.field(default_factory=dict)
    joints: list[str] = msgspec.field(default_factory=list)
    wheels: list[str] = msgspec.field(default_factory=list)
    base_kind: str = ""
    task: str = ""
    n_arm: int = -1
    n_wheels: int = -1
    collision: bool = False
    collision_summary: str = ""
