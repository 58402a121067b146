"""The collision rows' candidate search: every monitored pair near enough to need a row, its
distance, closest points and normal, each tick.

Self pairs, the floor and the obstacles go through compiled passes (:mod:`._pair_passes`: a
bounding-sphere broad phase, then the distances of swept spheres, boxes and planes of
:mod:`._distance` and GJK's for the convex hulls of meshes, :mod:`._gjk`) into one candidate
buffer (:class:`Candidates`); coal fills the entries those do not cover (a hull or box whose
core touches or overlaps the other's, a capsule whose segment is inside a box). Everything is in
the base frame: the bodies placed by the arm's joint placements, the obstacles by the base pose.
Which rows the candidates become is :mod:`.collision`'s business.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any, overload

import coal
import numpy as np
import pinocchio as pin

from .._typing import BoolArray, FloatArray, IntArray
from ..config import CollisionParams, ShapeConfig
from ..model.collision import (
    COVER_REACH,
    RobotGeometry,
    bounding_capsule,
    bounding_sphere,
    coal_shape,
    convex_vertices,
    exempt_mask,
    row_shape,
    shape_pose,
    transform,
)
from ._gjk import WARM_WIDTH, WORK_FLOATS, WORK_INTS, Layout
from ._pair_passes import (
    ROBOT_FLOATS,
    ROBOT_INTS,
    TABLE_FLOATS,
    TABLE_INTS,
    layout,
    left_to_coal,
    place_kernel,
    plane_pass,
    robot_passes,
    solid_pass,
)

FLOOR = -1
"""The other side of a candidate against the floor (``Candidates.other``; a body's index ≥ 0,
obstacle k: −2 − k)."""


class Table:
    """Primitives in arrays, for the compiled distances (``_distance.py``, ``_gjk.py``): kind 0 a
    swept segment [a0, a1] of radius r (sphere, capsule), 1 a box (centre c, rotation R, half
    extents h), 3 a convex vertex set (a mesh's hull: its vertices ``verts[vs:vs + vc]`` in its
    own frame, placed by c and R), 2 any other shape (coal computes its distances); ``centre`` is
    each one's bounding-sphere centre."""

    def __init__(self, n: int) -> None:
        self.kind = np.full(n, 2, dtype=np.int64)
        self.a0, self.a1, self.c, self.h, self.centre = (np.zeros((n, 3)) for _ in range(5))
        self.r = np.zeros(n)
        self.R = np.tile(np.eye(3), (n, 1, 1))
        self.verts = np.zeros((0, 3))
        self.vs, self.vc = np.zeros(n, dtype=np.int64), np.zeros(n, dtype=np.int64)

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
        elif (pts := convex_vertices(shape)) is not None:
            self.kind[k], self.vs[k], self.vc[k] = 3, self.verts.shape[0], pts.shape[0]
            self.verts = np.ascontiguousarray(np.vstack([self.verts, pts]))
        else:
            self.kind[k] = 2

    def same_shapes(self, other: Table) -> None:
        """This table's kinds, radii, half extents and vertex sets ← ``other``'s (its poses apart)."""
        self.kind[:], self.r[:], self.h[:] = other.kind, other.r, other.h
        self.verts, self.vs[:], self.vc[:] = other.verts, other.vs, other.vc

    def shapes(self) -> tuple[IntArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray,
                              FloatArray, IntArray, IntArray]:
        """The arrays the compiled passes take for each primitive, in their order."""
        return self.kind, self.a0, self.a1, self.r, self.c, self.R, self.h, self.verts, self.vs, self.vc


def place(Hj: FloatArray, joint: IntArray, local: Table, out: Table) -> None:
    """``out`` ← every primitive of ``local`` placed by its joint's placement Hj[joint[k]] (4×4)."""
    place_kernel(Hj, joint, local.kind, local.a0, local.a1, local.c, local.R, local.centre,
                 out.a0, out.a1, out.c, out.R, out.centre)


