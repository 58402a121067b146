"""The MuJoCo model of a robot description, built with :class:`mujoco.MjSpec` (no hand-written XML).

Built from what the rest of the stack uses, so the physics and the controller's model cannot
disagree:

- **arm**: the bodies, joints and inertias of the arm's reduced Pinocchio model
  (:class:`~wmm_qp.model.arm.ArmModel`: the URDF with every locked joint fixed at its locked value
  and its links' inertias merged into their parent, the mount folded in). One MuJoCo body per
  joint, at the joint's placement, with its mass, centre of mass and rotational inertia; a hinge
  (revolute, continuous) or a slide (prismatic) along the joint's axis, ``range`` the robot file's
  position limits. Each joint a velocity servo (``velocity`` actuator) whose force is capped at
  the robot file's ``torque_limit`` (``forcelimited``, ``forcerange``).
- **collision geometry**: the bodies of :class:`~wmm_qp.model.collision.RobotGeometry` (the robot
  file's primitives, the URDF's collision shapes with meshes as their convex hulls, the base's box),
  plus a sphere at the task point (``[physics] ee_tip_radius``) that touches the push box. The
  arm's geoms collide with the floor, the obstacles and the box, not with each other (the
  referee counts self collisions); the base's with the obstacles and the box, not the floor.
- **base**: a body at the floor's origin on slide x, slide y and hinge yaw joints (world axes;
  none for a fixed base) carrying the arm, with ``[physics] base_mass`` in a box of the base's
  ``body`` size (a 0.5 m cube without one); no actuators: :class:`~.mujoco_plant.MujocoPlant`
  applies the wheels' traction-limited force.
- **world**: the floor plane at ``[base] floor_z`` (z = 0 where the robot file has none), the
  scene's obstacles (static; planes, the fence, are not physical), the push box as a free body
  with its mass and friction μ (the floor's own friction is 0: MuJoCo takes the larger of two
  geoms' coefficients).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import coal
import mujoco
import numpy as np
import pinocchio as pin

import wmm_qp
from wmm_qp.config import FloatArray, ShapeConfig
from wmm_qp.model.collision import robot_geometry

from .config import BoxConfig, PhysicsConfig

ROBOT_BITS = (1, 0)
"""(contype, conaffinity) of the arm's geoms: they touch the floor, the obstacles and the box, not
each other (MuJoCo: two geoms touch when contype₁ & conaffinity₂ or contype₂ & conaffinity₁)."""
BASE_BITS = (8, 0)
"""(contype, conaffinity) of the base's geoms: the obstacles and the box, not the floor it rolls on."""
FLOOR_BITS = (2, 3)
"""(contype, conaffinity) of the floor: the arm and the box."""
OBSTACLE_BITS = (2, 11)
"""(contype, conaffinity) of the obstacles: the arm, the base and the box."""
BOX_BITS = (2, 9)
"""(contype, conaffinity) of the push box: the arm, the base, the floor and the obstacles."""
MIN_MASS = 1e-4
"""[kg] a body without mass of its own gets this much (MuJoCo needs mass behind every joint)."""

_AXES = {"X": (1.0, 0.0, 0.0), "Y": (0.0, 1.0, 0.0), "Z": (0.0, 0.0, 1.0)}


@dataclass
class MujocoRobot:
    """A compiled model and where the robot's pieces are in it.

    Attributes:
        spec: the specification (kept to rebuild with another box).
        model: the compiled model.
        arm_qpos, arm_dof: qpos and dof addresses of the arm's joints (the robot file's order).
        base_qpos, base_dof: the base's x, y, yaw addresses (empty for a fixed base).
        base_body: the base body's id.
        ee_body: the id of the body that carries the EE frame.
        box_body, box_geom: the push box's body and geom ids (-1: no box).
        floor_z: [m] the physics floor's height.
    """

    spec: mujoco.MjSpec
    model: mujoco.MjModel
    arm_qpos: np.ndarray
    arm_dof: np.ndarray
    base_qpos: np.ndarray
    base_dof: np.ndarray
    base_body: int
    ee_body: int
    box_body: int
    box_geom: int
    floor_z: float


