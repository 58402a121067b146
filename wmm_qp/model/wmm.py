"""The whole WMM: forward kinematics (2) and the Jacobians of eq. (5), for any arm and base.

Frames: world w, base b (at (x_b, y_b) on the ground, heading ψ), arm root m at the mount in b
(folded into the arm's model: p_m and J_arm are base-frame quantities, docs/model.md "Any robot"). The EE
position in w is eq. (2):

    x = [x_b, y_b, 0] + Rz(ψ)·p_m(q_m).

Velocities, eq. (5): ẋ = J_b q̇_b + J_m v_m = J v with v = [v_b; v_m] ∈ R^(n_wheels + n_arm),

    J_b = [[1, 0, −p_y], [0, 1, p_x], [0, 0, 0]],  p = Rz(ψ) p_m,
    J_m = Rz(ψ)·J_arm,   J = [J_b P(ψ), J_m]          (P of eq. (3), the base kind's).

Pose task (r = 6, docs/model.md "Any robot"): three angular rows follow, [0, 0, P₃(ψ)] for the wheels (the
base's yaw rate turns the EE about z) and Rz(ψ)·J_ω,arm for the arm.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .._jit import jit
from .._typing import FloatArray
from ..config import RobotConfig
from .arm import ArmModel
from .bases import Base, make_base


def rot_z(yaw: float) -> FloatArray:
    """Rz(ψ), 3×3."""
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


@dataclass(slots=True)
class Kinematics:
    """Everything the controllers need at one configuration (world frame unless noted).

    Attributes:
        q_base: [m, m, rad] base pose (x_b, y_b, ψ) the kinematics were computed at.
        q_arm: [rad] arm joint values.
        R: Rz(ψ).
        p_arm: [m] EE position in the base frame, p_m(q_m).
        x: [m] EE position in the world, eq. (2).
        J_arm: 3×n translational arm Jacobian in the base frame (the DM's, eq. (8)).
        J_m: r×n world-aligned arm block of J, Rz(ψ)·J_arm (angular rows too for the pose task).
        J_b: 3×3 base Jacobian (w.r.t. q̇_b = [ẋ_b, ẏ_b, ψ̇]).
        P: 3×n_wheels wheel → base velocity map, eq. (3).
        J: r×(n_wheels + n) whole-robot task Jacobian [J_b P, J_m], eq. (5).
        dJ_arm: (n, 3, n) ∂J_arm/∂q_k, or None when not requested.
        R_ee: EE orientation in the world (pose task), or None.
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
    R_ee: FloatArray | None = None


@jit
def _assemble(
    q_base: FloatArray, p_arm: FloatArray, J_arm: FloatArray, M: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """R, x, J_b, P, J of :class:`Kinematics` from the arm's FK and its r×n Jacobian (compiled).

    J_arm's rows 0–2 are translational; with r = 6, rows 3–5 are angular."""
    c, s = math.cos(q_base[2]), math.sin(q_base[2])
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    px, py = c * p_arm[0] - s * p_arm[1], s * p_arm[0] + c * p_arm[1]  # Rz(ψ) p_m
    x = np.array([q_base[0] + px, q_base[1] + py, p_arm[2]])  # eq. (2)
    J_b = np.array([[1.0, 0.0, -py], [0.0, 1.0, px], [0.0, 0.0, 0.0]])  # eq. (5)
    r, n_w, n_a = J_arm.shape[0], M.shape[1], J_arm.shape[1]
    P = np.empty((3, n_w))  # eq. (3): blkdiag(Rz2(ψ), 1)·M
    J = np.empty((r, n_w + n_a))  # eq. (5): [J_b P, J_m]
    for j in range(n_w):
        P[0, j] = c * M[0, j] - s * M[1, j]
        P[1, j] = s * M[0, j] + c * M[1, j]
        P[2, j] = M[2, j]
        J[0, j] = P[0, j] - py * P[2, j]
        J[1, j] = P[1, j] + px * P[2, j]
        J[2, j] = 0.0
        if r == 6:  # the base's yaw rate turns the EE about the world z axis
            J[3, j] = 0.0
            J[4, j] = 0.0
            J[5, j] = P[2, j]
    for k in range(0, r, 3):  # J_m = Rz(ψ) J_arm, each block of three rows
        for j in range(n_a):
            J[k, n_w + j] = c * J_arm[k, j] - s * J_arm[k + 1, j]
            J[k + 1, n_w + j] = s * J_arm[k, j] + c * J_arm[k + 1, j]
            J[k + 2, n_w + j] = J_arm[k + 2, j]
    return R, x, J_b, P, J


class WmmModel:
    """Kinematic model of the wheeled mobile manipulator (any arm, any base kind).

    Args:
        config: the robot description.

    Attributes:
        arm: the arm's Pinocchio model (base frame).
        base: the base kind's kinematics (P of eq. (3)).
        n_arm, n_wheels, n_v: the sizes of v = [v_b; v_m].
    """

    def __init__(self, config: RobotConfig) -> None:
        self.config = config
        self.arm = ArmModel(config.arm, config.path)
        self.base: Base = make_base(config.base)
        self.n_arm = self.arm.n
        self.n_wheels = self.base.n_wheels
        self.n_v = self.n_wheels + self.n_arm

    def ee_position(self, q_base: FloatArray, q_arm: FloatArray) -> FloatArray:
        """x(q) [m], eq. (2)."""
        p = rot_z(q_base[2]) @ self.arm.position(q_arm)
        return np.array([q_base[0] + p[0], q_base[1] + p[1], p[2]])

    def ee_pose(self, q_base: FloatArray, q_arm: FloatArray) -> tuple[FloatArray, FloatArray]:
        """x(q) [m] and the EE orientation in the world (3×3)."""
        p, R = self.arm.pose(q_arm)
        Rz = rot_z(q_base[2])
        x = Rz @ p
        return np.array([q_base[0] + x[0], q_base[1] + x[1], x[2]]), Rz @ R

    def kinematics(
        self, q_base: FloatArray, q_arm: FloatArray, hessian: bool = False, pose: bool = False
    ) -> Kinematics:
        """FK and Jacobians at (q_b, q_m); with ``hessian`` also ∂J_arm/∂q (for eq. (9)); with
        ``pose`` the task Jacobian has the angular rows too (r = 6) and ``R_ee`` is set."""
        q_base, q_arm = np.asarray(q_base, float), np.asarray(q_arm, float)
        if q_base.shape != (3,):  # the kernel does not bounds-check
            raise ValueError(f"q_base must have 3 entries, got shape {q_base.shape}")
        R_ee = None
        if pose:
            p_arm, R_arm, J6 = self.arm.pose_jacobian(q_arm)
            J_arm = np.ascontiguousarray(J6[:3])
            R, x, J_b, P, J = _assemble(q_base, p_arm, J6, self.base.M)  # eqs. (2), (3), (5)
            R_ee = R @ R_arm
        else:
            p_arm, J_arm = self.arm.position_jacobian(q_arm)
            R, x, J_b, P, J = _assemble(q_base, p_arm, J_arm, self.base.M)  # eqs. (2), (3), (5)
        J_m = J[:, self.n_wheels :]
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
            R_ee=R_ee,
        )
