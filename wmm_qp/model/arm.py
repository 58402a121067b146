"""The manipulator on Pinocchio: position of the EE frame, its Jacobian and Hessian.

Only the translational part is used (r = 3: the EE orientation is free). Continuous
joints are stored by Pinocchio as (cos, sin) pairs; :meth:`ArmModel.pin_q` maps the 7 joint
angles to Pinocchio's configuration vector once per call.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from .._jit import jit
from ..config import N_ARM, FloatArray
from ..exceptions import ConfigError

_LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
IntArray = np.ndarray[Any, np.dtype[np.int64]]


@jit
def _pin_q(q: FloatArray, idx_q: IntArray, nq: IntArray, out: FloatArray) -> None:
    for i in range(q.shape[0]):
        if nq[i] == 1:
            out[idx_q[i]] = q[i]
        else:  # continuous joint: (cos, sin)
            out[idx_q[i]] = math.cos(q[i])
            out[idx_q[i] + 1] = math.sin(q[i])


class ArmModel:
    """Pinocchio model of the arm, expressed in the arm's base frame.

    Args:
        urdf: the arm's URDF.
        ee_frame: the end-effector frame's name.

    Raises:
        ConfigError: the URDF does not load, lacks the frame, or is not a 7-DOF chain.
    """

    def __init__(self, urdf: Path, ee_frame: str) -> None:
        try:
            self.model = pin.buildModelFromUrdf(str(urdf))
        except (RuntimeError, ValueError) as e:
            raise ConfigError(urdf, "", f"Pinocchio cannot load this URDF: {e}") from None
        if self.model.nv != N_ARM:
            raise ConfigError(urdf, "", f"expected a {N_ARM}-DOF arm, the URDF has {self.model.nv}")
        if not self.model.existFrame(ee_frame):
            raise ConfigError(urdf, "", f"no frame named {ee_frame!r}")
        self.data = self.model.createData()
        self.frame_id = self.model.getFrameId(ee_frame)
        joints = [self.model.joints[j] for j in range(1, self.model.njoints)]
        # Where each joint angle goes in Pinocchio's q: idx_q, and nq (1: the angle; 2: cos, sin)
        self._idx_q = np.array([j.idx_q for j in joints], dtype=np.int64)
        self._nq = np.array([j.nq for j in joints], dtype=np.int64)
        self._q = pin.neutral(self.model)
        self.joint_names = [self.model.names[j] for j in range(1, self.model.njoints)]

    def pin_q(self, q: FloatArray) -> FloatArray:
        """Pinocchio configuration of the 7 joint angles q [rad] (a reused buffer)."""
        q = np.asarray(q, dtype=np.float64)
        if q.shape != (N_ARM,):  # the kernel does not bounds-check
            raise ValueError(f"q must have {N_ARM} entries, got shape {q.shape}")
        _pin_q(q, self._idx_q, self._nq, self._q)
        return self._q

    def position(self, q: FloatArray) -> FloatArray:
        """p_m(q_m) [m]: EE position in the arm base frame, eq. (1)."""
        pin.forwardKinematics(self.model, self.data, self.pin_q(q))
        return pin.updateFramePlacement(self.model, self.data, self.frame_id).translation.copy()

    def position_jacobian(self, q: FloatArray) -> tuple[FloatArray, FloatArray]:
        """EE position and translational Jacobian (3×7) in the arm base frame, eqs. (1), (5)."""
        qq = self.pin_q(q)
        pin.computeJointJacobians(self.model, self.data, qq)  # also runs forward kinematics
        p = pin.updateFramePlacement(self.model, self.data, self.frame_id).translation.copy()
        J = pin.getFrameJacobian(self.model, self.data, self.frame_id, _LWA)[:3].copy()
        return p, J

    def jacobian_derivatives(self, q: FloatArray) -> FloatArray:
        """∂J/∂q_k for every joint k: an array D with D[k] = ∂J_arm/∂q_k (3×7), shape (7, 3, 7).

        Analytic, from Pinocchio's kinematic Hessian. Must follow :meth:`position_jacobian`
        at the same q (it reuses the joint Jacobians computed there). With pin ≥ 4.1 the
        returned tensor must be read as ``H.reshape(nv, nv, 6)[k, i, :] = ∂J_i/∂q_k``
        (DESIGN.md §1; checked against finite differences in the tests).
        """
        pin.computeJointKinematicHessians(self.model, self.data)
        H = pin.getFrameKinematicHessian(self.model, self.data, self.frame_id, _LWA)
        nv = self.model.nv
        return np.ascontiguousarray(H.reshape(nv, nv, 6)[:, :, :3].transpose(0, 2, 1))
