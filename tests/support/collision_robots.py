"""The shipped robots with their collision rows on, built once: the model, the QP controller and
the EE at the robot's start (for the collision tests, and benchmarks/collision/ in process)."""

from __future__ import annotations

from functools import cache

import numpy as np

import wmm_qp as w
from wmm_qp.config import default_config_dir

ROBOTS = default_config_dir() / "robots"


@cache
def model(name: str = "gen3_mecanum.toml") -> w.WmmModel:
    return w.WmmModel(w.load_robot_config(ROBOTS / name))


def qp(name: str = "gen3_mecanum.toml", **collision: object) -> w.Controller:
    """The shipped QP controller with the collision rows on (``enabled=False`` turns them off)."""
    cfg = w.load_controller_config().with_(collision={"enabled": True, **collision})
    return w.make_controller("qp", model(name), cfg)


def start_x(name: str = "gen3_mecanum.toml") -> np.ndarray:
    m = model(name)
    return m.ee_position(np.zeros(3), m.config.arm.start)
