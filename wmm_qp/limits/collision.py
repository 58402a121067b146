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
the rows together not be (two contacts pulling apart), the stage is solved again with the rows
relaxed together (:meth:`Rows.relax_together`): l ← min(damper, C v_r), v_r the command inside the
bounds that comes nearest to meeting every damper at once, which therefore admits v_r: no
collision row ever makes a stage infeasible. (Not to the braking command v₀ = clip(0, lb, ub): its
rate for a pair may be an approach, and a stage relaxed to it kept approaching at that rate tick
after tick — TIAGo's hand into its torso column on the circle, docs/model.md "priority".) The
influence distance must exceed the distance the robot needs to stop (docs/model.md gives the
numbers).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import coal
import numpy as np
import pinocchio as pin

from .._jit import jit
from .._typing import FloatArray
from ..config import CollisionParams, ShapeConfig
from ..model.collision import RobotGeometry, bounding_sphere, coal_shape, row_shape, shape_pose, transform
from ..scene import Fence, Scene
from ._distance import box_plane, swept_box, swept_plane, swept_swept

IntArray = np.ndarray

_LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
RELAX_MARGIN = 1e-9  # [m/s]
PARALLEL = 0.995  # two rows of one pair of links this parallel (cos) are one
JOINT_ITERATIONS = 300  # projected-gradient iterations of the rows' joint command (``Rows.relax_together``)
JOINT_WEIGHT = 1e-6  # its pull towards the braking command [-]: breaks ties, the shortfalls decide
JOINT_FLOOR_WEIGHT = 10.0  # its penalty on a row below what the braking command gives it [-]
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

    def relax_together(self, lb: FloatArray, ub: FloatArray, C_box: FloatArray | None = None,
                       l_box: FloatArray | None = None, u_box: FloatArray | None = None) -> FloatArray:
        """Relax the rows together (``l_brake``), when relaxed one by one (``l``) they exclude each
        other: each row to min(damper, C_k v_r), v_r a command of the box lb ≤ v ≤ ub that does
        for no row worse than the braking command v₀ = clip(0, lb, ub) or its damper, whichever
        asks less (the floor C_k v_r ≥ min(C_k v₀, damper_k)), and within that comes nearest to
        stopping every approach the braking command lets go on (the target max(floor_k,
        min(damper_k, 0)); least squares of the shortfalls, :func:`_joint_command`, then moved
        back towards v₀ as far as the floors and the EE box rows l_box ≤ C_box v ≤ u_box, which
        admit v₀, need). Every row and bound admits v_r, so the stage is feasible; no row admits
        more than it did relaxed to v₀ (before); where v₀ keeps a pair approaching, v_r slows
        that approach as far as the bounds allow with the others: relaxed to v₀, TIAGo's hand
        went on towards its torso column at the braking command's rate, 2–6 cm/s for 0.8 s, into
        contact (``wmm-qp experiment circle``, docs/model.md "priority"). Not more than stopping
        it: v_r asking each pair for its full damper separation moved a Panda deep in
        self-contact fast along rows of the bodies' capsules that its cylinders did not follow
        (``wmm-qp verify``, ``panda_link1_0/panda_hand_1`` 1.1 mm deeper in a tick).

        Returns:
            v_r (the stage's reference point: ``_hold_ee_box`` moves back towards it).
        """
        v0 = np.minimum(np.maximum(0.0, lb), ub)
        floor = np.minimum(self.C @ v0, self.damper)
        target = np.maximum(floor, np.minimum(self.damper, 0.0))  # no approach, where braking lets one go on
        v = np.empty(lb.shape[0])
        _joint_command(self.C, target, floor, lb, ub, v0, JOINT_ITERATIONS, v)
        lo, hi, C = floor, np.full(floor.shape[0], np.inf), self.C
        if C_box is not None and l_box is not None and u_box is not None and C_box.shape[0]:
            lo, hi, C = np.concatenate((lo, l_box)), np.concatenate((hi, u_box)), np.vstack((C, C_box))
        e0, e1 = C @ v0, C @ v
        t = 1.0  # the largest step from v₀ towards v that keeps every floor and EE box row
        for k in range(C.shape[0]):
            if e1[k] > hi[k] and e1[k] > e0[k]:
                t = min(t, max(0.0, (hi[k] - e0[k]) / (e1[k] - e0[k])))
            elif e1[k] < lo[k] and e1[k] < e0[k]:
                t = min(t, max(0.0, (lo[k] - e0[k]) / (e1[k] - e0[k])))
        v = v0 + t * (v - v0)
        self.l_brake = np.minimum(self.damper, self.C @ v) - RELAX_MARGIN
        return v


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
    checked_idx: IntArray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))  # their indices
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
    mask = exempt_mask(geometry, s.exempt)
    o = _Obstacle(s.name, shape, shape_pose(s), center, radius, plane, mask, np.flatnonzero(mask).astype(np.int64))
    if plane:
        o.normal_w, o.offset_w = np.asarray(s.normal, dtype=float), s.offset
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
        self._cand = self._candidates(0)
        self._no_fence, self._no_fence_d = np.zeros((0, self.n_w + self.n_a)), np.zeros(0)  # read only
        self._no_fence.setflags(write=False)
        self._no_fence_d.setflags(write=False)

    def _candidates(self, n_obstacles: int) -> tuple:
        """The candidate buffer (d, p_a, p_b, n̂, ok, body a, the other side, d_s): room for every
        monitored pair at once (self, floor, each obstacle against every body)."""
        n = self._pairs.shape[0] + self._floor_idx.shape[0] + n_obstacles * len(self.geo.bodies)
        return (np.empty(n), np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 3)), np.ones(n, dtype=np.bool_),
                np.empty(n, dtype=np.int64), np.empty(n, dtype=np.int64), np.empty(n))

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
        self._obs_joint = np.zeros(len(solid), dtype=np.int64)  # every obstacle placed by the one H
        self.obstacles = obs
        self._cand = self._candidates(len(obs))
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
        oMi = self._oMi
        for k, j in enumerate(self._joint_ids):  # the joints that carry bodies: their placements
            self._Hj[k] = oMi[j].homogeneous
        _place(self._Hj, self._body_joint, self._shapes, self._placed)
        pl = self._placed
        # every pair the broad phase lets through, in one buffer: (d, p_a, p_b, n̂, ok (False: coal
        # computes it), body a, the other side: a body ≥ 0, the floor -1, obstacle k -2 - k; its d_s)
        d, P, Q, N, ok, I, J, DS = self._cand
        n = 0
        if self._pairs.shape[0]:  # robot vs robot (base frame; the base's motion cancels)
            n = _self_pass(pl.kind, pl.a0, pl.a1, pl.r, pl.c, pl.R, pl.h, pl.centre, self._pairs, self._pair_r, d_i,
                           p.safety_distance, d, P, Q, N, ok, I, J, DS, n)
        if self._floor_idx.shape[0]:  # robot vs the floor z = floor_z (the same plane in the base frame)
            n = _plane_pass(pl.kind, pl.a0, pl.a1, pl.r, pl.c, pl.R, pl.h, pl.centre, self._radii, self._floor_idx,
                            True, self._floor_n, self._floor_o, d_i, -1, p.floor_margin, d, P, Q, N, ok, I, J, DS, n)
        Rb = tb = None
        if self.obstacles:  # robot vs obstacles, in the base frame at this base pose
            c, s_ = math.cos(q_base[2]), math.sin(q_base[2])
            Rb = np.array([[c, -s_, 0.0], [s_, c, 0.0], [0.0, 0.0, 1.0]])
            tb = np.array([q_base[0], q_base[1], 0.0])
            solid, world, placed, radii, checked, planes = self._obs
            if solid.shape[0]:
                H = self._H_world  # world → base frame
                H[0, :3, :3], H[0, :3, 3] = Rb.T, -(Rb.T @ tb)
                _place(H, self._obs_joint, world, placed)
                n = _solid_pass(pl.kind, pl.a0, pl.a1, pl.r, pl.c, pl.R, pl.h, pl.centre, self._radii,
                                placed.kind, placed.a0, placed.a1, placed.r, placed.c, placed.R, placed.h,
                                placed.centre, radii, checked, solid, d_i, p.safety_distance,
                                d, P, Q, N, ok, I, J, DS, n)
            for oi_ in planes:
                o = self.obstacles[oi_]
                o.place(Rb, tb)
                n = _plane_pass(pl.kind, pl.a0, pl.a1, pl.r, pl.c, pl.R, pl.h, pl.centre, self._radii, o.checked_idx,
                                False, o.normal_b, o.offset_b, d_i, -2 - oi_, p.safety_distance,
                                d, P, Q, N, ok, I, J, DS, n)
        if n and not ok[:n].all():
            self._coal_fill(n, Rb, tb)
        fC, fd, fnames = self._fence_rows(q_base, x_ee, J_ee, n_v)
        nf = len(fnames)
        out = Rows(np.zeros((0, n_v)), np.zeros(0))
        if not n and not nf:
            return out
        C, D, DS_, IA, IB, NN, keys, best_k = _assemble(
            d, P, Q, N, I, J, DS, n, d_i, MAX_ROWS, nf, n_v, np.asarray(self.geo.arm.data.J), self._support,
            self._body_joint_ids, self.M, self.n_w, self._body_link, self._n_links, len(self.obstacles))
        if best_k >= 0:
            out.min_distance, out.closest = float(d[best_k]), self._name(int(I[best_k]), int(J[best_k]))
        m = D.shape[0]
        if not m and not nf:
            return out
        if nf:
            C[m:] = fC
            dist, d_s = np.concatenate((D, fd)), np.concatenate((DS_, np.zeros(nf)))
        else:
            dist, d_s = D, DS_
        # a moving obstacle b: ḋ = n̂ᵀJ_a v − n̂ᵀv_b, so its rows ask n̂ᵀv_b more of the robot
        shift = np.zeros(dist.shape[0])
        if self._moving and m:
            assert Rb is not None
            for k in np.flatnonzero(IB <= -2).tolist():
                shift[k] = float(NN[k] @ (Rb.T @ self.obstacles[-2 - int(IB[k])].velocity_w))
        l, l_brake, damper = _all_bounds(C, v_prev, lb, ub, dist, d_s, d_i, p.gain, self.latency, shift,
                                         self._accel, p.braking)
        # two bodies of one pair of links: one row where they are parallel (the key: link a, and
        # link b, the floor or the obstacle; each fence row its own)
        keep = _distinct_rows(C, l, keys)
        if keep.shape[0] == C.shape[0]:  # nothing merged: keep is 0, 1, …
            out.C, out.l, out.l_brake, out.damper, out.distances = C, l, l_brake, damper, dist
        else:
            out.C, out.l, out.l_brake, out.damper = C[keep], l[keep], l_brake[keep], damper[keep]
            out.distances = dist[keep]
        out.names = [self._name(int(IA[k]), int(IB[k])) if k < m else fnames[k - m] for k in keep.tolist()]
        return out

    def _coal_fill(self, n: int, Rb: FloatArray | None, tb: FloatArray | None) -> None:
        """The candidates the compiled distances left to coal (box-box, meshes, a capsule whose
        segment is inside a box), computed by coal in place."""
        d, P, Q, N, ok, I, J, _ = self._cand
        bodies = self.geo.bodies
        for k in np.flatnonzero(~ok[:n]).tolist():
            i, j = int(I[k]), int(J[k])
            if j >= 0:
                got = self._coal(bodies[i].shape, self._T(i), bodies[j].shape, self._T(j))
            elif j == -1:
                got = self._coal(bodies[i].shape, self._T(i), self._floor, self._identity)
            else:
                assert Rb is not None and tb is not None
                o = self.obstacles[-2 - j]
                if o.plane:  # coal's half-space, built when a body needs it
                    o.shape = coal.Halfspace(-o.normal_b, -o.offset_b)  # coal: solid where n'·p ≤ d
                    got = self._coal(bodies[i].shape, self._T(i), o.shape, o.transform())
                else:
                    Mo = pin.SE3(Rb.T @ o.world.rotation, Rb.T @ (o.world.translation - tb))
                    got = self._coal(bodies[i].shape, self._T(i), o.shape, transform(Mo))
            d[k], P[k], Q[k], N[k] = got

    def _name(self, i: int, j: int) -> str:
        """A row's pair: "a/b" (bodies), "a/floor", "a/<obstacle id>" (j = -2 - its index)."""
        key = (i, j)
        name = self._names.get(key)
        if name is None:
            bodies = self.geo.bodies
            other = bodies[j].name if j >= 0 else "floor" if j == -1 else self.obstacles[-2 - j].name
            name = self._names[key] = f"{bodies[i].name}/{other}"
        return name

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
        if not _fence_near(A, c, float(q_base[0]), float(q_base[1]), self.n_w, f.ee_lower, f.ee_upper, x, d_i):
            return self._no_fence, self._no_fence_d, []  # the usual tick: one compiled call
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
def _pair_one(
    ka: IntArray, a0: FloatArray, a1: FloatArray, ra: FloatArray, ca: FloatArray, Ra: FloatArray, ha: FloatArray,
    i: int, kb: IntArray, b0: FloatArray, b1: FloatArray, rb: FloatArray, cb: FloatArray, Rb: FloatArray,
    hb: FloatArray, j: int, d: FloatArray, P: FloatArray, Q: FloatArray, N: FloatArray, ok: np.ndarray, k: int,
) -> None:
    """Entry k ← the distance of A[i] to B[j] (ok False where coal must compute it)."""
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


