"""The plant: the simulated robot's hardware, behind the firmware and the referees.

A plant is a :class:`wmm_qp_robot.hardware.HardwareInterface` (the seam of ros2_control's
hardware interface) with simulated time: the robot's firmware (:class:`~.robot.SimRobot`)
``write``\\ s the rates it wants the drives to follow, ``advance``\\ s the plant by one step and
``read``\\ s back what the hardware measured. A plant knows nothing of commands, streams, stops or
limits to enforce; the firmware and the referees know nothing of how the motion is produced.

Implementations: :class:`~.kinematic_plant.KinematicPlant` (the rates happen exactly, the base
slips through :mod:`.slip`, the push box is quasi-static, :mod:`.contact`) and
:class:`~.mujoco_plant.MujocoPlant` (rigid-body physics, torque-limited servos; optional).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

from wmm_qp_robot.hardware import HardwareInterface

from wmm_qp.config import FloatArray

from .config import BoxConfig
from .contact import Box


@dataclass(slots=True)
class PlantState:
    """What the hardware measured after a step (ground truth included).

    Attributes:
        q_arm: [rad or m] joint positions (the robot description's joint order).
        v_arm: [rad/s or m/s] joint velocities.
        wheel_speeds: [rad/s] wheel speeds (the base kind's wheel order).
        base_true: [m, m, rad] the true base pose (x, y, ψ).
        tau: [N·m or N] joint torques: the kinematic plant's are the box contact's J_mᵀ F only
            (it carries no weight), a physics plant's are what its drives exert (servo and
            gravity compensation).
        contact_force: [N] force the EE applies to the box (world).
        stalled_joint: a joint (0-based) at its torque limit this step, or None (the first).
        lagging_joint: a joint (0-based) that could not follow its commanded rate this step, or
            None (the first; the kinematic plant's joints always follow).
    """

    q_arm: FloatArray
    v_arm: FloatArray
    wheel_speeds: FloatArray
    base_true: FloatArray
    tau: FloatArray
    contact_force: FloatArray
    stalled_joint: int | None
    lagging_joint: int | None = None


class Plant(HardwareInterface, Protocol):
    """The simulated hardware a :class:`~.robot.SimRobot` drives.

    Attributes:
        box: the push box (its face's world x, its config; a physics plant also its centre and
            orientation, which it may tip to), or None.
    """

    box: Box | None

    def reset(self, q_base: FloatArray, q_arm: FloatArray, box: BoxConfig | None) -> None:
        """Put the robot at rest at (q_base [m, m, rad], q_arm [rad]) with this box (None: none)."""

    def place_box(self, box: BoxConfig | None) -> None:
        """Put a box in the scene now (None: remove it), keeping the robot's state."""

    def set_base_pose(self, pose: Sequence[float] | FloatArray) -> None:
        """Carry the base to pose [m, m, rad] (someone lifted it), keeping its rates."""

    def write(self, wheel_speeds: FloatArray, arm_rates: FloatArray) -> None:
        """The rates the drives follow from now on: wheels [rad/s], joints [rad/s or m/s]."""

    def advance(self, dt: float) -> None:
        """Advance the hardware by dt [s]."""

    def read(self) -> PlantState:
        """What the hardware measures now."""
