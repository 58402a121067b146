"""The random states ``wmm-qp verify`` referees: inside, at and beyond the limits, at the velocity
limits, near and at singularities, and near collisions, in every mode."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from ..model.wmm import WmmModel
from ..types import Mode, Reference, RobotState
from .collision import CollisionJudge


@dataclass
class Sample:
    """One random test case: a state, a reference, and what kind of case it is."""

    state: RobotState
    reference: Reference
    case: str


def sample_states(
    model: WmmModel,
    n: int,
    seed: int,
    modes: tuple[Mode, ...] = tuple(Mode),
    pose: bool = False,
    judge: CollisionJudge | None = None,
    influence: float = 0.15,
) -> Iterator[Sample]:
    """Random states and references covering the corners the bounds must survive.

    States: inside the limits, exactly at and just beyond a position limit, at and beyond
    the velocity limits, at the acceleration limits (large previous rates), near and at
    arm singularities (every second joint — 2, 4, 6, … — at or near 0, clipped to its range: the
    Gen3 stretched straight, and the same family on any arm). References: small, huge,
    discontinuous (a random jump each sample), in every mode; with ``pose`` also a target
    orientation (a random rotation of up to ~π about a random axis) and angular feed-forward.
    With a collision ``judge``, three more cases: near a self-collision or the floor (arm
    configurations drawn until a monitored pair is within ``influence`` of touching), near an
    obstacle (the base placed so that the EE is within ``influence`` of one) and at the fence
    (the base's origin within ``influence`` of a fence edge, moving out).
    """
    rng = np.random.default_rng(seed)
    arm, base = model.config.arm, model.config.base
    lo = np.where(np.isfinite(arm.position_lower), arm.position_lower, -np.pi)
    hi = np.where(np.isfinite(arm.position_upper), arm.position_upper, np.pi)
    vmax, wmax = arm.velocity_max, base.wheel_speed_max
    n_a, n_w = arm.n, base.n_wheels
    bending = np.arange(1, n_a, 2)
    cases: tuple[str, ...] = (
        "inside",
        "at_limit",
        "beyond_limit",
        "at_velocity_limit",
        "beyond_velocity_limit",
        "near_singular",
        "singular",
    )
    if judge is not None:
        cases += ("near_self", "near_obstacle", "at_fence")
    for i in range(n):
        case = cases[i % len(cases)]
        q = rng.uniform(lo, hi)
        v = rng.uniform(-1, 1, n_a) * vmax * rng.uniform(0, 1)
        w = rng.uniform(-1, 1, n_w) * wmax * rng.uniform(0, 1)
        limited = np.flatnonzero(np.isfinite(arm.position_upper))
        j = rng.choice(limited)
        side = rng.choice([-1.0, 1.0])
        edge = arm.position_upper[j] if side > 0 else arm.position_lower[j]
        if case == "at_limit":
            q[j] = edge
            v[j] = side * rng.uniform(0, vmax[j])
        elif case == "beyond_limit":
            q[j] = edge + side * rng.uniform(1e-6, 0.05)
            v[j] = side * rng.uniform(0, vmax[j])
        elif case == "at_velocity_limit":
            v = rng.choice([-1.0, 1.0], n_a) * vmax
            w = rng.choice([-1.0, 1.0], n_w) * wmax
        elif case == "beyond_velocity_limit":
            v = rng.choice([-1.0, 1.0], n_a) * vmax * rng.uniform(1.0, 1.5, n_a)
            w = rng.choice([-1.0, 1.0], n_w) * wmax * rng.uniform(1.0, 1.5, n_w)
        elif case in ("near_singular", "singular"):
            eps = 0.0 if case == "singular" else 0.05
            q[bending] = np.clip(rng.uniform(-eps, eps, bending.size), lo[bending], hi[bending])
        q_base = np.array([*rng.uniform(-2, 2, 2), rng.uniform(-np.pi, np.pi)])
        if judge is not None and case == "near_self":
            for _ in range(200):  # until a self or floor pair is within the influence distance
                d = judge.distances(q_base, q)
                near = [v for k, v in d.items() if not k.startswith("fence:") and "/" in k]
                if not near or min(near) < influence:  # no pairs (no [collision] shapes): any state
                    break
                q = rng.uniform(lo, hi)
        elif judge is not None and case == "near_obstacle" and judge.scene.obstacles:
            o = judge.scene.obstacles[int(rng.integers(len(judge.scene.obstacles)))]
            p_ee = model.arm.position(q)  # base frame
            yaw = float(rng.uniform(-np.pi, np.pi))
            heading = rng.normal(size=2)
            heading /= np.linalg.norm(heading)
            reach = float(np.max(o.size)) if o.kind == "box" else o.radius + 0.5 * o.length
            target = np.asarray(o.xyz[:2]) + heading * (reach + rng.uniform(0.0, influence))
            c_, s_ = np.cos(yaw), np.sin(yaw)
            ee = np.array([c_ * p_ee[0] - s_ * p_ee[1], s_ * p_ee[0] + c_ * p_ee[1]])  # Rz(ψ) p, x-y
            q_base = np.array([target[0] - ee[0], target[1] - ee[1], yaw])
        elif judge is not None and case == "at_fence":
            A, _ = judge.scene.fence.half_planes()
            if A.shape[0]:
                k = int(rng.integers(A.shape[0]))
                edge = judge.scene.fence.base[k]
                nxt = judge.scene.fence.base[(k + 1) % A.shape[0]]
                point = edge + rng.uniform(0, 1) * (nxt - edge) - A[k] * rng.uniform(0.0, influence)
                q_base = np.array([point[0], point[1], rng.uniform(-np.pi, np.pi)])
                w = rng.choice([-1.0, 1.0], n_w) * wmax * rng.uniform(0.3, 1.0)
        state = RobotState(q_base=q_base, q_arm=q, v_arm=v, wheel_speeds=w)
        x = model.ee_position(q_base, q)
        scale = rng.choice([1e-3, 0.05, 10.0])  # small, ordinary, huge
        x_d = x + rng.normal(size=3) * scale
        xd_d = rng.normal(size=3) * rng.choice([0.0, 0.05, 5.0])
        direction = rng.normal(size=3)
        quat_d, omega_d = None, np.zeros(3)
        if pose:
            quat_d = rng.normal(size=4)
            omega_d = rng.normal(size=3) * rng.choice([0.0, 0.1, 3.0])
        for mode in modes:
            ref = Reference(mode, x_d=x_d, xd_d=xd_d, direction=direction, quat_d=quat_d, omega_d=omega_d)
            yield Sample(state, ref, case)


