"""Velocity dampers (Faverjon & Tournassoud; NEO's form) and the workspace fence as hard QP rows.

For a monitored pair (a, b) at distance d with closest points p_a, p_b and n̂ = (p_a − p_b)/d,
ḋ = n̂ᵀ(J_{p_a} − J_{p_b}) v. While d < d_i (the influence distance):

    n̂ᵀ(J_{p_a} − J_{p_b}) v ≥ −ξ (d' − d_s)/(d_i − d_s)                       (damper)

with d_s the safety distance (``collision.floor_margin`` for the floor), ξ the gain [m/s], raised
to the braking profile −√(2 β a_n (d' − d_s)) where that is larger (a_n = Σ_j |C_j| A_j: see
``_row_bounds``; a slow arm cannot follow the linear damper's deceleration near d_i), and
d' = d − τ·max(0, −ḋ_prev) the distance left after the state's age τ at the approach speed the
robot already has (ḋ_prev from the bounds' centre, the last command): like bounds (13), the rows
account for the state's latency. A moving obstacle (its ``velocity`` v_b, world frame) closes the
distance by n̂ᵀv_b on its own: its rows ask that much more of the robot, ḋ = n̂ᵀJ_a v − n̂ᵀv_b
(the robot gives way at the obstacle's approach speed, as far as the bounds allow).
Point Jacobians: a point p on joint j moves at v_j + ω_j × (p − o_j), so
n̂ᵀJ_p = n̂ᵀJ_v + ((p − o_j) × n̂)ᵀJ_ω (the joint's Jacobian in the base frame); for a pair with
the world (floor, obstacles) the base's motion adds n̂ᵀ[[1, 0, −p_y], [0, 1, p_x], [0, 0, 0]]·M on the
wheels (eq. (5)'s J_b for the point p, eq. (3)'s M); between two bodies of the robot it cancels.

Fence (the scene's): for each edge of the base polygon, n_eᵀ ṗ_b ≤ ξ (c_e − n_eᵀ p_b − d_s)/(d_i − d_s)
while the base's origin is within d_i of it, and the EE box the same way on each axis.

At most ``MAX_ROWS`` body pairs (the closest) per tick, and of one pair of links' rows only those
that are not parallel (cos > 0.995; the more restrictive is kept): nearly parallel rows of one
link's several shapes would only slow the solvers. Keeping only the closest pair of bodies of two
links is not enough: another body of the same links went deeper (verify, the Panda's finger).

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
from dataclasses import dataclass, field, replace

import coal
import numpy as np
import pinocchio as pin

from .._jit import jit
from ..config import CollisionParams, FloatArray, ShapeConfig
from ..model.collision import RobotGeometry, bounding_sphere, coal_shape, row_shape, shape_pose, transform
from ..scene import Fence, Scene
from ._distance import box_plane, swept_box, swept_plane, swept_swept

IntArray = np.ndarray

_LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
RELAX_MARGIN = 1e-9  # [m/s]
PARALLEL = 0.995  # two rows of one pair of links this parallel (cos) are one
MAX_ROWS = 48
"""At most this many body pairs per tick, the nearest to their safety distance first (further pairs
are left out only while MAX_ROWS nearer ones are within the influence distance), but never one
inside its safety distance: with a whole Panda sampled inside a wall, the cap had left out a
finger 3.8 mm from its link5 (``wmm-qp verify``, 400 samples: 120 collisions; now 0). Of those,
two rows of one pair of links that are parallel (cos > 0.995) become one, the more restrictive."""


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


class Table:
    """Primitives in arrays, for the compiled distances (``_distance.py``): kind 0 a swept segment
    [a0, a1] of radius r (sphere, capsule), 1 a box (centre c, rotation R, half extents h), 2 any
    other shape (coal computes its distances); ``centre`` is each one's bounding-sphere centre."""

    def __init__(self, n: int) -> None:
        self.kind = np.full(n, 2, dtype=np.int64)
        self.a0, self.a1, self.c, self.h, self.centre = (np.zeros((n, 3)) for _ in range(5))
        self.r = np.zeros(n)
        self.R = np.tile(np.eye(3), (n, 1, 1))

    def set(self, k: int, shape: coal.CollisionGeometry, M: pin.SE3, centre: FloatArray) -> None:
        """Entry k: ``shape`` at pose M (its frame's), bounding-sphere centre ``centre`` (shape frame)."""
        self.c[k], self.R[k] = M.translation, M.rotation
        self.centre[k] = M.act(centre)
        if isinstance(shape, coal.Capsule):
            self.kind[k], self.r[k] = 0, shape.radius
            self.a0[k], self.a1[k] = M.act(np.array([0.0, 0.0, -shape.halfLength])), M.act(
                np.array([0.0, 0.0, shape.halfLength]))
        elif isinstance(shape, coal.Sphere):
            self.kind[k], self.r[k] = 0, shape.radius
            self.a0[k] = self.a1[k] = M.translation
        elif isinstance(shape, coal.Box):
            self.kind[k], self.h[k] = 1, shape.halfSide
        else:
            self.kind[k] = 2


