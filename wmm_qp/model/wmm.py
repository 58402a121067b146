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

from .._jit import jit
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


@jit
def _assemble(
    q_base: FloatArray, p_arm: FloatArray, J_arm: FloatArray, mount: FloatArray, M: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """R, x, J_b, P, J of :class:`Kinematics` from the arm's FK and Jacobian (compiled)."""
    c, s = math.cos(q_base[2]), math.sin(q_base[2])
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    mx, my = mount[0] + p_arm[0], mount[1] + p_arm[1]
    px, py = c * mx - s * my, s * mx + c * my  # Rz(ψ)(p_mount + p_m)
    x = np.array([q_base[0] + px, q_base[1] + py, mount[2] + p_arm[2]])  # eq. (2)
    J_b = np.array([[1.0, 0.0, -py], [0.0, 1.0, px], [0.0, 0.0, 0.0]])  # eq. (5)
    n_w, n_a = M.shape[1], J_arm.shape[1]
    P = np.empty((3, n_w))  # eqs. (3), (20): blkdiag(Rz2(ψ), 1)·M
    J = np.empty((3, n_w + n_a))  # eq. (5): [J_b P, J_m]
    for j in range(n_w):
        P[0, j] = c * M[0, j] - s * M[1, j]
        P[1, j] = s * M[0, j] + c * M[1, j]
        P[2, j] = M[2, j]
        J[0, j] = P[0, j] - py * P[2, j]
        J[1, j] = P[1, j] + px * P[2, j]
        J[2, j] = 0.0
    for j in range(n_a):  # J_m = Rz(ψ) J_arm
        J[0, n_w + j] = c * J_arm[0, j] - s * J_arm[1, j]
        J[1, n_w + j] = s * J_arm[0, j] + c * J_arm[1, j]
        J[2, n_w + j] = J_arm[2, j]
    return R, x, J_b, P, J


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
        if q_base.shape != (3,):  # the kernel does not bounds-check
            raise ValueError(f"q_base must have 3 entries, got shape {q_base.shape}")
        p_arm, J_arm = self.arm.position_jacobian(q_arm)
        R, x, J_b, P, J = _assemble(q_base, p_arm, J_arm, self.mount, self.base.M)  # eqs. (2), (3), (5)
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
