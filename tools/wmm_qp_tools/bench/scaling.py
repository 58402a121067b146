"""Per-tick cost against the number of arm joints: n − 1, n and 2n for the robot's arm of n joints
(6, 7 and 14 for the Gen3).

A synthetic benchmark: it builds the controller's whole-robot QP itself, with ``wmm_qp``'s pieces,
on Pinocchio models of its own (one or two arms, any number of joints), so it does not go
through ``QpController``: per tick, kinematics of every EE (``computeJointJacobians``), the bounds
(13) (``joint_motion_bounds``) and the wheel bounds, the QP of docs/model.md "The QP" with a task slack
(z = [v_b; v_m; s], H = blkdiag(W_x⁻¹, ρI), A = [J_b P, J_m, I], one 3-row task per arm;
always feasible, as the controller's slack stage) and a persistent ``wmm_qp.solvers``
backend. The n-joint row is the robot's own arm through this same path, so the rows compare
with each other (not with the controller's own figures).

Models (from the robot's URDF, reduced as ``wmm_qp`` reduces it: the robot file's joints, every
other joint locked, the mount folded in; a dual-arm URDF is generated in a temporary directory):

* n − 1: the arm with its third joint locked at 0 (for the Gen3: joint_3, the Gen3 6-DOF's
  topology);
* n: the arm;
* 2n: two copies of the arm side by side on the base (±0.25 m in y), each EE following its own
  circle (a 6-row task).

The base is the robot's (its kind's P(ψ) of eq. (3) and its wheel limits).
"""

from __future__ import annotations

import sys
import tempfile
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

import wmm_qp as w
from wmm_qp.limits import braking_command, joint_motion_bounds, wheel_bounds, wheel_braking_command
from wmm_qp.model.arm import mount_placement
from wmm_qp.model.bases import make_base
from wmm_qp.solvers import INF, QPProblem, make_backend
from wmm_qp.urdf import reduced_model
from wmm_qp_tools.bench.stats import now_ns, summarize_ns
from wmm_qp_tools.bench.trajectory import circle

_LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
SLACK_WEIGHT = 1e6  # ρ of the task slack


def dual_arm_urdf(urdf: Path, out: Path, offset_y: float = 0.25) -> Path:
    """A URDF with two copies of ``urdf`` (names prefixed l_ and r_) at ±offset_y [m]."""
    src = ET.parse(urdf).getroot()
    root = ET.Element("robot", {"name": "dual"})
    ET.SubElement(root, "link", {"name": "torso"})
    for prefix, y in (("l_", offset_y), ("r_", -offset_y)):
        base_link = None
        children = {e.get("link") for e in src.iter("child")}
        for el in src:
            if el.tag not in ("link", "joint"):
                continue
            e = ET.fromstring(ET.tostring(el))
            e.set("name", prefix + str(e.get("name")))
            for tag in ("parent", "child"):
                for sub in e.iter(tag):
                    sub.set("link", prefix + str(sub.get("link")))
            for mat in e.iter("material"):
                mat.set("name", prefix + str(mat.get("name")))
            root.append(e)
            if el.tag == "link" and el.get("name") not in children:
                base_link = prefix + str(el.get("name"))
        fix = ET.SubElement(root, "joint", {"name": prefix + "mount", "type": "fixed"})
        ET.SubElement(fix, "parent", {"link": "torso"})
        ET.SubElement(fix, "child", {"link": str(base_link)})
        ET.SubElement(fix, "origin", {"xyz": f"0 {y} 0", "rpy": "0 0 0"})
    ET.ElementTree(root).write(out)
    return out


