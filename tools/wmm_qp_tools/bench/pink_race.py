"""A side-by-side race against pink (``pin-pink``) on the same robot and trajectory.

pink's robot: the robot's own arm model (wmm_qp's reduced Pinocchio model: the robot file's
joints, every other joint locked, the mount folded in, the robot file's limits) on a planar
root joint (x, y, yaw; velocity = body twist). Its tick: ``Configuration.update(q)``
(kinematics), set the target, ``solve_ik`` with a position-only ``FrameTask`` on the EE frame,
``ConfigurationLimit`` and ``VelocityLimit`` (and, in the second variant, pink's
``AccelerationLimit``, which limits the arm joints only: it skips the planar base joint),
solver ``proxqp`` — exactly what a pink user writes.

Same control law: with task gain K_x·Δt and target x_d + ẋ_d/K_x, pink's dead-beat step
Δq = gain·J⁺e gives v = ẋ_d + K_x(x_d − x), which is eq. (18). The target's orientation is
the EE's current one, so the task is position-only. Base velocity limits for pink are the
body-twist box the wheel limits allow on each axis alone: for axis i, the largest s with
|w_j(s·e_i)| ≤ w_max,j for every wheel j (for the Mecanum base R·w_max, R·w_max, R·w_max/L).
A planar joint moves sideways, so the race needs a holonomic base (Mecanum, omni); on a
differential drive or a fixed base it is reported as not available.

Ours: ``QpController.step`` in TRACK mode with the same solver (proxsuite), whose tick also
includes the bounds (13), the acceleration bounds of the wheels, σ_min and the diagnostics.
Both robots are integrated exactly; both commands are checked (finite, inside their
velocity limits, tracking the circle) so that the race is fair.
"""

from __future__ import annotations

import sys
from typing import Any

import numpy as np

import wmm_qp as w
from wmm_qp_tools.bench.stats import now_ns, summarize_ns
from wmm_qp_tools.bench.trajectory import IdealRobot, circle


def pink_available() -> bool:
    try:
        import pink  # noqa: F401
    except ImportError:
        return False
    return True


def planar_model(robot: w.RobotConfig, arm: Any) -> Any:
    """pink's model: a planar root joint carrying the robot's reduced arm model, with the robot
    file's position and velocity limits."""
    import pinocchio as pin

    planar = pin.Model()
    jid = planar.addJoint(0, pin.JointModelPlanar(), pin.SE3.Identity(), "planar_base")
    fid = planar.addFrame(pin.Frame("planar_base_link", jid, 0, pin.SE3.Identity(), pin.FrameType.BODY))
    model = pin.appendModel(planar, arm.model, fid, pin.SE3.Identity())
    lo, hi, vmax = model.lowerPositionLimit.copy(), model.upperPositionLimit.copy(), model.velocityLimit.copy()
    for i, name in enumerate(robot.arm.joints):
        j = model.joints[model.getJointId(name)]
        vmax[j.idx_v] = robot.arm.velocity_max[i]
        if j.nq == 1:  # continuous joints (cos, sin) have no position limits
            lo[j.idx_q], hi[j.idx_q] = robot.arm.position_lower[i], robot.arm.position_upper[i]
    model.lowerPositionLimit, model.upperPositionLimit, model.velocityLimit = lo, hi, vmax
    return model


def twist_box(base: Any, wheel_limit: np.ndarray) -> np.ndarray:
    """Per axis of the body twist (v_x, v_y, ω) alone, the largest magnitude the wheel limits allow."""
    out = np.zeros(3)
    for i in range(3):
        wheels = np.abs(base.wheel_speeds(np.eye(3)[i]))
        used = wheels > 1e-12
        out[i] = float(np.min(np.asarray(wheel_limit)[used] / wheels[used])) if used.any() else 0.0
    return out