@dataclass
class _Obstacle:
    name: str
    shape: coal.CollisionGeometry
    world: pin.SE3
    center: FloatArray
    radius: float
    plane: bool
    checked: FloatArray  # bool per body: the bodies this obstacle is checked against
    normal_w: FloatArray = field(default_factory=lambda: np.zeros(3))  # a plane's, world frame
    offset_w: float = 0.0
    placed: Table = field(default_factory=lambda: Table(1))  # in the base frame, this tick
    centre_b: FloatArray = field(default_factory=lambda: np.zeros(3))
    normal_b: FloatArray = field(default_factory=lambda: np.zeros(3))
    offset_b: float = 0.0
    _M: pin.SE3 = field(default_factory=pin.SE3.Identity)
    velocity_w: FloatArray = field(default_factory=lambda: np.zeros(3))  # [m/s] world frame

    def place(self, Rb: FloatArray, tb: FloatArray) -> None:
        """This tick's pose in the base frame, the base at (Rb, tb) in the world."""
        if self.plane:  # n·p_w ≤ c  ⇔  (Rbᵀ n)·p_b ≤ c − n·tb
            self.normal_b, self.offset_b = Rb.T @ self.normal_w, self.offset_w - float(self.normal_w @ tb)
            return
        self._M = pin.SE3(Rb.T @ self.world.rotation, Rb.T @ (self.world.translation - tb))
        self.placed.set(0, self.shape, self._M, self.center)
        self.centre_b = self.placed.centre[0]

    def transform(self) -> coal.Transform3s:
        if self.plane:
            return coal.Transform3s()  # a plane obstacle's coal shape is built in the base frame
        return transform(self._M)


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
    center, radius = (np.zeros(3), math.inf) if plane else bounding_sphere(row_shape(shape))
    o = _Obstacle(s.name, shape, shape_pose(s), center, radius, plane, exempt_mask(geometry, s.exempt))
    if plane:
        o.normal_w, o.offset_w = np.asarray(s.size, dtype=float), float(s.xyz[2])
    if s.velocity is not None:
        o.velocity_w = np.asarray(s.velocity, dtype=float)
    return o