@jit
def _pairs_kernel(
    ka: IntArray, a0: FloatArray, a1: FloatArray, ra: FloatArray, ca: FloatArray, Ra: FloatArray, ha: FloatArray,
    kb: IntArray, b0: FloatArray, b1: FloatArray, rb: FloatArray, cb: FloatArray, Rb: FloatArray, hb: FloatArray,
    I: IntArray, J: IntArray, d: FloatArray, P: FloatArray, Q: FloatArray, N: FloatArray, ok: np.ndarray,
) -> None:
    for k in range(I.shape[0]):
        _pair_one(ka, a0, a1, ra, ca, Ra, ha, I[k], kb, b0, b1, rb, cb, Rb, hb, J[k], d, P, Q, N, ok, k)


def _pair_distances(A: Table, I: IntArray, J: IntArray, B: Table, buf: tuple) -> tuple:
    """Distances of A[I[k]] to B[J[k]] (ok False where coal must compute it: box-box, meshes)."""
    d, P, Q, N, ok = buf
    _pairs_kernel(A.kind, A.a0, A.a1, A.r, A.c, A.R, A.h, B.kind, B.a0, B.a1, B.r, B.c, B.R, B.h,
                  np.asarray(I, dtype=np.int64), np.asarray(J, dtype=np.int64), d, P, Q, N, ok)
    return d, P, Q, N, ok