def _run_pink(
    robot: w.RobotConfig, cfg: w.ControllerConfig, ticks: int, accel: bool, max_seconds: float
) -> dict[str, Any]:
    """pink's ticks; proxqp gets our backend's tolerances (its default, ~1e-5 on Δq = v·dt,
    lets the acceleration limits be exceeded by a few rad/s²)."""
    import pinocchio as pin
    import qpsolvers
    from pink import Configuration, solve_ik
    from pink.limits import AccelerationLimit, ConfigurationLimit, VelocityLimit
    from pink.tasks import FrameTask

    wmm = w.WmmModel(robot)
    arm = wmm.arm
    model = planar_model(robot, arm)
    data = model.createData()
    b = robot.base
    v_lim = np.concatenate([twist_box(wmm.base, b.wheel_speed_max), robot.arm.velocity_max])
    a_lim = np.concatenate([twist_box(wmm.base, b.wheel_acceleration_max), robot.arm.acceleration_max])
    limits: list[Any] = [ConfigurationLimit(model), VelocityLimit(model, v_lim)]
    acc_limit = AccelerationLimit(model, a_lim) if accel else None
    if acc_limit is not None:
        limits.append(acc_limit)
    # q: planar (x, y, cos ψ, sin ψ), then the arm (continuous joints as cos, sin pairs).
    q = np.concatenate([[0.0, 0.0, 1.0, 0.0], arm.pin_q(np.array(robot.arm.start)).copy()])
    conf = Configuration(model, data, q)
    ee = robot.arm.ee_frame
    dt, K = cfg.dt, float(np.max(cfg.K_x)) if np.ndim(cfg.K_x) else float(cfg.K_x)
    task = FrameTask(ee, position_cost=1.0, orientation_cost=0.0, gain=K * dt)
    x0 = conf.get_transform_frame_to_world(ee).translation.copy()
    solver_kwargs = {"eps_abs": cfg.qp.eps_abs, "eps_rel": 0.0}
    samples: list[int] = []
    err2: list[float] = []
    excess, fails = 0.0, 0
    v_prev = np.zeros(model.nv)
    deadline = now_ns() + int(max_seconds * 1e9)
    for k in range(ticks):
        x_d, xd_d = circle(x0, k * dt)
        t0 = now_ns()
        conf.update(q)
        T = conf.get_transform_frame_to_world(ee)
        task.set_target(pin.SE3(T.rotation, x_d + xd_d / K))
        try:
            v = solve_ik(conf, [task], dt, solver="proxqp", limits=limits, **solver_kwargs)
            if acc_limit is not None:
                acc_limit.set_last_integration(v, dt)
        except Exception:  # pink raises when the QP fails: count it, brake
            v = np.zeros(model.nv)
            fails += 1
        samples.append(now_ns() - t0)
        if not np.isfinite(v).all():
            fails += 1
            v = np.zeros(model.nv)
        excess = max(excess, float(np.max(np.abs(v) - v_lim)))
        if (
            acc_limit is not None
        ):  # only the joints pink limits (its AccelerationLimit skips the base)
            i = acc_limit.indices
            excess = max(excess, float(np.max(np.abs(v[i] - v_prev[i]) / dt - a_lim[i])))
        v_prev = v
        q = pin.integrate(model, q, v * dt)
        if k * dt >= 1.0:
            pin.framesForwardKinematics(model, data, q)
            x = data.oMf[model.getFrameId(ee)].translation
            err2.append(float(np.sum((x - circle(x0, (k + 1) * dt)[0]) ** 2)))
        if now_ns() > deadline:
            print(f"  pink: time budget reached after {k + 1} ticks", file=sys.stderr)
            break
        if k % 5000 == 4999:
            print(f"  pink: {k + 1}/{ticks}", file=sys.stderr, flush=True)
    limited = [] if acc_limit is None else [int(i) for i in acc_limit.indices]
    return {
        "tick_us": summarize_ns(samples),
        "failures": fails,
        "max_limit_excess": excess,
        "track_rms_m": float(np.sqrt(np.mean(err2))) if err2 else None,
        "qpsolvers": qpsolvers.__version__,
        "nv": int(model.nv),
        "accel_limited_dofs": limited,
    }


