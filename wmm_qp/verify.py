"""Constraint-satisfaction referee and random state sampler (``wmm-qp verify``).

The referee re-derives every hard bound from the raw robot config, independently of
:mod:`wmm_qp.limits` (which the controllers use), and checks one command against one state.
It asks of a command only what is physically possible from the state:

* acceleration: |v − v_prev| ≤ A·dt;
* velocity: |v| ≤ V, or — if the joint is already faster than V — it slows down at A;
* position: the next position q + v·dt stays inside the limits (or, beyond a limit, does not
  go further out), unless even full braking at A cannot achieve it, in which case the
  command must be that full braking; and the robot must still be able to stop: holding the
  command for dt and then braking at A tick by tick must end inside the limits, or no further
  out than braking right now would;
* wheel: wheel speed and acceleration, the same way;
* ee_box (DM_CARTESIAN only, on the axes with a finite bound of eq. (17)'s box): the EE position
  predicted after one tick, p = x + Δt·J v (eqs. (2), (5), the model's kinematics), stays inside
  the box, or — if the EE is already outside — no further out than it is, or — if even full
  braking at A cannot keep it in — no further out than full braking takes it. The box comes from
  the controller's config (like the limits from the robot's), the rule is re-derived here.

* collision (with a :class:`CollisionJudge`: every monitored pair of the robot description, self,
  floor and the scene's obstacles, and the fence): the distance after one tick, computed from the
  geometry at the predicted configuration (q + Δt·v_m, the base moved by Δt·P(ψ) v_b; no Jacobian,
  no linearisation), stays at or above the safety distance, or — if the pair is already closer —
  no closer than it is, or — if even full braking at A cannot achieve that — no closer than full
  braking takes it; the base's origin stays inside the fence polygon and the EE inside the fence
  box the same way.

Tolerance: 1e-9 (absolute, in rad/s; for ee_box in m/s, i.e. 1e-9·Δt on the position); for
collision 1e-5 m (the second-order term of one tick's motion the linear rows do not see).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np

from ._typing import FloatArray
from .config import CollisionParams, RobotConfig
from .model.wmm import WmmModel
from .scene import Scene
from .types import AT_REST, Command, Mode, Reference, RobotState

KINDS = ("position", "velocity", "acceleration", "wheel", "ee_box", "collision")
TOL = 1e-9
COLLISION_TOL = 1e-5  # [m]


def check_command(
    robot: RobotConfig,
    dt: float,
    state: RobotState,
    cmd: Command,
    tol: float = TOL,
    *,
    model: WmmModel | None = None,
    ee_box: tuple[FloatArray, FloatArray] | None = None,
    collision: CollisionJudge | None = None,
) -> dict[str, int]:
    """Number of joints (or wheels, or EE axes) whose command violates each kind of hard bound.

    ``ee_box`` = (lower, upper) [m], given with ``model``, also checks the EE box of eq. (17) (pass
    it for a DM_CARTESIAN command only); otherwise the "ee_box" count is 0.
    """
    arm, base = robot.arm, robot.base
    v, v0, q = np.asarray(cmd.arm_rates), state.v_arm, state.q_arm
    a = arm.acceleration_max * dt
    out = dict.fromkeys(KINDS, 0)
    finite = np.isfinite(v)
    out["acceleration"] = int(np.sum(~finite | (np.abs(v - v0) > a + tol)))
    out["velocity"] = int(np.sum(~finite | (np.abs(v) > np.maximum(arm.velocity_max, np.abs(v0) - a) + tol)))
    with np.errstate(invalid="ignore"):
        up = np.maximum(arm.position_upper - q, 0.0) / dt  # never further out
        lo = np.minimum(arm.position_lower - q, 0.0) / dt
        too_high = v > np.maximum(up, v0 - a) + tol
        too_low = v < np.minimum(lo, v0 + a) - tol
        # braking distance: where the joint stops if it brakes at A after this command
        stop_cmd = _stop_position(q, v, a, dt)
        stop_now = _stop_position(q, v0 - np.clip(v0, -a, a), a, dt)
        overrun_hi = stop_cmd > np.maximum(arm.position_upper, stop_now) + tol * dt
        overrun_lo = stop_cmd < np.minimum(arm.position_lower, stop_now) - tol * dt
    out["position"] = int(np.sum(~finite | too_high | too_low | overrun_hi | overrun_lo))
    w = np.asarray(cmd.wheel_speeds)
    w0 = np.zeros(base.n_wheels) if state.wheel_speeds is AT_REST else state.wheel_speeds
    aw = base.wheel_acceleration_max * dt
    bad_w = (
        ~np.isfinite(w)
        | (np.abs(w - w0) > aw + tol)
        | (np.abs(w) > np.maximum(base.wheel_speed_max, np.abs(w0) - aw) + tol)
    )
    out["wheel"] = int(np.sum(bad_w))
    if model is not None and ee_box is not None:
        out["ee_box"] = check_ee_box(model, dt, state, cmd, ee_box[0], ee_box[1], tol)
    if collision is not None:
        out["collision"] = collision.check(dt, state, cmd)
    return out


def check_ee_box(
    model: WmmModel,
    dt: float,
    state: RobotState,
    cmd: Command,
    lower: FloatArray,
    upper: FloatArray,
    tol: float = TOL,
) -> int:
    """Number of EE axes on which the command leaves the box [lower, upper] of eq. (17) (see the
    module docstring): p = x + Δt·J v against the box widened to x and to full braking's p."""
    arm, base = model.config.arm, model.config.base
    lower, upper = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
    kin = model.kinematics(state.q_base, state.q_arm)  # eqs. (2), (5)
    a, aw = arm.acceleration_max * dt, base.wheel_acceleration_max * dt
    v0 = state.v_arm
    w0 = np.zeros(base.n_wheels) if state.wheel_speeds is AT_REST else state.wheel_speeds
    brake = np.concatenate([w0 - np.clip(w0, -aw, aw), v0 - np.clip(v0, -a, a)])  # full braking at A
    v = np.concatenate([np.asarray(cmd.wheel_speeds, dtype=float), np.asarray(cmd.arm_rates, dtype=float)])
    p, p_brake = kin.x + dt * (kin.J @ v), kin.x + dt * (kin.J @ brake)
    hi = np.maximum(np.maximum(upper, kin.x), p_brake)
    lo = np.minimum(np.minimum(lower, kin.x), p_brake)
    boxed = np.isfinite(lower) | np.isfinite(upper)
    with np.errstate(invalid="ignore"):
        bad = ~np.isfinite(p) | (p > hi + tol * dt) | (p < lo - tol * dt)
    return int(np.sum(boxed & bad))


