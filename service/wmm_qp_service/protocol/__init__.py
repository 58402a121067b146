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

The messages are grouped by who speaks them: :mod:`.robot` (state, truth, command, box,
gripper), :mod:`.service` (setpoint, obstacles, mode, status, telemetry, info) and the envelope
and codec every one shares, :mod:`.wire`.
"""

from .robot import GRIPPER_ACTIONS, BoxMsg, CommandMsg, GripperMsg, StateMsg, TruthMsg
from .service import InfoMsg, LoopStats, ModeMsg, ObstaclesMsg, SetpointMsg, StatusMsg, TelemetryMsg
from .wire import PROTOCOL_VERSION, Header, Msg, decode, decoder, encode

__all__ = [
    "GRIPPER_ACTIONS",
    "PROTOCOL_VERSION",
    "BoxMsg",
    "CommandMsg",
    "GripperMsg",
    "Header",
    "InfoMsg",
    "LoopStats",
    "ModeMsg",
    "Msg",
    "ObstaclesMsg",
    "SetpointMsg",
    "StateMsg",
    "StatusMsg",
    "TelemetryMsg",
    "TruthMsg",
    "decode",
    "decoder",
    "encode",
]