SE3_DOUBLES = 12
"""A Pinocchio SE3 in memory: its rotation (column-major, 9 doubles), then its translation."""


def placement_table(data: Any) -> FloatArray | None:
    """The joints' placements ``data.oMi`` as one read-only (njoints, 12) view of Pinocchio's own
    memory, row j: joint j's rotation column by column, then its translation; it follows every
    forward kinematics, so the compiled pass reads the placements in place instead of Python
    copying each one a tick. None where the memory is not laid out so (checked here, address by
    address: consecutive SE3s of 96 bytes, the rotation column-major, the translation after it):
    the placements are then copied one by one."""
    oMi = data.oMi
    n, R0 = len(oMi), oMi[0].rotation
    size = SE3_DOUBLES * R0.itemsize

    def address(a: np.ndarray) -> int:
        return int(a.__array_interface__["data"][0])

    start = address(R0)
    for j in range(n):
        R, t = oMi[j].rotation, oMi[j].translation
        b = R0.itemsize  # column-major rotation (strides b, 3b), the translation 9 doubles after it
        if (R.dtype != np.float64 or t.dtype != np.float64 or R.strides != (b, 3 * b) or t.strides != (b,)
                or address(R) != start + j * size or address(t) != start + j * size + 9 * b):
            return None
    table = np.lib.stride_tricks.as_strided(R0, shape=(n, SE3_DOUBLES), strides=(size, R0.itemsize), writeable=False)
    for j in range(n):  # the values too, as they are now
        H = oMi[j].homogeneous
        R = table[j, :9].reshape(3, 3, order="F")
        if not (np.array_equal(R, H[:3, :3]) and np.array_equal(table[j, 9:], H[:3, 3])):
            return None
    return table


def pack(arrays: list[tuple[Any, str]], dtype: type) -> tuple[np.ndarray, IntArray]:
    """The arrays ``getattr(owner, name)`` copied into one arena of ``dtype``, in order, each
    attribute then set to its view of it (so what fills the view fills the arena): (the arena, L),
    ``L[k]`` = array k's (offset, size, shape…) (the compiled unpacking: ``_pair_passes._view1``)."""
    got = [np.asarray(getattr(owner, name)) for owner, name in arrays]
    arena: np.ndarray = np.empty(sum(a.size for a in got), dtype=dtype)
    L = np.zeros((len(got), 5), dtype=np.int64)
    o = 0
    for k, ((owner, name), a) in enumerate(zip(arrays, got, strict=True)):
        view = arena[o : o + a.size].reshape(a.shape)
        view[...] = a
        L[k, 0], L[k, 1], L[k, 2 : 2 + a.ndim] = o, a.size, a.shape
        setattr(owner, name, view)
        o += a.size
    return arena, L


class ShapeArenas:
    """A table's arrays packed into one float and one int arena (:func:`pack`: the table's arrays
    become views of them, so what places the table fills the arenas), as the compiled GJK takes a
    table (:data:`._gjk.Layout`), with ``warm_rows`` warm starts (:data:`._gjk.WARM_WIDTH`) and GJK's
    workspace after it. Pack a table once its shapes are set (``Table.set`` and ``same_shapes``
    replace the vertex array).

    Attributes:
        F, I: the arenas; L: the table's layout in them.
        warm: (warm_rows, WARM_WIDTH) the warm starts, a view; ``ow``: their offset in F.
        ws, wi: the workspace's offsets in F and I.
    """

    def __init__(self, table: Table, warm_rows: int = 0) -> None:
        self.warm, self.work = np.zeros((warm_rows, WARM_WIDTH)), np.zeros(WORK_FLOATS)
        self.work_ids = np.zeros(WORK_INTS, dtype=np.int64)
        floats, ints = (*TABLE_FLOATS, "warm", "work"), (*TABLE_INTS, "work_ids")
        self.F, Lf = pack([(self if k in ("warm", "work") else table, k) for k in floats], np.float64)
        self.I, Li = pack([(self if k == "work_ids" else table, k) for k in ints], np.int64)
        self.L: Layout = layout(Lf, Li, floats, ints)
        self.ow, self.ws = int(Lf[floats.index("warm"), 0]), int(Lf[floats.index("work"), 0])
        self.wi = int(Li[ints.index("work_ids"), 0])


