"""The σ_min floor of the DM modes (wmm_qp/limits/singularity_floor.py): its gradient against finite
differences, and, in closed loop with the sim on several robots, that raising DM in the null space
never takes σ_min(J_m) below the floor and leaves an arm that then tracks a target undamped. (The
Panda's and TIAGo's ascents, from their starts along x and from near the floor along their least
mobile direction, stay clear of the floor for seconds: they are in the gradient test only.)"""

from __future__ import annotations

from dataclasses import replace
from functools import cache
from pathlib import Path

import numpy as np
import pytest
from wmm_qp_sim import SimCommand, SimRobot, load_sim_config

import wmm_qp as w
from wmm_qp.config import default_config_dir
from wmm_qp.limits.singularity_floor import INFLUENCE, floor_row, sigma_min_gradient
from wmm_qp.pseudoinverse import sigma_min

ROBOTS = default_config_dir() / "robots"
FILES = {
    "gen3_mecanum": ROBOTS / "gen3_mecanum.toml",
    "ur5_omni": ROBOTS / "ur5_omni.toml",
    "panda_diffdrive": ROBOTS / "panda_diffdrive.toml",
    "tiago": ROBOTS / "tiago.toml",
    "z1_omni": Path(__file__).resolve().parents[2] / "examples" / "z1_omni" / "z1_omni.toml",
}
TRACK_BOUND = 0.005  # [m] EE error (ground truth) of the tracking that follows a DM phase, in process
SIGMA_TOL = 1e-4  # [m/rad] the damper holds the floor to first order per tick


@cache
def model(name: str) -> w.WmmModel:
    return w.WmmModel(w.load_robot_config(FILES[name]))


def controller(
    name: str, direction: np.ndarray | None = None, floor: float | None = None, **changes: object
) -> w.QpController:
    """The shipped controller config without collision rows, DM along ``direction``, σ_f = ``floor``
    (None: the shipped one), and any other ``changes``."""
    cfg = w.load_controller_config().with_(collision={"enabled": False}, **changes)
    if direction is not None:
        cfg = cfg.with_(direction=direction / np.linalg.norm(direction))
    if floor is not None:
        cfg = cfg.with_(sigma_min_floor=floor)
    ctl = w.make_controller("qp", model(name), cfg)
    assert isinstance(ctl, w.QpController)
    return ctl


def sim_at(name: str, q_arm: np.ndarray) -> SimRobot:
    cfg = load_sim_config()
    cfg = replace(cfg, firmware=False, slip=replace(cfg.slip, enabled=False))
    sim = SimRobot(model(name), cfg, seed=1, collisions=False)
    sim.reset(q_arm=q_arm)
    return sim


def run(ctl: w.Controller, sim: SimRobot, steps: int, reference: object) -> list[w.Command]:
    """Controller and sim in process; ``reference(k, state)`` or a fixed reference."""
    cmds = []
    for k in range(steps):
        st = sim.robot_state()
        cmd = ctl.step(st, reference(k, st) if callable(reference) else reference)
        cmds.append(cmd)
        sim.step(SimCommand(cmd.wheel_speeds, cmd.arm_rates, period=ctl.dt, seq=k), ctl.dt)
    return cmds


def null_space_dm(ctl: w.Controller, sim: SimRobot, seconds: float) -> list[w.Command]:
    """Null-space DM (eqs. (18)–(19)) holding the EE where it starts."""
    m = ctl.model
    x0 = m.ee_position(sim.base_odom, sim.q_arm)
    return run(ctl, sim, round(seconds / ctl.dt), w.Reference(w.Mode.DM_NULLSPACE, x_d=x0, xd_d=np.zeros(3)))


def track_hold(ctl: w.Controller, sim: SimRobot, seconds: float) -> tuple[list[w.Command], float]:
    """TRACK the EE's position where the DM phase left it; returns the commands and the largest EE
    error against the ground truth [m]."""
    m = ctl.model
    x_d = m.ee_position(sim.base_odom, sim.q_arm)
    ref = w.Reference(w.Mode.TRACK, x_d=x_d, xd_d=np.zeros(3))
    cmds, err = [], 0.0
    for k in range(round(seconds / ctl.dt)):
        cmd = ctl.step(sim.robot_state(), ref)
        cmds.append(cmd)
        sim.step(SimCommand(cmd.wheel_speeds, cmd.arm_rates, period=ctl.dt, seq=k), ctl.dt)
        err = max(err, float(np.linalg.norm(m.ee_position(sim.base_true, sim.q_arm) - x_d)))
    return cmds, err


