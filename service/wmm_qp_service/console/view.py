"""The console's 3D scene (viser): the robot from its URDF, its base, the target gizmo, the DM
arrow, the force-manipulability ellipsoid, trails, obstacles and the fence.

Frames: the world is the robot's world (the base frame's z = 0, its origin at the base's pose);
the robot is drawn at its ground-truth pose (``sim/truth``'s ``base_true``; without one at
odometry), the odometry pose the controller uses (``state.q_base``) as a labelled frame beside it.
"""

from __future__ import annotations

import math
from functools import partial
from typing import TYPE_CHECKING, Any

import numpy as np

from wmm_qp import RobotConfig, Scene, WmmModel
from wmm_qp.config import FloatArray, ShapeConfig

from .geometry import (
    Ellipsoid,
    Trail,
    display_scale,
    drawn_radii,
    force_ellipsoid,
    matrix_to_quat,
    rpy_quat,
    yaw_quat,
)

if TYPE_CHECKING:
    import viser

GREY = (150, 150, 160)
DARK = (80, 80, 90)
TARGET = (255, 140, 0)
EE = (30, 144, 255)
BASE_TRAIL = (60, 179, 113)
OBSTACLE = (200, 60, 60)
FENCE = (220, 180, 0)
ELLIPSOID = (147, 112, 219)
ARROW = (220, 20, 60)


def wheel_positions(robot: RobotConfig) -> list[tuple[float, float]]:
    """(x, y) of each wheel's contact point in the base frame (docs/robots.md, the kinds' tables)."""
    b = robot.base
    if b.kind == "mecanum":
        return [(b.l1, b.l2), (b.l1, -b.l2), (-b.l1, b.l2), (-b.l1, -b.l2)]
    if b.kind == "omni":
        return [(b.base_radius * math.cos(math.radians(a)), b.base_radius * math.sin(math.radians(a)))
                for a in (90.0, 210.0, 330.0)]
    if b.kind == "diff_drive":
        return [(0.0, b.track_width / 2), (0.0, -b.track_width / 2)]
    return []


def add_shape(scene: Any, name: str, shape: ShapeConfig, color: tuple[int, int, int],
              opacity: float | None = None) -> None:
    """A collision primitive (box, sphere, capsule, cylinder; along local z) at its pose under ``name``."""
    wxyz, pos = rpy_quat(shape.rpy), np.asarray(shape.xyz, float)
    if shape.kind == "box":
        scene.add_box(name, color=color, dimensions=tuple(float(v) for v in shape.size), wxyz=wxyz,
                      position=pos, opacity=opacity)
    elif shape.kind == "sphere":
        scene.add_icosphere(name, radius=shape.radius, color=color, position=pos, opacity=opacity)
    elif shape.kind in ("capsule", "cylinder"):
        scene.add_frame(name, show_axes=False, wxyz=wxyz, position=pos)
        scene.add_cylinder(f"{name}/body", radius=shape.radius, height=shape.length, color=color,
                           opacity=opacity)
        if shape.kind == "capsule":
            for k, z in (("a", shape.length / 2), ("b", -shape.length / 2)):
                scene.add_icosphere(f"{name}/{k}", radius=shape.radius, color=color, position=(0.0, 0.0, z),
                                    opacity=opacity)


