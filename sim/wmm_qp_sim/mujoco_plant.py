"""The physics plant: the robot as rigid bodies in MuJoCo, driven like a real robot's drives.

The model is built from the robot description (:mod:`.mujoco_model`). Each step:

- **Arm**: each joint's velocity servo (a MuJoCo ``velocity`` actuator, gain
  torque_limit / ``servo_error``) drives it toward the written rate. Gravity is carried by the
  robot's own loop, as on a torque-controlled arm: the drives add the bias forces (gravity,
  Coriolis) MuJoCo computes at the current state, ``qfrc_bias``, clipped to the torque limit, and
  the servo gets what is left (its ``forcerange`` is [−τ_lim − g, τ_lim − g] that step), so the
  total a joint exerts never exceeds ``torque_limit``. A joint that needs more (a heavy push, a
  load it cannot hold) does not follow: it is reported at its torque limit (``stalled_joint``)
  and, once its rate is ``tracking_error`` off the command, as not following (``lagging_joint``).
- **The drives' position limits**: a velocity servo's rate is off its target by the load it does
  not carry over its gain (the arm's other joints accelerating load it through the inertia; a
  push); commanded 0 at a limit, such a joint drifts on into it, and bounds (13), 0 at a limit,
  never pull it back. Each drive therefore caps its servo's target rate at
  (q_max − m − q)/Δt above and (q_min + m − q)/Δt below (m = ``limit_margin``, Δt the step), the
  rate that reaches its own limit in one step, as a drive's firmware limit does: a joint held at
  its limit stays within m of the robot file's limit, and one past the drive's line is pulled back.
  (The cap also holds a joint a command would carry past its limit: the kinematic plant, which
  executes every command as it is, shows such a controller to the referee.)
- **Base** (wheel level): the written wheel speeds give the commanded world twist P(ψ)·w
  (eq. (3)), integrated into the pose the wheels roll the base to, p_w. Rolling wheels tie the base
  to p_w: a force servo F = K_p·(p_w − p) + K_v·(P(ψ)·w − ṗ) (K_p = m·ω², K_v = 2·m·ω,
  ω = 1 / ``base_time_constant``; the yaw the same with the base's yaw inertia) whose planar force
  is capped at the traction limit μ_wheel·m·g and its yaw torque at μ_wheel·m·g·ρ (m the whole
  robot's mass, ρ the wheels' yaw lever R / (n·mean|M_ω,i|): half the track of a differential
  drive, l1 + l2 of the Mecanum base). Pushed harder than that, the wheels slip: the force stays
  at the cap and p_w is re-anchored where the base is. A differential drive's commanded twist has
  no lateral part, so the same servo holds it against sliding sideways, up to the traction limit;
  Mecanum and omni bases are servoed in all three directions.
- **Measurements**: joint positions and velocities, the drives' torques (servo + gravity
  compensation), the wheel speeds that would produce the base's achieved body twist (the base
  kind's inverse, M⁺), the true base pose, the force the EE's body applies to the box (its
  contacts with the box), the box's face.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import mujoco
import numpy as np

import wmm_qp
from wmm_qp.config import FloatArray, ShapeConfig

from .config import BoxConfig, PhysicsConfig
from .contact import Box
from .mujoco_model import MujocoRobot, add_box, build_spec, compile_robot, locate
from .plant import PlantState


class MujocoPlant:
    """Rigid-body physics behind the robot's firmware (see the module docstring).

    Args:
        model: the robot's kinematic model (its description builds the MuJoCo model).
        physics: the physics parameters.
        dt: [s] the step the model is compiled for (another dt at :meth:`advance` re-sets it).
        obstacles: static world-frame obstacles (the scene's).
    """

    def __init__(self, model: wmm_qp.WmmModel, physics: PhysicsConfig, dt: float = 1e-3,
                 obstacles: Sequence[ShapeConfig] = ()) -> None:
        self.wmm = model
        self.physics = physics
        self.n_arm, self.n_wheels = model.n_arm, model.n_wheels
        self.torque_limit = np.array(model.config.arm.torque_limit, dtype=float)
        arm = model.config.arm
        self.q_min = np.array(arm.position_lower, dtype=float) + physics.limit_margin  # [rad or m] the drives' limits
        self.q_max = np.array(arm.position_upper, dtype=float) - physics.limit_margin
        self.robot: MujocoRobot = compile_robot(build_spec(model, physics, dt, None, obstacles), model)
        self.data = mujoco.MjData(self.robot.model)
        self.box: Box | None = None
        M = model.base.M
        yaw = np.abs(M[2]) if M.shape[1] else np.zeros(0)
        R = float(model.config.base.wheel_radius)
        self.lever = R / (len(yaw) * float(yaw.mean())) if yaw.size and yaw.mean() > 0 else 0.5  # ρ [m]
        self.reset(np.zeros(3), np.array(model.config.arm.start, dtype=float), None)

    # ------------------------------------------------------------------ scene
    def _set_box(self, box: BoxConfig | None, keep_state: bool) -> None:
        r = self.robot
        if box is not None and box.height <= r.floor_z:  # no volume above the floor: no box
            box = None
        old = r.spec.body("push_box")
        if old is not None:
            r.spec.delete(old)
        if box is not None:
            add_box(r.spec, box, r.floor_z)
        if keep_state:
            model, self.data = r.spec.recompile(r.model, self.data)
        else:
            model = r.spec.compile()
            self.data = mujoco.MjData(model)
        self.robot = locate(r.spec, model, self.wmm)
        self.box = Box(box) if box is not None else None

    def reset(self, q_base: FloatArray, q_arm: FloatArray, box: BoxConfig | None) -> None:
        """At rest at (q_base [m, m, rad], q_arm [rad]) with this box."""
        self._set_box(box, keep_state=False)
        self.q_base0 = np.array(q_base, dtype=float).reshape(3)
        mujoco.mj_resetData(self.robot.model, self.data)
        self.data.qpos[self.robot.arm_qpos] = np.asarray(q_arm, dtype=float).reshape(self.n_arm)
        self.set_base_pose(self.q_base0)
        self.cmd_arm = np.zeros(self.n_arm)
        self.cmd_wheels = np.zeros(self.n_wheels)
        self.tau = np.zeros(self.n_arm)
        self.stalled_joint: int | None = None
        self.lagging_joint: int | None = None
        m = self.robot.model
        mujoco.mj_forward(m, self.data)
        self.mass = float(m.body_subtreemass[self.robot.base_body])
        if self.robot.base_dof.size:
            e, Me = np.zeros(m.nv), np.zeros(m.nv)
            e[int(self.robot.base_dof[2])] = 1.0
            mujoco.mj_mulM(m, self.data, Me, e)  # the yaw column of the mass matrix
            self.yaw_inertia = float(Me[int(self.robot.base_dof[2])])  # [kg·m²] about the base's axis

    def place_box(self, box: BoxConfig | None) -> None:
        """Put a box in the scene now (None: remove it), keeping the robot's state."""
        self._set_box(box, keep_state=True)

    def set_base_pose(self, pose: Sequence[float] | FloatArray) -> None:
        """Carry the base to pose [m, m, rad], keeping its velocity."""
        r, p = self.robot, np.array(pose, dtype=float).reshape(3)
        if r.base_qpos.size:
            self.data.qpos[r.base_qpos] = p
            self.rolled = p.copy()  # [m, m, rad] where the wheels have rolled the base to
        else:  # a fixed base: the body itself is where it stands
            r.model.body_pos[r.base_body] = [p[0], p[1], 0.0]
            r.model.body_quat[r.base_body] = [np.cos(p[2] / 2), 0.0, 0.0, np.sin(p[2] / 2)]
            self.q_base0 = p
        mujoco.mj_kinematics(r.model, self.data)

    # ------------------------------------------------------------------ stepping
    def write(self, wheel_speeds: FloatArray, arm_rates: FloatArray) -> None:
        """The rates the servos follow: wheels [rad/s], joints [rad/s or m/s]."""
        self.cmd_wheels = np.array(wheel_speeds, dtype=float)
        self.cmd_arm = np.array(arm_rates, dtype=float)

    def advance(self, dt: float) -> None:
        """One physics step of dt [s]: gravity compensation, servos (capped at the drives' position
        limits), the wheels' traction."""
        r, d = self.robot, self.data
        m = r.model
        if m.opt.timestep != dt:
            m.opt.timestep = dt
        mujoco.mj_step1(m, d)
        lim = self.torque_limit
        g = np.clip(d.qfrc_bias[r.arm_dof], -lim, lim)  # the drives carry the robot, within their limits
        d.qfrc_applied[r.arm_dof] = g
        m.actuator_forcerange[:, 0] = -lim - g
        m.actuator_forcerange[:, 1] = lim - g
        q = d.qpos[r.arm_qpos]  # the drives' limits: the rate that reaches each one in this step, at most
        d.ctrl[:] = np.minimum(np.maximum(self.cmd_arm, (self.q_min - q) / dt), (self.q_max - q) / dt)
        if r.base_dof.size:
            d.qfrc_applied[r.base_dof] = self._traction(d.qpos[r.base_qpos], d.qvel[r.base_dof], dt)
        mujoco.mj_step2(m, d)
        self.tau = d.actuator_force + g
        at_limit = np.flatnonzero(np.abs(self.tau) >= lim * (1.0 - 1e-6))
        self.stalled_joint = int(at_limit[0]) if at_limit.size else None
        lag = np.flatnonzero(np.abs(d.qvel[r.arm_dof] - self.cmd_arm) > self.physics.tracking_error)
        self.lagging_joint = int(lag[0]) if lag.size else None
        if self.box is not None and r.box_body >= 0:
            R = d.xmat[r.box_body].reshape(3, 3)
            # the face's centre (the body's centre less half its depth along the box's own x)
            self.box.face_x = float(d.xpos[r.box_body][0] - 0.5 * self.box.config.width * R[0, 0])
            self.box.rpy = _rpy(R)
            self.box.center = d.xpos[r.box_body].copy()

    def _traction(self, qpos: FloatArray, qvel: FloatArray, dt: float) -> FloatArray:
        """[N, N, N·m] the wheels' force on the base at pose qpos, velocity qvel, traction-limited
        (the module docstring); advances the rolled pose p_w by dt [s]."""
        p = self.physics
        t = self.wmm.base.body_twist(self.cmd_wheels)  # eq. (3): M·w, body frame
        c, s = np.cos(qpos[2]), np.sin(qpos[2])
        v_cmd = np.array([c * t[0] - s * t[1], s * t[0] + c * t[1], t[2]])  # P(ψ)·w
        self.rolled = self.rolled + v_cmd * dt
        w = 1.0 / p.base_time_constant
        err = self.rolled - qpos
        F = self.mass * (w * w * err[:2] + 2.0 * w * (v_cmd[:2] - qvel[:2]))
        tz = self.yaw_inertia * (w * w * err[2] + 2.0 * w * (v_cmd[2] - qvel[2]))
        cap = p.mu_wheel * self.mass * p.g
        norm = float(np.hypot(F[0], F[1]))
        if norm > cap:  # the wheels slip: the most they can push, and they roll on from here
            F *= cap / norm
            self.rolled[:2] = qpos[:2]
        if abs(tz) > cap * self.lever:
            tz = float(np.copysign(cap * self.lever, tz))
            self.rolled[2] = qpos[2]
        return np.array([F[0], F[1], tz])

    # ------------------------------------------------------------------ measuring
    def contact_force(self) -> FloatArray:
        """[N] the force the EE's body applies to the box (world), summed over their contacts."""
        r, d = self.robot, self.data
        total = np.zeros(3)
        if r.box_geom < 0:
            return total
        f = np.zeros(6)
        bodies = r.model.geom_bodyid
        for i in range(d.ncon):
            con = d.contact[i]
            g1, g2 = int(con.geom1), int(con.geom2)
            if r.box_geom not in (g1, g2) or r.ee_body not in (bodies[g1], bodies[g2]):
                continue
            mujoco.mj_contactForce(r.model, d, i, f)
            on_geom2 = con.frame.reshape(3, 3).T @ f[:3]  # contact frame → world: geom1's push on geom2
            total += on_geom2 if g2 == r.box_geom else -on_geom2
        return total

    def base_pose(self) -> FloatArray:
        """[m, m, rad] the true base pose."""
        r = self.robot
        return self.data.qpos[r.base_qpos].copy() if r.base_qpos.size else self.q_base0.copy()

    def wheel_speeds(self) -> FloatArray:
        """[rad/s] the wheel speeds of the base's achieved body twist (M⁺ · twist)."""
        r = self.robot
        if not r.base_dof.size:
            return np.zeros(self.n_wheels)
        yaw = float(self.data.qpos[r.base_qpos[2]])
        v = self.data.qvel[r.base_dof]
        c, s = np.cos(yaw), np.sin(yaw)
        body = np.array([c * v[0] + s * v[1], -s * v[0] + c * v[1], v[2]])
        return np.asarray(self.wmm.base.wheel_speeds(body), dtype=float)

    def read(self) -> PlantState:
        """What the sensors measure now (ground truth included)."""
        r, d = self.robot, self.data
        return PlantState(q_arm=d.qpos[r.arm_qpos].copy(), v_arm=d.qvel[r.arm_dof].copy(),
                          wheel_speeds=self.wheel_speeds(), base_true=self.base_pose(), tau=self.tau.copy(),
                          contact_force=self.contact_force(), stalled_joint=self.stalled_joint,
                          lagging_joint=self.lagging_joint)


def _rpy(R: FloatArray) -> FloatArray:
    """[rad] roll, pitch, yaw of the rotation matrix R (R = Rz(yaw)·Ry(pitch)·Rx(roll))."""
    return np.array([math.atan2(R[2, 1], R[2, 2]), math.asin(max(-1.0, min(1.0, -R[2, 0]))),
                     math.atan2(R[1, 0], R[0, 0])])
