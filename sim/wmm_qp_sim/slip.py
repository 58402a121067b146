"""Base slip and drift: the true base motion departs from the base kind's nominal model.

Noise model (seeded, see ``configs/sim.toml``):

    w_true,i = w_i · (1 + b_i + n_i(t))                  per-wheel effective speed
    twist_true = M · w_true + [0, 0, d · ‖(v_x, v_y)‖]    d = yaw_drift_per_meter [rad/m]

b_i ~ N(0, wheel_scale_std²) is drawn once per reset (a systematic scale error such as a worn
roller); n_i(t) is an Ornstein–Uhlenbeck process with stationary std wheel_noise_std and
correlation time wheel_noise_tau (roller slip on an uneven floor), updated exactly each step:
n ← a·n + σ·sqrt(1 − a²)·ξ, a = exp(−dt/τ), ξ ~ N(0, 1). Odometry uses M · w.

M is the base kind's (eq. (3)): every slip acts through it, so a differential drive (M's v_y row
zero) never slides sideways, with or without slip — the drift term turns it, it does not push it.
"""

from __future__ import annotations

import numpy as np

from wmm_qp.config import FloatArray

from .config import SlipConfig


class SlipModel:
    """Seeded slip/drift generator.

    Args:
        config: the slip parameters.
        M: 3 × n_wheels base matrix (eq. (3)), wheel speeds → body twist [v_x, v_y, ω].
        rng: the random generator (owned by the sim, seeded).
    """

    def __init__(self, config: SlipConfig, M: FloatArray, rng: np.random.Generator) -> None:
        self.config = config
        self.M = M
        self.rng = rng
        self.n = int(M.shape[1])
        self.bias = np.zeros(self.n)
        self.noise = np.zeros(self.n)

    def reset(self) -> None:
        """Draw a new systematic scale error b and start n(t) from its stationary law."""
        c = self.config
        self.bias = (
            self.rng.normal(0.0, c.wheel_scale_std, self.n) if c.enabled else np.zeros(self.n)
        )
        self.noise = (
            self.rng.normal(0.0, c.wheel_noise_std, self.n) if c.enabled else np.zeros(self.n)
        )

    def true_body_twist(self, wheel_speeds: FloatArray, dt: float) -> FloatArray:
        """The base's true body twist [m/s, m/s, rad/s] for executed wheel speeds [rad/s].

        Advances n(t) by dt [s]. With slip disabled this is exactly M · w (the odometry's twist).
        """
        c = self.config
        if not c.enabled:
            return self.M @ wheel_speeds
        a = float(np.exp(-dt / c.wheel_noise_tau))
        self.noise = a * self.noise + c.wheel_noise_std * np.sqrt(
            1.0 - a * a
        ) * self.rng.standard_normal(self.n)
        twist = self.M @ (wheel_speeds * (1.0 + self.bias + self.noise))
        twist[2] += c.yaw_drift_per_meter * float(np.hypot(twist[0], twist[1]))
        return twist


def integrate_pose(pose: FloatArray, body_twist: FloatArray, dt: float) -> FloatArray:
    """Integrate a planar pose (x, y, ψ) by a constant body twist over dt [s] (midpoint heading).

    Odometry and ground truth both use this integrator, so they agree exactly without slip.
    """
    yaw_mid = pose[2] + 0.5 * body_twist[2] * dt
    c, s = np.cos(yaw_mid), np.sin(yaw_mid)
    return np.array(
        [
            pose[0] + (c * body_twist[0] - s * body_twist[1]) * dt,
            pose[1] + (s * body_twist[0] + c * body_twist[1]) * dt,
            pose[2] + body_twist[2] * dt,
        ]
    )