@jit
def _plane_one(
    kind: IntArray, a0: FloatArray, a1: FloatArray, r: FloatArray, c: FloatArray, R: FloatArray, h: FloatArray,
    i: int, normal: FloatArray, offset: float, d: FloatArray, P: FloatArray, Q: FloatArray, N: FloatArray,
    ok: np.ndarray, k: int,
) -> None:
    """Entry k ← the distance of A[i] to the plane (ok False where coal must compute it)."""
    ok[k] = True
    if kind[i] == 0:
        d[k] = swept_plane(a0[i], a1[i], r[i], normal, offset, P[k], Q[k], N[k])
    elif kind[i] == 1:
        d[k] = box_plane(c[i], R[i], h[i], normal, offset, P[k], Q[k], N[k])
    else:
        ok[k] = False


@jit
def _point_rows(
    Jw: FloatArray, support: FloatArray, bj: IntArray, IA: IntArray, IB: IntArray, pa: FloatArray, pb: FloatArray,
    n: FloatArray, M: FloatArray, n_w: int, C: FloatArray,
) -> None:
    """C[k] ← n̂ᵀ(J_{p_a} − J_{p_b}) of each pair (body IA[k], and body IB[k] ≥ 0 or the world),
    from the joints' world-frame (here: base-frame) Jacobian Jw (6 × nv, Pinocchio's data.J: a
    point p of joint j moves at J_v + J_ω × p over the columns the joint moves with; ``bj``: each
    body's joint); for pairs with the world, the base's motion of p_a on the wheels (eq. (5))."""
    for k in range(IA.shape[0]):
        nk = n[k]
        for side in range(2):
            j = bj[IA[k]] if side == 0 else bj[IB[k]] if IB[k] >= 0 else 0
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
        if IB[k] < 0:
            p = pa[k]
            a2 = -nk[0] * p[1] + nk[1] * p[0]
            for j in range(n_w):
                C[k, j] += nk[0] * M[0, j] + nk[1] * M[1, j] + a2 * M[2, j]


