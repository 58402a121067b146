"""Stable codes of every fault and protective stop, one enum for every layer.

A fault has a code and a message: the code (snake_case, ``^[a-z][a-z0-9_]*$``) is what status
keys, JSON outputs, clients and tests match; the message says what happened, with numbers, and
may be reworded freely. docs/protocol.md "Fault codes" lists them with their meaning.
"""

from __future__ import annotations

from enum import StrEnum


class FaultCode(StrEnum):
    """What went wrong, as a key that never changes with the wording of its message."""

    # --- the daemon's watchdog: conditions that hold the robot in a safe stop
    STATE_STALE = "state_stale"
    """No valid state for the watchdog's ``state_timeout`` (or the robot's token vanished)."""
    SECOND_STATE_SOURCE = "second_state_source"
    """States of a second robot instance on the key: two robots under one id."""
    ROBOT_PROTECTIVE_STOP = "robot_protective_stop"
    """The robot's firmware is in a protective stop (its own code in ``StateMsg.protective_code``)."""
    STATE_TOO_OLD = "state_too_old"
    """The median state-age bound exceeds ``state_age_max`` (bounds (13) assume fresh states)."""
    ROBOT_LOST = "robot_lost"
    """The robot's liveliness token vanished."""
    ROBOT_INSTANCE_CHANGED = "robot_instance_changed"
    """A restarted robot: a new instance id on the key."""
    # --- the command stream
    FOREIGN_COMMANDS = "foreign_commands"
    """The robot moves under commands that are not this daemon's."""
    ROBOT_FIRMWARE = "robot_firmware"
    """The robot reported new protective stops or refused commands (an event)."""
    COMMANDS_NOT_APPLIED = "commands_not_applied"
    """The robot's states name none of this stream's commands as applied."""
    STALL_BRAKING = "stall_braking"
    """This daemon stalled past the robot's command timeout: its stream is braked."""
    STREAM_BROKEN = "stream_broken"
    """The robot stopped following the commands (its timeout or a protective stop)."""
    LEASE_LOST = "lease_lost"
    """Another daemon holds the robot's lease."""
    CONTROLLER_FAILED = "controller_failed"
    """The controller could not produce a command (a failed solve): it braked."""
    # --- the operator's setpoint stream
    SETPOINT_CONFLICT = "setpoint_conflict"
    """A second source's setpoints while another holds the stream."""
    SETPOINT_STAMP_BACK = "setpoint_stamp_back"
    """A setpoint stamp jumped back: taken as a restarted stream."""
    SETPOINT_STAMP_STALE = "setpoint_stamp_stale"
    """A setpoint stamp that does not increase."""
    # --- the robot's firmware: why a protective stop started (``StateMsg.protective_code``)
    REFUSED_COMMAND = "refused_command"
    """A command beyond the rate limits, or not finite: refused, the robot brakes."""
    CANNOT_STOP_BEFORE_LIMIT = "cannot_stop_before_limit"
    """A joint could no longer brake to rest before its position limit at its acceleration limit."""
    ROBOT_REFLEX = "robot_reflex"
    """The robot's own controller stopped the motion (a reflex, a controller error)."""
    RECOVERY_REFUSED = "recovery_refused"
    """The robot refused to recover from an error."""
    ROBOT_STATE_LOST = "robot_state_lost"
    """The robot's own measurements (a ROS 2 robot's joint states) stopped or went stale: it brakes."""
