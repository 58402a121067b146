"""The kinematic plant: the drives execute the written rates exactly.

The arm integrates the written joint rates; the true base integrates the written wheel speeds
through the base kind's matrix with slip and drift (:mod:`.slip`); the measured rates are the
written ones. A push box is quasi-static (:mod:`.contact`): while the EE pushes it the joints
carry τ = J_mᵀ F, and a push that needs more torque than a joint has stalls the whole robot
(neither the arm nor the base moves; the wheels spin in place).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

import wmm_qp
from wmm_qp.config import FloatArray

from .config import BoxConfig, SlipConfig
from .contact import Box
from .plant import PlantState
from .slip import SlipModel, integrate_pose


class KinematicPlant:
    """Rates happen as written; slip on the base; quasi-static box contact.

    Args:
        model: the robot's kinematic model (its torque limits bound the push).
        slip: the slip and drift model's parameters.
        seed: seed of the slip noise (re-drawn from it at every reset).
    """

    def __init__(self, model: wmm_qp.WmmModel, slip: SlipConfig, seed: int) -> None:
        self.model = model
        self.seed = seed
        self.rng = np.random.default_rng(seed)
        self.slip = SlipModel(slip, model.base.M, self.rng)
        self.torque_limit = np.array(model.config.arm.torque_limit, dtype=float)
        self.n_arm, self.n_wheels = model.n_arm, model.n_wheels
        self.box: Box | None = None
        self.reset(np.zeros(3), np.array(model.config.arm.start, dtype=float), None)

    def reset(self, q_base: FloatArray, q_arm: FloatArray, box: BoxConfig | None) -> None:
        """At rest at (q_base [m, m, rad], q_arm [rad]); the slip noise re-drawn from the seed."""
        self.rng = np.random.default_rng(self.seed)
        self.slip.rng = self.rng
        self.slip.reset()
        self.q_arm = np.array(q_arm, dtype=float).reshape(self.n_arm)
        self.v_arm = np.zeros(self.n_arm)
        self.wheels = np.zeros(self.n_wheels)
        self.base_true = np.array(q_base, dtype=float).reshape(3)
        self.place_box(box)
        self.tau = np.zeros(self.n_arm)
        self.force = np.zeros(3)
        self.stalled_joint: int | None = None

    def place_box(self, box: BoxConfig | None) -> None:
        """Put a box in the scene now (None: remove it)."""
        self.box = Box(box) if box is not None else None

    def set_base_pose(self, pose: Sequence[float] | FloatArray) -> None:
        """Carry the base to pose [m, m, rad]."""
        self.base_true = np.array(pose, dtype=float).reshape(3)

    def write(self, wheel_speeds: FloatArray, arm_rates: FloatArray) -> None:
        """The rates executed from now on: wheels [rad/s], joints [rad/s or m/s]."""
        self.wheels = np.array(wheel_speeds, dtype=float)
        self.v_arm = np.array(arm_rates, dtype=float)

    def advance(self, dt: float) -> None:
        """Integrate the arm and the true base over dt [s]; push the box or stall against it."""
        q_new = self.q_arm + self.v_arm * dt
        base_new = integrate_pose(self.base_true, self.slip.true_body_twist(self.wheels, dt), dt)
        self.tau = np.zeros(self.n_arm)
        self.force = np.zeros(3)
        self.stalled_joint = None
        if self.box is not None:
            kin = self.model.kinematics(base_new, q_new)
            contact = self.box.check(kin.x, kin.J_m, self.torque_limit)
            self.tau, self.force, self.stalled_joint = contact.tau, contact.force, contact.stalled_joint
            if contact.stalled:
                return  # the robot is blocked by the box: neither the arm nor the base moves
            if contact.in_contact:
                self.box.slide_to(float(kin.x[0]))
        self.q_arm, self.base_true = q_new, base_new

    def read(self) -> PlantState:
        """The written rates, the integrated positions, the contact's torques and force."""
        return PlantState(q_arm=self.q_arm, v_arm=self.v_arm, wheel_speeds=self.wheels, base_true=self.base_true,
                          tau=self.tau, contact_force=self.force, stalled_joint=self.stalled_joint)