class CollisionJudge:
    """The collision rule of the module docstring for one robot, scene and safety distances.

    Args:
        model: the robot.
        scene: its obstacles and fence.
        safety_distance, floor_margin: [m] d_s of robot pairs (and obstacles), and of the floor.
    """

    def __init__(self, model: WmmModel, scene: Scene, safety_distance: float, floor_margin: float) -> None:
        import coal

        from .model.collision import coal_shape, robot_geometry, shape_pose

        self.model, self.scene = model, scene
        self.geo = robot_geometry(model.config, model.arm)
        self.d_s, self.d_floor = safety_distance, floor_margin
        self._coal = coal
        self._floor = coal.Halfspace(np.array([0.0, 0.0, 1.0]), self.geo.floor_z)  # solid: z ≤ floor_z
        from .model.collision import exempt_mask

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
        import pinocchio as pin

        coal, geo = self._coal, self.geo
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


def _stop_position(q: np.ndarray, v: np.ndarray, a_dt: np.ndarray, dt: float) -> np.ndarray:
    """Where a joint ends if it holds v for dt, then brakes by a_dt per tick (held dt each) to 0."""
    speed = np.abs(v)
    n = np.floor(speed / a_dt)
    braking = n * speed - a_dt * n * (n + 1.0) / 2.0  # Σ_{j=1..n} (|v| − j·a_dt)
    return q + np.sign(v) * dt * (speed + braking)


@dataclass
class Sample:
    """One random test case: a state, a reference, and what kind of case it is."""

    state: RobotState
    reference: Reference
    case: str


