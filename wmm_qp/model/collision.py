"""The robot's collision geometry and the pairs to monitor, built once at start-up (docs/model.md "Any robot").

Bodies come from the URDF's collision elements (``[collision] from_urdf``; meshes as their convex
hulls, so distances and closest points come from coal's GJK), from primitives in the robot file
(``[collision] shapes``; the Gen3's URDF has none) and from the base's box (``[base] body``). Each
body is fixed to a joint of the arm's reduced model (0: fixed to the base), at a placement in that
joint's frame; the base frame is the reduced model's world (the mount is folded in).

Pairs, decided here once and never per tick:

* robot vs robot: every two bodies except those on the same joint, on adjacent joints (a joint and
  its parent: they touch by construction), both fixed to the base, named in ``[collision] exclude``,
  or within ``TOUCH_DISTANCE`` (3 cm) of each other in at least 95 % of 200 random configurations
  inside the joint limits (seeded: every process decides the same) — touching by construction,
  like a capsule over a joint and the next-but-one link's. Decided on the shapes the rows keep
  apart (a cylinder's bounding capsule, which takes in the Panda's spheres at its ends: its
  link1/link3 spheres and capsules around joint 2 always touch; panda_moveit_config's SRDF
  disables link1/link3 too). Every exclusion is listed in ``excluded`` with its reason;
* robot vs the floor (the plane z = ``[base] floor_z``): every body that moves with the arm;
* robot vs obstacles (a scene's, in the world frame): every body, the base's too.

The referees check all of these. The controller's rows leave out, of them, a self pair of a body
whose row shape lies inside another body's of its link (``covered_by``: the Panda's URDF draws
each capsule as a cylinder and two spheres at its ends, all inside the cylinder's capsule), where
the containers' pair is monitored, while that pair is beyond d_s + ``COVER_REACH``: a shape inside
another is at least as far from anything, so the rows that keep the container d_s apart keep it
too (``row_pairs``, ``covered_pairs``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import coal
import numpy as np
import pinocchio as pin

from .. import urdf as urdf_io
from .._typing import BoolArray, FloatArray
from ..config import RobotConfig, ShapeConfig
from .arm import ArmModel


def coal_shape(shape: ShapeConfig) -> coal.CollisionGeometry:
    """The coal geometry of a primitive (capsules and cylinders along their local z)."""
    if shape.kind == "box":
        return coal.Box(*(float(v) for v in shape.size))
    if shape.kind == "sphere":
        return coal.Sphere(shape.radius)
    if shape.kind == "capsule":
        return coal.Capsule(shape.radius, shape.length)
    if shape.kind == "cylinder":
        return coal.Cylinder(shape.radius, shape.length)
    if shape.kind == "plane":  # n·p ≤ c is free, n·p > c solid
        return coal.Halfspace(-np.asarray(shape.normal, dtype=float), -shape.offset)  # coal: solid where n'·p ≤ d
    raise ValueError(f"unknown shape kind {shape.kind!r}")


def convex_hull(mesh: coal.BVHModelBase) -> coal.ConvexBase:
    """The convex hull of a mesh's vertices, its vertices only (qhull, triangulated).

    Not ``buildConvexRepresentation``: its Convex keeps every vertex of the mesh, the interior
    ones too, on which coal's GJK gives wrong distances that jump at sub-millimetre motion; on the
    hull of its vertices the distance is the vertices' own and continuous
    (``tests/core/test_convex_hulls.py``)."""
    points = [np.asarray(mesh.vertex(i), dtype=float) for i in range(mesh.num_vertices)]
    return coal.Convex.convexHull(points, False, "Qt")


def shape_pose(shape: ShapeConfig) -> pin.SE3:
    """A primitive's pose in its link's frame (identity for a plane: its offset is in the shape)."""
    if shape.kind == "plane":
        return pin.SE3.Identity()
    return pin.SE3(pin.rpy.rpyToMatrix(np.asarray(shape.rpy, dtype=float)), np.asarray(shape.xyz, dtype=float))


def row_shape(shape: coal.CollisionGeometry) -> coal.CollisionGeometry:
    """The shape the controller's rows keep apart for a body's ``shape``, in the same frame: for a
    cylinder the capsule of the same radius and segment (the compiled
    distances have no cylinder kernel), else the shape itself (spheres, capsules and boxes go to
    the compiled kernels as they are, convex meshes to coal).

    The rows keep these shapes ``collision.safety_distance`` apart: since each one contains its
    body, the bodies are at least as far apart (the referee checks the bodies). Convex meshes are
    not wrapped in capsules: capsules around meshes can be fat enough to put a robot's start
    configuration inside d_s, and the rows then fight every task."""
    if isinstance(shape, coal.Cylinder):
        return coal.Capsule(shape.radius, 2.0 * shape.halfLength)
    return shape


def bounding_sphere(shape: coal.CollisionGeometry) -> tuple[FloatArray, float]:
    """(centre, radius) of a sphere that contains ``shape``, in its own frame."""
    shape.computeLocalAABB()
    return np.asarray(shape.aabb_center, dtype=float).copy(), float(shape.aabb_radius)


def convex_vertices(shape: coal.CollisionGeometry) -> FloatArray | None:
    """(n, 3) the vertices of a plain convex vertex set (a mesh's hull: no swept radius), in its
    own frame; None for any other shape."""
    if isinstance(shape, coal.ConvexBase) and shape.num_points > 0 and shape.getSweptSphereRadius() == 0.0:
        return np.array([np.asarray(shape.point(i), dtype=float) for i in range(shape.num_points)])
    return None


CAPSULE_ROUNDING = 1e-9
"""[m] added to a box's and a vertex set's bounding capsule's radius: their corners and vertices,
placed, stay inside it whatever the rounding."""


def bounding_capsule(shape: coal.CollisionGeometry) -> tuple[FloatArray, FloatArray, float]:
    """(a, b, r): a capsule, the segment [a, b] swept by the radius r, that contains ``shape``, in
    its own frame; tighter than its bounding sphere for a long link. A sphere and a capsule are
    their own; a box's runs along its longest side, r its cross-section's half diagonal; a vertex
    set's (a mesh's hull) along its principal axis from its lowest to its highest vertex there, r
    the farthest vertex's distance from that axis. Any other shape: its bounding sphere."""
    if isinstance(shape, coal.Capsule):
        h = np.array([0.0, 0.0, shape.halfLength])
        return -h, h, float(shape.radius)
    if isinstance(shape, coal.Sphere):
        return np.zeros(3), np.zeros(3), float(shape.radius)
    if isinstance(shape, coal.Box):
        half = np.asarray(shape.halfSide, dtype=float)
        ax = int(np.argmax(half))
        e = np.zeros(3)
        e[ax] = half[ax]
        return -e, e, float(math.sqrt(float(np.sum(half**2)) - half[ax] ** 2)) + CAPSULE_ROUNDING
    pts = convex_vertices(shape)
    if pts is not None:
        mean = pts.mean(axis=0)
        axis = np.linalg.svd(pts - mean, full_matrices=False)[2][0] if pts.shape[0] > 1 else np.array([0.0, 0.0, 1.0])
        s = (pts - mean) @ axis
        off = (pts - mean) - np.outer(s, axis)
        r = float(np.sqrt(np.max(np.sum(off**2, axis=1)))) + CAPSULE_ROUNDING
        return mean + s.min() * axis, mean + s.max() * axis, r
    c, r = bounding_sphere(shape)
    return c, c.copy(), r