@jit
def _self_pass(
    kind: IntArray, a0: FloatArray, a1: FloatArray, r: FloatArray, c: FloatArray, R: FloatArray, h: FloatArray,
    centre: FloatArray, pairs: IntArray, pair_r: FloatArray, d_i: float, d_s: float,
    d: FloatArray, P: FloatArray, Q: FloatArray, N: FloatArray, ok: np.ndarray, I: IntArray, J: IntArray,
    DS: FloatArray, n: int,
) -> int:
    """The robot's own pairs whose bounding spheres are within d_i (the broad phase), their
    distances appended to the candidates from entry n; returns the new count."""
    for k in range(pairs.shape[0]):
        i, j = pairs[k, 0], pairs[k, 1]
        x, y, z = centre[i, 0] - centre[j, 0], centre[i, 1] - centre[j, 1], centre[i, 2] - centre[j, 2]
        if not math.sqrt(x * x + y * y + z * z) - pair_r[k] <= d_i:
            continue
        _pair_one(kind, a0, a1, r, c, R, h, i, kind, a0, a1, r, c, R, h, j, d, P, Q, N, ok, n)
        I[n], J[n], DS[n] = i, j, d_s
        n += 1
    return n


@jit
def _plane_pass(
    kind: IntArray, a0: FloatArray, a1: FloatArray, r: FloatArray, c: FloatArray, R: FloatArray, h: FloatArray,
    centre: FloatArray, radii: FloatArray, idx: IntArray, cull: bool, normal: FloatArray, offset: float,
    d_i: float, code: int, d_s: float,
    d: FloatArray, P: FloatArray, Q: FloatArray, N: FloatArray, ok: np.ndarray, I: IntArray, J: IntArray,
    DS: FloatArray, n: int,
) -> int:
    """The bodies ``idx`` against the plane normal·x = offset (free side ≤), appended from entry n
    (the other side coded ``code``); with ``cull`` only those whose bounding sphere is within d_i."""
    for t in range(idx.shape[0]):
        i = idx[t]
        if cull:
            gap = offset - (normal[0] * centre[i, 0] + normal[1] * centre[i, 1] + normal[2] * centre[i, 2]) - radii[i]
            if not gap <= d_i:
                continue
        _plane_one(kind, a0, a1, r, c, R, h, i, normal, offset, d, P, Q, N, ok, n)
        I[n], J[n], DS[n] = i, code, d_s
        n += 1
    return n