class RobotView:
    """Everything the console draws for one attached robot.

    Args:
        server: the viser server.
        robot: the robot description (its URDF, base, collision shapes).
        W: the diagonal of eq. (8)'s torque weights (for the ellipsoid).
        scene: obstacles and fence to draw (None: none).
        pose_task: the gizmo turns too (orientation setpoints).
    """

    def __init__(self, server: viser.ViserServer, robot: RobotConfig, W: FloatArray, scene: Scene | None,
                 pose_task: bool) -> None:
        import yourdfpy
        from viser.extras import ViserUrdf

        self.server = server
        self.robot = robot
        self.model = WmmModel(robot)
        self.W = np.asarray(W, float)
        s = server.scene
        self.floor_z = robot.base.floor_z if math.isfinite(robot.base.floor_z) else 0.0
        s.add_grid("/grid", width=8.0, height=8.0, cell_size=0.25, section_size=1.0, position=(0.0, 0.0, self.floor_z))
        # the robot at its ground-truth pose; the URDF under its mount
        self.base_frame = s.add_frame("/robot", show_axes=False)
        s.add_frame("/robot/mount", show_axes=False, wxyz=rpy_quat(robot.arm.mount_rpy),
                    position=np.asarray(robot.arm.mount_xyz, float))
        self.urdf = yourdfpy.URDF.load(str(robot.arm.urdf), build_scene_graph=True, load_meshes=True,
                                       filename_handler=partial(yourdfpy.filename_handler_magic,
                                                                dir=robot.arm.urdf.parent))
        self.has_meshes = bool(self.urdf.scene is not None and len(self.urdf.scene.geometry) > 0)
        self.viser_urdf = ViserUrdf(server, self.urdf, root_node_name="/robot/mount/urdf") if self.has_meshes else None
        self._link_frames: dict[str, Any] = {}
        self._sticks = False
        if not self.has_meshes:
            self._add_primitives()
        self._add_base()
        self._joint_index = {n: i for i, n in enumerate(self.urdf.actuated_joint_names)}
        self._cfg = np.zeros(len(self._joint_index))
        for name, value in robot.arm.locked:
            if name in self._joint_index:
                self._cfg[self._joint_index[name]] = value
        self._last_q: FloatArray | None = None
        # odometry (a fixed base has none: it would only hide the arm's foot), EE, trails
        fixed = robot.base.kind == "fixed"
        self.odom = s.add_frame("/odometry", axes_length=0.25, axes_radius=0.008, visible=not fixed)
        if not fixed:
            s.add_label("/odometry/label", "odometry", position=(0.0, 0.0, 0.3))
        self.ee_marker = s.add_icosphere("/ee", radius=0.02, color=EE)
        self.ee_trail, self.base_trail = Trail(), Trail(step=0.01)
        self._trail_nodes: dict[str, Any] = {}
        # target gizmo, DM arrow, ellipsoid
        self.gizmo = s.add_transform_controls("/target", scale=0.25, disable_rotations=not pose_task,
                                              depth_test=False, line_width=3.0)
        s.add_icosphere("/target/dot", radius=0.025, color=TARGET)
        self.arrow: Any = None
        self.ellipsoid = s.add_icosphere("/ellipsoid", radius=1.0, color=ELLIPSOID, opacity=0.35, subdivisions=3)
        self._scale: float | None = None
        self.last_ellipsoid: Ellipsoid | None = None
        if scene is not None:
            self.draw_scene(scene)

    # ----------------------------------------------------------------- static parts
    def _add_primitives(self) -> None:
        """Links without meshes (the Gen3's URDF has none): the robot file's collision shapes on
        their links, else a stick from each link to its child joint."""
        s = self.server.scene
        shapes = [sh for sh in self.robot.collision.shapes if sh.link not in ("", "base")]
        for link in {sh.link for sh in shapes}:
            self._link_frames[link] = s.add_frame(f"/robot/mount/links/{link}", show_axes=False)
        for i, sh in enumerate(shapes):
            add_shape(s, f"/robot/mount/links/{sh.link}/shape{i}", sh, GREY)
        if not shapes:
            for j in self.urdf.robot.joints:
                if j.parent not in self._link_frames:
                    self._link_frames[j.parent] = s.add_frame(f"/robot/mount/links/{j.parent}", show_axes=False)
        self._sticks = not shapes

    def _add_base(self) -> None:
        s = self.server.scene
        r = self.robot
        for sh in (*([r.base.body] if r.base.body is not None else []),
                   *[sh for sh in r.collision.shapes if sh.link == "base"]):
            add_shape(s, f"/robot/base_{sh.name}", sh, DARK)
        R = r.base.wheel_radius
        if R > 0 and not self.has_meshes_of_base():
            for k, (x, y) in enumerate(wheel_positions(r)):
                yaw = math.atan2(y, x) if r.base.kind == "omni" else 0.0
                # a wheel's axle is horizontal: the cylinder's z turned onto the base's y (or the radial)
                q = rpy_quat(np.array([math.pi / 2, 0.0, yaw]))
                s.add_cylinder(f"/robot/wheel{k}", radius=R, height=0.05, color=(40, 40, 40), wxyz=q,
                               position=(x, y, self.floor_z + R))

    @property
    def drawn(self) -> str:
        """How the arm is drawn and how many of its links: the URDF's meshes (the links with a
        visual mesh that loaded), the robot file's collision shapes, or sticks."""
        if self.has_meshes:
            scene = self.urdf.scene
            assert scene is not None
            links = {scene.graph.transforms.parents[g] for g in scene.geometry}
            return f"the URDF's meshes ({len(links)} links)"
        if not self._sticks:
            return f"the robot file's collision shapes ({len(self._link_frames)} links)"
        return f"sticks ({len(self._link_frames)} links)"

    def has_meshes_of_base(self) -> bool:
        """The URDF draws the base itself (TIAGo: the URDF's root is on the floor with its wheels)."""
        return self.has_meshes and any("wheel" in n for n in self.urdf.link_map)

    def draw_scene(self, scene: Scene) -> None:
        """Obstacles (translucent) and the fence: the base's polygon on the floor, the EE's box."""
        s = self.server.scene
        for i, ob in enumerate(scene.obstacles):
            if ob.kind == "plane":
                continue
            add_shape(s, f"/scene/obstacle{i}", ob, OBSTACLE, opacity=0.5)
            s.add_label(f"/scene/obstacle{i}/label", ob.name, position=np.asarray(ob.xyz, float))
        f = scene.fence
        if f.base.shape[0] >= 3:
            P = np.column_stack([f.base, np.full(f.base.shape[0], self.floor_z + 0.005)])
            seg = np.stack([P, np.roll(P, -1, axis=0)], axis=1)
            s.add_line_segments("/scene/fence_base", seg, FENCE, thickness=0.02)
        lo, hi = np.asarray(f.ee_lower, float), np.asarray(f.ee_upper, float)
        if np.isfinite(lo).all() and np.isfinite(hi).all():
            c = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
            edges = [(a, b) for a in range(8) for b in range(a + 1, 8) if bin(a ^ b).count("1") == 1]
            s.add_line_segments("/scene/fence_ee", np.array([[c[a], c[b]] for a, b in edges]), FENCE,
                                thickness=0.008)

    # ----------------------------------------------------------------- live parts
    def set_robot(self, q_arm: FloatArray, base_true: FloatArray, q_base: FloatArray) -> bool:
        """The robot's joints and its ground-truth base pose; the odometry frame. Returns whether
        the joints moved (nothing is sent for joints at rest)."""
        self.base_frame.position = (float(base_true[0]), float(base_true[1]), 0.0)
        self.base_frame.wxyz = yaw_quat(float(base_true[2]))
        self.odom.position = (float(q_base[0]), float(q_base[1]), 0.0)
        self.odom.wxyz = yaw_quat(float(q_base[2]))
        q = np.asarray(q_arm, float)
        if self._last_q is not None and q.shape == self._last_q.shape and np.abs(q - self._last_q).max() < 1e-4:
            return False  # at rest: nothing to send to the browsers
        self._last_q = q.copy()
        for name, v in zip(self.robot.arm.joints, q, strict=False):
            if name in self._joint_index:
                self._cfg[self._joint_index[name]] = v
        if self.viser_urdf is not None:
            self.viser_urdf.update_cfg(self._cfg)
            return True
        self.urdf.update_cfg(self._cfg)
        root = self.urdf.base_link
        for link, frame in self._link_frames.items():
            T = self.urdf.get_transform(link, root)
            frame.position = T[:3, 3]
            frame.wxyz = matrix_to_quat(T[:3, :3])
        if self._sticks:
            pts = [self.urdf.get_transform(j.child, root)[:3, 3] for j in self.urdf.robot.joints]
            par = [self.urdf.get_transform(j.parent, root)[:3, 3] for j in self.urdf.robot.joints]
            self.server.scene.add_line_segments("/robot/mount/sticks", np.stack([par, pts], axis=1), GREY,
                                                thickness=0.04)
        return True

    def set_ee(self, ee_true: FloatArray, base_true: FloatArray) -> None:
        """The EE's measured position and the trails of the EE and the base."""
        e = np.asarray(ee_true, float)
        if np.isfinite(e).all():
            self.ee_marker.position = e
        b = np.array([base_true[0], base_true[1], self.floor_z + 0.01])
        for key, trail, p, color in (("ee", self.ee_trail, e, EE), ("base", self.base_trail, b, BASE_TRAIL)):
            if trail.add(p) and len(trail.points) >= 2:
                self._trail_nodes[key] = self.server.scene.add_line_segments(
                    f"/trail_{key}", trail.segments(), color, thickness=0.006)

    def set_dm(self, q_arm: FloatArray, q_base: FloatArray, ee: FloatArray, direction: FloatArray | None,
               show_arrow: bool) -> Ellipsoid | None:
        """The force-manipulability ellipsoid at the EE (from J_m A J_mᵀ, eq. (8)) and the DM
        direction u (base frame, turned to the world by the base's yaw) as an arrow whose length is
        the ellipsoid's radius along u, the DM H2."""
        q = np.asarray(q_arm, float)
        if q.shape != (self.model.n_arm,) or not np.isfinite(q).all():
            return None
        k = self.model.kinematics(np.asarray(q_base, float), q)
        e = force_ellipsoid(k.J_m[:3], self.W)
        if self._scale is None:
            self._scale = display_scale(e)
        self.last_ellipsoid = e
        self.ellipsoid.position = np.asarray(ee, float)
        self.ellipsoid.wxyz = e.wxyz
        r = drawn_radii(e, self._scale)
        self.ellipsoid.scale = (float(r[0]), float(r[1]), float(r[2]))
        if direction is not None and show_arrow:
            u = k.R @ (np.asarray(direction, float) / np.linalg.norm(direction))
            length = min(1.0, e.radius_along(u) * self._scale)
            pts = np.array([[ee, np.asarray(ee, float) + length * u]])
            self.arrow = self.server.scene.add_arrows("/dm_arrow", pts, ARROW, shaft_radius=0.008,
                                                      head_radius=0.02, head_length=0.04)
        elif self.arrow is not None:
            self.arrow.visible = False
        return e

    def remove(self) -> None:
        """Remove everything this view drew (before attaching to another robot)."""
        self.server.scene.reset()