@dataclass
class Obstacle:
    """An obstacle as the search uses it (world frame; a plane's normal and offset apart).

    Attributes:
        name: its id (the rows' names).
        shape: its coal geometry (a plane's half-space is built in the base frame when needed).
        row: the shape its rows keep apart (:func:`row_shape`: a cylinder's capsule).
        world: its pose in the world.
        center, radius: [m] its row shape's bounding sphere (its frame; a plane: 0, inf).
        plane: it is a plane.
        checked: (bodies,) the bodies it is checked against (:func:`exempt_mask`).
        checked_idx: their indices.
        normal_w, offset_w: a plane's unit normal and offset [m] (world frame).
        normal_b, offset_b: the same in the base frame, this tick (:meth:`place`).
        velocity_w: [m/s] its velocity (world frame).
    """

    name: str
    shape: coal.CollisionGeometry
    world: pin.SE3
    center: FloatArray
    radius: float
    plane: bool
    checked: BoolArray
    checked_idx: IntArray
    normal_w: FloatArray = field(default_factory=lambda: np.zeros(3))
    offset_w: float = 0.0
    normal_b: FloatArray = field(default_factory=lambda: np.zeros(3))
    offset_b: float = 0.0
    velocity_w: FloatArray = field(default_factory=lambda: np.zeros(3))
    row: coal.CollisionGeometry | None = None

    @classmethod
    def of(cls, s: ShapeConfig, geometry: RobotGeometry) -> Obstacle:
        """The obstacle of a scene's (or a live message's) primitive."""
        shape = coal_shape(s)
        plane = s.kind == "plane"
        center, radius = (np.zeros(3), math.inf) if plane else bounding_sphere(row_shape(shape))
        mask = exempt_mask(geometry, s.exempt)
        o = cls(s.name, shape, shape_pose(s), center, radius, plane, mask, np.flatnonzero(mask).astype(np.int64),
                row=shape if plane else row_shape(shape))
        if plane:
            o.normal_w, o.offset_w = np.asarray(s.normal, dtype=float), s.offset
        if s.velocity is not None:
            o.velocity_w = np.asarray(s.velocity, dtype=float)
        return o

    def place(self, Rb: FloatArray, tb: FloatArray) -> None:
        """A plane's normal and offset in the base frame, the base at (Rb, tb) in the world:
        n·p_w ≤ c ⇔ (Rbᵀ n)·p_b ≤ c − n·tb."""
        self.normal_b, self.offset_b = Rb.T @ self.normal_w, self.offset_w - float(self.normal_w @ tb)


@dataclass
class Candidates:
    """The candidate buffer: room for every monitored pair at once (self, floor, each obstacle
    against every body); entries [0, n) are this tick's.

    Attributes:
        d: [m] signed distance (negative in penetration).
        p_a, p_b: [m] the closest points on the body and on the other side (base frame).
        normal: the unit normal n̂ from the other side to the body.
        ok: False where coal had to compute the entry (filled in by the search anyway).
        body: the body's index; other: the other side (a body ≥ 0, :data:`FLOOR`, obstacle k −2 − k).
        safety: [m] the pair's safety distance d_s.
        n: the number of entries this tick.
    """

    d: FloatArray
    p_a: FloatArray
    p_b: FloatArray
    normal: FloatArray
    ok: BoolArray
    body: IntArray
    other: IntArray
    safety: FloatArray
    n: int = 0

    @classmethod
    def room(cls, n: int) -> Candidates:
        return cls(np.empty(n), np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 3)), np.ones(n, dtype=np.bool_),
                   np.empty(n, dtype=np.int64), np.empty(n, dtype=np.int64), np.empty(n))


