"""The manipulator on Pinocchio: pose of the EE frame, its Jacobian and Hessian, in the base frame.

The "EE frame" is the task point: the ``ee_frame`` link moved by the tool offset
(``ee_offset_xyz``, ``ee_offset_rpy``; zero by default), a frame added to the reduced model, so
kinematics, Jacobians, Hessians (the DM's gradient) and the collision rows all use it.

Built once from the robot description: Pinocchio's reduced model of the chosen joints (every
other joint of the URDF locked), its root placed at the mount (docs/model.md "Any robot": p_mount + R_mount
p_m(q_m), R_mount J_arm), so every quantity here is already expressed in the base frame. The
per-tick code only indexes. Continuous joints are stored by Pinocchio as (cos, sin) pairs;
:meth:`ArmModel.pin_q` maps the n joint values to Pinocchio's configuration vector.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pinocchio as pin

from .. import urdf as urdf_io
from .._jit import jit
from .._typing import FloatArray, IntArray
from ..config import ArmConfig
from ..exceptions import ConfigError

_LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED


@jit
def _pin_q(q: FloatArray, idx_q: IntArray, nq: IntArray, out: FloatArray) -> None:
    for i in range(q.shape[0]):
        if nq[i] == 1:
            out[idx_q[i]] = q[i]
        else:  # continuous joint: (cos, sin)
            out[idx_q[i]] = math.cos(q[i])
            out[idx_q[i] + 1] = math.sin(q[i])


def mount_placement(config: ArmConfig) -> pin.SE3:
    """The arm's root in the base frame (``mount_xyz``, ``mount_rpy``)."""
    rpy = np.asarray(config.mount_rpy, dtype=float)
    return pin.SE3(pin.rpy.rpyToMatrix(rpy), np.asarray(config.mount_xyz, dtype=float))


def ee_offset_placement(config: ArmConfig) -> pin.SE3:
    """The task point in the ``ee_frame`` link's frame (``ee_offset_xyz``, ``ee_offset_rpy``)."""
    rpy = np.asarray(config.ee_offset_rpy, dtype=float)
    return pin.SE3(pin.rpy.rpyToMatrix(rpy), np.asarray(config.ee_offset_xyz, dtype=float))


