"""The whole WMM: forward kinematics (2) and the Jacobians of eq. (5).

Frames: world w, base b (at (x_b, y_b) on the ground, heading ψ), arm base m at
``mount_offset`` in b. The EE position in w is eq. (2):

    x = [x_b, y_b, 0] + Rz(ψ)·(p_mount + p_m(q_m)).

Velocities, eq. (5): ẋ = J_b q̇_b + J_m v_m = J v with v = [v_b; v_m] ∈ R¹¹,

    J_b = [[1, 0, −p_y], [0, 1, p_x], [0, 0, 0]],  p = Rz(ψ)(p_mount + p_m),
    J_m = Rz(ψ)·J_arm,   J = [J_b P(ψ), J_m].
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..config import N_ARM, N_WHEELS, FloatArray, RobotConfig
from .arm import ArmModel
from .mecanum import MecanumBase

N_V = N_WHEELS + N_ARM


def rot_z(yaw: float) -> FloatArray:
    """Rz(ψ), 3×3."""
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


@dataclass(slots=True)
class Kinematics:
    """Everything the controllers need at one configuration (world frame unless noted).

    Attributes:
        q_base: [m, m, rad] base pose (x_b, y_b, ψ) the kinematics were computed at.
        q_arm: [rad] arm joint angles.
        R: Rz(ψ).
        p_arm: [m] EE position in the arm base frame, p_m(q_m).
        x: [m] EE position in the world, eq. (2).
        J_arm: 3×7 translational arm Jacobian in the arm base frame.
        J_m: 3×7 world-aligned arm Jacobian, Rz(ψ)·J_arm.
        J_b: 3×3 base Jacobian (w.r.t. q̇_b = [ẋ_b, ẏ_b, ψ̇]).
        P: 3×4 wheel → base velocity map, eq. (20).
        J: 3×11 whole-robot Jacobian [J_b P, J_m], eq. (5).
        dJ_arm: (7, 3, 7) ∂J_arm/∂q_k, or None when not requested.
    """

    q_base: FloatArray
    q_arm: FloatArray
    R: FloatArray
    p_arm: FloatArray
    x: FloatArray
    J_arm: FloatArray
    J_m: FloatArray
    J_b: FloatArray
    P: FloatArray
    J: FloatArray
    dJ_arm: FloatArray | None = None


class WmmModel:
    """Kinematic model of the wheeled mobile manipulator.

    Args:
        config: the robot config (URDF, mount offset, base geometry).
    """

    def __init__(self, config: RobotConfig) -> None:
        self.config = config
        self.arm = ArmModel(config.arm.urdf, config.arm.ee_frame)
        self.base = MecanumBase(config.base)
        self.mount = np.asarray(config.arm.mount_offset, dtype=float)

    def ee_position(self, q_base: FloatArray, q_arm: FloatArray) -> FloatArray:
        """x(q) [m], eq. (2)."""
        p = rot_z(q_base[2]) @ (self.mount + self.arm.position(q_arm))
        return np.array([q_base[0] + p[0], q_base[1] + p[1], p[2]])

    def kinematics(self, q_base: FloatArray, q_arm: FloatArray, hessian: bool = False) -> Kinematics:
        """FK and Jacobians at (q_b, q_m); with ``hessian`` also ∂J_arm/∂q (for eq. (9))."""
        q_base, q_arm = np.asarray(q_base, float), np.asarray(q_arm, float)
        p_arm, J_arm = self.arm.position_jacobian(q_arm)
        qb0, qb1, yaw = q_base.tolist()
        R = rot_z(yaw)
        p = R @ (self.mount + p_arm)  # Rz(ψ)(p_mount + p_m)
        px, py, pz = p.tolist()
        x = np.array((qb0 + px, qb1 + py, pz))  # eq. (2)
        J_b = np.array([[1.0, 0.0, -py], [0.0, 1.0, px], [0.0, 0.0, 0.0]])  # eq. (5)
        P = R @ self.base.M  # eqs. (3), (20): blkdiag(Rz2(ψ), 1)·M, and R is exactly that
        J = np.empty((3, N_V))  # eq. (5): [J_b P, J_m]
        np.matmul(J_b, P, out=J[:, :N_WHEELS])
        np.matmul(R, J_arm, out=J[:, N_WHEELS:])  # J_m = Rz(ψ) J_arm
        J_m = J[:, N_WHEELS:]
        dJ = self.arm.jacobian_derivatives(q_arm) if hessian else None
        return Kinematics(
            q_base=q_base,
            q_arm=q_arm,
            R=R,
            p_arm=p_arm,
            x=x,
            J_arm=J_arm,
            J_m=J_m,
            J_b=J_b,
            P=P,
            J=J,
            dJ_arm=dJ,
        )