class CollisionRows:
    """Builds the damper and fence rows each tick (see the module docstring).

    Args:
        geometry: the robot's bodies and pairs.
        M: the base's 3 × n_wheels matrix (eq. (3)).
        params: d_i, d_s, the floor margin, ξ.
        latency: [s] τ, the state's age the rows account for (the controller's ``state_latency``).
        accel: A of each column of v = [wheels, arm] (the controller's bounds (13)): the braking
            profile's deceleration.
    """

    def __init__(self, geometry: RobotGeometry, M: FloatArray, params: CollisionParams, latency: float,
                 accel: FloatArray) -> None:
        self.geo = geometry
        self.M = np.asarray(M, dtype=float)
        own = geometry.robot.collision.influence_distance  # the robot file's, when larger
        if own is not None and own > params.influence_distance:
            params = replace(params, influence_distance=own)
        self.p = params
        self.latency = latency
        self.n_w = self.M.shape[1]
        self.n_a = geometry.arm.n
        self._accel = np.asarray(accel, dtype=float)
        self.obstacles: list[_Obstacle] = []
        self.shapes: tuple[ShapeConfig, ...] = ()  # the obstacles in force, as given to set_obstacles
        self._names: dict[tuple[int, int], str] = {}
        self._moving = False
        self._obs_boxes = np.zeros(0, dtype=np.int64)
        self._obs_joint = np.zeros(0, dtype=np.int64)
        self._H_world = np.eye(4)[None].copy()  # world → base frame, refilled each tick
        self._obs: tuple = (np.zeros(0, dtype=np.int64), Table(0), Table(0), np.zeros(0),
                            np.zeros((0, len(geometry.bodies)), dtype=bool), [])
        self.fence = Fence()
        self._floor = coal.Halfspace(np.array([0.0, 0.0, 1.0]), geometry.floor_z)  # coal: n·p ≤ d is solid: z ≤ floor_z
        self._identity = coal.Transform3s()
        self._req = coal.DistanceRequest()
        self._res = coal.DistanceResult()
        bodies = geometry.bodies
        self._joints = np.unique([b.joint for b in bodies]) if bodies else np.zeros(0, dtype=int)
        where = {int(j): k for k, j in enumerate(self._joints)}
        self._body_joint = np.array([where[b.joint] for b in bodies], dtype=int)
        # the broad phase: each row shape's bounding sphere (a cylinder's capsule reaches past the
        # cylinder's own sphere: culling on that would let a pair in already inside d_s)
        self._radii = np.array([b.row_radius for b in bodies], dtype=float)
        self._pairs = np.array(geometry.self_pairs, dtype=int).reshape(-1, 2)
        self._pair_r = self._radii[self._pairs[:, 0]] + self._radii[self._pairs[:, 1]]
        self._floor_idx = np.array(geometry.floor_bodies, dtype=int)
        self._floor_n, self._floor_o = np.array([0.0, 0.0, -1.0]), -geometry.floor_z  # free: z ≥ floor_z
        # the compiled path: each body's primitive in its joint's frame, placed each tick
        self._shapes = Table(len(bodies))
        for k, b in enumerate(bodies):
            self._shapes.set(k, b.row, b.placement, b.row_center)
        self._placed = Table(len(bodies))
        self._placed.kind[:] = self._shapes.kind
        self._placed.r[:], self._placed.h[:] = self._shapes.r, self._shapes.h
        self._Hj = np.tile(np.eye(4), (len(self._joints), 1, 1))
        self._joint_ids = [int(j) for j in self._joints]
        self._oMi = geometry.arm.data.oMi  # the proxy, once: fetching data.oMi costs ~1 µs each time
        model = geometry.arm.model  # support[j, k]: joint j moves with the velocity column k
        self._support = np.zeros((model.njoints, model.nv))
        for j in range(1, model.njoints):
            a = j
            while a > 0:
                jm = model.joints[a]
                self._support[j, jm.idx_v : jm.idx_v + jm.nv] = 1.0
                a = model.parents[a]
        self._fence_A, self._fence_c = np.zeros((0, 2)), np.zeros(0)
        self._body_joint_ids = np.array([b.joint for b in bodies], dtype=np.int64)
        links = sorted({b.link for b in bodies})
        self._body_link = np.array([links.index(b.link) for b in bodies], dtype=np.int64)
        self._n_links = len(links)

    def set_scene(self, scene: Scene) -> None:
        self.set_obstacles(scene.obstacles)
        self.fence = scene.fence
        self._fence_A, self._fence_c = scene.fence.half_planes()

    def set_obstacles(self, obstacles: tuple[ShapeConfig, ...] | list[ShapeConfig]) -> None:
        """Replace the obstacle set (atomically: the next tick sees the new set only).

        The solid obstacles go into one table (world frame; a cylinder as the capsule that
        contains it), placed in the base frame each tick in one compiled call; the planes apart."""
        self.shapes = tuple(obstacles)  # the set in force, as given
        self._names = {}  # row names by pair (the obstacle indices change here)
        obs = [_obstacle(s, self.geo) for s in obstacles]
        solid = [k for k, o in enumerate(obs) if not o.plane]
        world, placed = Table(len(solid)), Table(len(solid))
        for r, k in enumerate(solid):
            o = obs[k]
            world.set(r, row_shape(o.shape), o.world, o.center)  # o.center, o.radius: of the row shape
        placed.kind[:], placed.r[:], placed.h[:] = world.kind, world.r, world.h
        checked = np.array([obs[k].checked for k in solid], dtype=bool).reshape(len(solid), len(self.geo.bodies))
        radii = np.array([obs[k].radius for k in solid], dtype=float)
        self._obs = (np.array(solid, dtype=np.int64), world, placed, radii, checked,
                     [k for k, o in enumerate(obs) if o.plane])
        self._obs_boxes = np.flatnonzero(world.kind == 1)  # rows of the table that are boxes
        self._obs_joint = np.zeros(len(solid), dtype=np.int64)  # every obstacle placed by the one H
        self.obstacles = obs
        self._moving = any(bool(o.velocity_w.any()) for o in obs)

    # ------------------------------------------------------------------ per tick
    def rows(
        self,
        q_base: FloatArray,
        x_ee: FloatArray,
        J_ee: FloatArray,
        v_prev: FloatArray,
        lb: FloatArray,
        ub: FloatArray,
    ) -> Rows:
        """The rows at the state the arm's data was last computed at (``kinematics`` ran just before:
        the arm's forward kinematics and joint Jacobians are current).

        Args:
            q_base: [m, m, rad] base pose.
            x_ee: [m] EE position (world), J_ee its 3 × n_v world Jacobian (for the fence's EE box).
            v_prev: the bounds' centre (last command or state rates), for the latency term.
            lb, ub: the stage's box bounds on v (for the relaxations).
        """
        p, d_i = self.p, self.p.influence_distance
        n_v = self.n_w + self.n_a
        out = Rows(np.zeros((0, n_v)), np.zeros(0))
        oMi = self._oMi
        for k, j in enumerate(self._joint_ids):  # the joints that carry bodies: their placements
            self._Hj[k] = oMi[j].homogeneous
        _place(self._Hj, self._body_joint, self._shapes, self._placed)
        pl = self._placed
        bodies = self.geo.bodies
        # every pair within d_i, as arrays: (d, p_a, p_b, n̂, body a, the other side: a body ≥ 0,
        # the floor -1, obstacle k -2 - k; its d_s)
        parts: list[tuple[FloatArray, FloatArray, FloatArray, FloatArray, IntArray, IntArray, float]] = []
        best = [math.inf, 0, 0]

        def collect(d: FloatArray, P: FloatArray, Q: FloatArray, N: FloatArray, I: IntArray, J: IntArray,
                    d_s: float) -> None:
            k = int(np.argmin(d))
            if d[k] < best[0]:
                best[:] = float(d[k]), int(I[k]), int(J[k])
            near = d < d_i
            if near.all():
                parts.append((d, P, Q, N, I, J, d_s))
            elif near.any():
                parts.append((d[near], P[near], Q[near], N[near], I[near], J[near], d_s))

        # robot vs robot (base frame; the base's motion cancels)
        if self._pairs.shape[0]:
            diff = pl.centre[self._pairs[:, 0]] - pl.centre[self._pairs[:, 1]]
            gap = np.sqrt(np.einsum("ij,ij->i", diff, diff)) - self._pair_r  # (a norm: 3× slower)
            cand = self._pairs[gap <= d_i]
            if cand.shape[0]:
                d, P, Q, N, ok = _pair_distances(pl, cand[:, 0], cand[:, 1], pl, self._buf(cand.shape[0]))
                for k in np.flatnonzero(~ok).tolist():  # box-box and other shapes: coal
                    i, j = int(cand[k, 0]), int(cand[k, 1])
                    d[k], P[k], Q[k], N[k] = self._coal(bodies[i].shape, self._T(i), bodies[j].shape, self._T(j))
                collect(d, P, Q, N, cand[:, 0], cand[:, 1], p.safety_distance)
        # robot vs the floor z = floor_z (the same plane in the base frame)
        if self._floor_idx.shape[0]:
            gap = pl.centre[self._floor_idx, 2] - self._radii[self._floor_idx] - self.geo.floor_z
            cand1 = self._floor_idx[gap <= d_i]
            if cand1.shape[0]:
                d, P, Q, N, ok = _plane_distances(pl, cand1, self._floor_n, self._floor_o, self._buf(cand1.shape[0]))
                for k in np.flatnonzero(~ok).tolist():
                    i = int(cand1[k])
                    d[k], P[k], Q[k], N[k] = self._coal(bodies[i].shape, self._T(i), self._floor, self._identity)
                collect(d, P, Q, N, cand1, np.full(cand1.shape[0], -1, dtype=np.int64), p.floor_margin)
        if self.obstacles:  # robot vs obstacles, in the base frame at this base pose
            c, s_ = math.cos(q_base[2]), math.sin(q_base[2])
            Rb = np.array([[c, -s_, 0.0], [s_, c, 0.0], [0.0, 0.0, 1.0]])
            tb = np.array([q_base[0], q_base[1], 0.0])
            solid, world, placed, radii, checked, planes = self._obs
            if solid.shape[0]:
                H = self._H_world  # world → base frame
                H[0, :3, :3], H[0, :3, 3] = Rb.T, -(Rb.T @ tb)
                _place(H, self._obs_joint, world, placed)
                diff3 = pl.centre[None, :, :] - placed.centre[:, None, :]
                gap = np.sqrt(np.einsum("obi,obi->ob", diff3, diff3)) - self._radii[None, :] - radii[:, None]
                boxes = self._obs_boxes
                if boxes.shape[0]:  # a box: the distance of each body's bounding sphere to the box itself
                    rel = np.einsum("oji,obj->obi", placed.R[boxes],
                                    pl.centre[None, :, :] - placed.c[boxes][:, None, :])  # box frame
                    out_ = np.maximum(np.abs(rel) - placed.h[boxes][:, None, :], 0.0)
                    gap[boxes] = np.sqrt(np.einsum("obi,obi->ob", out_, out_)) - self._radii[None, :]
                oi, bi = np.nonzero((gap <= d_i) & checked)
                if oi.shape[0]:
                    d, P, Q, N, ok = _pair_distances(pl, bi, oi, placed, self._buf(oi.shape[0]))
                    for k in np.flatnonzero(~ok).tolist():  # box-box and other shapes: coal
                        o, i = self.obstacles[int(solid[oi[k]])], int(bi[k])
                        Mo = pin.SE3(Rb.T @ o.world.rotation, Rb.T @ (o.world.translation - tb))
                        d[k], P[k], Q[k], N[k] = self._coal(bodies[i].shape, self._T(i), o.shape, transform(Mo))
                    collect(d, P, Q, N, bi, -2 - solid[oi], p.safety_distance)
            for oi_ in planes:
                o = self.obstacles[oi_]
                o.place(Rb, tb)
                cand2 = np.flatnonzero(o.checked)
                if not cand2.shape[0]:
                    continue
                d, P, Q, N, ok = _plane_distances(pl, cand2, o.normal_b, o.offset_b, self._buf(cand2.shape[0]))
                for k in np.flatnonzero(~ok).tolist():  # coal's half-space, built when a body needs it
                    i = int(cand2[k])
                    o.shape = coal.Halfspace(-o.normal_b, -o.offset_b)  # coal: solid where n'·p ≤ d
                    d[k], P[k], Q[k], N[k] = self._coal(bodies[i].shape, self._T(i), o.shape, o.transform())
                collect(d, P, Q, N, cand2, np.full(cand2.shape[0], -2 - oi_, dtype=np.int64), p.safety_distance)
        if math.isfinite(best[0]):
            out.min_distance, out.closest = float(best[0]), self._name(int(best[1]), int(best[2]))
        fC, fd, fnames = self._fence_rows(q_base, x_ee, J_ee, n_v)
        if not parts and not fnames:
            return out
        if parts:
            D = np.concatenate([part[0] for part in parts])
            DS = np.concatenate([np.full(part[0].shape[0], part[6]) for part in parts])
            margin = D - DS  # the nearest to its safety distance first; every pair inside it kept
            order = np.argsort(margin, kind="stable")[: max(MAX_ROWS, int(np.count_nonzero(margin < 0.0)))]
            PA = np.concatenate([part[1] for part in parts])[order]
            PB = np.concatenate([part[2] for part in parts])[order]
            NN = np.concatenate([part[3] for part in parts])[order]
            IA = np.concatenate([part[4] for part in parts])[order]
            IB = np.concatenate([part[5] for part in parts])[order]
            DS, D = DS[order], D[order]
        else:
            D, DS = np.zeros(0), np.zeros(0)
            IA = IB = np.zeros(0, dtype=np.int64)
        m = D.shape[0]
        C = np.zeros((m + len(fnames), n_v))
        if m:
            bj = self._body_joint_ids
            jb = np.where(IB >= 0, bj[np.maximum(IB, 0)], 0)
            _point_rows(np.asarray(self.geo.arm.data.J), self._support, bj[IA], jb, PA, PB, NN, IB < 0, self.M,
                        self.n_w, C)
        if fnames:
            C[m:] = fC
        dist = np.concatenate((D, fd))
        d_s = np.concatenate((DS, np.zeros(len(fnames))))
        # a moving obstacle b: ḋ = n̂ᵀJ_a v − n̂ᵀv_b, so its rows ask n̂ᵀv_b more of the robot
        shift = np.zeros(dist.shape[0])
        if self._moving and m:
            c, s_ = math.cos(q_base[2]), math.sin(q_base[2])
            Rb = np.array([[c, -s_, 0.0], [s_, c, 0.0], [0.0, 0.0, 1.0]])
            for k in np.flatnonzero(IB <= -2).tolist():
                shift[k] = float(NN[k] @ (Rb.T @ self.obstacles[-2 - int(IB[k])].velocity_w))
        l, l_brake, damper = _all_bounds(C, v_prev, lb, ub, dist, d_s, d_i, p.gain, self.latency, shift,
                                         self._accel, p.braking)
        # two bodies of one pair of links: one row where they are parallel (the key: link a, and
        # link b, the floor or the obstacle; each fence row its own)
        nl = self._n_links
        other = np.where(IB >= 0, self._body_link[np.maximum(IB, 0)], nl - 1 - IB)
        keys = np.concatenate((self._body_link[IA] * (nl + 2 + len(self.obstacles)) + other,
                               -1 - np.arange(len(fnames))))
        keep = _distinct_rows(C, l, keys)
        out.C, out.l, out.l_brake, out.damper, out.distances = C[keep], l[keep], l_brake[keep], damper[keep], dist[keep]
        out.names = [self._name(int(IA[k]), int(IB[k])) if k < m else fnames[k - m] for k in keep.tolist()]
        return out

    def _name(self, i: int, j: int) -> str:
        """A row's pair: "a/b" (bodies), "a/floor", "a/<obstacle id>" (j = -2 - its index)."""
        key = (i, j)
        name = self._names.get(key)
        if name is None:
            bodies = self.geo.bodies
            other = bodies[j].name if j >= 0 else "floor" if j == -1 else self.obstacles[-2 - j].name
            name = self._names[key] = f"{bodies[i].name}/{other}"
        return name

    def _buf(self, n: int) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, np.ndarray]:
        return np.empty(n), np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 3)), np.empty(n, dtype=np.bool_)

    def _T(self, i: int) -> coal.Transform3s:
        """Body i's pose in the base frame as coal's (for the pairs coal computes)."""
        b = self.geo.bodies[i]
        return transform(self.geo.arm.data.oMi[b.joint] * b.placement if b.joint else b.placement)

    def _coal(self, a: coal.CollisionGeometry, Ta: coal.Transform3s, b: coal.CollisionGeometry,
              Tb: coal.Transform3s) -> tuple[float, FloatArray, FloatArray, FloatArray]:
        res = self._res
        res.clear()
        d = coal.distance(a, Ta, b, Tb, self._req, res)
        return float(d), np.asarray(res.getNearestPoint1()), np.asarray(res.getNearestPoint2()), _normal(res)

    def _fence_rows(self, q_base: FloatArray, x: FloatArray, J: FloatArray,
                    n_v: int) -> tuple[FloatArray, FloatArray, list[str]]:
        """(rows, distances, names) of the fence dampers within the influence distance (d_s = 0)."""
        f, d_i = self.fence, self.p.influence_distance
        A, c = self._fence_A, self._fence_c
        rows: list[FloatArray] = []
        dist: list[float] = []
        names: list[str] = []
        if A.shape[0] and self.n_w:
            gaps = c - A @ q_base[:2]  # distance to each edge's line, inside ≥ 0
            near = np.flatnonzero(gaps < d_i)
            if near.shape[0]:
                cs, sn = math.cos(q_base[2]), math.sin(q_base[2])
                P2 = np.array([[cs, -sn], [sn, cs]]) @ self.M[:2]  # the base origin's world velocity, eq. (3)
                for k in near:
                    row = np.zeros(n_v)
                    row[: self.n_w] = -A[k] @ P2  # ḋ = −n_eᵀ ṗ_b
                    rows.append(row)
                    dist.append(float(gaps[k]))
                    names.append(f"fence:base edge {k}")
        up, lo = f.ee_upper - x, x - f.ee_lower  # inf where the box is open
        if (up < d_i).any() or (lo < d_i).any():
            for ax in range(3):
                for sign, d in ((1.0, up[ax]), (-1.0, lo[ax])):
                    if d < d_i:
                        rows.append(-sign * np.asarray(J[ax], dtype=float))
                        dist.append(float(d))
                        names.append(f"fence:ee {'xyz'[ax]}")
        if not rows:
            return np.zeros((0, n_v)), np.zeros(0), names
        return np.array(rows), np.array(dist), names