class ArmModel:
    """Pinocchio model of the arm, expressed in the base frame.

    Args:
        config: the arm of a loaded robot description (joints, locked joints, mount).
        source: the robot file, for errors (default: the URDF).

    Raises:
        ConfigError: the URDF does not load or lacks the frame or a joint.
    """

    def __init__(self, config: ArmConfig, source: Any = None) -> None:
        where = source if source is not None else config.urdf
        full = urdf_io.load_full_model(where, config.urdf)
        for name in config.joints:
            if not full.existJointName(name):
                raise ConfigError(where, "arm.joints", f"the URDF has no joint named {name!r}")
        urdf_io.ee_frame_id(where, full, config.ee_frame)  # a link, not a joint: else one line
        self.mount = mount_placement(config)
        self.model = urdf_io.reduced_model(full, config.joints, dict(config.locked), self.mount)
        self.flange_id = urdf_io.ee_frame_id(where, self.model, config.ee_frame)
        self.frame_id = urdf_io.add_task_frame(self.model, self.flange_id, ee_offset_placement(config))
        self.data = self.model.createData()
        ids = [self.model.getJointId(n) for n in config.joints]
        if self.model.nv != len(ids):
            raise ConfigError(where, "arm.joints", f"the reduced model has {self.model.nv} DOF, not {len(ids)}")
        # Where each joint value goes in Pinocchio's q (idx_q; nq 1: the value, 2: cos, sin) and v
        self._idx_q = np.array([self.model.joints[j].idx_q for j in ids], dtype=np.int64)
        self._nq = np.array([self.model.joints[j].nq for j in ids], dtype=np.int64)
        self._idx_v = np.array([self.model.joints[j].idx_v for j in ids], dtype=np.int64)
        self._identity_order = bool((self._idx_v == np.arange(len(ids))).all())
        self._q = pin.neutral(self.model)
        self.joint_names = list(config.joints)
        self.n = len(ids)

    def pin_q(self, q: FloatArray) -> FloatArray:
        """Pinocchio configuration of the n joint values q (a reused buffer)."""
        q = np.asarray(q, dtype=np.float64)
        if not q.flags.writeable:  # a read-only array (a robot file's start) is another numba type:
            q = q.copy()  # one specialisation of the kernel, compiled at warm-up, not later
        if q.shape != (self.n,):  # the kernel does not bounds-check
            raise ValueError(f"q must have {self.n} entries, got shape {q.shape}")
        _pin_q(q, self._idx_q, self._nq, self._q)
        return self._q

    def _cols(self, J: FloatArray) -> FloatArray:
        """J's columns in the order of ``joints`` (Pinocchio's v order is the chain's: a no-op)."""
        return J if self._identity_order else J[..., self._idx_v]

    def position(self, q: FloatArray) -> FloatArray:
        """p(q_m) [m]: EE position in the base frame, eqs. (1), (2) (mount included)."""
        pin.forwardKinematics(self.model, self.data, self.pin_q(q))
        return pin.updateFramePlacement(self.model, self.data, self.frame_id).translation.copy()

    def pose(self, q: FloatArray) -> tuple[FloatArray, FloatArray]:
        """EE position and orientation (3×3) in the base frame."""
        pin.forwardKinematics(self.model, self.data, self.pin_q(q))
        M = pin.updateFramePlacement(self.model, self.data, self.frame_id)
        return M.translation.copy(), M.rotation.copy()

    def position_jacobian(self, q: FloatArray) -> tuple[FloatArray, FloatArray]:
        """EE position and translational Jacobian (3×n) in the base frame, eqs. (1), (5)."""
        qq = self.pin_q(q)
        pin.computeJointJacobians(self.model, self.data, qq)  # also runs forward kinematics
        p = pin.updateFramePlacement(self.model, self.data, self.frame_id).translation.copy()
        J = pin.getFrameJacobian(self.model, self.data, self.frame_id, _LWA)[:3].copy()
        return p, self._cols(J)

    def pose_jacobian(self, q: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """EE position, orientation (3×3) and the 6×n Jacobian [linear; angular] in the base frame
        (LOCAL_WORLD_ALIGNED: the EE's velocity and angular velocity, base-frame axes)."""
        qq = self.pin_q(q)
        pin.computeJointJacobians(self.model, self.data, qq)
        M = pin.updateFramePlacement(self.model, self.data, self.frame_id)
        J = pin.getFrameJacobian(self.model, self.data, self.frame_id, _LWA).copy()
        return M.translation.copy(), M.rotation.copy(), self._cols(J)

    def jacobian_derivatives(self, q: FloatArray) -> FloatArray:
        """∂J/∂q_k for every joint k: an array D with D[k] = ∂J_arm/∂q_k (3×n), shape (n, 3, n).

        Analytic, from Pinocchio's kinematic Hessian. Must follow :meth:`position_jacobian` or
        :meth:`pose_jacobian` at the same q (it reuses the joint Jacobians computed there). With
        pin ≥ 4.1 the returned tensor must be read as ``H.reshape(nv, nv, 6)[k, i, :] = ∂J_i/∂q_k``
        (docs/model.md; checked against finite differences in the tests).
        """
        pin.computeJointKinematicHessians(self.model, self.data)
        H = pin.getFrameKinematicHessian(self.model, self.data, self.frame_id, _LWA)
        nv = self.model.nv
        D = H.reshape(nv, nv, 6)[:, :, :3].transpose(0, 2, 1)
        if not self._identity_order:
            D = D[self._idx_v][:, :, self._idx_v]
        return np.ascontiguousarray(D)