class GenericWmm:
    """The robot's base carrying an arm model with one or more EE frames (any number of joints)."""

    def __init__(
        self,
        model: pin.Model,
        ee_frames: list[str],
        robot: w.RobotConfig,
        vmax: np.ndarray,
        amax: np.ndarray,
        qlo: np.ndarray,
        qhi: np.ndarray,
    ) -> None:
        self.model, self.data = model, model.createData()
        self.frames = [model.getFrameId(f) for f in ee_frames]
        self.base = make_base(robot.base)
        self.robot = robot
        self.vmax, self.amax, self.qlo, self.qhi = vmax, amax, qlo, qhi
        self.n = model.nv
        joints = [model.joints[j] for j in range(1, model.njoints)]
        self._rev = [(j.idx_q, j.idx_v) for j in joints if j.nq == 1]
        self._cont = [(j.idx_q, j.idx_v) for j in joints if j.nq == 2]
        self._q = pin.neutral(model)

    def pin_q(self, q: np.ndarray) -> np.ndarray:
        for iq, iv in self._rev:
            self._q[iq] = q[iv]
        for iq, iv in self._cont:
            self._q[iq], self._q[iq + 1] = np.cos(q[iv]), np.sin(q[iv])
        return self._q

    def kinematics(self, q_base: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Stacked EE positions x (3k,) [m] and the whole-robot Jacobian J (3k × (n_wheels + n)), eq. (5)."""
        pin.computeJointJacobians(self.model, self.data, self.pin_q(q))
        c, s = np.cos(q_base[2]), np.sin(q_base[2])
        R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        P = self.base.P(float(q_base[2]))
        xs, Js = [], []
        for f in self.frames:
            p = R @ pin.updateFramePlacement(self.model, self.data, f).translation
            Ja = pin.getFrameJacobian(self.model, self.data, f, _LWA)[:3]
            J_b = np.array([[1.0, 0.0, -p[1]], [0.0, 1.0, p[0]], [0.0, 0.0, 0.0]])
            xs.append(np.array([q_base[0] + p[0], q_base[1] + p[1], p[2]]))
            Js.append(np.hstack([J_b @ P, R @ Ja]))
        return np.concatenate(xs), np.vstack(Js)


def build_models(robot: w.RobotConfig, tmp: Path) -> dict[int, GenericWmm]:
    """{n − 1, n, 2n: model} for the robot's arm of n joints (the module docstring); no n − 1
    model for an arm of fewer than three joints."""
    arm = robot.arm
    n, ee = arm.n, arm.ee_frame
    full = pin.buildModelFromUrdf(str(arm.urdf))
    mount, locked = mount_placement(arm), dict(arm.locked)
    lo = np.asarray(arm.position_lower, float)
    hi = np.asarray(arm.position_upper, float)
    vm, am = np.asarray(arm.velocity_max, float), np.asarray(arm.acceleration_max, float)
    out = {n: GenericWmm(reduced_model(full, arm.joints, locked, mount), [ee], robot, vm, am, lo, hi)}
    if n >= 3:
        keep = [i for i in range(n) if i != 2]
        fewer = reduced_model(full, tuple(arm.joints[i] for i in keep), locked | {arm.joints[2]: 0.0}, mount)
        out[n - 1] = GenericWmm(fewer, [ee], robot, vm[keep], am[keep], lo[keep], hi[keep])
    dual_full = pin.buildModelFromUrdf(str(dual_arm_urdf(arm.urdf, tmp / "dual.urdf")))
    sides = ("l_", "r_")
    dual = reduced_model(
        dual_full,
        tuple(p + j for p in sides for j in arm.joints),
        {p + j: v for p in sides for j, v in locked.items()},
        mount,
    )
    out[2 * n] = GenericWmm(
        dual, [p + ee for p in sides], robot, np.tile(vm, 2), np.tile(am, 2), np.tile(lo, 2), np.tile(hi, 2)
    )
    return out


def start_q(robot: w.RobotConfig, n: int) -> np.ndarray:
    """The start of each model: the robot's ``arm.start`` (without its third joint for n − 1, twice for 2n)."""
    q = np.array(robot.arm.start, dtype=float)
    return {q.size - 1: np.delete(q, 2), q.size: q, 2 * q.size: np.tile(q, 2)}[n]


def run_one(
    m: GenericWmm, cfg: w.ControllerConfig, solver: str, ticks: int, max_seconds: float
) -> dict[str, Any]:
    """Ticks of the generic QP controller on one model along the circle (each EE its own)."""
    dt, alpha = cfg.dt, cfg.qp.alpha
    n, nw = m.n, m.base.n_wheels
    w_inv = 1.0 / np.concatenate([np.full(nw, alpha), np.full(n, 1.0 - alpha)])  # eq. (12)
    m_eq = 3 * len(m.frames)
    H = np.diag(np.concatenate([w_inv, np.full(m_eq, SLACK_WEIGHT)]))
    g = np.zeros(nw + n + m_eq)
    I_s, s_lo, s_hi = np.eye(m_eq), np.full(m_eq, -INF), np.full(m_eq, INF)
    K = float(np.max(cfg.K_x))
    backend = make_backend(solver, cfg.qp.eps_abs)
    qb, q, v, wh = np.zeros(3), start_q(m.robot, n), np.zeros(n), np.zeros(nw)
    x0, _ = m.kinematics(qb, q)
    k_ee = x0.size // 3
    C0, e0 = np.zeros((0, nw + n + m_eq)), np.zeros(0)
    samples: list[int] = []
    fails = 0
    err2: list[float] = []
    deadline = now_ns() + int(max_seconds * 1e9)
    for k in range(ticks):
        refs = [circle(x0[3 * i : 3 * i + 3], k * dt) for i in range(k_ee)]
        x_d = np.concatenate([r[0] for r in refs])
        xd_d = np.concatenate([r[1] for r in refs])
        t0 = now_ns()
        x, J = m.kinematics(qb, q)
        lo, hi = joint_motion_bounds(q, v, m.qlo, m.qhi, m.vmax, m.amax, dt)  # eq. (13)
        wlo, whi = wheel_bounds(wh, m.robot.base, dt)
        xdot = xd_d + K * (x_d - x)  # eq. (18)
        p = QPProblem(
            H=H,
            g=g,
            A=np.hstack([J, I_s]),
            b=xdot,
            C=C0,
            l=e0,
            u=e0,
            lb=np.concatenate([wlo, lo, s_lo]),
            ub=np.concatenate([whi, hi, s_hi]),
        )
        sol = backend.solve(p)
        z = np.clip(sol.z, p.lb, p.ub) if sol.ok and sol.z is not None else None
        samples.append(now_ns() - t0)
        if z is None:
            fails += 1
            z = np.concatenate(
                [wheel_braking_command(wh, m.robot.base, dt), braking_command(v, m.amax, dt)]
            )
        wh, v = z[:nw], z[nw : nw + n]
        q = q + dt * v
        qb = qb + dt * (m.base.P(float(qb[2])) @ wh)
        if k * dt >= 1.0:
            xn, _ = m.kinematics(qb, q)
            x_next = np.concatenate(
                [circle(x0[3 * i : 3 * i + 3], (k + 1) * dt)[0] for i in range(k_ee)]
            )
            err2.append(float(np.mean((xn - x_next) ** 2)) * 3)
        if now_ns() > deadline:
            break
    return {
        "n_arm": n,
        "n_vars": nw + n + m_eq,
        "n_eq": m_eq,
        "tick_us": summarize_ns(samples),
        "failures": fails,
        "track_rms_m": float(np.sqrt(np.mean(err2))) if err2 else None,
    }


def run(
    robot: w.RobotConfig,
    cfg: w.ControllerConfig,
    solvers: list[str],
    ticks: int,
    max_seconds: float = 30.0,
) -> dict[str, Any]:
    """{solver: {n_arm: run_one(...)}} for n_arm in n − 1, n, 2n (n: the robot's arm)."""
    res: dict[str, Any] = {
        "note": "synthetic: the whole-robot QP built in the benchmark on its own one- and two-arm models"
    }
    with tempfile.TemporaryDirectory() as d:
        models = build_models(robot, Path(d))
        for s in solvers:
            res[s] = {}
            for n, m in sorted(models.items()):
                print(f"scaling: {s} / {n} arm joints ({ticks} ticks)", file=sys.stderr, flush=True)
                res[s][str(n)] = run_one(m, cfg, s, ticks, max_seconds)
    return res
