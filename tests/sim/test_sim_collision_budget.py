"""The sim referee's motion budget (``wmm_qp_robot.collision``) skips pair distances without
changing a single count: two sims stepped with the same commands, one with the budget and one
computing every pair at every step, count the same collisions, by pair, at the same steps.

The commands are wild on purpose (joint rates swept through their limits, the base driven and
turned, a teleport, obstacles replaced mid-run), so that the robot hits itself, the floor and the
obstacles: a budget that ever ran ahead of the motion would miss a step of one of them.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import replace

import numpy as np
import pytest
from wmm_qp_sim import SimCommand, SimRobot, load_sim_config

import wmm_qp as w
from wmm_qp.config import default_config_dir
from wmm_qp.scene import obstacles_from_tables

ROBOTS = default_config_dir() / "robots"


def obstacles(x: np.ndarray, shift: float) -> tuple:
    return obstacles_from_tables("test", [
        {"id": "ball", "kind": "sphere", "radius": 0.1, "xyz": list(x + [shift, 0.15, 0.0])},
        {"id": "crate", "kind": "box", "size": [0.3, 0.3, 0.3], "xyz": list(x + [0.0, -0.3 + shift, -0.2])},
    ])


def drive(name: str, steps: int, skip: bool, seed: int = 3) -> tuple[SimRobot, list[Counter[str]]]:
    robot = w.load_robot_config(ROBOTS / name)
    model = w.WmmModel(robot)
    sim = SimRobot(model, replace(load_sim_config(), firmware=False), seed=1, collisions=True)
    assert sim.collision is not None
    sim.collision.skip = skip
    sim.reset()
    x0 = model.ee_position(np.zeros(3), robot.arm.start)
    sim.set_obstacles(obstacles(x0, 0.0))
    rng = np.random.default_rng(seed)
    v = np.asarray(robot.arm.velocity_max, dtype=float)
    freq, phase = rng.uniform(0.2, 1.5, v.size), rng.uniform(0.0, 6.3, v.size)
    nw = sim.n_wheels
    wmax = np.asarray(robot.base.wheel_speed_max, dtype=float) * np.ones(nw)
    wf, wp = rng.uniform(0.1, 0.5, nw), rng.uniform(0.0, 6.3, nw)
    hits = []
    for k in range(steps):
        t = k * 0.002
        arm = 1.5 * v * np.sin(2 * np.pi * freq * t + phase)  # beyond the limits at the peaks
        wheels = 0.5 * wmax * np.sin(2 * np.pi * wf * t + wp)
        if k == steps // 3:
            sim.base_true = sim.base_true + [0.05, -0.03, 0.2]  # carried off
        if k == steps // 2:
            sim.set_obstacles(obstacles(x0, 0.1))
        before = Counter(sim.collision.counts)
        sim.step(SimCommand(wheels, arm, period=0.002, seq=k), 0.002)
        hits.append(sim.collision.counts - before)
    return sim, hits


@pytest.mark.parametrize("name", ["gen3_mecanum.toml", "panda_diffdrive.toml", "ur5_omni.toml", "tiago.toml"])
def test_the_budget_counts_every_collision_the_full_check_counts(name: str) -> None:
    full, full_hits = drive(name, 1500, skip=False)
    fast, fast_hits = drive(name, 1500, skip=True)
    assert full.collision is not None and fast.collision is not None
    assert sum(sum(h.values()) for h in full_hits) > 20, full.collision.counts  # the drive does collide
    assert fast_hits == full_hits  # the same pairs at the same steps
    assert fast.collision.computed < 0.5 * full.collision.computed, (fast.collision.computed,
                                                                     full.collision.computed)