def _quat(R: FloatArray) -> list[float]:
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, np.ascontiguousarray(R, dtype=float).reshape(9))
    return q.tolist()


def _joint_axis(jm: pin.JointModel) -> tuple[int, tuple[float, float, float]]:
    """(MuJoCo joint type, axis) of a one-DOF Pinocchio joint."""
    name = jm.shortname()
    kind = mujoco.mjtJoint.mjJNT_SLIDE if name.startswith("JointModelP") else mujoco.mjtJoint.mjJNT_HINGE
    if "Unaligned" in name:
        axis = np.asarray(jm.extract().axis, dtype=float)
        return kind, (float(axis[0]), float(axis[1]), float(axis[2]))
    return kind, _AXES[name[-1]]


def _add_coal_geom(spec: mujoco.MjSpec, body: mujoco.MjsBody, name: str, shape: coal.CollisionGeometry,
                   M: pin.SE3, bits: tuple[int, int]) -> None:
    g = body.add_geom(name=name, pos=M.translation.tolist(), quat=_quat(M.rotation))
    g.contype, g.conaffinity = bits
    g.mass = 0.0  # the inertias are the URDF's, not the shapes'
    if isinstance(shape, coal.Sphere):
        g.type, g.size = mujoco.mjtGeom.mjGEOM_SPHERE, [shape.radius, 0, 0]
    elif isinstance(shape, coal.Capsule):
        g.type, g.size = mujoco.mjtGeom.mjGEOM_CAPSULE, [shape.radius, shape.halfLength, 0]
    elif isinstance(shape, coal.Cylinder):
        g.type, g.size = mujoco.mjtGeom.mjGEOM_CYLINDER, [shape.radius, shape.halfLength, 0]
    elif isinstance(shape, coal.Box):
        g.type, g.size = mujoco.mjtGeom.mjGEOM_BOX, np.asarray(shape.halfSide, dtype=float).tolist()
    elif isinstance(shape, coal.ConvexBase):
        points = np.array([shape.point(i) for i in range(shape.num_points)], dtype=float)
        spec.add_mesh(name=f"{name}_hull", uservert=points.reshape(-1).tolist())
        g.type, g.meshname = mujoco.mjtGeom.mjGEOM_MESH, f"{name}_hull"
    else:
        raise ValueError(f"collision body {name!r}: no MuJoCo geom for {type(shape).__name__}")


def _add_obstacle(body: mujoco.MjsBody, s: ShapeConfig, bits: tuple[int, int]) -> mujoco.MjsGeom | None:
    """A static or box geom of a world-frame primitive (None: a plane, not physical here)."""
    sizes = {"box": (mujoco.mjtGeom.mjGEOM_BOX, lambda: (0.5 * np.asarray(s.size, dtype=float)).tolist()),
             "sphere": (mujoco.mjtGeom.mjGEOM_SPHERE, lambda: [s.radius, 0.0, 0.0]),
             "capsule": (mujoco.mjtGeom.mjGEOM_CAPSULE, lambda: [s.radius, 0.5 * s.length, 0.0]),
             "cylinder": (mujoco.mjtGeom.mjGEOM_CYLINDER, lambda: [s.radius, 0.5 * s.length, 0.0])}
    if s.kind not in sizes:
        return None
    kind, size = sizes[s.kind]
    R = pin.rpy.rpyToMatrix(np.asarray(s.rpy, dtype=float))
    g = body.add_geom(name=f"obstacle_{s.name}", type=kind, size=size(), pos=np.asarray(s.xyz, dtype=float).tolist(),
                      quat=_quat(R))
    g.contype, g.conaffinity = bits
    return g