def sample_states(
    model: WmmModel,
    n: int,
    seed: int,
    modes: tuple[Mode, ...] = tuple(Mode),
    pose: bool = False,
    judge: CollisionJudge | None = None,
    influence: float = 0.15,
) -> Iterator[Sample]:
    """Random states and references covering the corners the bounds must survive.

    States: inside the limits, exactly at and just beyond a position limit, at and beyond
    the velocity limits, at the acceleration limits (large previous rates), near and at
    arm singularities (every second joint — 2, 4, 6, … — at or near 0, clipped to its range: the
    Gen3 stretched straight, and the same family on any arm). References: small, huge,
    discontinuous (a random jump each sample), in every mode; with ``pose`` also a target
    orientation (a random rotation of up to ~π about a random axis) and angular feed-forward.
    With a collision ``judge``, three more cases: near a self-collision or the floor (arm
    configurations drawn until a monitored pair is within ``influence`` of touching), near an
    obstacle (the base placed so that the EE is within ``influence`` of one) and at the fence
    (the base's origin within ``influence`` of a fence edge, moving out).
    """
    rng = np.random.default_rng(seed)
    arm, base = model.config.arm, model.config.base
    lo = np.where(np.isfinite(arm.position_lower), arm.position_lower, -np.pi)
    hi = np.where(np.isfinite(arm.position_upper), arm.position_upper, np.pi)
    vmax, wmax = arm.velocity_max, base.wheel_speed_max
    n_a, n_w = arm.n, base.n_wheels
    bending = np.arange(1, n_a, 2)
    cases: tuple[str, ...] = (
        "inside",
        "at_limit",
        "beyond_limit",
        "at_velocity_limit",
        "beyond_velocity_limit",
        "near_singular",
        "singular",
    )
    if judge is not None:
        cases += ("near_self", "near_obstacle", "at_fence")
    for i in range(n):
        case = cases[i % len(cases)]
        q = rng.uniform(lo, hi)
        v = rng.uniform(-1, 1, n_a) * vmax * rng.uniform(0, 1)
        w = rng.uniform(-1, 1, n_w) * wmax * rng.uniform(0, 1)
        limited = np.flatnonzero(np.isfinite(arm.position_upper))
        j = rng.choice(limited)
        side = rng.choice([-1.0, 1.0])
        edge = arm.position_upper[j] if side > 0 else arm.position_lower[j]
        if case == "at_limit":
            q[j] = edge
            v[j] = side * rng.uniform(0, vmax[j])
        elif case == "beyond_limit":
            q[j] = edge + side * rng.uniform(1e-6, 0.05)
            v[j] = side * rng.uniform(0, vmax[j])
        elif case == "at_velocity_limit":
            v = rng.choice([-1.0, 1.0], n_a) * vmax
            w = rng.choice([-1.0, 1.0], n_w) * wmax
        elif case == "beyond_velocity_limit":
            v = rng.choice([-1.0, 1.0], n_a) * vmax * rng.uniform(1.0, 1.5, n_a)
            w = rng.choice([-1.0, 1.0], n_w) * wmax * rng.uniform(1.0, 1.5, n_w)
        elif case in ("near_singular", "singular"):
            eps = 0.0 if case == "singular" else 0.05
            q[bending] = np.clip(rng.uniform(-eps, eps, bending.size), lo[bending], hi[bending])
        q_base = np.array([*rng.uniform(-2, 2, 2), rng.uniform(-np.pi, np.pi)])
        if judge is not None and case == "near_self":
            for _ in range(200):  # until a self or floor pair is within the influence distance
                d = judge.distances(q_base, q)
                if min(v for k, v in d.items() if not k.startswith("fence:") and "/" in k) < influence:
                    break
                q = rng.uniform(lo, hi)
        elif judge is not None and case == "near_obstacle" and judge.scene.obstacles:
            o = judge.scene.obstacles[int(rng.integers(len(judge.scene.obstacles)))]
            p_ee = model.arm.position(q)  # base frame
            yaw = float(rng.uniform(-np.pi, np.pi))
            heading = rng.normal(size=2)
            heading /= np.linalg.norm(heading)
            reach = float(np.max(o.size)) if o.kind == "box" else o.radius + 0.5 * o.length
            target = np.asarray(o.xyz[:2]) + heading * (reach + rng.uniform(0.0, influence))
            c_, s_ = np.cos(yaw), np.sin(yaw)
            ee = np.array([c_ * p_ee[0] - s_ * p_ee[1], s_ * p_ee[0] + c_ * p_ee[1]])  # Rz(ψ) p, x-y
            q_base = np.array([target[0] - ee[0], target[1] - ee[1], yaw])
        elif judge is not None and case == "at_fence":
            A, _ = judge.scene.fence.half_planes()
            if A.shape[0]:
                k = int(rng.integers(A.shape[0]))
                edge = judge.scene.fence.base[k]
                nxt = judge.scene.fence.base[(k + 1) % A.shape[0]]
                point = edge + rng.uniform(0, 1) * (nxt - edge) - A[k] * rng.uniform(0.0, influence)
                q_base = np.array([point[0], point[1], rng.uniform(-np.pi, np.pi)])
                w = rng.choice([-1.0, 1.0], n_w) * wmax * rng.uniform(0.3, 1.0)
        state = RobotState(q_base=q_base, q_arm=q, v_arm=v, wheel_speeds=w)
        x = model.ee_position(q_base, q)
        scale = rng.choice([1e-3, 0.05, 10.0])  # small, ordinary, huge
        x_d = x + rng.normal(size=3) * scale
        xd_d = rng.normal(size=3) * rng.choice([0.0, 0.05, 5.0])
        direction = rng.normal(size=3)
        quat_d, omega_d = None, np.zeros(3)
        if pose:
            quat_d = rng.normal(size=4)
            omega_d = rng.normal(size=3) * rng.choice([0.0, 0.1, 3.0])
        for mode in modes:
            ref = Reference(mode, x_d=x_d, xd_d=xd_d, direction=direction, quat_d=quat_d, omega_d=omega_d)
            yield Sample(state, ref, case)


