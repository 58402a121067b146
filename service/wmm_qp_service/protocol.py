"""Typed, versioned wire messages (msgspec Structs, msgpack-encoded).

Every message is a msgpack map with ``type`` (the schema's tag), ``v`` (protocol version),
``robot`` (the robot id), ``seq`` (sender's counter) and ``stamp`` ([s], sender's
``time.time()``), plus its own fields. On receipt all five are required (a message that lacks
one is rejected, ``schema``), although the Python constructors fill ``type`` and ``v``.
Vectors are lists of floats whose lengths are the robot's (its description's joints and wheels,
or 3 for task-space vectors), checked on receipt by :mod:`wmm_qp_service.validation`. Joint
vectors are in the robot description's joint order (``RobotConfig.arm.joints``), wheel vectors
in its base kind's wheel order (``WmmModel.base.wheel_names``); the daemon's ``info`` reply names
both. Units are SI, angles rad (a prismatic joint's values are m, m/s). See docs/protocol.md.
"""

from __future__ import annotations

from typing import Any, TypeVar

import msgspec

PROTOCOL_VERSION = 3
"""Bumped on any incompatible change of a schema below (2: the sim instance, the control lease,
the setpoint's source and the command's period and state seq are required fields; 3: the state
holds only what a real robot reports, the sim's evaluation data moved to :class:`TruthMsg`). Optional
fields with a default may be added within a version (2 gained the setpoint's ``q`` and ``w``,
the status's ``quat_d``, ``orientation_ignored``, ``fault_active``, ``last_fault_age`` and
``orientation_error``, and the info reply's robot description)."""


class _Msg(msgspec.Struct, kw_only=True, forbid_unknown_fields=True, tag_field="type"):
    v: int = PROTOCOL_VERSION
    robot: str
    seq: int = 0
    stamp: float = 0.0


class Header(msgspec.Struct, forbid_unknown_fields=False):
    """The fields every message has (checked for presence on receipt, and used to explain a
    rejected message)."""

    type: str | None = None
    v: int | None = None
    robot: str | None = None
    seq: int | None = None
    stamp: float | None = None


class StateMsg(_Msg, tag="state", kw_only=True):
    """robot → daemon: what the robot measures and its firmware reports (at the robot's rate).

    Only what a real robot reports: the sim's evaluation data (ground truth, the box, the
    referee) is in :class:`TruthMsg`, which nothing on the control path needs.

    Attributes:
        t: [s] robot time.
        q_base: [m, m, rad] base pose from odometry (what a controller may use).
        q_arm: [rad or m] n_arm joint values (the robot description's joint order).
        v_arm: [rad/s or m/s] n_arm executed joint rates.
        wheel_speeds: [rad/s] n_wheels executed wheel speeds (the base kind's wheel order).
        tau: [N·m or N] n_arm measured joint torques (the sim: from its contact model).
        gripper_width: [m] the gripper's opening (nan: no gripper).
        stale_stop: the firmware is braking because commands went stale.
        cmd_seq: seq of the last command the robot applied (-1: none).
        instance: this robot process's identity (random, fixed for its life): the daemon
            latches it and treats states of another instance as a second source (a fault).
        lease: the control lease holder whose commands the robot applies ("" = none).
        protective_stop: the robot's firmware is braking (a refused command or a motion that
            could not stop before a limit), or holds it at rest until a new command stream.
        protective_stops: protective stops since the robot process started.
        protective_reason: why the last one started.
        refused: commands not applied, by reason (``lease``, ``instance``, ``firmware``,
            and the validation reasons).

    ``seq`` is the robot's step counter: consecutive states of one instance have consecutive seq.
    """

    t: float
    q_base: list[float]
    q_arm: list[float]
    v_arm: list[float]
    wheel_speeds: list[float]
    tau: list[float]
    gripper_width: float = float("nan")
    stale_stop: bool = False
    cmd_seq: int = -1
    instance: str
    lease: str = ""
    protective_stop: bool = False
    protective_stops: int = 0
    protective_reason: str = ""
    refused: dict[str, int] = msgspec.field(default_factory=dict)


class TruthMsg(_Msg, tag="truth", kw_only=True):
    """sim (or a driver's referee) → observers: evaluation data no controller may use.

    Published on ``<robot>/sim/truth`` with each state; the daemon runs the same without it
    (its telemetry's ``ee_error`` is then nan and its status's ``sim_violations`` empty).

    Attributes:
        t: [s] robot time of the state this truth belongs to.
        instance: the publishing robot process's instance (as its states').
        state_seq: seq of the state published with it.
        base_true: [m, m, rad] ground-truth base pose (nan: unknown, e.g. a real robot).
        ee_true: [m] ground-truth EE position ("motion capture"; nan: unknown).
        contact_force: [N] 3 EE contact force of the sim's contact model (nan: unknown).
        box_position: [m] box position along the push axis (nan: no box).
        stalled_joint: the joint (0-based) that stalled the push this step (-1: none).
        violations: limit-referee counts by kind.
    """

    t: float
    instance: str
    state_seq: int
    base_true: list[float]
    ee_true: list[float]
    contact_force: list[float]
    box_position: float = float("nan")
    stalled_joint: int = -1
    violations: dict[str, int] = msgspec.field(default_factory=dict)


