"""The robot's messages: what the robot side publishes (``state``, ``sim/truth``) and what it is
sent (``cmd`` from the daemon; ``sim/box`` and ``gripper`` from clients)."""

from __future__ import annotations

import msgspec

from .wire import Msg


class StateMsg(Msg, tag="state", kw_only=True):
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
        cmd_seq: seq of the last command the robot applied, or refused with a stop that names
            it (its sender then sees the stream stopped) (-1: none).
        instance: this robot process's identity (random, fixed for its life): the daemon
            latches it and treats states of another instance as a second source (a fault).
        lease: the control lease holder whose commands the robot applies ("" = none).
        protective_stop: the robot's firmware is braking (a refused command or a motion that
            could not stop before a limit), or holds it at rest until a new command stream.
        protective_stops: protective stops since the robot process started.
        protective_reason: why the last one started.
        protective_code: its stable code (``refused_command``, ``cannot_stop_before_limit``,
            ``robot_reflex``, ``recovery_refused``: :class:`wmm_qp.fault_codes.FaultCode`; "" = none yet).
        refused: commands not applied, by reason (``lease``, ``instance``, ``seq``, ``firmware``:
            the firmware's refusals, each a fault of the sender's; ``ended``: legal commands of
            a stream a stale or protective stop had ended; the FR3's ``recovering``: a new stream
            within a second of a refused recovery; and the validation reasons).

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
    protective_code: str = ""
    refused: dict[str, int] = msgspec.field(default_factory=dict)


class TruthMsg(Msg, tag="truth", kw_only=True):
    """sim (or a driver's referee) → observers: evaluation data no controller may use.

    Published on ``<robot>/sim/truth`` with each state; the daemon runs the same without it
    (its telemetry's ``ee_error`` is then nan and its status's ``robot_violations`` empty).

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


class CommandMsg(Msg, tag="cmd", kw_only=True):
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


class BoxMsg(Msg, tag="box"):
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


class GripperMsg(Msg, tag="gripper", kw_only=True):
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