def warm_up_obstacles(x: FloatArray) -> tuple[ShapeConfig, ...]:
    """One obstacle of every kind around the point x [m] (world), each ~0.1 m from it, the sphere
    moving, the box exempting the EE: ticked once, every compiled kernel of the rows is loaded
    (or compiled) before a real-time loop starts, not at the first obstacle that comes near."""
    from ..scene import obstacles_from_tables

    x = np.asarray(x, dtype=float)

    def at(dx: float, dy: float, dz: float) -> list[float]:
        return [float(x[0] + dx), float(x[1] + dy), float(x[2] + dz)]

    return obstacles_from_tables("<warm-up obstacles>", [
        {"id": "warm-up sphere", "kind": "sphere", "radius": 0.1, "xyz": at(0.2, 0.0, 0.0),
         "velocity": [-0.01, 0.0, 0.0]},
        {"id": "warm-up box", "kind": "box", "size": [0.2, 0.2, 0.2], "xyz": at(-0.2, 0.0, 0.0), "exempt": ["ee"]},
        {"id": "warm-up capsule", "kind": "capsule", "radius": 0.08, "length": 0.2, "xyz": at(0.0, 0.18, 0.0)},
        {"id": "warm-up cylinder", "kind": "cylinder", "radius": 0.08, "length": 0.2, "xyz": at(0.0, -0.18, 0.0)},
        {"id": "warm-up plane", "kind": "plane", "normal": [0.0, 0.0, 1.0], "offset": float(x[2] + 0.15)},
    ])