class CommandMsg(_Msg, tag="cmd", kw_only=True):
    """daemon → sim: one tick's command, held by the sim until the next.

    Attributes:
        wheel_speeds: [rad/s] n_wheels wheel speeds (the base kind's wheel order).
        arm_rates: [rad/s or m/s] n_arm joint rates (the robot description's joint order).
        status: controller status (ok, saturated, damped, safe_stop).
        lease: the sender's control lease id (the sim applies commands of the holder only).
        instance: the sim instance the command is for (the daemon's latched one).
        period: [s] the control period Δt the command's bounds (13) assume; the sim's referee
            judges the change from the previous command over it.
        state_seq: seq of the state the command was computed from (-1: a predicted state).
        stream: the seq of the first command of the stream this one continues: a new value
            says the sender started again from the robot's measured rates (the referee then
            judges it against what the robot executes, else against the previous command).
    """

    wheel_speeds: list[float]
    arm_rates: list[float]
    status: str = "ok"
    lease: str
    instance: str
    period: float
    state_seq: int = -1
    stream: int


class BoxMsg(_Msg, tag="box"):
    """client → sim: place a box in the scene now (between two sim steps), pushed along +x.

    Attributes:
        mass: [kg] box mass.
        mu: [-] Coulomb friction coefficient box/floor.
        face_x: [m] world x of the face the EE pushes on.
        center_y: [m] world y of the face's centre.
        width: [m] face extent along y.
        height: [m] face extent along z (from the floor).
    """

    mass: float
    mu: float
    face_x: float
    center_y: float
    width: float = 0.4
    height: float = 0.6


GRIPPER_ACTIONS = ("open", "close", "move", "grasp")
"""The gripper commands: ``open`` and ``close`` (to the gripper's full and zero width at
``speed``), ``move`` (to ``width`` at ``speed``), ``grasp`` (close to ``width`` at ``speed``,
holding with ``force``)."""


class GripperMsg(_Msg, tag="gripper", kw_only=True):
    """client → robot: one gripper command, applied at once (a new one replaces a running one).

    Attributes:
        action: one of :data:`GRIPPER_ACTIONS`.
        width: [m] the target opening (``move``, ``grasp``; ignored by ``open``/``close``).
        speed: [m/s] the fingers' speed (the robot clamps it to its ``[gripper] speed_max``).
        force: [N] the grasp force (``grasp``; clamped to ``[gripper] force_max``).
        source: the sender's id.
    """

    action: str
    width: float = 0.0
    speed: float = 0.05
    force: float = 0.0
    source: str


class SetpointMsg(_Msg, tag="setpoint", kw_only=True):
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


class ObstaclesMsg(_Msg, tag="obstacles", kw_only=True):
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


class ModeMsg(_Msg, tag="mode"):
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
        trigger: ``rate`` (fixed-rate ticks) or ``state`` (a tick per new state, ``loop.trigger``).
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


class StatusMsg(_Msg, tag="status"):
    """daemon → all: what the daemon is doing (~10 Hz, and on the ``info`` query).

    Attributes:
        mode: current mode.
        state_ok: a fresh, valid state is arriving.
        safe_stop: the daemon is commanding a safe stop.
        controller_status, reason: of the last command.
        last_fault: the last fault seen ("" = none), e.g. "state stale", "sim lost"; it stays
            after the fault cleared: ``fault_active`` says whether one holds the robot now.
        fault_active: a fault holds the robot now (a safe stop, a broken command stream, a lost
            lease), or ``resume_needed``: the robot does not follow setpoints until a client acts.
        last_fault_age: [s] time since ``last_fault`` was recorded (daemon clock; nan: none).
        loop: timing figures.
        rejected: rejected messages, by reason.
        accepted: accepted messages, by key (state, setpoint, mode).
        sim_violations: the referee's counts, by kind (from the last ``sim/truth`` message;
            empty without one).
        x, x_d: [m] EE position (model, odometry: of the last command, or of the last state
            when the command has none, as a safe stop's; never NaN, [] before a state) and
            smoothed target.
        dm: directional manipulability along the active direction.
        sim_alive: the sim's liveliness token is present.
        faults: faults seen since start, by kind.
        lease: this daemon's control lease id; ``lease_holder``: the holder the sim reports.
        sim_instance: the latched sim instance ("" = none yet).
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
    fault_active: bool = False
    last_fault_age: float = float("nan")
    loop: LoopStats = msgspec.field(default_factory=LoopStats)
    rejected: dict[str, int] = msgspec.field(default_factory=dict)
    accepted: dict[str, int] = msgspec.field(default_factory=dict)
    sim_violations: dict[str, int] = msgspec.field(default_factory=dict)
    x: list[float] = msgspec.field(default_factory=list)
    x_d: list[float] = msgspec.field(default_factory=list)
    dm: float = float("nan")
    sim_alive: bool = False
    faults: dict[str, int] = msgspec.field(default_factory=dict)
    lease: str = ""
    lease_holder: str = ""
    sim_instance: str = ""
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


class TelemetryMsg(_Msg, tag="telemetry"):
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


class InfoMsg(_Msg, tag="info"):
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


_ENC = msgspec.msgpack.Encoder()

T = TypeVar("T", bound=msgspec.Struct)


def encode(msg: msgspec.Struct) -> bytes:
    """msgpack bytes of a message."""
    return _ENC.encode(msg)


def decoder(cls: type[T]) -> msgspec.msgpack.Decoder[T]:
    """A reusable strict decoder for one message type."""
    return msgspec.msgpack.Decoder(cls)


def decode(cls: type[T], data: bytes) -> T:
    """Decode one message of a known type (raises :class:`msgspec.DecodeError`)."""
    return msgspec.msgpack.decode(data, type=cls)
