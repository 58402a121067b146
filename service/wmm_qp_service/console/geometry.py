"""What the console draws, as plain numbers: the force-manipulability ellipsoid, rotations, and
the rolling buffers of the trails and plots. No viser, no Zenoh: tested on its own."""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from wmm_qp.config import FloatArray

AXIS_MAX = 1.0
"""[m] longest semi-axis drawn (a direction near a singular one has a huge force capacity)."""


@dataclass(frozen=True)
class Ellipsoid:
    """The torque-weighted force-manipulability ellipsoid at the EE (world-aligned axes).

    The forces f the arm exerts with a unit weighted torque, ‖W J_mᵀ f‖ ≤ 1, i.e.
    fᵀ (J_m A J_mᵀ) f ≤ 1 with A = WᵀW (eq. (8)): its semi-axes are 1/√λᵢ along the
    eigenvectors of J_m A J_mᵀ, and its radius along a unit u is the DM H2(u) of eq. (8).

    Attributes:
        radii: [N/(N·m)] the three semi-axes 1/√λᵢ (capped at 1e6, as the DM is).
        wxyz: the rotation whose columns are the eigenvectors (a right-handed frame).
    """

    radii: FloatArray
    wxyz: FloatArray

    def radius_along(self, u: FloatArray) -> float:
        """Its radius along the unit vector u (world): H2(u) = (uᵀ M u)^(−1/2)."""
        R = quat_to_matrix(self.wxyz)
        v = R.T @ (np.asarray(u, float) / np.linalg.norm(u))
        return float(1.0 / math.sqrt(float(np.sum((v / self.radii) ** 2))))


def force_ellipsoid(J_m: FloatArray, W: FloatArray) -> Ellipsoid:
    """The ellipsoid of :class:`Ellipsoid` from the 3×n translational arm Jacobian J_m (world-aligned)
    and the diagonal of W (eq. (8)).

    Args:
        J_m: 3×n, Rz(ψ) J_arm.
        W: n, the torque weights (A = diag(W)²).
    """
    J = np.asarray(J_m, float)[:3]
    M = (J * np.asarray(W, float) ** 2) @ J.T  # J_m A J_mᵀ, eq. (8)
    lam, V = np.linalg.eigh(M)
    if np.linalg.det(V) < 0:
        V[:, 0] = -V[:, 0]
    radii = 1.0 / np.sqrt(np.maximum(lam, 1e-12))
    return Ellipsoid(radii=radii, wxyz=matrix_to_quat(V))


def display_scale(reference: Ellipsoid, size: float = 0.2) -> float:
    """[m per N/(N·m)] the scale that draws ``reference``'s middle semi-axis ``size`` long."""
    return size / float(np.median(reference.radii))


def drawn_radii(e: Ellipsoid, scale: float) -> FloatArray:
    """[m] the semi-axes as drawn: scaled, capped at :data:`AXIS_MAX` and at least 2 mm."""
    return np.clip(e.radii * scale, 0.002, AXIS_MAX)


def matrix_to_quat(R: FloatArray) -> FloatArray:
    """A rotation matrix as a unit quaternion (w, x, y, z) (Shepperd's method)."""
    R = np.asarray(R, float)
    t = np.trace(R)
    if t > 0:
        s = 2.0 * math.sqrt(t + 1.0)
        q = [0.25 * s, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s]
    else:
        i = int(np.argmax(np.diag(R)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * math.sqrt(max(1e-300, 1.0 + R[i, i] - R[j, j] - R[k, k]))
        v = [0.0, 0.0, 0.0]
        v[i] = 0.25 * s
        v[j] = (R[j, i] + R[i, j]) / s
        v[k] = (R[k, i] + R[i, k]) / s
        q = [(R[k, j] - R[j, k]) / s, *v]
    out = np.array(q)
    out /= np.linalg.norm(out)
    return out if out[0] >= 0 else -out


def quat_to_matrix(wxyz: FloatArray) -> FloatArray:
    """A quaternion (w, x, y, z) as a 3×3 rotation matrix."""
    w, x, y, z = np.asarray(wxyz, float) / np.linalg.norm(wxyz)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def yaw_quat(yaw: float) -> FloatArray:
    """(w, x, y, z) of a rotation by ``yaw`` [rad] about z."""
    return np.array([math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)])


def wxyz_to_xyzw(q: FloatArray) -> list[float]:
    """Viser's (w, x, y, z) as the protocol's [x, y, z, w]."""
    return [float(q[1]), float(q[2]), float(q[3]), float(q[0])]


def xyzw_to_wxyz(q: list[float]) -> FloatArray:
    """The protocol's [x, y, z, w] as viser's (w, x, y, z)."""
    return np.array([q[3], q[0], q[1], q[2]], dtype=float)


def rpy_quat(rpy: FloatArray) -> FloatArray:
    """(w, x, y, z) of a URDF ``rpy`` (roll, pitch, yaw about the fixed x, y, z axes)."""
    r, p, y = (float(v) / 2 for v in rpy)
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    return np.array([cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy,
                     cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy])


class Trail:
    """The last ``n`` points of a path, thinned to points at least ``step`` [m] apart."""

    def __init__(self, n: int = 400, step: float = 0.005) -> None:
        self.step = step
        self.points: deque[FloatArray] = deque(maxlen=n)

    def add(self, p: FloatArray) -> bool:
        """Add p when it is ``step`` from the last point (or the first); returns whether it was."""
        p = np.asarray(p, float)
        if not np.isfinite(p).all():
            return False
        if self.points and float(np.linalg.norm(p - self.points[-1])) < self.step:
            return False
        self.points.append(p.copy())
        return True

    def segments(self) -> FloatArray:
        """(k, 2, 3) consecutive point pairs (k = len − 1; empty below two points)."""
        if len(self.points) < 2:
            return np.zeros((0, 2, 3))
        P = np.array(self.points)
        return np.stack([P[:-1], P[1:]], axis=1)


class Series:
    """Samples (t, values…) of the last ``window`` [s], for the live plots."""

    def __init__(self, names: tuple[str, ...], window: float = 30.0) -> None:
        self.names = names
        self.window = window
        self._rows: deque[tuple[float, ...]] = deque()

    def add(self, t: float, *values: float) -> None:
        """Append one sample at time t [s] (monotonic) and drop those older than the window."""
        if len(values) != len(self.names):
            raise ValueError(f"{len(self.names)} values expected, got {len(values)}")
        self._rows.append((t, *values))
        while self._rows and self._rows[0][0] < t - self.window:
            self._rows.popleft()

    def arrays(self, now: float) -> tuple[FloatArray, ...]:
        """(t − now, series 1, …): t from −window to 0; nan where a value was not finite."""
        if not self._rows:
            return tuple(np.zeros(0) for _ in range(len(self.names) + 1))
        A = np.array(self._rows, dtype=float)
        A[:, 0] -= now
        return tuple(A[:, i].copy() for i in range(A.shape[1]))

    def __len__(self) -> int:
        return len(self._rows)