def _run_ours(
    robot: w.RobotConfig, cfg: w.ControllerConfig, ticks: int, max_seconds: float
) -> dict[str, Any]:
    model = w.WmmModel(robot)
    ctl = w.make_controller("qp", model, cfg.with_(qp={"solver": "proxsuite"}))
    ctl.warm_up()  # compiled kernels loaded before timing, as the daemon does
    bot = IdealRobot.at_start(model)
    x0 = bot.ee()
    samples: list[int] = []
    err2: list[float] = []
    excess, fails = 0.0, 0
    deadline = now_ns() + int(max_seconds * 1e9)
    for k in range(ticks):
        x_d, xd_d = circle(x0, k * ctl.dt)
        ref = w.Reference(mode=w.Mode.TRACK, x_d=x_d, xd_d=xd_d)
        state = bot.state()
        t0 = now_ns()
        cmd = ctl.step(state, ref)
        samples.append(now_ns() - t0)
        fails += cmd.status == w.Status.SAFE_STOP
        excess = max(
            excess,
            float(np.max(np.abs(cmd.arm_rates) - robot.arm.velocity_max)),
            float(np.max(np.abs(cmd.wheel_speeds) - robot.base.wheel_speed_max, initial=-np.inf)),
        )
        bot.apply(cmd, ctl.dt)
        if k * ctl.dt >= 1.0:
            err2.append(float(np.sum((bot.ee() - circle(x0, (k + 1) * ctl.dt)[0]) ** 2)))
        if now_ns() > deadline:
            break
    return {
        "tick_us": summarize_ns(samples),
        "failures": fails,
        "max_limit_excess": excess,
        "track_rms_m": float(np.sqrt(np.mean(err2))) if err2 else None,
    }


def valid(r: dict[str, Any], tol_m: float = 0.005) -> bool:
    """Finite commands that never failed, inside their limits (to 1e-3, the solver tolerance on
    Δq = v·dt seen as an acceleration), tracking within tol_m [m] RMS."""
    rms = r["track_rms_m"]
    return bool(
        r["failures"] == 0 and r["max_limit_excess"] <= 1e-3 and rms is not None and rms <= tol_m
    )


def run(
    robot: w.RobotConfig, cfg: w.ControllerConfig, ticks: int, max_seconds: float = 60.0
) -> dict[str, Any]:
    """{"ours", "pink", "pink_accel", "ratio_p50", "ratio_p99", "fair"} or {"available": False}."""
    base = w.WmmModel(robot).base
    if not base.holonomic:  # first: this holds whether pink is installed or not
        return {
            "available": False,
            "reason": f"the pink race needs a holonomic base (pink's planar root joint moves sideways); "
            f"{robot.name!r} has a {base.kind} base",
        }
    if not pink_available():
        return {
            "available": False,
            "reason": "pin-pink is not installed: pip install 'wmm-qp[bench]'",
        }
    cfg = cfg.with_(task={"kind": "position"})  # pink's task here is position-only: so is ours
    print(f"pink race: ours ({ticks} ticks)", file=sys.stderr, flush=True)
    ours = _run_ours(robot, cfg, ticks, max_seconds)
    print(f"pink race: pink ({ticks} ticks)", file=sys.stderr, flush=True)
    pink = _run_pink(robot, cfg, ticks, accel=False, max_seconds=max_seconds)
    print(f"pink race: pink + AccelerationLimit ({ticks} ticks)", file=sys.stderr, flush=True)
    pink_acc = _run_pink(robot, cfg, ticks, accel=True, max_seconds=max_seconds)
    for r in (ours, pink, pink_acc):
        r["valid"] = valid(r)
    import pink as pink_mod

    return {
        "available": True,
        "pink_version": getattr(pink_mod, "__version__", "?"),
        "solver": "proxqp",
        "ours": ours,
        "pink": pink,
        "pink_accel": pink_acc,
        "ratio_p50": round(pink["tick_us"]["p50"] / ours["tick_us"]["p50"], 2),
        "ratio_p99": round(pink["tick_us"]["p99"] / ours["tick_us"]["p99"], 2),
        "ratio_accel_p50": round(pink_acc["tick_us"]["p50"] / ours["tick_us"]["p50"], 2),
        "fair": bool(ours["valid"] and pink["valid"]),
    }