@dataclass
class Body:
    """One collision object of the robot.

    Attributes:
        name: its name (a URDF geometry's, or the robot file's).
        link: the link it belongs to ("base" for the base's own).
        joint: the reduced model's joint that carries it (0: fixed to the base).
        placement: its pose in that joint's frame (joint 0: the base frame).
        shape: the coal geometry.
        center, radius: a bounding sphere in the body's own frame (the broad phase).
        row, row_center, row_radius: the shape the controller's rows keep apart (``row_shape``)
            and its bounding sphere, in the same frame.
    """

    name: str
    link: str
    joint: int
    placement: pin.SE3
    shape: coal.CollisionGeometry
    center: FloatArray = field(default_factory=lambda: np.zeros(3))
    radius: float = 0.0
    row: coal.CollisionGeometry = field(init=False)
    row_center: FloatArray = field(init=False)
    row_radius: float = field(init=False)

    def __post_init__(self) -> None:
        self.center, self.radius = bounding_sphere(self.shape)
        self.row = row_shape(self.shape)
        self.row_center, self.row_radius = bounding_sphere(self.row)


def row_segment(body: Body) -> tuple[FloatArray, FloatArray, float] | None:
    """(a, b, r): a body's row shape as the segment [a, b] swept by the radius r, in its joint's
    frame, where it is a sphere or a capsule (a cylinder's row shape: its own ``bounding_capsule``);
    None for any other."""
    if not isinstance(body.row, coal.Capsule | coal.Sphere):
        return None
    a, b, r = bounding_capsule(body.row)
    return np.asarray(body.placement.act(a), dtype=float), np.asarray(body.placement.act(b), dtype=float), r