class PairNames(Sequence[str]):
    """The names of pairs (:meth:`PairSearch.name`), made when one is read: a tick's rows carry
    dozens (TIAGo's 48), and only a reason that cites a row reads one.

    Args:
        name: the pair's name of (body, other) (:meth:`PairSearch.namer`: the tick's obstacles).
        body, other: the pairs, coded as :class:`Candidates`'.
    """

    def __init__(self, name: Callable[[int, int], str], body: IntArray, other: IntArray) -> None:
        self._name, self.body, self.other = name, body, other

    def __len__(self) -> int:
        return int(self.body.shape[0])

    @overload
    def __getitem__(self, k: int) -> str: ...

    @overload
    def __getitem__(self, k: slice) -> list[str]: ...

    def __getitem__(self, k: int | slice) -> str | list[str]:
        if isinstance(k, slice):
            return [self[i] for i in range(*k.indices(len(self)))]
        if not -len(self) <= k < len(self):
            raise IndexError(k)
        return self._name(int(self.body[k]), int(self.other[k]))

    def __iter__(self) -> Iterator[str]:  # (not Sequence's: an IndexError of a name is no end)
        for k in range(len(self)):
            yield self[k]

    def __add__(self, more: PairNames) -> PairNames:
        return PairNames(self._name, np.concatenate((self.body, more.body)), np.concatenate((self.other, more.other)))

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Sequence) and list(self) == list(other)

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        return repr(list(self))