@jit
def _place_kernel(
    Hj: FloatArray, joint: IntArray, kind: IntArray, a0: FloatArray, a1: FloatArray, c: FloatArray,
    R: FloatArray, centre: FloatArray, o_a0: FloatArray, o_a1: FloatArray, o_c: FloatArray, o_R: FloatArray,
    o_centre: FloatArray,
) -> None:
    for k in range(joint.shape[0]):
        j = joint[k]
        for r in range(3):
            o_a0[k, r] = Hj[j, r, 3]
            o_a1[k, r] = Hj[j, r, 3]
            o_c[k, r] = Hj[j, r, 3]
            o_centre[k, r] = Hj[j, r, 3]
            for m in range(3):
                o_a0[k, r] += Hj[j, r, m] * a0[k, m]
                o_a1[k, r] += Hj[j, r, m] * a1[k, m]
                o_c[k, r] += Hj[j, r, m] * c[k, m]
                o_centre[k, r] += Hj[j, r, m] * centre[k, m]
                acc = 0.0
                for q in range(3):
                    acc += Hj[j, r, q] * R[k, q, m]
                o_R[k, r, m] = acc


def _place(Hj: FloatArray, joint: IntArray, local: Table, out: Table) -> None:
    """``out`` ← every body placed in the base frame (joint placements Hj, 4×4; joint 0's identity)."""
    _place_kernel(Hj, joint, local.kind, local.a0, local.a1, local.c, local.R, local.centre,
                  out.a0, out.a1, out.c, out.R, out.centre)


