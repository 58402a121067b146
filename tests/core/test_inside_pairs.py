"""The rows of the pairs inside their safety distance (wmm_qp/limits/inside_pairs.py): on the bodies,
at the configuration full braking reaches."""

from __future__ import annotations

import numpy as np
import pytest
from support.collision_robots import model

import wmm_qp as w
from wmm_qp.scene import load_scene
from wmm_qp.verify import CollisionJudge

# Two of the Panda's states of ``wmm-qp verify --robot-config configs/robots/panda_diffdrive.toml
# --samples 2000`` (seed 0, the default scene; both sampled beyond a position limit, hold mode),
# each a collision before these rows: the command took the pair deeper than full braking would.
FINGER_IN_BASE = w.RobotState(  # sample 122: a finger's sphere 12.7 cm in the base's box
    q_base=np.array([-1.3158081377062945, 1.0808500436508646, 2.2721428588149237]),
    q_arm=np.array([-2.2137091890950815, -1.2091611166271126, -2.926200884356982, -2.0902346378462413,
                    -0.4973868056287154, 1.7267414565646466, 2.56688145997176]),
    v_arm=np.array([1.7357296456467182, -1.7006324765521126, -0.9831324836390204, 0.20771763224227074,
                    -1.1023176261172978, -0.8254701866541081, 2.490495826875483]),
    wheel_speeds=np.array([-7.885887331169532, 3.0886978841659607]),
)
FINGER_REF = w.Reference("hold", x_d=np.array([-1.3401185208142863, -1.6162887953638365, -0.6049874830570162]),
                         xd_d=np.array([-5.115301401345627, -6.902637871281208, -2.344285785222721]))
HAND_AT_LINK1 = w.RobotState(  # sample 512: link1's and the hand's cylinders 0.2 mm inside d_s
    q_base=np.array([-0.09392960640433934, 1.717385097913935, -3.0094621720103523]),
    q_arm=np.array([2.2283368330176265, 0.10139511298102155, -2.1159212733198673, -3.0771622638057488,
                    1.1069191148391515, 0.3129660464432344, -2.3647525473958386]),
    v_arm=np.array([-0.6205731778120378, 1.6465697019337233, -0.8199063693803514, -1.0161170095959706,
                    0.14682756951189016, 0.7726078604009514, -1.9835116857324695]),
    wheel_speeds=np.array([3.491052728072761, 0.7662436312552618]),
)
HAND_REF = w.Reference("hold", x_d=np.array([-0.2973259514948579, 1.571491073035516, 0.6880892973823622]),
                       xd_d=np.array([-3.525164984717793, 6.2599107316176426, -4.042841399106434]))
CASES = {
    # the nearest face of the base's box changes 0.3 of a tick into the motion
    "finger_in_base": (FINGER_IN_BASE, FINGER_REF, "panda_rightfinger_2/base_body"),
    # the capsules the rows keep apart are 1.2 cm in each other; the judge checks the cylinders
    "hand_at_link1": (HAND_AT_LINK1, HAND_REF, "panda_link1_0/panda_hand_1"),
}


def panda() -> tuple[w.WmmModel, w.Controller, CollisionJudge]:
    m = model("panda_diffdrive.toml")
    cfg = w.load_controller_config()
    ctl = w.make_controller("qp", m, cfg)
    scene = load_scene(None)
    ctl.set_scene(scene)
    p = cfg.collision
    return m, ctl, CollisionJudge(m, scene, p.safety_distance, p.floor_margin)


@pytest.mark.parametrize("case", list(CASES))
def test_a_pair_inside_d_s_goes_no_deeper_than_full_braking_takes_it(case: str) -> None:
    """verify's rule on the bodies: the pair's distance after the tick no less than full braking's
    (to 1e-5 m). The rows of the row shapes at the state had let the command take it 1.5e-5 m
    (the finger: another face nearest by the end of the tick) and 2.0e-5 m (the cylinders: the
    capsules' witness points are not theirs) deeper than braking."""
    _, ctl, judge = panda()
    state, ref, pair = CASES[case]
    cmd = ctl.step(state, ref)
    assert cmd.status.value == "saturated", cmd.reason
    assert judge.check(ctl.dt, state, cmd) == 0, judge.last
    rows = ctl.last_collision_rows()
    assert rows is not None and pair in rows.names