class PairSearch:
    """Each tick, every monitored pair within the influence distance and its distance.

    Args:
        geometry: the robot's bodies and pairs (the arm's data: its joint placements are read).
        params: d_i (``influence_distance``, the broad phase's reach), d_s and the floor margin.
    """

    def __init__(self, geometry: RobotGeometry, params: CollisionParams) -> None:
        self.geo = geometry
        self.p = params
        self.obstacles: list[Obstacle] = []
        self.shapes: tuple[ShapeConfig, ...] = ()  # the obstacles in force, as given to set_obstacles
        self.moving = False  # an obstacle of the set has a velocity
        self.base_rotation = np.eye(3)  # Rb of the last search (the world → base frame rotation's transpose)
        self._names: dict[tuple[int, int], str] = {}
        self._floor = coal.Halfspace(np.array([0.0, 0.0, 1.0]), geometry.floor_z)  # coal: n·p ≤ d is solid: z ≤ floor_z
        self._identity = coal.Transform3s()
        self._req = coal.DistanceRequest()
        self._res = coal.DistanceResult()
        bodies = geometry.bodies
        joints = np.unique([b.joint for b in bodies]) if bodies else np.zeros(0, dtype=int)
        where = {int(j): k for k, j in enumerate(joints)}
        self._body_joint = np.array([where[b.joint] for b in bodies], dtype=int)  # index into _joint_ids
        # the broad phase: each row shape's bounding sphere (a cylinder's capsule reaches past the
        # cylinder's own sphere: culling on that would let a pair in already inside d_s)
        self._radii = np.array([b.row_radius for b in bodies], dtype=float)
        # the pairs of a body inside another last, each with its containers' pair (−1: none;
        # self_pass computes them only near d_s: RobotGeometry.covered_pairs)
        covered = geometry.covered_pairs
        self._pairs = np.array(geometry.row_pairs + [(i, j) for i, j, _ in covered], dtype=int).reshape(-1, 2)
        self._cover = np.array([-1] * len(geometry.row_pairs) + [k for _, _, k in covered], dtype=int)
        self._pair_d = np.full(self._pairs.shape[0], math.inf)  # each pair's distance this tick (inf: beyond
        # d_i, not computed; −inf: left to coal)
        self._pair_r = self._radii[self._pairs[:, 0]] + self._radii[self._pairs[:, 1]]
        self._floor_idx = np.array(geometry.floor_bodies, dtype=int)
        self._floor_n, self._floor_o = np.array([0.0, 0.0, -1.0]), -geometry.floor_z  # free: z ≥ floor_z
        # the compiled path: each body's primitive in its joint's frame, placed each tick
        self._shapes = Table(len(bodies))
        for k, b in enumerate(bodies):
            self._shapes.set(k, b.row, b.placement, b.row_center)
        self.placed = Table(len(bodies))  # the bodies in the base frame, this tick
        self.placed.same_shapes(self._shapes)
        # the narrower broad phase of the self pairs GJK computes: each row shape's bounding capsule
        # (model/collision.py: bounding_capsule), in its joint's frame, placed each tick
        caps = [bounding_capsule(b.row) for b in bodies]
        self._cap_local = np.array([[b.placement.act(a), b.placement.act(e)] for b, (a, e, _) in zip(bodies, caps,
                                                                                                      strict=True)],
                                   dtype=float).reshape(len(bodies), 2, 3)
        self._cap_r = np.array([r for _, _, r in caps], dtype=float)
        self._cap = np.zeros((len(bodies), 2, 3))  # placed: the base frame, this tick
        self._Hj = np.tile(np.eye(4), (len(joints), 1, 1))
        self._body_H = [b.placement.homogeneous for b in bodies]  # each body in its joint's frame
        self._joint_ids = [int(j) for j in joints]
        # each carrying joint's placement, fetched once: Pinocchio hands out a reference into the
        # arm's data (its values follow every forward kinematics; the data is never replaced), and
        # reading .homogeneous off it costs ~0.25 µs against ~0.65 µs through data.oMi[j] each tick
        self._placements = [geometry.arm.data.oMi[j] for j in self._joint_ids]
        # or, where Pinocchio's memory allows it, all of them read in place by the compiled pass
        table = placement_table(geometry.arm.data)
        self._in_place = table is not None
        self._oMi = table if table is not None else np.zeros((0, SE3_DOUBLES))
        self._joint_id = np.array(self._joint_ids, dtype=np.int64)
        self._H_world = np.eye(4)[None].copy()  # world → base frame, refilled each tick
        self._solid_joint = np.zeros(0, dtype=np.int64)
        self._solid: tuple[IntArray, Table, Table, FloatArray, BoolArray, list[int]] = (
            np.zeros(0, dtype=np.int64), Table(0), Table(0), np.zeros(0),
            np.zeros((0, len(bodies)), dtype=bool), [])
        self.candidates = Candidates.room(self._pairs.shape[0] + self._floor_idx.shape[0])
        self._warm = np.zeros((self._pairs.shape[0], WARM_WIDTH))  # GJK's start for each self pair (the last result)
        # how far each body has moved since its travel last restarted, and each self pair's last
        # lower bound of its distance beyond d_i (_pair_passes.body_travel, self_pass): a pair of
        # capsules that cannot have come within d_i since is not computed again
        self._last_H = np.tile(np.eye(4), (len(joints), 1, 1))
        self._moved = np.zeros((len(bodies), 5))  # last centre, travel, its sum's compensation
        self._slack = np.full((self._pairs.shape[0], 2), -math.inf)
        self._warm_solid = np.zeros((0, WARM_WIDTH))  # ... for each (solid obstacle, body)
        self._work, self._work_ids = np.zeros(WORK_FLOATS), np.zeros(WORK_INTS, dtype=np.int64)  # GJK's workspace
        self._obstacle_arenas = ShapeArenas(self._solid[2])
        self._bind()
        self._make_namer()

    def set_obstacles(self, obstacles: tuple[ShapeConfig, ...] | list[ShapeConfig]) -> None:
        """Replace the obstacle set (atomically: the next tick sees the new set only).

        The solid obstacles go into one table (world frame; a cylinder as the capsule that
        contains it), placed in the base frame each tick in one compiled call; the planes apart."""
        self.shapes = tuple(obstacles)
        self._names = {}  # row names by pair (the obstacle indices change here)
        obs = [Obstacle.of(s, self.geo) for s in obstacles]
        solid = [k for k, o in enumerate(obs) if not o.plane]
        world, placed = Table(len(solid)), Table(len(solid))
        for r, k in enumerate(solid):
            o = obs[k]
            world.set(r, row_shape(o.shape), o.world, o.center)  # o.center, o.radius: of the row shape
        placed.same_shapes(world)
        self._obstacle_arenas = ShapeArenas(placed)  # (placed's arrays become its views: place() fills them)
        checked = np.array([obs[k].checked for k in solid], dtype=bool).reshape(len(solid), len(self.geo.bodies))
        radii = np.array([obs[k].radius for k in solid], dtype=float)
        self._solid = (np.array(solid, dtype=np.int64), world, placed, radii, checked,
                       [k for k, o in enumerate(obs) if o.plane])
        self._solid_joint = np.zeros(len(solid), dtype=np.int64)  # every obstacle placed by the one H
        self._warm_solid = np.zeros((len(solid) * len(self.geo.bodies), WARM_WIDTH))
        self.obstacles = obs
        self._make_namer()
        n = self._pairs.shape[0] + self._floor_idx.shape[0] + len(obs) * len(self.geo.bodies)
        self.candidates = Candidates.room(n)
        self._bind()
        self.moving = any(bool(o.velocity_w.any()) for o in obs)

    def _bind(self) -> None:
        """:func:`robot_passes`'s arguments, in one tuple: the robot side's arrays, which the search
        fills in place each tick, packed into two arenas (:func:`pack`: each array here becomes
        its view of them) once, and again when ``set_obstacles`` makes new candidates (whoever
        replaces one of these arrays must call this again): the call unboxes 6 arrays a tick
        instead of 42 (~48 ns each on the 2-core host of docs/benchmarks.md §12), and nothing is
        gathered."""
        p, pl, c, loc = self.p, self.placed, self.candidates, self._shapes
        floats = {"Hj": (self, "_Hj"), "l_a0": (loc, "a0"), "l_a1": (loc, "a1"), "l_c": (loc, "c"),
                  "l_R": (loc, "R"), "l_centre": (loc, "centre"), "a0": (pl, "a0"), "a1": (pl, "a1"), "r": (pl, "r"),
                  "c": (pl, "c"), "R": (pl, "R"), "h": (pl, "h"), "verts": (pl, "verts"), "centre": (pl, "centre"),
                  "radii": (self, "_radii"), "pair_r": (self, "_pair_r"), "floor_n": (self, "_floor_n"),
                  "d": (c, "d"), "P": (c, "p_a"), "Q": (c, "p_b"), "N": (c, "normal"), "safety": (c, "safety"),
                  "warm": (self, "_warm"), "cap_local": (self, "_cap_local"), "cap_r": (self, "_cap_r"),
                  "cap": (self, "_cap"), "last_H": (self, "_last_H"), "moved": (self, "_moved"),
                  "slack": (self, "_slack"), "pair_d": (self, "_pair_d"), "warm_solid": (self, "_warm_solid"),
                  "work": (self, "_work")}
        ints = {"joint_id": (self, "_joint_id"), "joint": (self, "_body_joint"), "kind": (pl, "kind"),
                "vs": (pl, "vs"), "vc": (pl, "vc"), "pairs": (self, "_pairs"), "floor_idx": (self, "_floor_idx"),
                "body": (c, "body"), "other": (c, "other"), "cover": (self, "_cover"), "work_ids": (self, "_work_ids")}
        F, Lf = pack([floats[k] for k in ROBOT_FLOATS], np.float64)
        I, Li = pack([ints[k] for k in ROBOT_INTS], np.int64)
        self.arenas: tuple[Any, ...] = (F, Lf, I, Li)
        """The arenas (F, Lf, I, Li): the candidates' arrays are views of them too (``_rows``)."""
        o = self._obstacle_arenas
        robot = layout(Lf, Li, ROBOT_FLOATS, ROBOT_INTS)
        self._solid_args: tuple[FloatArray, IntArray, Layout, FloatArray, FloatArray, FloatArray, IntArray,
                                Layout] = (F, I, robot, pl.centre, self._radii, o.F, o.I, o.L)
        """:func:`solid_pass`'s first arguments: the bodies' table and the obstacles' in their arenas."""
        self._gjk_at = (int(Lf[ROBOT_FLOATS.index("warm_solid"), 0]), int(Lf[ROBOT_FLOATS.index("work"), 0]),
                        int(Li[ROBOT_INTS.index("work_ids"), 0]))
        """:func:`solid_pass`'s GJK starts and workspace, their offsets in the robot's arenas."""
        self.robot_args: tuple[Any, ...] = (self._oMi, F, Lf, I, Li, c.ok, p.influence_distance,
                                            p.safety_distance, self._floor_o, p.floor_margin,
                                            p.safety_distance + COVER_REACH)
        """:func:`robot_passes`'s arguments (a new tuple whenever the arenas are new)."""

    def reset(self) -> None:
        """GJK starts every pair afresh (its warm starts forgotten), and every pair is computed at
        the next search (none left out by its last distance)."""
        self._warm[:] = 0.0
        self._warm_solid[:] = 0.0
        self._slack[:, 0] = -math.inf

    def search(self, q_base: FloatArray) -> Candidates:
        """Every pair the broad phase lets through at the state the arm's data was last computed
        at (its joint placements current), the base at ``q_base`` [m, m, rad]: its distance,
        closest points and normal in the candidates' first ``n`` entries."""
        self.place_joints()
        # the bodies placed, robot vs robot (base frame; the base's motion cancels) and robot vs the
        # floor z = floor_z (the same plane in the base frame), in one compiled call
        n, left = robot_passes(*self.robot_args)
        return self.after_robot(q_base, n, left)

    def place_joints(self) -> None:
        """Where Pinocchio's placements cannot be read in place: the joints that carry bodies, their
        placements copied one by one (before :func:`robot_passes`)."""
        if not self._in_place:
            Hj = self._Hj
            for k, M in enumerate(self._placements):
                Hj[k] = M.homogeneous

    def after_robot(self, q_base: FloatArray, n: int, left: int) -> Candidates:
        """The search after :func:`robot_passes` gave n candidates (``left`` of them to coal): the
        obstacles' passes, then coal's distances; the candidates."""
        c = self.candidates
        Rb = tb = None
        n_robot = n
        if self.obstacles:  # robot vs obstacles, in the base frame at this base pose
            p, d_i, pl = self.p, self.p.influence_distance, self.placed
            buf = (c.d, c.p_a, c.p_b, c.normal, c.ok, c.body, c.other, c.safety)
            cos, sin = math.cos(q_base[2]), math.sin(q_base[2])
            Rb = np.array([[cos, -sin, 0.0], [sin, cos, 0.0], [0.0, 0.0, 1.0]])
            tb = np.array([q_base[0], q_base[1], 0.0])
            self.base_rotation = Rb
            solid, world, placed, radii, checked, planes = self._solid
            if solid.shape[0]:
                H = self._H_world  # world → base frame
                H[0, :3, :3], H[0, :3, 3] = Rb.T, -(Rb.T @ tb)
                place(H, self._solid_joint, world, placed)
                n = solid_pass(*self._solid_args, placed.kind, placed.c, placed.R, placed.h, placed.centre, radii,
                               checked, solid, d_i, p.safety_distance, *buf, n, *self._gjk_at)
            for index in planes:
                o = self.obstacles[index]
                o.place(Rb, tb)
                n = plane_pass(*pl.shapes(), pl.centre, self._radii, o.checked_idx, False, o.normal_b, o.offset_b, d_i,
                               -2 - index, p.safety_distance, *buf, n)
        if self.obstacles:
            left += left_to_coal(c.ok, n_robot, n)
        if left:
            self._coal_fill(n, Rb, tb)
        c.n = n
        return c

    def _coal_fill(self, n: int, Rb: FloatArray | None, tb: FloatArray | None) -> None:
        """The candidates the compiled distances left to coal (a hull or box whose core touches
        or overlaps the other's, a capsule whose segment is inside a box), computed by coal in place."""
        c, bodies = self.candidates, self.geo.bodies
        poses: dict[int, coal.Transform3s] = {}  # each body's, once this tick

        def T(i: int) -> coal.Transform3s:
            M = poses.get(i)
            if M is None:
                H = self._Hj[self._body_joint[i]] @ self._body_H[i]  # the joint's placement (this tick's) · the body's
                M = poses[i] = coal.Transform3s(H[:3, :3], H[:3, 3])
            return M

        for k in np.flatnonzero(~c.ok[:n]).tolist():
            body, other = int(c.body[k]), int(c.other[k])
            if other >= 0:  # the row shapes, as the compiled passes take them (a cylinder's capsule)
                got = self._coal(bodies[body].row, T(body), bodies[other].row, T(other))
            elif other == FLOOR:
                got = self._coal(bodies[body].row, T(body), self._floor, self._identity)
            else:
                assert Rb is not None and tb is not None
                o = self.obstacles[-2 - other]
                if o.plane:  # coal's half-space, built when a body needs it
                    o.shape = coal.Halfspace(-o.normal_b, -o.offset_b)  # coal: solid where n'·p ≤ d
                    got = self._coal(bodies[body].row, T(body), o.shape, self._identity)
                else:
                    Mo = pin.SE3(Rb.T @ o.world.rotation, Rb.T @ (o.world.translation - tb))
                    got = self._coal(bodies[body].row, T(body), o.row or o.shape, transform(Mo))
            c.d[k], c.p_a[k], c.p_b[k], c.normal[k] = got

    def name(self, body: int, other: int) -> str:
        """A pair's name: "a/b" (bodies), "a/floor", "a/<obstacle id>"."""
        return _pair_name(self.geo.bodies, self.obstacles, self._names, body, other)

    def namer(self) -> Callable[[int, int], str]:
        """:meth:`name` with this tick's obstacle set: it names the pairs of this tick's candidates
        whatever set the search holds later (``set_obstacles`` makes a new list and cache, and a
        new namer)."""
        return self._namer

    def _make_namer(self) -> None:
        bodies, obstacles, cache = self.geo.bodies, self.obstacles, self._names
        self._namer = lambda body, other: _pair_name(bodies, obstacles, cache, body, other)

    def _coal(self, a: coal.CollisionGeometry, Ta: coal.Transform3s, b: coal.CollisionGeometry,
              Tb: coal.Transform3s) -> tuple[float, FloatArray, FloatArray, FloatArray]:
        res = self._res
        res.clear()
        d = coal.distance(a, Ta, b, Tb, self._req, res)
        return float(d), np.asarray(res.getNearestPoint1()), np.asarray(res.getNearestPoint2()), unit_normal(res)


def _pair_name(bodies: Sequence[Any], obstacles: list[Obstacle], cache: dict[tuple[int, int], str], body: int,
               other: int) -> str:
    """"a/b" (bodies), "a/floor", "a/<obstacle id>" (``cache``: the names made so far)."""
    key = (body, other)
    name = cache.get(key)
    if name is None:
        rest = bodies[other].name if other >= 0 else "floor" if other == FLOOR else obstacles[-2 - other].name
        name = cache[key] = f"{bodies[body].name}/{rest}"
    return name


def unit_normal(res: coal.DistanceResult) -> FloatArray:
    """n̂ from body b to body a: −coal's normal (which points from the first shape to the second),
    defined in penetration too."""
    n = -np.asarray(res.normal, dtype=float)
    nn = math.sqrt(float(n @ n))  # (np.linalg.norm: ~5 µs of checks on 3 numbers, each coal pair)
    return n / nn if nn > 1e-12 else np.array([0.0, 0.0, 1.0])


