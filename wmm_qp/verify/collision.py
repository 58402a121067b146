"""The collision rule of ``wmm-qp verify``: every monitored pair of the robot description (self,
floor, the scene's obstacles) and the fence, on the geometry itself, no Jacobian.

The distance after one tick, computed from the geometry at the predicted configuration
(q + Δt·v_m, the base moved by Δt·P(ψ) v_b; no linearisation), stays at or above the safety
distance, or — if the pair is already closer — no closer than it is, or — if even full braking
at A cannot achieve that — no closer than full braking takes it; the base's origin stays inside
the fence's polygon and the EE inside the EE fence the same way. Tolerance 1e-5 m (the second-order
term of one tick's motion the linear rows do not see).
"""

from __future__ import annotations

import coal
import numpy as np
import pinocchio as pin

from .._typing import FloatArray
from ..model.collision import coal_shape, exempt_mask, robot_geometry, shape_pose
from ..model.wmm import WmmModel
from ..scene import Scene
from ..types import AT_REST, Command, RobotState

COLLISION_TOL = 1e-5  # [m]


class CollisionJudge:
    """The collision rule (the module docstring) for one robot, scene and safety distances.

    Args:
        model: the robot.
        scene: its obstacles and fence.
        safety_distance, floor_margin: [m] d_s of robot pairs (and obstacles), and of the floor.
    """

    def __init__(self, model: WmmModel, scene: Scene, safety_distance: float, floor_margin: float) -> None:
        self.model, self.scene = model, scene
        self.geo = robot_geometry(model.config, model.arm)
        self.d_s, self.d_floor = safety_distance, floor_margin
        self._floor = coal.Halfspace(np.array([0.0, 0.0, 1.0]), self.geo.floor_z)  # solid: z ≤ floor_z
        self.obstacles = []
        for o in scene.obstacles:
            shape, pose = coal_shape(o), shape_pose(o)
            if o.kind == "plane":
                centre, radius = np.zeros(3), np.inf
            else:
                shape.computeLocalAABB()
                centre, radius = pose.act(np.asarray(shape.aabb_center, dtype=float)), float(shape.aabb_radius)
            self.obstacles.append((o.name, shape, pose, exempt_mask(self.geo, o.exempt), centre, radius))
        # a pair whose bounding spheres are this far apart cannot break the rule (its distance is
        # at least the safety distance): its gap stands in for the distance (exact for the rule)
        self.cutoff = max(safety_distance, floor_margin) + 0.01
        self.last = ""  # the pair of the last violation

    def distances(self, q_base: FloatArray, q_arm: FloatArray) -> dict[str, float]:
        """Every monitored pair's distance [m] (and the fence's margins) at one configuration."""
        geo = self.geo
        M = geo.placements(q_arm)  # base frame
        c, s = np.cos(q_base[2]), np.sin(q_base[2])
        wb = pin.SE3(np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]), np.array([q_base[0], q_base[1], 0.0]))
        W = [wb * m for m in M]
        T = [coal.Transform3s(m.rotation, m.translation) for m in W]
        req, out = coal.DistanceRequest(), {}
        b = geo.bodies
        cen = [W[k].act(body.center) for k, body in enumerate(b)]  # bounding spheres, world frame
        cut = self.cutoff
        for i, j in geo.self_pairs:
            gap = float(np.linalg.norm(cen[i] - cen[j])) - b[i].radius - b[j].radius
            out[f"{b[i].name}/{b[j].name}"] = gap if gap >= cut else coal.distance(
                b[i].shape, T[i], b[j].shape, T[j], req, coal.DistanceResult())
        for i in geo.floor_bodies:
            gap = float(cen[i][2]) - b[i].radius - geo.floor_z
            out[f"{b[i].name}/floor"] = gap if gap >= cut else coal.distance(
                b[i].shape, T[i], self._floor, coal.Transform3s(), req, coal.DistanceResult())
        for name, shape, pose, checked, centre, radius in self.obstacles:
            To = coal.Transform3s(pose.rotation, pose.translation)
            for i in (int(k) for k in np.flatnonzero(checked)):
                gap = float(np.linalg.norm(cen[i] - centre)) - b[i].radius - radius
                out[f"{b[i].name}/{name}"] = gap if gap >= cut else coal.distance(
                    b[i].shape, T[i], shape, To, req, coal.DistanceResult())
        fence = self.scene.fence
        A, cc = fence.half_planes()
        for k in range(A.shape[0]):
            out[f"fence:base edge {k}"] = float(cc[k] - A[k] @ q_base[:2])
        x = self.model.ee_position(q_base, q_arm)
        for ax in range(3):
            if np.isfinite(fence.ee_upper[ax]):
                out[f"fence:ee {'xyz'[ax]}+"] = float(fence.ee_upper[ax] - x[ax])
            if np.isfinite(fence.ee_lower[ax]):
                out[f"fence:ee {'xyz'[ax]}-"] = float(x[ax] - fence.ee_lower[ax])
        return out

    def _margin(self, name: str) -> float:
        if name.startswith("fence:"):
            return 0.0
        return self.d_floor if name.endswith("/floor") else self.d_s

    def _after(self, dt: float, state: RobotState, wheels: FloatArray, arm_rates: FloatArray) -> dict[str, float]:
        q_b = state.q_base + dt * (self.model.base.P(float(state.q_base[2])) @ wheels)
        return self.distances(q_b, state.q_arm + dt * arm_rates)

    def check(self, dt: float, state: RobotState, cmd: Command, tol: float = COLLISION_TOL) -> int:
        """The number of pairs (and fence margins) the command violates (module docstring)."""
        cfg = self.model.config
        a, aw = cfg.arm.acceleration_max * dt, cfg.base.wheel_acceleration_max * dt
        v0 = state.v_arm
        w0 = np.zeros(cfg.base.n_wheels) if state.wheel_speeds is AT_REST else state.wheel_speeds
        w, v = np.asarray(cmd.wheel_speeds, dtype=float), np.asarray(cmd.arm_rates, dtype=float)
        if not (np.isfinite(w).all() and np.isfinite(v).all()):
            return 1
        now = self.distances(state.q_base, state.q_arm)
        nxt = self._after(dt, state, w, v)
        brake = None
        bad = 0
        for name, d1 in nxt.items():
            floor = min(now[name], self._margin(name))
            if d1 >= floor - tol:
                continue
            if brake is None:
                brake = self._after(dt, state, w0 - np.clip(w0, -aw, aw), v0 - np.clip(v0, -a, a))
            if d1 >= brake[name] - tol:
                continue
            bad += 1
            self.last = f"{name}: {now[name]:.4f} -> {d1:.4f} m"
        return bad