@jit
def _solid_pass(
    kind: IntArray, a0: FloatArray, a1: FloatArray, r: FloatArray, c: FloatArray, R: FloatArray, h: FloatArray,
    centre: FloatArray, radii: FloatArray,
    okind: IntArray, o0: FloatArray, o1: FloatArray, orad: FloatArray, oc: FloatArray, oR: FloatArray,
    oh: FloatArray, ocentre: FloatArray, oradii: FloatArray, checked: np.ndarray, solid: IntArray,
    d_i: float, d_s: float,
    d: FloatArray, P: FloatArray, Q: FloatArray, N: FloatArray, ok: np.ndarray, I: IntArray, J: IntArray,
    DS: FloatArray, n: int,
) -> int:
    """Every checked body against every solid obstacle (placed in the base frame) within d_i: the
    broad phase on the bodies' bounding spheres (against a box: the sphere's distance to the box
    itself), appended from entry n (the other side coded −2 − the obstacle's index)."""
    for o in range(okind.shape[0]):
        for b in range(kind.shape[0]):
            if not checked[o, b]:
                continue
            if okind[o] == 1:  # in the box's frame: the sphere's centre outside each slab
                s2 = 0.0
                for a in range(3):
                    rel = (oR[o, 0, a] * (centre[b, 0] - oc[o, 0]) + oR[o, 1, a] * (centre[b, 1] - oc[o, 1])
                           + oR[o, 2, a] * (centre[b, 2] - oc[o, 2]))
                    e = max(abs(rel) - oh[o, a], 0.0)
                    s2 += e * e
                gap = math.sqrt(s2) - radii[b]
            else:
                x, y, z = centre[b, 0] - ocentre[o, 0], centre[b, 1] - ocentre[o, 1], centre[b, 2] - ocentre[o, 2]
                gap = math.sqrt(x * x + y * y + z * z) - radii[b] - oradii[o]
            if not gap <= d_i:
                continue
            _pair_one(kind, a0, a1, r, c, R, h, b, okind, o0, o1, orad, oc, oR, oh, o, d, P, Q, N, ok, n)
            I[n], J[n], DS[n] = b, -2 - solid[o], d_s
            n += 1
    return n