@jit
def _pairs_kernel(
    ka: IntArray, a0: FloatArray, a1: FloatArray, ra: FloatArray, ca: FloatArray, Ra: FloatArray, ha: FloatArray,
    kb: IntArray, b0: FloatArray, b1: FloatArray, rb: FloatArray, cb: FloatArray, Rb: FloatArray, hb: FloatArray,
    I: IntArray, J: IntArray, d: FloatArray, P: FloatArray, Q: FloatArray, N: FloatArray, ok: np.ndarray,
) -> None:
    for k in range(I.shape[0]):
        i, j = I[k], J[k]
        ok[k] = True
        if ka[i] == 0 and kb[j] == 0:
            d[k] = swept_swept(a0[i], a1[i], ra[i], b0[j], b1[j], rb[j], P[k], Q[k], N[k])
        elif ka[i] == 0 and kb[j] == 1:
            d[k] = swept_box(a0[i], a1[i], ra[i], cb[j], Rb[j], hb[j], P[k], Q[k], N[k])
            ok[k] = d[k] + ra[i] >= 0.0  # the segment itself inside the box: see swept_box
        elif ka[i] == 1 and kb[j] == 0:
            d[k] = swept_box(b0[j], b1[j], rb[j], ca[i], Ra[i], ha[i], Q[k], P[k], N[k])
            N[k] = -N[k]
            ok[k] = d[k] + rb[j] >= 0.0
        else:
            ok[k] = False


