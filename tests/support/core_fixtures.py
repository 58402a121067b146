"""Shared, cached objects for the core tests (import from test modules)."""

from __future__ import annotations

from functools import cache

import numpy as np

import wmm_qp as w


@cache
def robot() -> w.RobotConfig:
    return w.load_robot_config()


@cache
def config() -> w.ControllerConfig:
    """The shipped controller config in the paper's setting: no collision rows (on by default).
    The core tests check the paper's equations and bounds (13); the rows' own tests turn them on
    (tests/core/test_collision.py)."""
    return w.load_controller_config().with_(collision={"enabled": False})


@cache
def model() -> w.WmmModel:
    return w.WmmModel(robot())


def random_arm_q(rng: np.random.Generator) -> np.ndarray:
    arm = robot().arm
    lo = np.where(np.isfinite(arm.position_lower), arm.position_lower, -np.pi)
    hi = np.where(np.isfinite(arm.position_upper), arm.position_upper, np.pi)
    return rng.uniform(lo, hi)


Q0 = np.array(w.load_robot_config().arm.start)
