"""Quasi-static box contact: the push experiment's box and the joint torques it causes.

The box sits on the floor in front of the EE; its face is a plane x = face_x (world), spanning
y ∈ center_y ± width/2 and z ∈ [0, height]. Quasi-static Coulomb model (inertia neglected, as
the paper's slow push):

- The EE is in contact when, after a step, it lies beyond the face (x_EE > face_x) inside the
  face's extent. To keep the box sliding the robot must push with F = μ m g along +x.
- The joint torques this needs are τ = J_mᵀ F (F = the force the EE applies, world frame;
  J_m the world-aligned arm Jacobian). If every |τ_i| ≤ τ_lim,i the box slides with the EE:
  the face moves to x_EE.
- Otherwise the push stalls: the box does not move, and neither does the robot (the joints
  hold at their torque limit, the wheels spin in place — odometry still integrates them).
  The EE stays where it was (at the face). The force then exerted is the largest s along +x
  that respects every torque limit, s = min_i τ_lim,i / |(J_mᵀ x̂)_i|, so the stalled joint
  (the arg-min) reports exactly its torque limit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wmm_qp.config import FloatArray

from .config import BoxConfig

PUSH_AXIS = np.array([1.0, 0.0, 0.0])


@dataclass(slots=True)
class ContactResult:
    """Outcome of one contact check.

    Attributes:
        in_contact: the EE is beyond the face, inside its extent.
        stalled: the push needs more torque than some joint has: the robot must not move.
        force: [N] force the EE applies to the box (world).
        tau: [N·m] joint torques J_mᵀ force.
        stalled_joint: index (0-based) of the joint that limits the push, or None.
    """

    in_contact: bool
    stalled: bool
    force: FloatArray
    tau: FloatArray
    stalled_joint: int | None


class Box:
    """A box pushed along +x.

    Args:
        config: mass, friction and geometry.

    Attributes:
        face_x: [m] world x of the pushed face now.
        rpy: [rad] the box's roll, pitch, yaw (world); zeros while it stands upright (the
            quasi-static box always does; a physics box may tip).
        center: [m] the box's centre (world) where a plant measures it, else None (upright, its
            face at ``face_x``).
    """

    def __init__(self, config: BoxConfig) -> None:
        self.config = config
        self.face_x = config.face_x
        self.rpy = np.zeros(3)
        self.center: FloatArray | None = None

    @property
    def tilt(self) -> float:
        """[rad] how far the box leans from upright (roll and pitch)."""
        return float(np.hypot(self.rpy[0], self.rpy[1]))

    @property
    def displacement(self) -> float:
        """[m] how far the box has been pushed from its start."""
        return self.face_x - self.config.face_x

    def in_face(self, ee: FloatArray) -> bool:
        """The EE's y and z are inside the face's extent."""
        c = self.config
        return bool(abs(ee[1] - c.center_y) <= 0.5 * c.width and 0.0 <= ee[2] <= c.height)

    def check(self, ee: FloatArray, J_m: FloatArray, torque_limit: FloatArray) -> ContactResult:
        """The contact at a candidate configuration (EE position ee [m], world Jacobian J_m).

        Does not move the box: call :meth:`slide_to` when the motion is accepted.
        """
        if not (ee[0] > self.face_x and self.in_face(ee)):
            return ContactResult(False, False, np.zeros(3), np.zeros(J_m.shape[1]), None)
        F = self.config.friction_force * PUSH_AXIS
        tau = J_m.T @ F  # τ = J_mᵀ F
        if np.all(np.abs(tau) <= torque_limit):
            return ContactResult(True, False, F, tau, None)
        per_newton = np.abs(J_m.T @ PUSH_AXIS)
        with np.errstate(divide="ignore"):
            ratio = np.where(per_newton > 0, torque_limit / per_newton, np.inf)
        joint = int(np.argmin(ratio))
        F_max = float(ratio[joint]) * PUSH_AXIS
        return ContactResult(True, True, F_max, J_m.T @ F_max, joint)

    def slide_to(self, x: float) -> None:
        """The box slides so that its face is at world x [m] (never backwards)."""
        self.face_x = max(self.face_x, x)