def _to_segment(p: FloatArray, a: FloatArray, b: FloatArray) -> float:
    """The distance of the point p to the segment [a, b] (at start-up; the per-tick distances are
    ``wmm_qp.limits._distance``'s compiled ones, which this layer does not import)."""
    d = b - a
    length2 = float(d @ d)
    t = 0.0 if length2 == 0.0 else min(1.0, max(0.0, float((p - a) @ d) / length2))
    return float(np.linalg.norm(p - (a + t * d)))


COVER_TOLERANCE = 1e-12
"""[m] how far one body's row shape may reach out of another's and still count as inside it
(``RobotGeometry.covered_by``): the rounding of their placements (~1e-17 m on the Panda's)."""

COVER_REACH = 0.01
"""[m] a self pair of a body inside another (``RobotGeometry.covered_pairs``) has rows of its own
while its containers' pair is within d_s + this (their distance this tick)."""

TOUCH_DISTANCE = 0.03
"""[m] two bodies this close in nearly every configuration touch by construction: never monitored."""
TOUCH_SAMPLES, TOUCH_FRACTION = 200, 0.95


class RobotGeometry:
    """The robot's bodies and the pairs of them (and of them and the floor) to monitor.

    Args:
        robot: the robot description.
        arm: its arm model (whose reduced Pinocchio model the bodies are attached to).
    """

    def __init__(self, robot: RobotConfig, arm: ArmModel) -> None:
        self.robot, self.arm = robot, arm
        self.bodies: list[Body] = []
        self._from_urdf(robot, arm)
        model = arm.model
        for s in robot.collision.shapes:
            if s.link == "base":
                joint, where = 0, pin.SE3.Identity()
            else:
                if not model.existFrame(s.link):  # a link of a locked part: merged into its joint's frame
                    raise ValueError(f"collision shape {s.name!r}: no frame {s.link!r} in the reduced model")
                f = model.frames[model.getFrameId(s.link)]
                joint, where = int(f.parentJoint), f.placement
            self.bodies.append(Body(s.name, s.link, joint, where * shape_pose(s), coal_shape(s)))
        if robot.base.body is not None:
            b = robot.base.body
            self.bodies.append(Body(b.name, "base", 0, shape_pose(b), coal_shape(b)))
        self.floor_z = float(robot.base.floor_z)
        self.excluded: list[tuple[str, str, str]] = []  # (a, b, why)
        self.self_pairs = self._self_pairs(robot)
        self.floor_bodies = [i for i, b in enumerate(self.bodies) if b.joint > 0] if np.isfinite(self.floor_z) else []
        self.covered_by = self._covered()
        """Each body's container (−1: none): another body of its link whose row shape contains its
        own (``_covered``)."""
        self.row_pairs, self.covered_pairs = self._row_pairs()
        """The self pairs the rows monitor every tick, and (i, j, the index of the containers' pair
        in ``row_pairs``) of those they monitor only while that pair is within d_s +
        ``COVER_REACH`` (``_row_pairs``)."""

    # ------------------------------------------------------------------ building
    def _from_urdf(self, robot: RobotConfig, arm: ArmModel) -> None:
        c = robot.collision
        if not c.from_urdf:
            return
        urdf = c.urdf if c.urdf is not None else robot.arm.urdf
        full = pin.buildModelFromUrdf(str(urdf))
        dirs = urdf_io.package_dirs(urdf)
        geom = pin.buildGeomFromUrdf(full, str(urdf), pin.GeometryType.COLLISION, package_dirs=dirs)
        keep = {full.getJointId(n) for n in robot.arm.joints}
        lock = [j for j in range(1, full.njoints) if j not in keep]
        q = urdf_io.lock_configuration(full, dict(robot.arm.locked))
        _, reduced_geom = pin.buildReducedModel(full, geom, lock, q)
        mount = arm.mount
        for g in reduced_geom.geometryObjects:
            link = full.frames[g.parentFrame].name if g.parentFrame < len(full.frames) else g.name
            if link in c.ignore_links:
                continue
            shape = g.geometry
            if isinstance(shape, coal.BVHModelBase):
                shape = convex_hull(shape)
            placement = g.placement if g.parentJoint > 0 else mount * g.placement
            self.bodies.append(Body(g.name, link, int(g.parentJoint), placement, shape))

    def _self_pairs(self, robot: RobotConfig) -> list[tuple[int, int]]:
        parents = self.arm.model.parents
        exclude = {frozenset(p) for p in robot.collision.exclude}
        candidates = []
        for i, a in enumerate(self.bodies):
            for j in range(i + 1, len(self.bodies)):
                b = self.bodies[j]
                why = ""
                if a.joint == b.joint:
                    why = "same joint" if a.joint else "both fixed to the base"
                elif parents[a.joint] == b.joint or parents[b.joint] == a.joint:
                    why = "adjacent joints"
                elif frozenset((a.link, b.link)) in exclude:
                    why = "excluded in the robot file"
                if why:
                    self.excluded.append((a.name, b.name, why))
                else:
                    candidates.append((i, j))
        if not candidates:
            return []
        arm = robot.arm
        lo = np.where(np.isfinite(arm.position_lower), arm.position_lower, -np.pi)
        hi = np.where(np.isfinite(arm.position_upper), arm.position_upper, np.pi)
        # decided on the shapes the controller's rows keep apart (a cylinder's bounding capsule):
        # a pair whose row shapes always touch would fight every task from the start
        bodies = self.bodies
        rng = np.random.default_rng(0)
        close = np.zeros(len(candidates))
        for _ in range(TOUCH_SAMPLES):
            M = self.placements(rng.uniform(lo, hi))
            c = [m.act(body.row_center) for m, body in zip(M, bodies, strict=True)]
            for k, (i, j) in enumerate(candidates):
                if np.linalg.norm(c[i] - c[j]) - bodies[i].row_radius - bodies[j].row_radius >= TOUCH_DISTANCE:
                    continue  # the bounding spheres are apart: so are the shapes
                close[k] += distance(bodies[i].row, M[i], bodies[j].row, M[j])[0] < TOUCH_DISTANCE
        pairs = []
        for k, (i, j) in enumerate(candidates):
            if close[k] >= TOUCH_FRACTION * TOUCH_SAMPLES:
                share = 100.0 * close[k] / TOUCH_SAMPLES
                self.excluded.append((self.bodies[i].name, self.bodies[j].name,
                                      f"within {TOUCH_DISTANCE} m in {share:.0f} % of random configurations"))
            else:
                pairs.append((i, j))
        return pairs

    def _covered(self) -> list[int]:
        """Each body's container, −1 for none: a body of the same link, itself not inside another,
        whose row shape (a sphere or a capsule: ``row_segment``) contains the body's row shape,
        within ``COVER_TOLERANCE``. A capsule (or sphere) B lies inside a capsule A where both ends
        of B's segment are within r_A − r_B of A's segment (the distance to a segment is convex
        along B's). A URDF that draws a capsule as a cylinder and two spheres at its ends (the
        Panda's) gives a cylinder whose row shape, its capsule, contains both spheres. Bodies are
        taken largest first (a container's length + 2r is no less than what it contains), so two
        equal bodies leave the first one monitored."""
        segments = [row_segment(b) for b in self.bodies]
        covered = [-1] * len(self.bodies)
        swept = [k for k, s in enumerate(segments) if s is not None]
        extent = {k: float(np.linalg.norm(s[1] - s[0])) + 2.0 * s[2] for k, s in enumerate(segments) if s is not None}
        kept: list[int] = []
        for k in sorted(swept, key=lambda k: -extent[k]):
            b0, b1, rb = segments[k]  # type: ignore[misc]
            for a in kept:
                if self.bodies[a].link != self.bodies[k].link:  # (a link rides on one joint)
                    continue
                a0, a1, ra = segments[a]  # type: ignore[misc]
                if max(_to_segment(b0, a0, a1), _to_segment(b1, a0, a1)) + rb - ra <= COVER_TOLERANCE:
                    covered[k] = a
                    break
            else:
                kept.append(k)
        return covered

    def container(self, k: int) -> int:
        """Body k's container (``covered_by``), or k itself where it has none."""
        return self.covered_by[k] if self.covered_by[k] >= 0 else k

    def _row_pairs(self) -> tuple[list[tuple[int, int]], list[tuple[int, int, int]]]:
        """The self pairs the rows monitor every tick, and those they monitor only near d_s: of
        ``self_pairs``, (i, j) where (c_i, c_j) is monitored too (c_k: k's container, or k itself;
        not both k themselves) goes to the second list as (i, j, the index of (c_i, c_j) in the
        first). A shape inside another is at least as far from anything, so while the containers'
        pair is beyond d_s + ``COVER_REACH`` the rows that keep it d_s apart keep this one too;
        nearer, it has its own rows (``self_pass``), and a pair inside d_s never comes nearer
        (docs/model.md "verify")."""
        monitored = set(self.self_pairs)
        pairs, covered = [], []
        for i, j in self.self_pairs:
            a, b = sorted((self.container(i), self.container(j)))
            if (a, b) != (i, j) and (a, b) in monitored:
                covered.append((i, j, a, b))
            else:
                pairs.append((i, j))
        index = {p: k for k, p in enumerate(pairs)}
        return pairs, [(i, j, index[(a, b)]) for i, j, a, b in covered]

    # ------------------------------------------------------------------ evaluation
    def placements(self, q_arm: FloatArray) -> list[pin.SE3]:
        """Every body's pose in the base frame at q_arm (runs forward kinematics)."""
        model, data = self.arm.model, self.arm.data
        pin.forwardKinematics(model, data, self.arm.pin_q(q_arm))
        return self.placements_after_fk()

    def placements_after_fk(self) -> list[pin.SE3]:
        """Every body's pose in the base frame from the arm's current forward kinematics."""
        oMi = self.arm.data.oMi
        return [self.placement(k, oMi) for k in range(len(self.bodies))]

    def placement(self, k: int, oMi: Any) -> pin.SE3:
        """Body k's pose in the base frame, the joints at ``oMi`` (a Pinocchio data's, after its
        forward kinematics)."""
        b = self.bodies[k]
        return oMi[b.joint] * b.placement if b.joint else b.placement


