"""Row sources (``wmm_qp/limits/rows.py``): every source of QP rows returns named rows of one
shape, and the QP controller's stages treat a source they have never seen like the shipped ones —
the arm-only relaxation, the stage solved again when the rows exclude each other, the reason that
names what cut the task."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import wmm_qp as w
from wmm_qp.controllers.qp.stage_rows import StageRows
from wmm_qp.limits.collision import CollisionRows
from wmm_qp.limits.ee_box import EeBox
from wmm_qp.limits.fence import FenceRows
from wmm_qp.limits.rows import Retry, Rows, RowSource, Tick
from wmm_qp.limits.singularity_floor import SigmaMinFloor
from wmm_qp.scene import load_scene
from wmm_qp.types import AT_REST

ROBOTS = w.default_config_dir() / "robots"


def _scene(tmp_path: Path, x: np.ndarray) -> w.Scene:
    """A ball 0.1 m beside the EE at x and a fence whose EE face is 0.05 m above it."""
    p = tmp_path / "scene.toml"
    p.write_text(f'[[obstacles]]\nid = "ball"\nkind = "sphere"\nradius = 0.05\n'
                 f"xyz = [{x[0]}, {x[1] + 0.15}, {x[2]}]\n\n"
                 f"[fence]\nee_lower = [-10.0, -10.0, -10.0]\nee_upper = [10.0, 10.0, {x[2] + 0.05}]\n")
    return load_scene(p)


def _tick(ctl: w.QpController, state: w.RobotState, mode: w.Mode) -> Tick:
    ctx = ctl.context(state, w.Reference(mode), need_gradient=True)
    wheels = np.zeros(ctl.n_wheels) if state.wheel_speeds is AT_REST else state.wheel_speeds
    return Tick(mode, ctx.kin, np.concatenate((wheels, state.v_arm)), ctx.lo, ctx.hi)


@pytest.mark.parametrize("robot", ["gen3_mecanum.toml", "ur5_omni.toml"])
def test_every_row_source_returns_named_rows_of_the_stated_shapes(robot: str, tmp_path: Path) -> None:
    """The EE box of eq. (17), the collision pairs, the fence and the σ_min floor, each active: C is
    (k, n_v) on v = [v_b; v_m], every other array (k,), one non-empty name per row, l ≤ u, and
    l ≤ l_brake never asks more than l."""
    model = w.WmmModel(w.load_robot_config(ROBOTS / robot))
    cfg = w.load_controller_config().with_(collision={"enabled": True}, sigma_min_floor=10.0)  # the floor always near
    ctl = w.QpController(model, cfg.with_(ee_box_lower=np.array([-np.inf, -np.inf, -10.0]),
                                          ee_box_upper=np.array([np.inf, np.inf, 10.0])))
    q = model.config.arm.start
    state = w.RobotState(q_base=np.zeros(3), q_arm=q, v_arm=np.full(model.config.arm.n, 0.01))
    ctl.set_scene(_scene(tmp_path, model.ee_position(np.zeros(3), q)))
    kinds = {EeBox: 0, CollisionRows: 0, FenceRows: 0, SigmaMinFloor: 0}
    for source in ctl.row_sources:
        rows = source.compute_rows(_tick(ctl, state, w.Mode.DM_CARTESIAN))
        assert rows is not None, source.name
        k = rows.n
        kinds[type(source)] = k
        assert rows.C.shape == (k, ctl.n_v), source.name
        for a in (rows.l, rows.l_brake, rows.damper, rows.distances, rows.upper()):
            assert a.shape == (k,), source.name
        assert len(rows.names) == k and all(isinstance(n, str) and n for n in rows.names), rows.names
        assert (rows.l <= rows.upper()).all() and (rows.l_brake <= rows.l).all(), source.name
        assert (rows.l <= rows.damper).all(), source.name  # relaxed, never tightened
    assert all(k >= 1 for k in kinds.values()), kinds
    assert ctl.row_sources[0].compute_rows(_tick(ctl, state, w.Mode.TRACK)) is None  # eq. (17): DM_CARTESIAN only


class _Copy(RowSource):
    """A source the controller has never seen: it gives the rows it is handed, in every mode."""

    name = "copy"

    def __init__(self, rows: Rows, retry: Retry) -> None:
        self.rows, self.retry = rows, retry

    def compute_rows(self, tick: Tick) -> Rows:
        return self.rows


def test_the_arm_only_relaxation_treats_a_new_source_like_the_dampers(tmp_path: Path) -> None:
    """The arm-first stage holds the wheels and relaxes every row to what the arm alone can do:
    the collision rows, and the same rows given by a new (KEEP) source, give the same stage,
    l = min(damper, max C_arm v_m + C_w w) − C_w w."""
    model = w.WmmModel(w.load_robot_config(ROBOTS / "gen3_mecanum.toml"))
    ctl = w.QpController(model, w.load_controller_config().with_(collision={"enabled": True}))
    q = model.config.arm.start
    ctl.set_scene(_scene(tmp_path, model.ee_position(np.zeros(3), q)))
    state = w.RobotState(q_base=np.zeros(3), q_arm=q, v_arm=np.full(7, 0.2), wheel_speeds=np.full(4, 2.0))
    tick = _tick(ctl, state, w.Mode.TRACK)
    assert ctl.collision is not None
    rows = ctl.collision.compute_rows(tick)
    assert rows.n >= 1
    ctx = ctl.context(state, w.Reference(w.Mode.TRACK), need_gradient=False)
    xdot = np.array([0.05, 0.0, 0.0])
    stages = []
    for source in (ctl.collision, _Copy(Rows(rows.C.copy(), rows.l.copy(), l_brake=rows.l_brake.copy(),
                                             damper=rows.damper.copy(), names=list(rows.names),
                                             distances=rows.distances.copy()), Retry.KEEP)):
        p, held = ctl.build_arm_first(ctx, xdot, StageRows([(source, source.compute_rows(tick))], ctl.n_v))
        stages.append((p.C.copy(), p.l.copy(), p.u.copy(), held))
    (C1, l1, u1, held), (C2, l2, u2, _) = stages
    np.testing.assert_array_equal(C1, C2)
    np.testing.assert_array_equal(l1, l2)
    np.testing.assert_array_equal(u1, u2)
    share = rows.C[:, :4] @ held
    Ca = rows.C[:, 4:]
    best = np.sum(np.maximum(Ca * ctx.lo[4:], Ca * ctx.hi[4:]), axis=1)
    np.testing.assert_allclose(l1, np.minimum(rows.damper, best + share) - share, rtol=0, atol=1e-15)


def test_a_new_source_is_relaxed_in_the_retry_and_named_when_it_cuts_the_task() -> None:
    """A new source (ADMIT) whose rows exclude every command of bounds (13) (l above the box) but
    admit the braking command once relaxed (l_brake = u = 0: the robot held still): the stage has
    no solution, is solved again with the rows relaxed, and the command holds them (v = 0); the
    task is cut, and the reason is the source's own."""

    class Hold(RowSource):
        name = "hold"
        retry = Retry.ADMIT
        rechecked = False

        def compute_rows(self, tick: Tick) -> Rows:
            n = tick.lb.shape[0]
            C = np.eye(n)
            return Rows(C, tick.ub + 0.1, l_brake=np.zeros(n), damper=tick.ub + 0.1,
                        names=[f"hold {i}" for i in range(n)], distances=np.zeros(n), u=np.zeros(n))

        def cut_reason(self, rows: Rows, v: np.ndarray) -> str:
            return "hold: the robot held still" if np.allclose(rows.C @ v, 0.0) else ""

    model = w.WmmModel(w.load_robot_config(ROBOTS / "gen3_mecanum.toml"))
    cfg = w.load_controller_config().with_(qp={"solver": "daqp", "arm_first": False}, collision={"enabled": False})
    ctl = w.QpController(model, cfg)
    ctl.row_sources.append(Hold())
    q = model.config.arm.start
    cmd = ctl.step(w.RobotState(np.zeros(3), q), w.Reference(w.Mode.TRACK, xd_d=[0.05, 0.0, 0.0]))
    assert cmd.status == w.Status.SATURATED, (cmd.status, cmd.reason)
    assert cmd.reason.startswith("hold: the robot held still"), cmd.reason
    np.testing.assert_allclose(cmd.v, 0.0, atol=1e-9)
