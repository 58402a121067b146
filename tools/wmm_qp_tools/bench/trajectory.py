"""The moving reference every section follows, and the ideal robot that executes commands.

The paper's circle experiment (docs/model.md): x_d(t) = x0 + [0.25(cos ωt − 1), 0.25 sin ωt, 0],
ω = π/20 rad/s, from q_b = 0 and the robot's start configuration (``arm.start``; the Gen3's is
the paper's). The state fed back to the
controller is its own command integrated over one period (joint rates and wheel speeds are
executed exactly), so the state moves as on a perfect robot.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

import wmm_qp as w
from wmm_qp.config import FloatArray
from wmm_qp.tasks import rotation_to_quat

RADIUS = 0.25  # [m]
OMEGA = np.pi / 20.0  # [rad/s]


def circle(x0: FloatArray, t: float) -> tuple[FloatArray, FloatArray]:
    """x_d(t) [m] and ẋ_d(t) [m/s] of the paper's circle around the start point x0."""
    c, s = np.cos(OMEGA * t), np.sin(OMEGA * t)
    x_d = x0 + np.array([RADIUS * (c - 1.0), RADIUS * s, 0.0])
    xd_d = np.array([-RADIUS * OMEGA * s, RADIUS * OMEGA * c, 0.0])
    return x_d, xd_d


@dataclass(slots=True)
class IdealRobot:
    """A robot that executes every command exactly for one period dt [s]."""

    model: w.WmmModel
    q_base: FloatArray
    q_arm: FloatArray
    v_arm: FloatArray
    wheels: FloatArray

    @classmethod
    def at_start(cls, model: w.WmmModel) -> IdealRobot:
        """At rest at q_b = 0 and the robot's ``arm.start``."""
        q_arm = np.array(model.config.arm.start)
        return cls(model, np.zeros(3), q_arm, np.zeros(model.n_arm), np.zeros(model.n_wheels))

    def state(self) -> w.RobotState:
        return w.RobotState(
            q_base=self.q_base, q_arm=self.q_arm, v_arm=self.v_arm, wheel_speeds=self.wheels
        )

    def apply(self, cmd: w.Command, dt: float) -> None:
        """Integrate the command over dt: q_m += dt v_m, q_b += dt P(ψ) v_b (eqs. (3), (20))."""
        self.q_arm = self.q_arm + dt * cmd.arm_rates
        self.q_base = self.q_base + dt * (
            self.model.base.P(float(self.q_base[2])) @ cmd.wheel_speeds
        )
        self.v_arm = np.array(cmd.arm_rates)
        self.wheels = np.array(cmd.wheel_speeds)

    def ee(self) -> FloatArray:
        return self.model.ee_position(self.q_base, self.q_arm)

    def ee_quat(self) -> FloatArray:
        """The EE orientation (world), a quaternion [x, y, z, w]."""
        return rotation_to_quat(self.model.ee_pose(self.q_base, self.q_arm)[1])