def near_the_floor(name: str, floor: float) -> np.ndarray:
    """An arm configuration with σ_min ≈ 1.3·floor: on the joint-space segment from the robot's start
    to its straightest pose (every joint at the value in its range nearest 0), by bisection, when
    that pose is below it; else by descending σ_min's gradient from the start."""
    m = model(name)
    arm = m.config.arm
    q_start, q_straight = arm.start, np.clip(0.0, arm.position_lower, arm.position_upper)

    def sig(q: np.ndarray) -> float:
        return sigma_min(m.kinematics(np.zeros(3), q).J_m)

    target = 1.3 * floor
    assert sig(q_start) > target, name
    if sig(q_straight) < target:
        lo, hi = 0.0, 1.0
        for _ in range(40):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if sig(q_start + mid * (q_straight - q_start)) > target else (lo, mid)
        return np.asarray(q_start + lo * (q_straight - q_start))
    q = q_start.copy()
    for _ in range(2000):
        kin = m.kinematics(np.zeros(3), q, hessian=True)
        assert kin.dJ_arm is not None
        s, g = sigma_min_gradient(kin.J_arm, kin.dJ_arm)
        if s <= target:
            return q
        q = np.clip(q - 0.01 * g / np.linalg.norm(g), arm.position_lower, arm.position_upper)
    raise AssertionError(f"{name}: no configuration near sigma_min {target}")


def least_mobile_direction(name: str, q_arm: np.ndarray) -> np.ndarray:
    """The EE direction the arm moves least along at q_arm (J_m's left singular vector of σ_min):
    DM along it (eq. (8)) grows without bound as σ_min → 0, so its ascent heads for the singularity."""
    U, _, _ = np.linalg.svd(model(name).kinematics(np.zeros(3), q_arm).J_m)
    return np.asarray(U[:, -1])


# ------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", list(FILES))
def test_sigma_min_gradient_against_finite_differences(name: str) -> None:
    m = model(name)
    arm = m.config.arm
    lo = np.where(np.isfinite(arm.position_lower), arm.position_lower, -np.pi)
    hi = np.where(np.isfinite(arm.position_upper), arm.position_upper, np.pi)
    rng = np.random.default_rng(7)
    h = 1e-6
    for _ in range(5):
        q = rng.uniform(lo, hi)
        kin = m.kinematics(np.zeros(3), q, hessian=True)
        assert kin.dJ_arm is not None
        s, grad = sigma_min_gradient(kin.J_arm, kin.dJ_arm)
        assert s == pytest.approx(np.linalg.svd(kin.J_arm, compute_uv=False)[-1], abs=1e-8)
        fd = np.empty(m.n_arm)
        for k in range(m.n_arm):
            e = np.zeros(m.n_arm)
            e[k] = h
            fd[k] = (sigma_min(m.kinematics(np.zeros(3), q + e).J_arm)
                     - sigma_min(m.kinematics(np.zeros(3), q - e).J_arm)) / (2 * h)
        np.testing.assert_allclose(grad, fd, rtol=1e-6, atol=1e-6 * max(1.0, float(np.abs(fd).max())))


def test_the_row_is_absent_far_from_the_floor_and_asks_sigma_back_up_below_it() -> None:
    m = model("gen3_mecanum")
    q = m.config.arm.start
    kin = m.kinematics(np.zeros(3), q, hessian=True)
    assert kin.dJ_arm is not None
    s, grad = sigma_min_gradient(kin.J_arm, kin.dJ_arm)
    n_v = m.n_v
    wide = np.full(n_v, 10.0)
    assert floor_row(kin.J_arm, kin.dJ_arm, s / INFLUENCE * 0.99, np.zeros(n_v), -wide, wide, 0.0) is None
    assert floor_row(kin.J_arm, kin.dJ_arm, 0.0, np.zeros(n_v), -wide, wide, 0.0) is None
    row = floor_row(kin.J_arm, kin.dJ_arm, 2.0 * s, np.zeros(n_v), -wide, wide, 0.0)  # σ_min below its floor
    assert row is not None and row.l > 0.0  # σ_min must rise
    np.testing.assert_array_equal(row.C[: m.n_wheels], 0.0)
    np.testing.assert_array_equal(row.C[m.n_wheels :], grad)
    narrow = np.full(n_v, 1e-9)  # bounds (13) that cannot raise σ_min that fast: relaxed to what they admit
    row = floor_row(kin.J_arm, kin.dJ_arm, 2.0 * s, np.zeros(n_v), -narrow, narrow, 0.0)
    assert row is not None and row.l == pytest.approx(float(np.abs(row.C).sum()) * 1e-9)
    moving = np.zeros(n_v)
    moving[m.n_wheels :] = -grad  # σ_min falling: the state is τ old, σ_min is lower by now
    far = floor_row(kin.J_arm, kin.dJ_arm, 0.9 * s, moving, -wide, wide, 0.0)
    late = floor_row(kin.J_arm, kin.dJ_arm, 0.9 * s, moving, -wide, wide, 0.01)
    assert far is not None and late is not None and late.l > far.l