def _pair_distances(A: Table, I: IntArray, J: IntArray, B: Table, buf: tuple) -> tuple:
    """Distances of A[I[k]] to B[J[k]] (ok False where coal must compute it: box-box, meshes)."""
    d, P, Q, N, ok = buf
    _pairs_kernel(A.kind, A.a0, A.a1, A.r, A.c, A.R, A.h, B.kind, B.a0, B.a1, B.r, B.c, B.R, B.h,
                  np.asarray(I, dtype=np.int64), np.asarray(J, dtype=np.int64), d, P, Q, N, ok)
    return d, P, Q, N, ok


@jit
def _planes_kernel(
    kind: IntArray, a0: FloatArray, a1: FloatArray, r: FloatArray, c: FloatArray, R: FloatArray, h: FloatArray,
    I: IntArray, normal: FloatArray, offset: float, d: FloatArray, P: FloatArray, Q: FloatArray, N: FloatArray,
    ok: np.ndarray,
) -> None:
    for k in range(I.shape[0]):
        i = I[k]
        ok[k] = True
        if kind[i] == 0:
            d[k] = swept_plane(a0[i], a1[i], r[i], normal, offset, P[k], Q[k], N[k])
        elif kind[i] == 1:
            d[k] = box_plane(c[i], R[i], h[i], normal, offset, P[k], Q[k], N[k])
        else:
            ok[k] = False


def _plane_distances(A: Table, I: IntArray, normal: FloatArray, offset: float, buf: tuple) -> tuple:
    """Distances of A[I[k]] to the plane normal·x = offset (free side normal·x ≤ offset)."""
    d, P, Q, N, ok = buf
    _planes_kernel(A.kind, A.a0, A.a1, A.r, A.c, A.R, A.h, np.asarray(I, dtype=np.int64),
                   np.asarray(normal, dtype=float), float(offset), d, P, Q, N, ok)
    return d, P, Q, N, ok