@jit
def _assemble(
    d: FloatArray, P: FloatArray, Q: FloatArray, N: FloatArray, I: IntArray, J: IntArray, DS: FloatArray, n: int,
    d_i: float, max_rows: int, n_fence: int, n_v: int, Jw: FloatArray, support: FloatArray, bj: IntArray,
    M: FloatArray, n_w: int, body_link: IntArray, n_links: int, n_obstacles: int,
) -> tuple[FloatArray, FloatArray, FloatArray, IntArray, IntArray, FloatArray, IntArray, int]:
    """Of the n candidates: the closest (its index, −1 if none), and the rows of those within d_i,
    the nearest to their safety distance first, at most ``max_rows`` of them but every one inside
    its safety distance (MAX_ROWS): (C with n_fence zero rows below, D, DS, IA, IB, n̂, the rows'
    keys for :func:`_distinct_rows` (link a and the other side's link, the floor or the
    obstacle; −1 − t for fence row t), the closest's index)."""
    best_k, best = -1, math.inf
    for k in range(n):
        if d[k] < best:
            best, best_k = d[k], k
    near = np.empty(n, dtype=np.int64)
    m = 0
    for k in range(n):
        if d[k] < d_i:
            near[m] = k
            m += 1
    margin = np.empty(m)
    inside = 0
    for t in range(m):
        margin[t] = d[near[t]] - DS[near[t]]
        if margin[t] < 0.0:
            inside += 1
    order = np.argsort(margin, kind="mergesort")[: max(max_rows, inside)]
    m = order.shape[0]
    sel = near[order]
    D, DSo, NN, PA, PB = np.empty(m), np.empty(m), np.empty((m, 3)), np.empty((m, 3)), np.empty((m, 3))
    IA, IB = np.empty(m, dtype=np.int64), np.empty(m, dtype=np.int64)
    keys = np.empty(m + n_fence, dtype=np.int64)
    for t in range(m):
        k = sel[t]
        D[t], DSo[t], IA[t], IB[t] = d[k], DS[k], I[k], J[k]
        for a in range(3):
            NN[t, a], PA[t, a], PB[t, a] = N[k, a], P[k, a], Q[k, a]
        other = body_link[IB[t]] if IB[t] >= 0 else n_links - 1 - IB[t]
        keys[t] = body_link[IA[t]] * (n_links + 2 + n_obstacles) + other
    for t in range(n_fence):
        keys[m + t] = -1 - t
    C = np.zeros((m + n_fence, n_v))
    _point_rows(Jw, support, bj, IA, IB, PA, PB, NN, M, n_w, C)
    return C, D, DSo, IA, IB, NN, keys, best_k