def _set_inertia(body: mujoco.MjsBody, inertia: pin.Inertia) -> None:
    """A body's mass [kg], centre of mass [m] and rotational inertia about it [kg·m²], from Pinocchio's."""
    body.explicitinertial = True
    if inertia.mass > MIN_MASS:
        I = np.asarray(inertia.inertia, dtype=float)
        body.mass, body.ipos = float(inertia.mass), np.asarray(inertia.lever, dtype=float).tolist()
        body.fullinertia = [I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2]]
    else:
        body.mass, body.inertia = MIN_MASS, [1e-8, 1e-8, 1e-8]


def add_box(spec: mujoco.MjSpec, box: BoxConfig, floor_z: float) -> None:
    """The push box: a free body, its face at x = ``face_x``, from the floor to ``height``, as deep
    along x as it is wide, with its mass and friction μ."""
    half = [0.5 * box.width, 0.5 * box.width, 0.5 * (box.height - floor_z)]
    b = spec.worldbody.add_body(name="push_box", pos=[box.face_x + half[0], box.center_y, floor_z + half[2]])
    b.add_freejoint(name="push_box")
    g = b.add_geom(name="push_box", type=mujoco.mjtGeom.mjGEOM_BOX, size=half, mass=box.mass)
    g.friction = [box.mu, 0.0, 0.0]
    g.contype, g.conaffinity = BOX_BITS


def build_spec(wmm: wmm_qp.WmmModel, physics: PhysicsConfig, dt: float, box: BoxConfig | None = None,
               obstacles: Sequence[ShapeConfig] = ()) -> mujoco.MjSpec:
    """The specification of the robot, its floor, the obstacles and the box (see the module docstring).

    Args:
        wmm: the robot's model (its config gives the limits, its arm model the bodies).
        physics: the physics parameters.
        dt: [s] the integration step.
        box: the push box, or None.
        obstacles: static world-frame obstacles (the scene's).
    """
    robot = wmm.config
    arm, base_cfg = wmm.arm, robot.base
    spec = mujoco.MjSpec()
    spec.modelname = robot.name
    spec.compiler.degree = False  # joint ranges in radians, as the robot file's
    spec.option.timestep = dt
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.option.gravity = [0.0, 0.0, -physics.g]
    floor_z = float(base_cfg.floor_z) if math.isfinite(base_cfg.floor_z) else 0.0
    floor = spec.worldbody.add_geom(name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[0, 0, 1],
                                    pos=[0.0, 0.0, floor_z], friction=[0.0, 0.0, 0.0])
    floor.contype, floor.conaffinity = FLOOR_BITS
    for s in obstacles:
        _add_obstacle(spec.worldbody, s, OBSTACLE_BITS)
    # the base: planar joints, its own mass in its body's box
    base = spec.worldbody.add_body(name="base")
    if base_cfg.kind != "fixed":
        for name, jtype, direction in (("base_x", mujoco.mjtJoint.mjJNT_SLIDE, [1.0, 0.0, 0.0]),
                                       ("base_y", mujoco.mjtJoint.mjJNT_SLIDE, [0.0, 1.0, 0.0]),
                                       ("base_yaw", mujoco.mjtJoint.mjJNT_HINGE, [0.0, 0.0, 1.0])):
            base.add_joint(name=name, type=jtype, axis=direction)
    size = np.asarray(base_cfg.body.size, dtype=float) if base_cfg.body is not None and base_cfg.body.kind == "box" \
        else np.full(3, 0.5)
    com = np.asarray(base_cfg.body.xyz, dtype=float) if base_cfg.body is not None else np.zeros(3)
    m = physics.base_mass
    own = pin.Inertia(m, com, np.diag([m * (size[1] ** 2 + size[2] ** 2) / 12, m * (size[0] ** 2 + size[2] ** 2) / 12,
                                       m * (size[0] ** 2 + size[1] ** 2) / 12]))
    # the arm: one body per joint of the reduced model (the mount is folded into its placements);
    # the links fixed to its root (joint 0, e.g. panda_link0) ride on the base
    pm = arm.model
    _set_inertia(base, own + pm.inertias[0])
    bodies = [base]
    for j in range(1, pm.njoints):
        parent = bodies[pm.parents[j]]
        M = pm.jointPlacements[j]
        b = parent.add_body(name=pm.names[j], pos=M.translation.tolist(), quat=_quat(M.rotation))
        _set_inertia(b, pm.inertias[j])
        kind, axis = _joint_axis(pm.joints[j])
        b.add_joint(name=pm.names[j], type=kind, axis=list(axis), armature=physics.armature)
        bodies.append(b)
    arm_cfg = robot.arm
    for k, name in enumerate(arm_cfg.joints):
        jt = spec.joint(name)
        lo, hi = float(arm_cfg.position_lower[k]), float(arm_cfg.position_upper[k])
        if math.isfinite(lo) and math.isfinite(hi):
            jt.limited, jt.range = mujoco.mjtLimited.mjLIMITED_TRUE, [lo, hi]
        else:
            jt.limited = mujoco.mjtLimited.mjLIMITED_FALSE
        limit = float(arm_cfg.torque_limit[k])
        a = spec.add_actuator(name=name, target=name, trntype=mujoco.mjtTrn.mjTRN_JOINT)
        a.set_to_velocity(kv=limit / physics.servo_error)  # full torque at servo_error of velocity error
        a.forcelimited, a.forcerange = mujoco.mjtLimited.mjLIMITED_TRUE, [-limit, limit]
    # collision geometry, and the tip that pushes
    geo = robot_geometry(robot, arm)
    for i, body in enumerate(geo.bodies):
        _add_coal_geom(spec, bodies[body.joint], f"{body.name}_{i}", body.shape, body.placement,
                       ROBOT_BITS if body.joint else BASE_BITS)
    frame = pm.frames[arm.frame_id]
    tip = bodies[frame.parentJoint].add_geom(name="ee_tip", type=mujoco.mjtGeom.mjGEOM_SPHERE,
                                             size=[physics.ee_tip_radius, 0, 0],
                                             pos=frame.placement.translation.tolist(), mass=0.0)
    tip.contype, tip.conaffinity = ROBOT_BITS
    if box is not None:
        add_box(spec, box, floor_z)
    return spec


