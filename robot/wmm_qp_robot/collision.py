"""The referee's collision check: the distance of every monitored pair, every step (docs/model.md, "Collisions").

Independent of the controller's rows (``wmm_qp.limits.collision``): the same bodies and pairs (the
robot description's), but placed by Pinocchio's own geometry pipeline (``updateGeometryPlacements``
on a data of its own) at the sim's executed joint values, the obstacles placed with the TRUE base
pose (slip included, which the controller's odometry does not see), and distances from
``pinocchio.computeDistance`` / coal in the world frame. A pair closer than ``threshold`` counts one
``collision`` violation per step, by pair name.

Two conservative skips keep the count exact at a fraction of the cost (a Gen3 step cost
~120–270 µs checking every pair; the sim steps at 1 kHz next to the daemon):

* a broad phase skips the pairs whose bounding spheres are ``threshold`` or more apart (such a pair
  cannot be closer than the threshold);
* a motion budget: once a pair's distance d (or its spheres' gap) is known, it is not computed
  again until the motion since could have closed d − threshold. No point of a body moves by more
  than Σ_k |Δq_k|·L_k (L_k: the longest lever from joint k to the body — the chain's joint offsets
  and the body's bounding sphere, whatever the configuration; |Δq_k| for a prismatic joint) plus,
  against obstacles, |Δt_base| + |Δψ|·R (R: the body's farthest reach from the base's z axis); a
  planar base does not move any body towards the floor. A distance is 1-Lipschitz in the motion
  of either body, so a pair within budget is at least the threshold apart: the count is exact
  (``tests/sim/test_sim_collision_budget.py`` holds it to a check of every pair at every step).

``min_distance`` is the smallest distance computed, or the bounding spheres' gap of a skipped pair
(every distance below the threshold is computed).
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
        self._arm = model.arm
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
        self.obstacles: list[tuple[str, coal.CollisionGeometry, pin.SE3, np.ndarray, FloatArray, float]] = []
        self._centers = np.array([b.center for b in self.geo.bodies]).reshape(-1, 3)  # each body's frame
        self._radii = np.array([b.radius for b in self.geo.bodies], dtype=float)
        self._pairs = [(k, i, j) for k, (i, j) in enumerate(self.geo.self_pairs)]
        pairs = np.array(self.geo.self_pairs, dtype=np.int64).reshape(-1, 2)
        self._pi, self._pj = pairs[:, 0], pairs[:, 1]
        self._pair_radii = self._radii[self._pi] + self._radii[self._pj]
        self._world = np.zeros((len(self.geo.bodies), 3))
        self.counts: Counter[str] = Counter()
        self.min_distance = math.inf
        self.closest = ""
        self._request = coal.DistanceRequest()
        self.skip = True  # the motion budget (False: every pair's distance at every step)
        self._levers, self._reach = self._motion_bounds(model)
        self._n_floor = len(self.geo.floor_bodies)
        self._floor_idx = np.array(self.geo.floor_bodies, dtype=np.int64)
        self._last: tuple[FloatArray, FloatArray] | None = None  # (base_true, q_arm) at the last step
        self._b_self = np.full(len(self._pairs), -1.0)  # [m] budgets: the motion a pair may still take
        self._b_floor = np.full(self._n_floor, -1.0)
        self._b_obs = np.full((0, len(self.geo.bodies)), -1.0)
        self.computed = 0  # distances (or sphere gaps) computed, for the bench and the tests

    def _motion_bounds(self, model: wmm_qp.WmmModel) -> tuple[FloatArray, FloatArray]:
        """The levers L (bodies × arm joints) and reaches R (bodies) of the motion budget [m]; a
        joint of another kind than 1-DoF revolute or prismatic: L = inf (that body always checked)."""
        pm, bodies = self.pmodel, self.geo.bodies
        user = {int(pm.joints[j].idx_v): j for j in range(1, pm.njoints)}
        column = {user[int(v)]: k for k, v in enumerate(model.arm._idx_v)}  # pin joint id → arm joint
        L = np.zeros((len(bodies), model.arm.n))
        R = np.zeros(len(bodies))
        offsets = [float(np.linalg.norm(pm.jointPlacements[j].translation)) for j in range(pm.njoints)]
        for i, b in enumerate(bodies):
            own = float(np.linalg.norm(b.placement.act(b.center))) + b.radius  # joint origin → any point
            chain = [int(j) for j in pm.supports[b.joint]][1:]  # the joints that move it, root first
            R[i] = sum(offsets[j] for j in chain) + own
            for p, j in enumerate(chain):
                kind = pm.joints[j].shortname().removeprefix("JointModel")[:1]  # R…: revolute, P…: prismatic
                if pm.joints[j].nv != 1 or j not in column or kind not in ("R", "P"):
                    L[i, :] = math.inf
                    break
                if kind == "P":  # the body moves by |Δq|
                    L[i, column[j]] = 1.0
                else:  # |Δθ| times the farthest point from its axis
                    L[i, column[j]] = sum(offsets[m] for m in chain[p + 1:]) + own
        return L, R

    def set_obstacles(self, obstacles: tuple[ShapeConfig, ...] | list[ShapeConfig]) -> None:
        from wmm_qp.model.collision import exempt_mask

        out = []
        for o in obstacles:
            shape = coal_shape(o)
            if o.kind == "plane":
                centre, radius = np.zeros(3), math.inf
            else:
                shape.computeLocalAABB()
                centre, radius = shape_pose(o).act(np.asarray(shape.aabb_center, dtype=float)), float(shape.aabb_radius)
            out.append((o.name, shape, shape_pose(o), exempt_mask(self.geo, o.exempt), centre, radius))
        self.obstacles = out
        self._b_obs = np.full((len(out), len(self.geo.bodies)), -1.0)  # new obstacles: checked at once

    def reset(self) -> None:
        self.counts.clear()
        self.min_distance, self.closest = math.inf, ""
        self._last = None

    def check(self, base_true: FloatArray, q_arm: FloatArray) -> int:
        """Distances at the true base pose and the arm's joint values q_arm [rad]; returns the
        number of pairs closer than the threshold this step (each also counted by name)."""
        self._spend(np.asarray(base_true, dtype=float), np.asarray(q_arm, dtype=float))
        due_self, due_floor = np.flatnonzero(self._b_self < 0.0), np.flatnonzero(self._b_floor < 0.0)
        due_obs = self._b_obs < 0.0
        if not (due_self.size or due_floor.size or due_obs.any()):
            return 0
        pin.forwardKinematics(self.pmodel, self.pdata, self._arm.pin_q(q_arm))
        pin.updateGeometryPlacements(self.pmodel, self.pdata, self.gmodel, self.gdata)
        bad = 0
        req = self._request
        oMg, bodies, thr = self.gdata.oMg, self.geo.bodies, self.threshold
        base_frame = self._world
        for i in range(len(bodies)):  # bounding-sphere centres, base frame
            base_frame[i] = oMg[i].act(self._centers[i])
        names = self.gmodel.geometryObjects
        if due_self.size:  # the broad phase of the due pairs at once (a norm per pair cost ~2 µs each)
            pi, pj = self._pi[due_self], self._pj[due_self]
            diff = base_frame[pi] - base_frame[pj]
            gaps = np.sqrt(np.einsum("ij,ij->i", diff, diff)) - self._pair_radii[due_self]
            self._b_self[due_self] = gaps - thr
            far = gaps >= thr
            if far.any():  # the nearest skipped pair stands in for them all (as one by one)
                k = int(np.argmin(np.where(far, gaps, np.inf)))
                self._judge_far(float(gaps[k]), names[int(pi[k])].name, names[int(pj[k])].name)
            for k in np.flatnonzero(~far).tolist():
                p = int(due_self[k])
                i, j = int(self._pi[p]), int(self._pj[p])
                # coal.distance with a request and result of its own: pin.computeDistance on the
                # persistent GeometryData answered up to ~1 cm off (a Box against TIAGo's convex
                # arm_1 mesh) after the pair had been skipped, its solver state carried over
                Mi, Mj = oMg[i], oMg[j]
                d = coal.distance(bodies[i].shape, coal.Transform3s(Mi.rotation, Mi.translation), bodies[j].shape,
                                  coal.Transform3s(Mj.rotation, Mj.translation), req, coal.DistanceResult())
                self._b_self[p] = d - thr
                bad += self._judge(d, f"{names[i].name}/{names[j].name}")
        self.computed += int(due_self.size)
        c, s = math.cos(base_true[2]), math.sin(base_true[2])
        Rb = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        tb = np.array([base_true[0], base_true[1], 0.0])
        world_base = pin.SE3(Rb, tb)
        world = base_frame @ Rb.T + tb
        for f in due_floor.tolist():
            i = int(self._floor_idx[f])
            self.computed += 1
            gap = float(world[i, 2] - self._radii[i] - self.geo.floor_z)
            if gap >= thr:
                self._b_floor[f] = gap - thr
                self._judge_far(gap, bodies[i].name, "floor")
                continue
            M = world_base * oMg[i]  # the floor is z = floor_z in the world
            res = coal.DistanceResult()
            d = coal.distance(bodies[i].shape, coal.Transform3s(M.rotation, M.translation),
                              self._floor, coal.Transform3s(), req, res)
            self._b_floor[f] = d - thr
            bad += self._judge(d, f"{bodies[i].name}/floor")
        for k, (name, shape, pose, checked, centre, radius) in enumerate(self.obstacles):
            if not due_obs[k].any():
                continue
            To = coal.Transform3s(pose.rotation, pose.translation)
            for i in np.flatnonzero(due_obs[k]).tolist():
                if not checked[i]:
                    self._b_obs[k, i] = math.inf  # exempt: never
                    continue
                b = bodies[i]
                self.computed += 1
                if math.isfinite(radius):
                    gap = float(np.linalg.norm(world[i] - centre)) - self._radii[i] - radius
                    if gap >= thr:
                        self._b_obs[k, i] = gap - thr
                        self._judge_far(gap, b.name, name)
                        continue
                M = world_base * oMg[i]
                res = coal.DistanceResult()
                d = coal.distance(b.shape, coal.Transform3s(M.rotation, M.translation), shape, To, req, res)
                self._b_obs[k, i] = d - thr
                bad += self._judge(d, f"{b.name}/{name}")
        return bad

    def _spend(self, base: FloatArray, q: FloatArray) -> None:
        """Take this step's motion from every budget (all spent: every pair due)."""
        last = self._last
        self._last = (base.copy(), q.copy())
        if last is None or not self.skip:
            self._b_self[:], self._b_floor[:], self._b_obs[:] = -1.0, -1.0, -1.0
            return
        dq = np.abs(q - last[1])
        with np.errstate(invalid="ignore"):  # inf · 0 (a joint that did not move): nan, taken as inf
            moved = self._levers @ dq
        moved = np.where(np.isnan(moved), math.inf, moved)  # [m] the most any point of each body moved
        if self._pairs:
            self._b_self -= moved[self._pi] + moved[self._pj]
        if self._n_floor:
            self._b_floor -= moved[self._floor_idx]  # a planar base keeps every height
        if self._b_obs.size:
            dt_b = float(math.hypot(base[0] - last[0][0], base[1] - last[0][1]))
            dpsi = abs(math.remainder(float(base[2] - last[0][2]), math.tau))
            self._b_obs -= (moved + dt_b + dpsi * self._reach)[None, :]

    def _judge_far(self, gap: float, a: str, b: str) -> None:
        """A pair the broad phase skipped: its bounding spheres' gap stands in for min_distance."""
        if gap < self.min_distance:
            self.min_distance, self.closest = gap, f"{a}/{b}"

    def _judge(self, d: float, name: str) -> int:
        if d < self.min_distance:
            self.min_distance, self.closest = d, name
        if d < self.threshold:
            self.counts[name] += 1
            return 1
        return 0
