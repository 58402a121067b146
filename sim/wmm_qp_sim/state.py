"""Everything the simulated robot reports, ground truth included."""

from __future__ import annotations

from dataclasses import dataclass, field

from wmm_qp.config import FloatArray


@dataclass(slots=True)
class SimState:
    """Everything the sim reports (ground truth included).

    Attributes:
        t: [s] sim time since reset.
        q_arm: [rad] measured joint angles.
        v_arm: [rad/s] executed joint rates: what the drives run (the firmware's ramp and stops
            applied), exactly 0 at rest, as a real robot's state reports them (docs/drivers.md).
            The kinematic plant measures the same; a physics plant's measured rates lag them
            and are never exactly 0 (:class:`~.plant.PlantState`).
        wheel_speeds: [rad/s] executed wheel speeds, the same way (the odometry integrates the
            measured ones: a physics plant's are those of the base's achieved twist).
        base_odom: [m, m, rad] base pose integrated from the wheel speeds with the nominal model.
        base_true: [m, m, rad] true base pose (with slip and drift).
        ee_true: [m] true EE position (world), the "motion capture".
        tau: [N·m] joint torques: the kinematic plant's J_mᵀ F from the box contact (zeros without
            contact), a physics plant's what its drives exert (servo and gravity compensation).
        contact_force: [N] force the EE applies to the box (world).
        box_position: [m] world x of the box face, nan without a box.
        box_displacement: [m] how far the box has been pushed, nan without a box.
        stalled_joint: the joint (0-based) at its torque limit this step (the kinematic plant: the
            joint that stalled the push), or None.
        violations: counts by kind (see :mod:`.referee`).
        stale_stop: the sim is braking because commands went stale.
        rejected_commands: malformed commands ignored since reset.
        commands: valid commands received since reset.
        protective_stop: the firmware is braking the robot (or holds it at rest) after a
            command it refused.
        protective_stops: protective stops since reset.
        protective_reason: why the last protective stop started ("" = none yet).
        protective_code: its code (a :class:`~wmm_qp.fault_codes.FaultCode` value; "" = none yet).
        refused_commands: commands the firmware refused since reset (past a limit, or while
            braking in a protective stop): each one a fault of the sender's.
        ended_commands: commands of a stream a stale or protective stop had ended, refused since
            reset: the stop is the event (late commands of that stream are expected, e.g. a
            frozen sender's transmit queue), not each of them.
        drives: per joint, since reset: ``torque_limit`` the steps it was at its torque limit,
            ``tracking`` the steps it could not follow its commanded rate (a physics plant only;
            the first such joint of a step is counted). Reports, not violations.
        gripper_width: [m] the gripper's opening (nan: the robot file declares no gripper).
    """

    t: float
    q_arm: FloatArray
    v_arm: FloatArray
    wheel_speeds: FloatArray
    base_odom: FloatArray
    base_true: FloatArray
    ee_true: FloatArray
    tau: FloatArray
    contact_force: FloatArray
    box_position: float
    box_displacement: float
    stalled_joint: int | None
    violations: dict[str, int]
    stale_stop: bool
    rejected_commands: int = 0
    commands: int = 0
    protective_stop: bool = False
    protective_stops: int = 0
    protective_reason: str = ""
    protective_code: str = ""
    refused_commands: int = 0
    ended_commands: int = 0
    drives: dict[str, list[int]] = field(default_factory=dict)
    gripper_width: float = float("nan")