@dataclass
class VerifyReport:
    """Violations found by :func:`verify_controller`."""

    samples: int = 0
    steps: int = 0
    violations: int = 0
    by_kind: dict[str, int] = field(default_factory=lambda: dict.fromkeys(KINDS, 0))
    by_mode: dict[str, dict[str, int]] = field(default_factory=dict)
    by_case: dict[str, int] = field(default_factory=dict)
    statuses: dict[str, int] = field(default_factory=dict)
    examples: list[dict[str, object]] = field(default_factory=list)


def verify_controller(
    controller: object,
    model: WmmModel,
    n: int,
    seed: int,
    progress: object = None,
    ee_box: tuple[FloatArray, FloatArray] | None = None,
    scene: Scene | None = None,
) -> VerifyReport:
    """Run one step of ``controller`` for each of n random states in every mode; referee each.

    Args:
        controller: anything with ``step(state, reference) → Command`` and ``dt``.
        model: the robot.
        n: number of random states.
        seed: RNG seed.
        progress: optional callable(i, n, violations) called after each state (violations: so far).
        ee_box: (lower, upper) [m] of eq. (17), refereed in DM_CARTESIAN; default: the box of the
            controller's ``config`` (``ee_box_lower``, ``ee_box_upper``), if it has one.
        scene: obstacles and fence: when given, every command is also refereed for collisions
            (:class:`CollisionJudge`, the safety distances of the controller's ``config.collision``
            or the defaults) and states near collisions are sampled; a QP controller is given the
            scene, the baselines are not (they have no collision rows: the referee sees them collide).
    """
    rep = VerifyReport(by_mode={m.value: dict.fromkeys(KINDS, 0) for m in Mode})
    dt = float(controller.dt)  # type: ignore[attr-defined]
    if ee_box is None:
        cfg = getattr(controller, "config", None)
        if hasattr(cfg, "ee_box_lower") and hasattr(cfg, "ee_box_upper"):
            ee_box = (cfg.ee_box_lower, cfg.ee_box_upper)  # type: ignore[union-attr]
    modes = tuple(Mode)
    cfg = getattr(controller, "config", None)
    task = getattr(cfg, "task", None)
    pose = getattr(task, "kind", "position") == "pose"
    judge = None
    params = getattr(cfg, "collision", None) or CollisionParams()
    if scene is not None:
        judge = CollisionJudge(model, scene, params.safety_distance, params.floor_margin)
        if hasattr(controller, "set_scene"):
            controller.set_scene(scene)
    samples = sample_states(model, n, seed, modes, pose=pose, judge=judge, influence=params.influence_distance)
    for k, s in enumerate(samples):
        cmd = controller.step(s.state, s.reference)  # type: ignore[attr-defined]
        rep.steps += 1
        rep.statuses[cmd.status.value] = rep.statuses.get(cmd.status.value, 0) + 1
        box = ee_box if s.reference.mode == Mode.DM_CARTESIAN else None
        res = check_command(model.config, dt, s.state, cmd, model=model, ee_box=box, collision=judge)
        total = sum(res.values())
        if total:
            rep.violations += total
            rep.by_case[s.case] = rep.by_case.get(s.case, 0) + total
            for kind, c in res.items():
                rep.by_kind[kind] += c
                rep.by_mode[s.reference.mode.value][kind] += c
            if len(rep.examples) < 3:
                ex: dict[str, object] = {"case": s.case, "mode": s.reference.mode.value,
                                         "violations": {k: c for k, c in res.items() if c}}
                if res["collision"] and judge is not None:
                    ex["pair"] = judge.last
                rep.examples.append(ex)
        if (k + 1) % len(modes) == 0:
            rep.samples += 1
            if progress is not None:
                progress(rep.samples, n, rep.violations)  # type: ignore[operator]
    return rep
