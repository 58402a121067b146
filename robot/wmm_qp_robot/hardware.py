"""The hardware interface: the seam between a robot's firmware and what moves.

ros2_control's shape: the firmware ``write``\\ s the rates it wants the actuators to follow and
``read``\\ s back what the hardware measured; the hardware knows nothing of commands, streams,
stops or limits to enforce, the firmware and the referees nothing of how the motion is produced.
Implementations: the simulated plants (``wmm_qp_sim.kinematic_plant.KinematicPlant``,
``wmm_qp_sim.mujoco_plant.MujocoPlant``, which add ``advance`` for simulated time) and a driver's
link to a real robot. A new robot kind is one implementation.
"""

from __future__ import annotations

from typing import Protocol

from wmm_qp.config import FloatArray


class Measured(Protocol):
    """What a robot's hardware measures: the arm's joints in the robot description's order, the
    wheels in the base kind's order."""

    q_arm: FloatArray
    """[rad or m] joint positions."""
    v_arm: FloatArray
    """[rad/s or m/s] joint velocities."""
    wheel_speeds: FloatArray
    """[rad/s] wheel speeds."""


class HardwareInterface(Protocol):
    """A robot's hardware, as its firmware drives it."""

    def write(self, wheel_speeds: FloatArray, arm_rates: FloatArray) -> None:
        """The rates the drives follow from now on: wheels [rad/s], joints [rad/s or m/s]."""

    def read(self) -> Measured:
        """What the hardware measures now."""
