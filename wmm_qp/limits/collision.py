"""The collision dampers as hard QP rows: self, floor and obstacle pairs (docs/model.md "Collisions").

For a monitored pair (a, b) at distance d with closest points p_a, p_b and n̂ = (p_a − p_b)/d,
ḋ = n̂ᵀ(J_{p_a} − J_{p_b}) v: the row C of the pair, bounded by the velocity damper while d < d_i
(:mod:`.dampers`, the safety rule). Point Jacobians: a point p on joint j moves at v_j + ω_j ×
(p − o_j), so n̂ᵀJ_p = n̂ᵀJ_v + ((p − o_j) × n̂)ᵀJ_ω (the joint's Jacobian in the base frame); for a
pair with the world (floor, obstacles) the base's motion adds n̂ᵀ[[1, 0, −p_y], [0, 1, p_x], [0, 0,
0]]·M on the wheels (eq. (5)'s J_b for the point p, eq. (3)'s M); between two bodies of the robot
it cancels. The pairs near enough to need a row come from :mod:`.pair_search`. A pair whose row
shapes are inside d_s gets one more row, on its bodies, linearised at the configuration full braking
reaches (:mod:`.inside_pairs`); it is never merged.

At most ``MAX_ROWS`` body pairs per tick, and of one pair of links' rows only those that are not
parallel (cos > ``PARALLEL``; the more restrictive is kept): nearly parallel rows of one link's
several shapes would only slow the solvers. Keeping only the closest pair of bodies of two links
is not enough: another body of the same links may go deeper.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np

from .._jit import jit, jit_inline
from .._typing import BoolArray, FloatArray, IntArray
from ..config import CollisionParams, ShapeConfig
from ..model.collision import RobotGeometry
from ..scene import obstacles_from_tables
from ._pair_passes import candidates_of, robot_passes
from .dampers import DamperRows, damper_bounds, damper_bounds_into
from .inside_pairs import InsidePairs
from .pair_search import Obstacle, PairNames, PairSearch
from .rows import Rows, Tick

_NO_VELOCITIES = np.zeros((0, 3))  # no obstacle moves (``CollisionRows._obstacle_velocities``)
PARALLEL = 0.995  # two rows of one pair of links this parallel (cos) are one
MAX_ROWS = 48
"""At most this many body pairs per tick, the nearest to their safety distance first (further pairs
are left out only while MAX_ROWS nearer ones are within the influence distance), but never one
inside its safety distance, however many are. Of those, two rows of one pair of links that are
parallel (cos > ``PARALLEL``) become one, the more restrictive."""


class CollisionRows(DamperRows):
    """The damper rows of the robot's monitored pairs each tick (see the module docstring).

    Args:
        geometry: the robot's bodies and pairs.
        M: the base's 3 × n_wheels matrix (eq. (3)).
        params: d_i, d_s, the floor margin, ξ, β; the robot file's own influence distance
            replaces d_i where it is larger (``params`` then holds it).
        latency: [s] τ, the state's age the rows account for (the controller's ``state_latency``).
        accel: A of each column of v = [wheels, arm] (the controller's bounds (13)): the braking
            profile's deceleration.
        dt: [s] Δt, the control period (the rows of the pairs inside d_s: :mod:`.inside_pairs`).
    """

    def __init__(self, geometry: RobotGeometry, M: FloatArray, params: CollisionParams, latency: float,
                 accel: FloatArray, dt: float) -> None:
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
        self.search = PairSearch(geometry, params)
        self.inside = InsidePairs(geometry, self.M, dt)
        bodies = geometry.bodies
        # the joints' Jacobians (Pinocchio's data.J), fetched once: the array shares the arm data's
        # memory, so it holds the values of the last computeJointJacobians (~1.5 µs a tick saved)
        self._Jw = np.asarray(geometry.arm.data.J)
        model = geometry.arm.model  # support[j, k]: joint j moves with the velocity column k
        self._support = np.zeros((model.njoints, model.nv))
        for j in range(1, model.njoints):
            a = j
            while a > 0:
                jm = model.joints[a]
                self._support[j, jm.idx_v : jm.idx_v + jm.nv] = 1.0
                a = model.parents[a]
        self._body_joint = np.array([b.joint for b in bodies], dtype=np.int64)
        links = sorted({b.link for b in bodies})
        self._body_link = np.array([links.index(b.link) for b in bodies], dtype=np.int64)
        self._n_links = len(links)
        self._bind()

    def _bind(self) -> None:
        """:func:`_rows`'s arguments that change only with the obstacle set, in one tuple (after the
        search's arenas, ``_statics`` after ``robot_args``: :func:`_robot_rows`), for the search's
        arguments of now (``_bound_to``): ~1 µs of Python a tick saved."""
        p = self.p
        self._bound_to = self.search.robot_args
        W, Wi = _scratch(self.search.candidates.d.shape[0], self.n_w + self.n_a)  # _rows' work, every tick
        self._statics: tuple[Any, ...] = (p.influence_distance, MAX_ROWS, self.n_w + self.n_a, self._Jw, self._support,
                                          self._body_joint, self.M, self.n_w, self._body_link, self._n_links,
                                          len(self.search.obstacles), p.gain, self._accel, p.braking, W, Wi)

    @property
    def obstacles(self) -> list[Obstacle]:
        """The obstacles in force."""
        return self.search.obstacles

    @property
    def shapes(self) -> tuple[ShapeConfig, ...]:
        """The obstacles in force, as given to :meth:`set_obstacles`."""
        return self.search.shapes

    def set_obstacles(self, obstacles: tuple[ShapeConfig, ...] | list[ShapeConfig]) -> None:
        """Replace the obstacle set (atomically: the next tick sees the new set only)."""
        self.search.set_obstacles(obstacles)

    def compute_rows(self, tick: Tick) -> Rows:
        """The pairs' rows at the tick's state (its kinematics ran just before: the arm's forward
        kinematics and joint Jacobians are current)."""
        return self.rows(tick.kin.q_base, tick.kin.q_arm, tick.v_prev, tick.lb, tick.ub)

    def rows(self, q_base: FloatArray, q_arm: FloatArray, v_prev: FloatArray, lb: FloatArray,
             ub: FloatArray) -> Rows:
        """The monitored pairs' rows at the state the arm's data was last computed at.

        Args:
            q_base: [m, m, rad] base pose; q_arm: [rad] the arm's joints (the arm's data's).
            v_prev: the bounds' centre (the last command), for the latency term.
            lb, ub: the stage's box bounds on v (for the relaxations).
        """
        n_v, search = self.n_w + self.n_a, self.search
        if search.robot_args is not self._bound_to:  # a new obstacle set: new arenas
            self._bind()
        # the rows, their bounds and which of them to keep, in one compiled call (_rows), packed
        # into one float and one int array (each array a compiled call returns is allocated and boxed)
        if not search.obstacles:  # the usual scene: the search and the rows in one compiled call
            search.place_joints()
            args = (*search.robot_args, *self._statics, v_prev, lb, ub, self.latency)
            n, left, F, I, m, closest, n_inside = _robot_rows(*args)
            if left:  # coal's distances, then the rows (below)
                found = search.after_robot(q_base, n, left)
            else:
                found = search.candidates
                found.n = n
        else:
            found, m = search.search(q_base), -1
        if m < 0:  # obstacles, or candidates coal computed: the rows now
            args = (*search.arenas, *self._statics, found.n, self._obstacle_velocities(), v_prev, lb, ub, self.latency)
            F, I, m, closest, n_inside = _rows(*args)
        min_distance, nearest, namer = math.inf, "", self.search.namer()
        if closest >= 0:
            min_distance = found.d.item(closest)
            nearest = namer(found.body.item(closest), found.other.item(closest))
        if not m:
            return Rows(np.zeros((0, n_v)), np.zeros(0), min_distance=min_distance, closest=nearest)
        e = m * n_v
        out = Rows(F[:e].reshape(m, n_v), F[e : e + m], F[e + m : e + 2 * m], F[e + 2 * m : e + 3 * m],
                   PairNames(namer, I[:m], I[m : 2 * m]), F[e + 3 * m : e + 4 * m], min_distance, nearest)
        if n_inside:  # the pairs inside d_s (every one has a row, before the merge: _assemble)
            self._add_inside(out, I[2 * m : 2 * m + n_inside], I[2 * m + n_inside :], F[e + 4 * m :], q_base, q_arm,
                             v_prev, lb, ub)
        return out

    def _obstacle_velocities(self) -> FloatArray:
        """[m/s] (n_obstacles, 3) each obstacle's velocity in the base frame of the last search,
        Rbᵀ v_b; (0, 3) while none moves."""
        if not self.search.moving:
            return _NO_VELOCITIES
        Rb = self.search.base_rotation
        return np.array([Rb.T @ o.velocity_w for o in self.search.obstacles], dtype=float).reshape(-1, 3)

    def _obstacle_shift(self, normal: FloatArray, other: IntArray) -> FloatArray:
        """[m/s] n̂ᵀv_b of each row against a moving obstacle b (0 otherwise): ḋ = n̂ᵀJ_a v − n̂ᵀv_b,
        so its rows ask n̂ᵀv_b more of the robot."""
        shift = np.zeros(other.shape[0])
        if self.search.moving:
            Rb = self.search.base_rotation
            for k in np.flatnonzero(other <= -2).tolist():
                shift[k] = float(normal[k] @ (Rb.T @ self.search.obstacles[-2 - int(other[k])].velocity_w))
        return shift

    def _add_inside(self, out: Rows, body: IntArray, other: IntArray, safety: FloatArray, q_base: FloatArray,
                    q_arm: FloatArray, v_prev: FloatArray, lb: FloatArray, ub: FloatArray) -> None:
        """Append to ``out`` the rows of the pairs inside d_s on their bodies at the braking
        configuration (:mod:`.inside_pairs`): C_b v ≥ damper(d) + (d − d̃)/Δt, relaxed as every
        damper (to C_b v₀ at worst: the distance after the tick no less than braking's)."""
        p, m = self.p, body.shape[0]
        v0 = np.minimum(np.maximum(0.0, lb), ub)
        d, d_b, P, Q, N, Jw = self.inside.braking_end(body, other, q_base, q_arm, v0, self.search.obstacles)
        C = np.zeros((m, self.n_w + self.n_a))
        _point_rows(Jw, self._support, self._body_joint, body, other, P, Q, N, self.M, self.n_w, C)
        offset = (d - (d_b - self.inside.dt * (C @ v0))) / self.inside.dt  # (d − d̃)/Δt
        l, l_brake, damper = damper_bounds(C, v_prev, lb, ub, d, safety, p.influence_distance, p.gain,
                                           self.latency, self._obstacle_shift(N, other), self._accel, p.braking,
                                           offset)
        out.C, out.l = np.vstack((out.C, C)), np.concatenate((out.l, l))
        out.l_brake, out.damper = np.concatenate((out.l_brake, l_brake)), np.concatenate((out.damper, damper))
        out.distances = np.concatenate((out.distances, d))
        namer = self.search.namer()
        names = out.names if isinstance(out.names, PairNames) else PairNames(namer, body[:0], other[:0])
        out.names = names + PairNames(namer, body, other)


def warm_up_obstacles(x: FloatArray) -> tuple[ShapeConfig, ...]:
    """One obstacle of every kind around the point x [m] (world), each ~0.1 m from it, the sphere
    moving, the box exempting the EE: ticked once, every compiled kernel of the rows is loaded
    (or compiled) before a real-time loop starts, not at the first obstacle that comes near."""
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
def _assemble(
    d: FloatArray, P: FloatArray, Q: FloatArray, N: FloatArray, body: IntArray, other: IntArray, safety: FloatArray,
    n: int, d_i: float, max_rows: int, n_v: int, Jw: FloatArray, support: FloatArray, bj: IntArray,
    M: FloatArray, n_w: int, body_link: IntArray, n_links: int, n_obstacles: int,
) -> tuple[FloatArray, FloatArray, FloatArray, IntArray, IntArray, FloatArray, IntArray, int, int]:
    """Of the n candidates: the closest (its index, −1 if none), and the rows of those within d_i,
    the nearest to their safety distance first, at most ``max_rows`` of them but every one inside
    its safety distance (MAX_ROWS): (C, D, DS, IA, IB, n̂, the rows' keys for :func:`_distinct_rows`
    (link a and the other side's link, the floor or the obstacle), the closest's index, how many
    rows are inside their safety distance); the candidates as :mod:`._pair_passes` gives them (d,
    P, Q, N, body, other, safety). (:func:`_assemble_into` in arrays of its own.)"""
    W, Wi = _scratch(n, n_v)
    return _assemble_into(d, P, Q, N, body, other, safety, n, d_i, max_rows, n_v, Jw, support, bj, M, n_w, body_link,
                          n_links, n_obstacles, W, Wi)


@jit
def _scratch(n: int, n_v: int) -> tuple[FloatArray, IntArray]:
    """Room for :func:`_rows`'s work on n candidates of n_v columns (float, int)."""
    return np.empty(n * (SCRATCH_FLOATS + n_v) + n_v), np.empty(SCRATCH_INTS * n, dtype=np.int64)


SCRATCH_FLOATS = 18
"""Floats a candidate takes in :func:`_rows`'s scratch, besides its row of C (see :func:`_rows`)."""
SCRATCH_INTS = 6
"""Ints a candidate takes there."""


@jit_inline
def _assemble_into(
    d: FloatArray, P: FloatArray, Q: FloatArray, N: FloatArray, body: IntArray, other: IntArray, safety: FloatArray,
    n: int, d_i: float, max_rows: int, n_v: int, Jw: FloatArray, support: FloatArray, bj: IntArray,
    M: FloatArray, n_w: int, body_link: IntArray, n_links: int, n_obstacles: int, W: FloatArray, Wi: IntArray,
) -> tuple[FloatArray, FloatArray, FloatArray, IntArray, IntArray, FloatArray, IntArray, int, int]:
    """:func:`_assemble`, its arrays views of the scratch W, Wi (:func:`_scratch`; W's start and
    Wi's first 5 n: the rest is :func:`_rows`'s)."""
    best_k, best = -1, math.inf
    for k in range(n):
        if d[k] < best:
            best, best_k = d[k], k
    near = Wi[:n]
    m = 0
    for k in range(n):
        if d[k] < d_i:
            near[m] = k
            m += 1
    margin = W[:m]
    inside = 0
    for t in range(m):
        margin[t] = d[near[t]] - safety[near[t]]
        if margin[t] < 0.0:
            inside += 1
    order = np.argsort(margin, kind="mergesort")[: max(max_rows, inside)]
    m = order.shape[0]
    sel = Wi[n : n + m]
    for t in range(m):
        sel[t] = near[order[t]]
    o = n
    D, DSo = W[o : o + m], W[o + n : o + n + m]
    NN = W[o + 2 * n : o + 2 * n + 3 * m].reshape((m, 3))
    PA = W[o + 5 * n : o + 5 * n + 3 * m].reshape((m, 3))
    PB = W[o + 8 * n : o + 8 * n + 3 * m].reshape((m, 3))
    IA, IB, keys = Wi[2 * n : 2 * n + m], Wi[3 * n : 3 * n + m], Wi[4 * n : 4 * n + m]
    for t in range(m):
        k = sel[t]
        D[t], DSo[t], IA[t], IB[t] = d[k], safety[k], body[k], other[k]
        for a in range(3):
            NN[t, a], PA[t, a], PB[t, a] = N[k, a], P[k, a], Q[k, a]
        side = body_link[IB[t]] if IB[t] >= 0 else n_links - 1 - IB[t]  # link b, the floor or the obstacle
        keys[t] = body_link[IA[t]] * (n_links + 2 + n_obstacles) + side
    C = W[12 * n : 12 * n + m * n_v].reshape((m, n_v))
    C[:] = 0.0
    _point_rows(Jw, support, bj, IA, IB, PA, PB, NN, M, n_w, C)
    return C, D, DSo, IA, IB, NN, keys, best_k, inside


@jit
def _robot_rows(
    oMi: FloatArray, F: FloatArray, Lf: IntArray, I: IntArray, Li: IntArray, ok: BoolArray, reach: float,
    d_s: float, floor_o: float, floor_margin: float, cover_within: float,
    d_i: float, max_rows: int, n_v: int, Jw: FloatArray, support: FloatArray, bj: IntArray,
    M: FloatArray, n_w: int, body_link: IntArray, n_links: int, n_obstacles: int, gain: float, accel: FloatArray,
    braking: float, W: FloatArray, Wi: IntArray, v_prev: FloatArray, lb: FloatArray, ub: FloatArray, latency: float,
) -> tuple[int, int, FloatArray, IntArray, int, int, int]:
    """The usual tick's search and rows in one compiled call, where there are no obstacles:
    :func:`~._pair_passes.robot_passes` (its arguments first, ``reach`` its d_i), then :func:`_rows`
    on its candidates. Returns (n, left, then :func:`_rows`'s five), or m = −1 and no rows where
    the compiled distances left ``left`` candidates to coal (the rows wait for them)."""
    n, left = robot_passes(oMi, F, Lf, I, Li, ok, reach, d_s, floor_o, floor_margin, cover_within)
    if left:
        return n, left, np.zeros(0), np.zeros(0, dtype=np.int64), -1, -1, 0
    Fr, Ir, m, closest, inside = _rows(F, Lf, I, Li, d_i, max_rows, n_v, Jw, support, bj, M, n_w, body_link, n_links,
                                       n_obstacles, gain, accel, braking, W, Wi, n, np.zeros((0, 3)), v_prev, lb, ub,
                                       latency)
    return n, left, Fr, Ir, m, closest, inside


@jit
def _rows(
    F: FloatArray, Lf: IntArray, I: IntArray, Li: IntArray,
    d_i: float, max_rows: int, n_v: int, Jw: FloatArray, support: FloatArray, bj: IntArray,
    M: FloatArray, n_w: int, body_link: IntArray, n_links: int, n_obstacles: int, gain: float, accel: FloatArray,
    braking: float, W: FloatArray, Wi: IntArray, n: int, velocity_b: FloatArray, v_prev: FloatArray, lb: FloatArray,
    ub: FloatArray, latency: float,
) -> tuple[FloatArray, IntArray, int, int, int]:
    """A tick's collision rows from the n candidates (in the search's arenas F, I:
    :func:`~._pair_passes.candidates_of`), in one call: :func:`_assemble`'s rows, each
    one's approach of a moving obstacle n̂ᵀv_b (``velocity_b``: each obstacle's, base frame; empty:
    none moves), their bounds (:func:`~.dampers.damper_bounds`), and of each pair of links only the
    rows to keep (:func:`_distinct_rows`); the arguments that change only with the obstacle set
    first, then this tick's (from ``n``). W, Wi: room for the work (:func:`_scratch` for every
    candidate: of its arrays only the two returned and the sort's are allocated a tick). Returns
    (F, I, m, the closest candidate's index, s), the m kept rows and the s rows inside their
    safety distance (before the merge) packed in
    one float array F = [C (m × n_v, row by row), l, l_brake, damper, D (m each), DS of the s]
    and one int array I = [IA, IB (m each), IA, IB of the s]."""
    d, P, Q, N, body, other, safety = candidates_of(F, Lf, I, Li)
    nc = d.shape[0]  # the scratch's room: every candidate (W: margin, D, DS, n̂, p_a, p_b (3 each), C,
    # then shift, l, l_brake, damper, offset, norms, v0; Wi: near, sel, IA, IB, keys, keep)
    C, D, DS, IA, IB, NN, keys, closest, inside = _assemble_into(d, P, Q, N, body, other, safety, n, d_i, max_rows,
                                                                 n_v, Jw, support, bj, M, n_w, body_link, n_links,
                                                                 n_obstacles, W, Wi)
    m = D.shape[0]
    o = (12 + n_v) * nc
    shift, l, l_brake = W[o : o + m], W[o + nc : o + nc + m], W[o + 2 * nc : o + 2 * nc + m]
    o += 3 * nc
    damper, offset, norms = W[o : o + m], W[o + nc : o + nc + m], W[o + 2 * nc : o + 2 * nc + m]
    o += 3 * nc
    shift[:] = 0.0
    offset[:] = 0.0
    if velocity_b.shape[0]:
        for k in range(m):
            if IB[k] <= -2:
                v = velocity_b[-2 - IB[k]]
                shift[k] = NN[k, 0] * v[0] + NN[k, 1] * v[1] + NN[k, 2] * v[2]
    damper_bounds_into(C, v_prev, lb, ub, D, DS, d_i, gain, latency, shift, accel, braking, offset, W[o : o + n_v],
                       l, l_brake, damper)
    # two bodies of one pair of links: one row where they are parallel (the key: link a, and
    # link b, the floor or the obstacle)
    keep = Wi[5 * nc : 5 * nc + m]
    mk = _distinct_rows_into(C, l, keys, norms, keep)
    e = mk * n_v
    Fo = np.empty(e + 4 * mk + inside)
    Io = np.empty(2 * mk + 2 * inside, dtype=np.int64)
    for t in range(mk):
        k = keep[t]
        for c in range(n_v):
            Fo[t * n_v + c] = C[k, c]
        Fo[e + t], Fo[e + mk + t], Fo[e + 2 * mk + t], Fo[e + 3 * mk + t] = l[k], l_brake[k], damper[k], D[k]
        Io[t], Io[mk + t] = IA[k], IB[k]
    s = 0
    for k in range(m):
        if D[k] < DS[k]:
            Fo[e + 4 * mk + s], Io[2 * mk + s], Io[2 * mk + inside + s] = DS[k], IA[k], IB[k]
            s += 1
    return Fo, Io, mk, closest, inside


@jit_inline
def _point_rows(
    Jw: FloatArray, support: FloatArray, bj: IntArray, IA: IntArray, IB: IntArray, pa: FloatArray, pb: FloatArray,
    n: FloatArray, M: FloatArray, n_w: int, C: FloatArray,
) -> None:
    """C[k] ← n̂ᵀ(J_{p_a} − J_{p_b}) of each pair (body IA[k], and body IB[k] ≥ 0 or the world),
    from the joints' world-frame (here: base-frame) Jacobian Jw (6 × nv, Pinocchio's data.J: a
    point p of joint j moves at J_v + J_ω × p over the columns the joint moves with; ``bj``: each
    body's joint); for pairs with the world, the base's motion of p_a on the wheels (eq. (5))."""
    for k in range(IA.shape[0]):  # (by index: a view of a row costs a reference count)
        n0, n1, n2 = n[k, 0], n[k, 1], n[k, 2]
        for side in range(2):
            j = bj[IA[k]] if side == 0 else bj[IB[k]] if IB[k] >= 0 else 0
            if j == 0:
                continue
            if side == 0:
                p0, p1, p2 = pa[k, 0], pa[k, 1], pa[k, 2]
            else:
                p0, p1, p2 = pb[k, 0], pb[k, 1], pb[k, 2]
            sign = 1.0 if side == 0 else -1.0
            c0 = p1 * n2 - p2 * n1  # p × n̂
            c1 = p2 * n0 - p0 * n2
            c2 = p0 * n1 - p1 * n0
            for i in range(Jw.shape[1]):
                if support[j, i] != 0.0:
                    C[k, n_w + i] += sign * (
                        n0 * Jw[0, i] + n1 * Jw[1, i] + n2 * Jw[2, i]
                        + c0 * Jw[3, i] + c1 * Jw[4, i] + c2 * Jw[5, i]
                    )
        if IB[k] < 0:
            a2 = -n0 * pa[k, 1] + n1 * pa[k, 0]
            for j in range(n_w):
                C[k, j] += n0 * M[0, j] + n1 * M[1, j] + a2 * M[2, j]


@jit
def _distinct_rows(C: FloatArray, l: FloatArray, keys: IntArray) -> IntArray:
    """The rows to keep: of two rows of the same pair of links whose directions agree to within
    cos > PARALLEL (one link's several shapes against one obstacle), only the more restrictive."""
    keep = np.empty(C.shape[0], dtype=np.int64)
    return keep[: _distinct_rows_into(C, l, keys, np.empty(C.shape[0]), keep)]


@jit_inline
def _distinct_rows_into(C: FloatArray, l: FloatArray, keys: IntArray, norms: FloatArray, keep: IntArray) -> int:
    """:func:`_distinct_rows` into the caller's arrays (``norms``: room for each row's norm):
    the rows to keep are ``keep[:count]``; returns the count."""
    m, n_v = C.shape
    for k in range(m):  # (by index, not np.dot: a BLAS call on two row views costs a row's work many times)
        s = 0.0
        for c in range(n_v):
            s += C[k, c] * C[k, c]
        norms[k] = math.sqrt(s) + 1e-300
    n = 0
    for k in range(m):
        merged = False
        for i in range(n):
            j = keep[i]
            if keys[j] != keys[k]:
                continue
            s = 0.0
            for c in range(n_v):
                s += C[j, c] * C[k, c]
            if s > PARALLEL * norms[j] * norms[k]:
                if l[k] / norms[k] > l[j] / norms[j]:
                    keep[i] = k
                merged = True
                break
        if not merged:
            keep[n] = k
            n += 1
    return n