@jit
def _point_rows(
    Jw: FloatArray, support: FloatArray, ja: IntArray, jb: IntArray, pa: FloatArray, pb: FloatArray,
    n: FloatArray, world: np.ndarray, M: FloatArray, n_w: int, C: FloatArray,
) -> None:
    """C[k] ← n̂ᵀ(J_{p_a} − J_{p_b}) of each pair, from the joints' world-frame (here: base-frame)
    Jacobian Jw (6 × nv, Pinocchio's data.J: a point p of joint j moves at J_v + J_ω × p over the
    columns the joint moves with); for pairs with the world, the base's motion of p_a on the wheels."""
    for k in range(ja.shape[0]):
        nk = n[k]
        for side in range(2):
            j = ja[k] if side == 0 else jb[k]
            if j == 0:
                continue
            p = pa[k] if side == 0 else pb[k]
            sign = 1.0 if side == 0 else -1.0
            c0 = p[1] * nk[2] - p[2] * nk[1]  # p × n̂
            c1 = p[2] * nk[0] - p[0] * nk[2]
            c2 = p[0] * nk[1] - p[1] * nk[0]
            for i in range(Jw.shape[1]):
                if support[j, i] != 0.0:
                    C[k, n_w + i] += sign * (
                        nk[0] * Jw[0, i] + nk[1] * Jw[1, i] + nk[2] * Jw[2, i]
                        + c0 * Jw[3, i] + c1 * Jw[4, i] + c2 * Jw[5, i]
                    )
        if world[k]:
            p = pa[k]
            a2 = -nk[0] * p[1] + nk[1] * p[0]
            for j in range(n_w):
                C[k, j] += nk[0] * M[0, j] + nk[1] * M[1, j] + a2 * M[2, j]


@jit
def _all_bounds(
    C: FloatArray, v_prev: FloatArray, lb: FloatArray, ub: FloatArray, d: FloatArray, d_s: FloatArray,
    d_i: float, gain: float, latency: float, shift: FloatArray, accel: FloatArray, braking: float,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(l, l_brake, damper) of every row (see the module docstring); ``shift``: n̂ᵀv_b of a row
    against a moving obstacle (0 otherwise); ``accel``: A of each column of v."""
    m = C.shape[0]
    l, l_brake, damper = np.empty(m), np.empty(m), np.empty(m)
    v0 = np.minimum(np.maximum(0.0, lb), ub)
    for k in range(m):
        dk, best, brake = _row_bounds(C[k], v_prev, v0, lb, ub, d[k], d_s[k], d_i, gain, latency, shift[k],
                                      accel, braking)
        damper[k] = dk
        # a relaxed row would pass through a vertex of the box exactly: 1e-9 m/s below it, so that
        # no solver's tolerance reads the degenerate (feasible) problem as infeasible
        l[k] = min(dk, best - RELAX_MARGIN)
        l_brake[k] = min(dk, brake - RELAX_MARGIN)
    return l, l_brake, damper


@jit
def _row_bounds(
    row: FloatArray, v_prev: FloatArray, v0: FloatArray, lb: FloatArray, ub: FloatArray,
    d: float, d_s: float, d_i: float, gain: float, latency: float, shift: float, accel: FloatArray,
    braking: float,
) -> tuple[float, float, float]:
    """(the damper's bound, the most separating rate in lb ≤ v ≤ ub, the braking command's rate).

    The damper's bound is the larger of the linear damper and the braking profile
    −√(2 β a_n (d' − d_s)), a_n = Σ_j |C_j| A_j the fastest the pair's approach can be slowed
    (every joint braking for it at its A)."""
    prev = best = brake = a_n = 0.0
    for i in range(row.shape[0]):
        c = row[i]
        prev += c * v_prev[i]
        brake += c * v0[i]
        best += c * ub[i] if c > 0.0 else c * lb[i]
        a_n += abs(c) * accel[i]
    d_eff = d - latency * max(0.0, shift - prev)  # the approach during the state's age (ḋ = prev − shift)
    linear = -gain * (d_eff - d_s) / (d_i - d_s)
    profile = -math.sqrt(2.0 * braking * a_n * max(d_eff - d_s, 0.0))
    return max(linear, profile) + shift, best, brake


@jit
def _distinct_rows(C: FloatArray, l: FloatArray, keys: IntArray) -> IntArray:
    """The rows to keep: of two rows of the same pair of links whose directions agree to within
    cos > PARALLEL (one link's several shapes against one obstacle), only the more restrictive."""
    m = C.shape[0]
    norms = np.empty(m)
    for k in range(m):
        norms[k] = math.sqrt(np.dot(C[k], C[k])) + 1e-300
    keep = np.empty(m, dtype=np.int64)
    n = 0
    for k in range(m):
        merged = False
        for i in range(n):
            j = keep[i]
            if keys[j] == keys[k] and np.dot(C[j], C[k]) > PARALLEL * norms[j] * norms[k]:
                if l[k] / norms[k] > l[j] / norms[j]:
                    keep[i] = k
                merged = True
                break
        if not merged:
            keep[n] = k
            n += 1
    return keep[:n]




def _normal(res: coal.DistanceResult) -> FloatArray:
    """n̂ from body b to body a: −coal's normal (which points from the first shape to the second),
    defined in penetration too."""
    n = -np.asarray(res.normal, dtype=float)
    nn = float(np.linalg.norm(n))
    return n / nn if nn > 1e-12 else np.array([0.0, 0.0, 1.0])