def compile_robot(spec: mujoco.MjSpec, wmm: wmm_qp.WmmModel) -> MujocoRobot:
    """Compile the specification and find the robot's pieces in the model."""
    model = spec.compile()
    return locate(spec, model, wmm)


def locate(spec: mujoco.MjSpec, model: mujoco.MjModel, wmm: wmm_qp.WmmModel) -> MujocoRobot:
    """Where the robot's joints, base, EE body and box are in a compiled model."""
    joints = [model.joint(n) for n in wmm.config.arm.joints]
    base = [model.joint(n) for n in ("base_x", "base_y", "base_yaw")] if wmm.config.base.kind != "fixed" else []
    pm = wmm.arm.model
    ee_body = model.body(pm.names[pm.frames[wmm.arm.frame_id].parentJoint]).id
    box_body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "push_box")
    box_geom = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "push_box")
    floor = model.geom("floor")
    return MujocoRobot(
        spec=spec, model=model,
        arm_qpos=np.array([int(j.qposadr[0]) for j in joints], dtype=np.int64),
        arm_dof=np.array([int(j.dofadr[0]) for j in joints], dtype=np.int64),
        base_qpos=np.array([int(j.qposadr[0]) for j in base], dtype=np.int64),
        base_dof=np.array([int(j.dofadr[0]) for j in base], dtype=np.int64),
        base_body=model.body("base").id, ee_body=ee_body, box_body=box_body, box_geom=box_geom,
        floor_z=float(model.geom_pos[floor.id][2]))