@pytest.mark.parametrize("name", ["z1_omni", "ur5_omni"])
def test_null_space_dm_from_the_start_stops_at_the_floor_and_the_arm_then_holds_undamped(name: str) -> None:
    floor = w.load_controller_config().sigma_min_floor
    q0 = model(name).config.arm.start
    free = null_space_dm(controller(name, floor=0.0), sim_at(name, q0), 5.0)  # eqs. (18)–(19) alone
    assert min(c.sigma_min for c in free) < floor  # the ascent heads into the singularity
    ctl, sim = controller(name), sim_at(name, q0)
    cmds = null_space_dm(ctl, sim, 5.0)
    assert min(c.sigma_min for c in cmds) >= floor - SIGMA_TOL
    assert cmds[-1].dm > 1.5 * cmds[0].dm  # DM still rises, where the floor allows
    assert all(c.status == w.Status.OK for c in cmds), {c.reason for c in cmds if c.status != w.Status.OK}
    track, err = track_hold(ctl, sim, 1.0)
    assert not [c for c in track if c.status in (w.Status.DAMPED, w.Status.SAFE_STOP)]
    assert err < TRACK_BOUND


@pytest.mark.parametrize("name", ["gen3_mecanum", "ur5_omni", "z1_omni"])
def test_null_space_dm_from_near_the_floor_never_goes_below_it_and_the_arm_then_holds_undamped(name: str) -> None:
    floor = w.load_controller_config().sigma_min_floor
    q = near_the_floor(name, floor)
    u = least_mobile_direction(name, q)
    free = null_space_dm(controller(name, u, floor=0.0), sim_at(name, q), 3.0)
    assert min(c.sigma_min for c in free) < floor  # the ascent heads into the singularity
    ctl, sim = controller(name, u), sim_at(name, q)
    cmds = null_space_dm(ctl, sim, 3.0)
    assert min(c.sigma_min for c in cmds) >= floor - SIGMA_TOL
    assert cmds[-1].dm > cmds[0].dm
    track, err = track_hold(ctl, sim, 1.0)
    assert not [c for c in track if c.status in (w.Status.DAMPED, w.Status.SAFE_STOP)]
    assert err < TRACK_BOUND


@pytest.mark.parametrize("name", ["gen3_mecanum", "ur5_omni", "z1_omni"])
def test_cartesian_dm_from_near_the_floor_never_goes_below_it(name: str) -> None:
    """Eqs. (16)–(17) with the EE box open on every axis (so v_c = k_C ∇_x H2 whole): the task is the
    DM ascent there, and the floor row cuts it."""
    floor = w.load_controller_config().sigma_min_floor
    q = near_the_floor(name, floor)
    u = least_mobile_direction(name, q)
    box = {"ee_box_lower": np.full(3, -10.0), "ee_box_upper": np.full(3, 10.0)}
    free = run(controller(name, u, 0.0, **box), sim_at(name, q), 1500, w.Reference(w.Mode.DM_CARTESIAN))
    assert min(c.sigma_min for c in free) < floor  # eq. (17)'s ascent heads into the singularity
    cmds = run(controller(name, u, **box), sim_at(name, q), 1500, w.Reference(w.Mode.DM_CARTESIAN))
    assert min(c.sigma_min for c in cmds) >= floor - SIGMA_TOL
    assert any(c.reason.startswith("sigma_min floor") for c in cmds)  # the floor, not the bounds, cut it
    assert not [c for c in cmds if c.status == w.Status.SAFE_STOP]


def test_the_floor_is_a_controller_key_and_a_negative_one_is_a_clear_error(tmp_path: Path) -> None:
    assert w.load_controller_config().sigma_min_floor > w.load_controller_config().sigma_threshold
    p = tmp_path / "controller.toml"
    p.write_text("[dm]\nsigma_min_floor = -0.1\n")
    with pytest.raises(w.ConfigError) as e:
        w.load_controller_config(p)
    assert e.value.key == "dm.sigma_min_floor" and e.value.path == p and ">= 0" in e.value.reason