def robot_geometry(robot: RobotConfig, arm: ArmModel) -> RobotGeometry:
    """The robot's geometry, built once per arm model (the pair selection samples configurations:
    ~0.1–1 s) and shared by every controller and referee of that model."""
    geo = getattr(arm, "_collision_geometry", None)
    if geo is None or geo.robot is not robot:
        geo = RobotGeometry(robot, arm)
        arm._collision_geometry = geo  # type: ignore[attr-defined]
    return geo


def exempt_mask(geometry: RobotGeometry, exempt: tuple[str, ...]) -> BoolArray:
    """True for the bodies an obstacle is checked against: all but those on its ``exempt`` links
    ("ee": every body on the EE frame's joint)."""
    ee_joint = geometry.arm.model.frames[geometry.arm.frame_id].parentJoint
    return np.array(
        [not (b.link in exempt or ("ee" in exempt and b.joint == ee_joint)) for b in geometry.bodies], dtype=bool
    )


def transform(M: pin.SE3) -> coal.Transform3s:
    return coal.Transform3s(M.rotation, M.translation)


_REQ = coal.DistanceRequest()


def distance(
    a: coal.CollisionGeometry, Ma: pin.SE3, b: coal.CollisionGeometry, Mb: pin.SE3
) -> tuple[float, FloatArray, FloatArray]:
    """(d, p_a, p_b): the signed distance of two shapes and their closest points (frame of Ma, Mb)."""
    res = coal.DistanceResult()
    d = coal.distance(a, transform(Ma), b, transform(Mb), _REQ, res)
    return float(d), np.asarray(res.getNearestPoint1(), dtype=float), np.asarray(res.getNearestPoint2(), dtype=float)