@jit
def _fence_near(A: FloatArray, c: FloatArray, qx: float, qy: float, n_w: int, lower: FloatArray,
                upper: FloatArray, x: FloatArray, d_i: float) -> bool:
    """Whether the base's origin is within d_i of a fence edge or the EE within d_i of its box."""
    if n_w:
        for k in range(A.shape[0]):
            if c[k] - (A[k, 0] * qx + A[k, 1] * qy) < d_i:
                return True
    for a in range(3):  # noqa: SIM110 (a loop numba compiles)
        if upper[a] - x[a] < d_i or x[a] - lower[a] < d_i:
            return True
    return False


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
def _joint_command(C: FloatArray, target: FloatArray, floor: FloatArray, lb: FloatArray, ub: FloatArray,
                   v0: FloatArray, iterations: int, out: FloatArray) -> None:
    """out ← the v of lb ≤ v ≤ ub minimising Σ_k max(0, target_k − C_k v)² + w Σ_k max(0,
    floor_k − C_k v)² + μ‖v − v₀‖² (w = ``JOINT_FLOOR_WEIGHT``, μ = ``JOINT_WEIGHT``): the command
    nearest to meeting every row at once while keeping each above its floor, by accelerated
    projected gradient (FISTA) from v₀. Convex; its step 1/L with L = 2((1 + w)‖C‖_F² + μ) (an
    upper bound of the gradient's Lipschitz constant) converges without line search. Not exact,
    and need not be: the caller steps back towards v₀ until every floor holds, and relaxes the
    rows to what that command achieves, so every row admits it."""
    m, n = C.shape
    fro = 0.0  # ‖CᵀC‖₂ ≤ ‖C‖_F²
    for k in range(m):
        for i in range(n):
            fro += C[k, i] * C[k, i]
    lip = 2.0 * ((1.0 + JOINT_FLOOR_WEIGHT) * fro + JOINT_WEIGHT)
    x = v0.copy()
    y = v0.copy()
    grad = np.empty(n)
    t = 1.0
    for _ in range(iterations):
        for i in range(n):
            grad[i] = 2.0 * JOINT_WEIGHT * (y[i] - v0[i])
        for k in range(m):
            e = 0.0
            for i in range(n):
                e += C[k, i] * y[i]
            pull = max(0.0, target[k] - e) + JOINT_FLOOR_WEIGHT * max(0.0, floor[k] - e)
            if pull > 0.0:
                for i in range(n):
                    grad[i] -= 2.0 * pull * C[k, i]
        t_next = 0.5 * (1.0 + math.sqrt(1.0 + 4.0 * t * t))
        moved = 0.0
        for i in range(n):
            xi = min(max(y[i] - grad[i] / lip, lb[i]), ub[i])
            y[i] = xi + (t - 1.0) / t_next * (xi - x[i])
            moved = max(moved, abs(xi - x[i]))
            x[i] = xi
        t = t_next
        if moved < 1e-12:
            break
    for i in range(n):
        out[i] = x[i]


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
