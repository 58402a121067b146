"""The pose task (r = 6): position and orientation of the EE frame (docs/model.md "Any robot").

The task reads J v = [ẋ_d + K_x e_p; ω_d + K_R e_R] with J's angular rows those of the
LOCAL_WORLD_ALIGNED frame Jacobian (the base's yaw adds ω_z) and the orientation error the log
map e_R = log(R_d Rᵀ) (world frame: the rotation vector that turns R into R_d, ‖e_R‖ ≤ π). For a
constant R_d, Ṙ = [ω]× R gives ė_R ≈ −ω near e_R = 0, so ω = K_R e_R decays the error at rate
K_R like the position error of eq. (18).

Quaternions are [x, y, z, w] (the ROS / Eigen-coeffs order), normalised here.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from .._typing import FloatArray


def quat_to_matrix(q: FloatArray) -> FloatArray:
    """Rotation matrix of a quaternion [x, y, z, w] (normalised first)."""
    x, y, z, w = (float(v) for v in q)
    n = math.sqrt(x * x + y * y + z * z + w * w)
    return np.asarray(pin.Quaternion(w / n, x / n, y / n, z / n).toRotationMatrix(), dtype=np.float64)


def rotation_to_quat(R: FloatArray) -> FloatArray:
    """Quaternion [x, y, z, w] of a rotation matrix (w ≥ 0)."""
    q = np.asarray(pin.Quaternion(np.asarray(R, dtype=np.float64)).coeffs(), dtype=np.float64).copy()
    return -q if q[3] < 0 else q


def orientation_error(R_d: FloatArray, R: FloatArray) -> FloatArray:
    """e_R = log(R_d Rᵀ) [rad] (world frame), the pose task's orientation error."""
    return np.asarray(pin.log3(np.asarray(R_d, dtype=np.float64) @ np.asarray(R, dtype=np.float64).T), dtype=np.float64)
