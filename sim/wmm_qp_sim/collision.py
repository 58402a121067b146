"""The referee's collision check: the distance of every monitored pair, every step (issue 13).

Independent of the controller's rows (``wmm_qp.limits.collision``): the same bodies and pairs (the
robot description's), but placed by Pinocchio's own geometry pipeline (``updateGeometryPlacements``
on a data of its own) at the sim's executed joint values, the obstacles placed with the TRUE base
pose (slip included, which the controller's odometry does not see), and distances from
``pinocchio.computeDistance`` / coal in the world frame. A pair closer than ``threshold`` counts one
``collision`` violation per step, by pair name.
"""

from __future__ import annotations

import math
from collections import Counter

import coal
import numpy as np
import pinocchio as pin

import wmm_qp
from wmm_qp.config import FloatArray, ShapeConfig
from wmm_qp.model.collision import coal_shape, robot_geometry, shape_pose


class CollisionReferee:
    """Counts steps at which a monitored pair is closer than ``threshold`` [m].

    Args:
        model: the robot's model (its arm's reduced Pinocchio model; a data of its own is made).
        threshold: [m] a pair closer than this is a collision.
    """

    def __init__(self, model: wmm_qp.WmmModel, threshold: float) -> None:
        self.geo = robot_geometry(model.config, model.arm)
        self.threshold = threshold
        self.pmodel = model.arm.model
        self.pdata = self.pmodel.createData()
        self.gmodel = pin.GeometryModel()
        for b in self.geo.bodies:
            obj = pin.GeometryObject(b.name, b.joint, b.placement, b.shape)
            self.gmodel.addGeometryObject(obj)
        for i, j in self.geo.self_pairs:
            self.gmodel.addCollisionPair(pin.CollisionPair(i, j))
        self.gdata = pin.GeometryData(self.gmodel)
        self._floor = coal.Halfspace(np.array([0.0, 0.0, 1.0]), self.geo.floor_z)  # solid: z ≤ floor_z
        self.obstacles: list[tuple[str, coal.CollisionGeometry, pin.SE3, FloatArray]] = []
        self.counts: Counter[str] = Counter()
        self.min_distance = math.inf
        self.closest = ""

    def set_obstacles(self, obstacles: tuple[ShapeConfig, ...] | list[ShapeConfig]) -> None:
        from wmm_qp.limits.collision import exempt_mask

        self.obstacles = [(o.name, coal_shape(o), shape_pose(o), exempt_mask(self.geo, o.exempt)) for o in obstacles]

    def reset(self) -> None:
        self.counts.clear()
        self.min_distance, self.closest = math.inf, ""

    def check(self, base_true: FloatArray, q_pin: FloatArray) -> int:
        """Distances at the true base pose and Pinocchio configuration q_pin; returns the number of
        pairs closer than the threshold this step (each also counted by name)."""
        pin.forwardKinematics(self.pmodel, self.pdata, q_pin)
        pin.updateGeometryPlacements(self.pmodel, self.pdata, self.gmodel, self.gdata)
        bad = 0
        req = coal.DistanceRequest()
        for k, pair in enumerate(self.gmodel.collisionPairs):
            d = pin.computeDistance(self.gmodel, self.gdata, k).min_distance
            bad += self._judge(d, f"{self.gmodel.geometryObjects[pair.first].name}/"
                                  f"{self.gmodel.geometryObjects[pair.second].name}")
        c, s = math.cos(base_true[2]), math.sin(base_true[2])
        world_base = pin.SE3(np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]),
                             np.array([base_true[0], base_true[1], 0.0]))
        for i in self.geo.floor_bodies:
            M = world_base * self.gdata.oMg[i]  # the floor is z = floor_z in the world
            res = coal.DistanceResult()
            d = coal.distance(self.geo.bodies[i].shape, coal.Transform3s(M.rotation, M.translation),
                              self._floor, coal.Transform3s(), req, res)
            bad += self._judge(d, f"{self.geo.bodies[i].name}/floor")
        for name, shape, pose, checked in self.obstacles:
            To = coal.Transform3s(pose.rotation, pose.translation)
            for i, b in enumerate(self.geo.bodies):
                if not checked[i]:
                    continue
                M = world_base * self.gdata.oMg[i]
                res = coal.DistanceResult()
                d = coal.distance(b.shape, coal.Transform3s(M.rotation, M.translation), shape, To, req, res)
                bad += self._judge(d, f"{b.name}/{name}")
        return bad

    def _judge(self, d: float, name: str) -> int:
        if d < self.min_distance:
            self.min_distance, self.closest = d, name
        if d < self.threshold:
            self.counts[name] += 1
            return 1
        return 0
