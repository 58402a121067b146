"""The rows of the pairs inside their safety distance: on the bodies themselves, linearised at the
configuration full braking reaches (docs/model.md "Collisions", "inside d_s").

Outside d_s a pair's row (:mod:`.collision`) keeps its row shapes apart (a cylinder's capsule,
which contains the cylinder), linearised at the state: d + Δt·C v. Inside d_s the rule a command
must keep is relative (``wmm-qp verify``'s, :mod:`wmm_qp.verify.collision`): the bodies' distance
after the tick no less than now, or than full braking v₀ = clip(0, lb, ub) takes it; the dampers,
relaxed, ask C v ≥ C v₀. Neither stand-in carries that over to the bodies:

* the row shape is not the body: a capsule's witness points are not its cylinder's, and a command
  that approaches no faster than braking on the capsules can on the cylinders;
* the distance inside a body is not smooth: a sphere deep in a box is as deep as its nearest face
  lets it be, and that face can change within the tick, after which the row's rate is another
  face's (docs/model.md "inside d_s" has the Panda's two cases, measured).

So each pair whose row shapes are inside d_s gets one more row, on its bodies (coal), at the
braking configuration q_b = q + Δt·v₀ (the base moved by Δt·P(ψ) v₀ for a pair with the world):
with d_b the distance there and C_b its rate, the distance after the tick is
d(q + Δt·v) = d_b + Δt·C_b (v − v₀) to second order in Δt·(v − v₀), which bounds (13) keep below
2·A·Δt² per joint (a face switch between q_b and the command's configuration aside). The row is
the pair's damper asked of that prediction: d_b + Δt·C_b (v − v₀) ≥ d + Δt·damper(d), d the
bodies' distance now, i.e. C_b v ≥ damper(d) + (d − d̃)/Δt with d̃ = d_b − Δt·C_b v₀; relaxed like
every damper, to C_b v₀ at worst: the distance after the tick then no less than braking's, d_b.
"""

from __future__ import annotations

import math
from typing import Any

import coal
import numpy as np
import pinocchio as pin

from .._typing import FloatArray, IntArray
from ..model.collision import RobotGeometry, transform
from .pair_search import FLOOR, Obstacle, unit_normal


class InsidePairs:
    """The bodies' distances of the pairs inside d_s, now and at the braking configuration (the
    module docstring; :class:`~wmm_qp.limits.collision.CollisionRows` makes them rows).

    Args:
        geometry: the robot's bodies (the arm's model: a data of its own is kept here).
        M: the base's 3 × n_wheels matrix (eq. (3)).
        dt: [s] Δt, the control period.
    """

    def __init__(self, geometry: RobotGeometry, M: FloatArray, dt: float) -> None:
        self.geo = geometry
        self.M = np.asarray(M, dtype=float)
        self.dt = float(dt)
        self.n_w = self.M.shape[1]
        self._data = geometry.arm.model.createData()  # the braking configuration's (the tick's data stays)
        self._floor = coal.Halfspace(np.array([0.0, 0.0, 1.0]), geometry.floor_z)  # solid: z ≤ floor_z
        self._req = coal.DistanceRequest()
        self._res = coal.DistanceResult()

    def braking_end(
        self, body: IntArray, other: IntArray, q_base: FloatArray, q_arm: FloatArray, v0: FloatArray,
        obstacles: list[Obstacle],
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
        """The pairs (body[k], other[k]) on their bodies, now and at q_b (the module docstring).

        Args:
            body, other: the pairs, coded as :class:`~wmm_qp.limits.pair_search.Candidates`' (a
                body ≥ 0, the floor, obstacle j: −2 − j).
            q_base: [m, m, rad] the base pose; q_arm: [rad] the arm's joints (the arm's data holds
                their forward kinematics: the bodies' placements now).
            v0: [v_b; v_m] the braking command clip(0, lb, ub) [rad/s].
            obstacles: the obstacles in force (:attr:`PairSearch.obstacles`).

        Returns:
            (d, d_b, P, Q, N, Jw): each pair's distance now and at q_b [m]; at q_b its closest
            points on the body and on the other side and the unit normal from the other side to
            the body (base frame at q_b), and the joints' Jacobian there (6 × n_arm, as the arm's
            data.J).
        """
        geo, dt, m = self.geo, self.dt, body.shape[0]
        arm = geo.arm
        # the placements of the pairs' bodies only (a robot has dozens; a tick has a few such pairs)
        used = {int(k) for k in body} | {int(k) for k in other if k >= 0}
        now = {k: self._pose(k, arm.data.oMi) for k in used}
        pin.computeJointJacobians(arm.model, self._data, arm.pin_q(q_arm + dt * v0[self.n_w :]))
        at_b = {k: self._pose(k, self._data.oMi) for k in used}
        # the base after the braking tick, moved as the judge moves it: q_b + Δt·P(ψ) v₀ (eq. (3))
        c, s = math.cos(q_base[2]), math.sin(q_base[2])
        db = dt * (self.M @ v0[: self.n_w])  # [ẋ, ẏ, ψ̇]·Δt in the base frame
        q_base_b = q_base + np.array([c * db[0] - s * db[1], s * db[0] + c * db[1], db[2]])
        d, d_b = np.empty(m), np.empty(m)
        P, Q, N = np.empty((m, 3)), np.empty((m, 3)), np.empty((m, 3))
        for t in range(m):
            i, j = int(body[t]), int(other[t])
            d[t] = self._distance(i, j, now, q_base, obstacles)[0]
            d_b[t], P[t], Q[t], N[t] = self._distance(i, j, at_b, q_base_b, obstacles)
        return d, d_b, P, Q, N, np.asarray(self._data.J)

    def _pose(self, k: int, oMi: Any) -> coal.Transform3s:
        return transform(self.geo.placement(k, oMi))

    def _distance(self, i: int, j: int, poses: dict[int, coal.Transform3s], q_base: FloatArray,
                  obstacles: list[Obstacle]) -> tuple[float, FloatArray, FloatArray, FloatArray]:
        """(d, p_a, p_b, n̂ from b to a) of body i and the other side j on the bodies themselves,
        the bodies at ``poses`` (base frame), the base at ``q_base`` (for the obstacles)."""
        bodies = self.geo.bodies
        if j >= 0:
            other, To = bodies[j].shape, poses[j]
        elif j == FLOOR:
            other, To = self._floor, coal.Transform3s()
        else:
            o = obstacles[-2 - j]
            c, s = math.cos(q_base[2]), math.sin(q_base[2])
            Rb = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
            tb = np.array([q_base[0], q_base[1], 0.0])
            if o.plane:  # n·p ≤ offset is free: coal's half-space n'·p ≤ d' is the solid side
                other = coal.Halfspace(-(Rb.T @ o.normal_w), -(o.offset_w - float(o.normal_w @ tb)))
                To = coal.Transform3s()
            else:
                other, To = o.shape, transform(pin.SE3(Rb.T @ o.world.rotation, Rb.T @ (o.world.translation - tb)))
        res = self._res
        res.clear()
        d = float(coal.distance(bodies[i].shape, poses[i], other, To, self._req, res))
        p_a = np.asarray(res.getNearestPoint1(), dtype=float).copy()
        p_b = np.asarray(res.getNearestPoint2(), dtype=float).copy()
        return d, p_a, p_b, unit_normal(res)