@pytest.mark.parametrize("case", list(CASES))
def test_the_row_at_the_braking_configuration_predicts_the_bodies_distance_after_the_tick(case: str) -> None:
    """The inside pair's row on its bodies: d + Δt·(C_b v − offset) — i.e. d_b + Δt·C_b (v − v₀) —
    is the judge's distance after the tick for any command v of the box, to 1e-8 m (second order
    in Δt·(v − v₀)), across the finger's change of nearest face and on the cylinders themselves."""
    m, ctl, judge = panda()
    state, ref, pair = CASES[case]
    ctl.step(state, ref)
    rows = ctl.last_collision_rows()
    assert rows is not None
    ctx = ctl.context(state, ref, need_gradient=False)
    lb, ub = ctx.lo, ctx.hi
    v0 = np.clip(0.0, lb, ub)
    k = len(rows.names) - 1 - rows.names[::-1].index(pair)  # the inside rows come last
    C, d = rows.C[k], rows.distances[k]
    n_w = m.config.base.n_wheels
    now = judge.distances(state.q_base, state.q_arm)[pair]
    assert d == pytest.approx(now, abs=1e-12)  # the bodies' distance now, not the row shapes'
    d_b = judge._after(ctl.dt, state, v0[:n_w], v0[n_w:])[pair]
    rng = np.random.default_rng(0)
    for _ in range(20):
        v = rng.uniform(lb, ub)
        after = judge._after(ctl.dt, state, v[:n_w], v[n_w:])[pair]
        assert d_b + ctl.dt * (C @ (v - v0)) == pytest.approx(after, abs=1e-8)


@pytest.mark.parametrize("case", [*CASES, "start"])
def test_the_packed_rows_equal_the_rows_assembled_bounded_and_merged_one_by_one(case: str) -> None:
    """``CollisionRows.rows`` takes its rows packed in two arrays from one compiled call (``_rows``:
    the kept rows, then the pairs inside d_s before the merge); they equal, bit for bit, the rows
    of its parts called one by one (``_assemble``, ``damper_bounds``, ``_distinct_rows``) indexed
    by the rows kept, and the inside rows appended are those of the same pairs. The Panda's several
    capsules a link merge (at its start 42 rows become 10), and both cases have pairs inside d_s."""
    from wmm_qp.limits.collision import MAX_ROWS, _assemble, _distinct_rows
    from wmm_qp.limits.dampers import damper_bounds
    from wmm_qp.limits.pair_search import PairNames
    from wmm_qp.limits.rows import Rows

    m, ctl, _ = panda()
    if case == "start":
        state, ref = w.RobotState(np.zeros(3), m.config.arm.start), w.Reference("hold")
    else:
        state, ref, _pair = CASES[case]
    ctl.step(state, ref)  # the arm's data at the state
    col = ctl.collision  # type: ignore[attr-defined]
    ctx = ctl.context(state, ref, need_gradient=False)
    out = col.rows(ctx.kin.q_base, ctx.kin.q_arm, ctx.v_prev, ctx.lo, ctx.hi)
    f, p = col.search.candidates, col.p
    C, dist, safety, body, other, _normal, keys, _closest, n_inside = _assemble(
        f.d, f.p_a, f.p_b, f.normal, f.body, f.other, f.safety, f.n, p.influence_distance, MAX_ROWS, ctl.n_v,
        col._Jw, col._support, col._body_joint, col.M, col.n_w, col._body_link, col._n_links, len(col.obstacles))
    l, l_brake, damper = damper_bounds(C, ctx.v_prev, ctx.lo, ctx.hi, dist, safety, p.influence_distance, p.gain,
                                       col.latency, np.zeros(dist.shape[0]), col._accel, p.braking,
                                       np.zeros(dist.shape[0]))
    keep = _distinct_rows(C, l, keys)
    assert keep.shape[0] < dist.shape[0]  # rows merged
    names = PairNames(col.search.namer(), body[keep], other[keep])
    ref_rows = Rows(C[keep], l[keep], l_brake[keep], damper[keep], names, dist[keep])
    inside = np.flatnonzero(dist < safety)
    assert inside.shape[0] == n_inside and (n_inside > 0) == (case != "start")
    if n_inside:
        col._add_inside(ref_rows, body[inside], other[inside], safety[inside], ctx.kin.q_base, ctx.kin.q_arm,
                        ctx.v_prev, ctx.lo, ctx.hi)
    for field in ("C", "l", "l_brake", "damper", "distances"):
        assert np.array_equal(getattr(out, field), getattr(ref_rows, field)), field
    expected = [col.search.name(int(a), int(b)) for a, b in zip(body[keep], other[keep], strict=True)]
    expected += [col.search.name(int(a), int(b)) for a, b in zip(body[inside], other[inside], strict=True)]
    assert list(out.names) == expected
