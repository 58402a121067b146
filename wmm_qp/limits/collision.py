"""Velocity dampers (Faverjon & Tournassoud; NEO's form) and the workspace fence as hard QP rows.

For a monitored pair (a, b) at distance d with closest points p_a, p_b and n̂ = (p_a − p_b)/d,
ḋ = n̂ᵀ(J_{p_a} − J_{p_b}) v. While d < d_i (the influence distance):

    n̂ᵀ(J_{p_a} − J_{p_b}) v ≥ −ξ (d' − d_s)/(d_i − d_s)                       (damper)

with d_s the safety distance (``collision.floor_margin`` for the floor), ξ the gain [m/s] and
d' = d − τ·max(0, −ḋ_prev) the distance left after the state's age τ at the approach speed the
robot already has (ḋ_prev from the bounds' centre, the last command): like bounds (13), the rows
account for the state's latency. Point Jacobians: a point p on joint j moves at v_j + ω_j × (p − o_j),
so n̂ᵀJ_p = n̂ᵀJ_v + ((p − o_j) × n̂)ᵀJ_ω (the joint's Jacobian in the base frame); for a pair with
the world (floor, obstacles) the base's motion adds n̂ᵀ[[1, 0, −p_y], [0, 1, p_x], [0, 0, 0]]·M on the
wheels (eq. (5)'s J_b for the point p, eq. (3)'s M); between two bodies of the robot it cancels.

Fence (the scene's): for each edge of the base polygon, n_eᵀ ṗ_b ≤ ξ (c_e − n_eᵀ p_b − d_s)/(d_i − d_s)
while the base's origin is within d_i of it, and the EE box the same way on each axis.

One row per pair of links (the closest pair of their bodies) and per link and obstacle, at most
``MAX_ROWS`` (the closest) per tick: nearly parallel rows of one link's several shapes would only
slow the solvers.

Priority: the acceleration bounds (13) win. Each row is relaxed, where the bounds cannot meet it,
to the most separating rate they admit: l ← min(l, max_{lb ≤ v ≤ ub} C_k v) — the robot then
separates (or stops approaching) as hard as (13) allows. Each row alone is then feasible; should
the rows together not be (two contacts pulling apart), the stage is solved again with every row
relaxed to admit the braking command v₀ = clip(0, lb, ub) (the command nearest zero inside the
bounds), l ← min(l, C v₀), which no set of rows can exclude: no collision row ever makes a stage
infeasible, braking is always admitted. (Relaxing to C v₀ alone is not enough: a stage may then keep
approaching at the braking command's rate tick after tick without ever braking — found by
``tests/test_collision.py``, the arm folded into its base.) The influence distance must exceed the
distance the robot needs to stop (docs/model.md gives the numbers).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import coal
import numpy as np
import pinocchio as pin

from .._jit import jit
from ..config import CollisionParams, FloatArray, ShapeConfig
from ..model.collision import Body, RobotGeometry, coal_shape, shape_pose, transform
from ..scene import Fence, Scene

_LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
MAX_ROWS = 24
"""At most this many rows per tick: one per pair of links (the closest of their bodies) and per
link and obstacle, the closest first. Further pairs are left out only while MAX_ROWS closer ones
are within the influence distance."""


@dataclass
class Rows:
    """The collision and fence rows of one tick: l ≤ C v (no upper bound)."""

    C: FloatArray
    l: FloatArray  # the damper, relaxed to the most separating rate the bounds admit
    l_brake: FloatArray = field(default_factory=lambda: np.zeros(0))  # relaxed to admit the braking command
    damper: FloatArray = field(default_factory=lambda: np.zeros(0))  # the damper's own bound
    names: list[str] = field(default_factory=list)  # one per row: "a/b" or "fence:..."
    distances: FloatArray = field(default_factory=lambda: np.zeros(0))  # [m], per row
    min_distance: float = math.inf  # the closest monitored pair this tick (also beyond d_i)
    closest: str = ""


@dataclass
class _Obstacle:
    name: str
    shape: coal.CollisionGeometry
    world: pin.SE3
    center: FloatArray
    radius: float
    plane: bool
    checked: FloatArray  # bool per body: the bodies this obstacle is checked against


def exempt_mask(geometry: RobotGeometry, exempt: tuple[str, ...]) -> FloatArray:
    """True for the bodies an obstacle is checked against: all but those on its ``exempt`` links
    ("ee": every body on the EE frame's joint)."""
    ee_joint = geometry.arm.model.frames[geometry.arm.frame_id].parentJoint
    return np.array(
        [not (b.link in exempt or ("ee" in exempt and b.joint == ee_joint)) for b in geometry.bodies], dtype=bool
    )


def _obstacle(s: ShapeConfig, geometry: RobotGeometry) -> _Obstacle:
    shape = coal_shape(s)
    plane = s.kind == "plane"
    if not plane:
        shape.computeLocalAABB()
    center = np.zeros(3) if plane else np.asarray(shape.aabb_center, dtype=float).copy()
    radius = math.inf if plane else float(shape.aabb_radius)
    return _Obstacle(s.name, shape, shape_pose(s), center, radius, plane, exempt_mask(geometry, s.exempt))


class CollisionRows:
    """Builds the damper and fence rows each tick (see the module docstring).

    Args:
        geometry: the robot's bodies and pairs.
        M: the base's 3 × n_wheels matrix (eq. (3)).
        params: d_i, d_s, the floor margin, ξ.
        latency: [s] τ, the state's age the rows account for (the controller's ``state_latency``).
    """

    def __init__(self, geometry: RobotGeometry, M: FloatArray, params: CollisionParams, latency: float) -> None:
        self.geo = geometry
        self.M = np.asarray(M, dtype=float)
        self.p = params
        self.latency = latency
        self.n_w = self.M.shape[1]
        self.n_a = geometry.arm.n
        self.obstacles: list[_Obstacle] = []
        self.fence = Fence()
        self._floor = coal.Halfspace(np.array([0.0, 0.0, 1.0]), geometry.floor_z)  # coal: n·p ≤ d is solid: z ≤ floor_z
        self._identity = coal.Transform3s()
        self._req = coal.DistanceRequest()
        self._res = coal.DistanceResult()
        bodies = geometry.bodies
        # the broad phase's arrays: each body's bounding-sphere centre in its joint's frame
        self._joints = np.unique([b.joint for b in bodies]) if bodies else np.zeros(0, dtype=int)
        where = {int(j): k for k, j in enumerate(self._joints)}
        self._body_joint = np.array([where[b.joint] for b in bodies], dtype=int)
        self._local_centers = np.array([b.placement.act(b.center) for b in bodies]).reshape(-1, 3)
        self._radii = np.array([b.radius for b in bodies], dtype=float)
        self._pairs = np.array(geometry.self_pairs, dtype=int).reshape(-1, 2)
        self._pair_r = self._radii[self._pairs[:, 0]] + self._radii[self._pairs[:, 1]]
        self._floor_idx = np.array(geometry.floor_bodies, dtype=int)

    def set_scene(self, scene: Scene) -> None:
        self.set_obstacles(scene.obstacles)
        self.fence = scene.fence

    def set_obstacles(self, obstacles: tuple[ShapeConfig, ...] | list[ShapeConfig]) -> None:
        """Replace the obstacle set (atomically: the next tick sees the new set only)."""
        self.obstacles = [_obstacle(s, self.geo) for s in obstacles]

    # ------------------------------------------------------------------ per tick
    def _dist(self, a: coal.CollisionGeometry, Ta: coal.Transform3s, b: coal.CollisionGeometry,
              Tb: coal.Transform3s) -> tuple[float, FloatArray, FloatArray]:
        res = self._res
        res.clear()
        d = coal.distance(a, Ta, b, Tb, self._req, res)
        p_a, p_b = res.getNearestPoint1(), res.getNearestPoint2()
        return float(d), np.asarray(p_a, dtype=float), np.asarray(p_b, dtype=float)

    def _point_row(self, body: Body, p: FloatArray, n: FloatArray, out: FloatArray, sign: float) -> None:
        """out[n_w:] += sign · n̂ᵀ J_p (arm columns; p, n̂ in the base frame)."""
        if body.joint == 0:
            return
        data = self.geo.arm.data
        J = pin.getJointJacobian(self.geo.arm.model, data, body.joint, _LWA)
        _add_point_row(J, data.oMi[body.joint].translation, p, n, sign, out, self.n_w)

    def _base_row(self, p: FloatArray, n: FloatArray, out: FloatArray) -> None:
        """out[:n_w] += n̂ᵀ J_b(p) M: the base twist's motion of a robot point p (base frame)."""
        if self.n_w:
            _add_base_row(self.M, p, n, out)

    def rows(
        self,
        q_base: FloatArray,
        x_ee: FloatArray,
        J_ee: FloatArray,
        v_prev: FloatArray,
        lb: FloatArray,
        ub: FloatArray,
    ) -> Rows:
        """The rows at the state the arm's data was last computed at (``kinematics`` ran just before).

        Args:
            q_base: [m, m, rad] base pose.
            x_ee: [m] EE position (world), J_ee its 3 × n_v world Jacobian (for the fence's EE box).
            v_prev: the bounds' centre (last command or state rates), for the latency term.
            lb, ub: the stage's box bounds on v (for the braking command v₀).
        """
        geo, p = self.geo, self.p
        d_i = p.influence_distance
        n_v = self.n_w + self.n_a
        v0 = np.minimum(np.maximum(0.0, lb), ub)
        C_rows: list[FloatArray] = []
        bounds: list[float] = []
        names: list[str] = []
        dists: list[float] = []
        out = Rows(np.zeros((0, n_v)), np.zeros(0))

        keyed: dict[tuple[str, str], int] = {}  # (link, link or obstacle): its row (the closest bodies')
        brakes: list[float] = []
        dampers: list[float] = []

        def add(row: FloatArray, d: float, d_s: float, name: str, key: tuple[str, str] | None = None) -> None:
            damper, best, brake = _row_bounds(row, v_prev, v0, lb, ub, d, d_s, d_i, p.gain, self.latency)
            lo, lo_brake = min(damper, best), min(damper, brake)
            if key is not None:
                k = keyed.get(key)
                if k is not None:  # two bodies of the same links: keep the closer pair's row only
                    if d < dists[k]:
                        C_rows[k], bounds[k], brakes[k], names[k], dists[k] = row, lo, lo_brake, name, d
                        dampers[k] = damper
                    return
                keyed[key] = len(C_rows)
            C_rows.append(row)
            bounds.append(lo)
            brakes.append(lo_brake)
            dampers.append(damper)
            names.append(name)
            dists.append(d)

        bodies = geo.bodies
        centers = self._centers()  # bounding spheres, base frame (the broad phase, vectorised)
        cache: dict[int, coal.Transform3s] = {}

        def T(k: int) -> coal.Transform3s:
            t = cache.get(k)
            if t is None:
                t = cache[k] = transform(self._placement(k))
            return t

        def pair(i: int, b_shape: coal.CollisionGeometry, Tb: coal.Transform3s, other: Body | None,
                 d_s: float, name: str, world: bool, key: tuple[str, str]) -> None:
            a = bodies[i]
            d, pa, pb = self._dist(a.shape, T(i), b_shape, Tb)
            if d < out.min_distance:
                out.min_distance, out.closest = d, name
            if d >= d_i:
                return
            n = _normal(self._res)
            row = np.zeros(n_v)
            self._point_row(a, pa, n, row, 1.0)
            if other is not None:
                self._point_row(other, pb, n, row, -1.0)
            if world:
                self._base_row(pa, n, row)
            add(row, d, d_s, name, key)

        if self._pairs.shape[0]:  # robot vs robot (base frame; the base's motion cancels)
            gap = np.linalg.norm(centers[self._pairs[:, 0]] - centers[self._pairs[:, 1]], axis=1) - self._pair_r
            for k in np.flatnonzero(gap <= d_i):
                i, j = self._pairs[k]
                pair(int(i), bodies[j].shape, T(int(j)), bodies[j], p.safety_distance,
                     f"{bodies[i].name}/{bodies[j].name}", False, (bodies[i].link, bodies[j].link))
        if self._floor_idx.shape[0]:  # robot vs the floor z = floor_z (a plane of the base frame too)
            gap = centers[self._floor_idx, 2] - self._radii[self._floor_idx] - geo.floor_z
            for k in np.flatnonzero(gap <= d_i):
                i = int(self._floor_idx[k])
                pair(i, self._floor, self._identity, None, p.floor_margin, f"{bodies[i].name}/floor", False,
                     (bodies[i].link, "floor"))
        if self.obstacles:
            c, s = math.cos(q_base[2]), math.sin(q_base[2])
            world_base = pin.SE3(np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]),
                                 np.array([q_base[0], q_base[1], 0.0]))
            base_world = world_base.inverse()
            for o in self.obstacles:
                Mo = base_world * o.world  # the obstacle in the base frame
                To = transform(Mo)
                if o.plane:
                    near = np.flatnonzero(o.checked)
                else:
                    gap = np.linalg.norm(centers - Mo.act(o.center), axis=1) - self._radii - o.radius
                    near = np.flatnonzero((gap <= d_i) & o.checked)
                for i in near:
                    pair(int(i), o.shape, To, None, p.safety_distance, f"{bodies[i].name}/{o.name}", True,
                         (bodies[i].link, o.name))
        self._fence_rows(q_base, x_ee, J_ee, add, n_v)
        if C_rows:
            keep = np.argsort(dists)[:MAX_ROWS]  # the closest pairs, if more than MAX_ROWS are near
            out.C, out.l, out.l_brake = np.array(C_rows)[keep], np.array(bounds)[keep], np.array(brakes)[keep]
            out.names, out.distances = [names[k] for k in keep], np.array(dists)[keep]
            out.damper = np.array(dampers)[keep]
        return out

    def _placement(self, k: int) -> pin.SE3:
        b = self.geo.bodies[k]
        return self.geo.arm.data.oMi[b.joint] * b.placement if b.joint else b.placement

    def _centers(self) -> FloatArray:
        """Each body's bounding-sphere centre in the base frame (from the arm's current FK)."""
        oMi = self.geo.arm.data.oMi
        R = np.empty((len(self._joints), 3, 3))
        t = np.empty((len(self._joints), 3))
        for k, j in enumerate(self._joints):
            M = oMi[int(j)]
            R[k], t[k] = M.rotation, M.translation
        return np.einsum("kab,kb->ka", R[self._body_joint], self._local_centers) + t[self._body_joint]

    def _fence_rows(self, q_base: FloatArray, x: FloatArray, J: FloatArray, add: object, n_v: int) -> None:
        f, d_i = self.fence, self.p.influence_distance
        A, c = f.half_planes()
        if A.shape[0] and self.n_w:
            cs, sn = math.cos(q_base[2]), math.sin(q_base[2])
            P2 = np.array([[cs, -sn], [sn, cs]]) @ self.M[:2]  # the base origin's world velocity, eq. (3)
            for k in range(A.shape[0]):
                d = float(c[k] - A[k] @ q_base[:2])  # distance to the edge's line, inside ≥ 0
                if d < d_i:
                    row = np.zeros(n_v)
                    row[: self.n_w] = -A[k] @ P2  # ḋ = −n_eᵀ ṗ_b
                    add(row, d, 0.0, f"fence:base edge {k}")  # type: ignore[operator]
        for ax in range(3):
            for sign, bound in ((1.0, f.ee_upper[ax]), (-1.0, f.ee_lower[ax])):
                if not math.isfinite(bound):
                    continue
                d = sign * (bound - x[ax])
                if d < d_i:
                    add(-sign * np.asarray(J[ax], dtype=float), d, 0.0, f"fence:ee {'xyz'[ax]}")  # type: ignore[operator]


@jit
def _row_bounds(
    row: FloatArray, v_prev: FloatArray, v0: FloatArray, lb: FloatArray, ub: FloatArray,
    d: float, d_s: float, d_i: float, gain: float, latency: float,
) -> tuple[float, float, float]:
    """(the damper's bound, the most separating rate in lb ≤ v ≤ ub, the braking command's rate)."""
    prev = best = brake = 0.0
    for i in range(row.shape[0]):
        c = row[i]
        prev += c * v_prev[i]
        brake += c * v0[i]
        best += c * ub[i] if c > 0.0 else c * lb[i]
    d_eff = d - latency * max(0.0, -prev)  # the approach during the state's age
    return -gain * (d_eff - d_s) / (d_i - d_s), best, brake


@jit
def _add_point_row(J: FloatArray, o: FloatArray, p: FloatArray, n: FloatArray, sign: float, out: FloatArray,
                   first: int) -> None:
    """out[first:] += sign·(n̂ᵀJ_v + ((p − o) × n̂)ᵀJ_ω): n̂ᵀ of the velocity of point p on the joint."""
    r0, r1, r2 = p[0] - o[0], p[1] - o[1], p[2] - o[2]
    c0, c1, c2 = r1 * n[2] - r2 * n[1], r2 * n[0] - r0 * n[2], r0 * n[1] - r1 * n[0]
    for i in range(J.shape[1]):
        out[first + i] += sign * (
            n[0] * J[0, i] + n[1] * J[1, i] + n[2] * J[2, i] + c0 * J[3, i] + c1 * J[4, i] + c2 * J[5, i]
        )


@jit
def _add_base_row(M: FloatArray, p: FloatArray, n: FloatArray, out: FloatArray) -> None:
    """out[:n_w] += n̂ᵀ [[1, 0, −p_y], [0, 1, p_x], [0, 0, 0]] M (eq. (5)'s J_b at p, eq. (3)'s M)."""
    a0, a1, a2 = n[0], n[1], -n[0] * p[1] + n[1] * p[0]
    for j in range(M.shape[1]):
        out[j] += a0 * M[0, j] + a1 * M[1, j] + a2 * M[2, j]


def _normal(res: coal.DistanceResult) -> FloatArray:
    """n̂ from body b to body a: −coal's normal (which points from the first shape to the second),
    defined in penetration too."""
    n = -np.asarray(res.normal, dtype=float)
    nn = float(np.linalg.norm(n))
    return n / nn if nn > 1e-12 else np.array([0.0, 0.0, 1.0])
