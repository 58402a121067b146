"""An experiment written once (experiments/scenario.py) and its in-process driver (experiments/runner.py):
phases, their ticks, their references and where the trace records each one."""

from __future__ import annotations

import math

import numpy as np
import pytest
from wmm_qp_tools.experiments import dm, push
from wmm_qp_tools.experiments.runner import phase_ticks, run
from wmm_qp_tools.experiments.scenario import Anchor, Phase, Scenario, Target
from wmm_qp_tools.experiments.setup import make_setup

import wmm_qp as w

X = np.array([1.0, 0.0, 0.0])


def test_a_phase_streams_its_target_from_its_anchor_or_leaves_x_d_to_the_controller() -> None:
    def target(t: float, start: Anchor) -> Target:
        return Target(start.x + t * X, X, start.quat)

    moving = Phase("move", w.Mode.TRACK, 1.0, direction=X, target=target)
    ref = moving.reference(0.5, Anchor(np.array([0.6, 0.0, 0.5]), np.array([0.0, 0.0, 0.0, 1.0])))
    assert ref.mode == w.Mode.TRACK and ref.x_d is not None
    np.testing.assert_allclose(ref.x_d, [1.1, 0.0, 0.5])
    np.testing.assert_allclose(ref.xd_d, X)
    np.testing.assert_allclose(ref.direction, X)
    np.testing.assert_allclose(ref.quat_d, [0.0, 0.0, 0.0, 1.0])
    assert moving.mode_message() == ("track", [1.0, 0.0, 0.0])
    cartesian = dm.cartesian_phase(X, 2.0)
    ref = cartesian.reference(0.5, Anchor(np.zeros(3)))
    assert ref.mode == w.Mode.DM_CARTESIAN and ref.x_d is None  # the controller moves the EE itself
    assert Phase("hold", w.Mode.HOLD, 1.0).mode_message() == ("hold", None)


def test_a_scenario_needs_unique_phase_names_and_normalises_its_dm_direction() -> None:
    p = Phase("a", w.Mode.HOLD, 1.0)
    with pytest.raises(ValueError, match="unique names"):
        Scenario("s", (p, p), X)
    np.testing.assert_allclose(Scenario("s", (p,), np.array([0.0, 0.0, 2.0])).dm_direction, [0.0, 0.0, 1.0])
    assert Scenario("s", (p, Phase("b", w.Mode.HOLD, 0.5)), X).duration == 1.5


@pytest.mark.parametrize(("durations", "ticks"), [
    ((5.0, 15.0), [2500, 7500]),  # the dm experiment
    ((0.75, 1.25, 1.35), [375, 625, 675]),  # push with 3 s of DM first
    ((0.3003, 0.3003), [151, 149]),  # b starts at the first tick at or after 0.3003 s; 300.3 ticks in all
    ((0.0026, 0.0004), [2, 0]),  # b's first tick would be at 4 ms: beyond the run's two ticks (3 ms)
])
def test_a_phase_starts_at_the_first_tick_at_or_after_its_start_time(durations: tuple[float, ...],
                                                                      ticks: list[int]) -> None:
    sc = Scenario("s", tuple(Phase(f"p{i}", w.Mode.HOLD, d) for i, d in enumerate(durations)), X)
    # (the rule of the dm experiment's switch: its first null-space tick is the first at t ≥ t_switch)
    assert phase_ticks(sc, 0.002) == ticks
    assert sum(ticks) == round(sum(durations) / 0.002)


def test_in_process_the_trace_records_where_each_phase_starts_and_the_box_from_the_push_on() -> None:
    """push with DM first: the DM phases, then the box placed and pushed, in one trace."""
    s = make_setup("qp")
    sc = push.scenarios(dm_duration=1.0)["with_dm"]  # 0.25 s Cartesian, 0.75 s null space, then the push
    tr = run(s, sc)
    starts = tr.phase_starts
    assert list(starts) == [dm.CARTESIAN, dm.NULLSPACE, push.PUSH]
    assert starts[dm.CARTESIAN] == 0 and starts[dm.NULLSPACE] == 125 and starts[push.PUSH] == 500
    assert set(tr.mode[:125]) == {"dm_cartesian"} and set(tr.mode[125:500]) == {"dm_nullspace"}
    assert set(tr.mode[500:]) == {"track"} and len(tr.t) <= 500 + 338  # the push: 0.675 s at most
    np.testing.assert_allclose(tr.t[:3], [0.0, 0.002, 0.004])
    assert np.isnan(tr.box_displacement[:500]).all() and tr.box_displacement[500] == 0.0  # placed at the push
    assert tr.box_displacement_end >= tr.box_displacement[-1] and tr.box_tilt_end == 0.0
    # the push's reference starts where the controller estimated the EE at its first tick
    x_model = s.model.ee_position(tr.base_odom[500], tr.q[500])
    np.testing.assert_allclose(tr.ee_des[500], x_model, atol=1e-12)
    # the null space holds the EE where the controller estimated it at the switch
    np.testing.assert_allclose(tr.ee_des[125:500], np.tile(tr.ee_des[125], (375, 1)))
    m = push.push_metrics(s, tr)
    assert m["dm_at_push_start"] == tr.dm[500] and m["distance"] == tr.box_displacement_end
    assert m["box_tilt_deg"] == 0.0 and math.isfinite(m["max_weighted_torque_norm"])


def test_a_phase_that_is_done_ends_early() -> None:
    s = make_setup("qp")
    ticks: list[float] = []

    def done(t: float, _robot: object) -> bool:
        ticks.append(t)
        return t >= 0.01 - 1e-12

    sc = Scenario("s", (Phase("a", w.Mode.HOLD, 1.0, done=done), Phase("b", w.Mode.HOLD, 0.02)), X)
    tr = run(s, sc)
    assert tr.phase_starts == {"a": 0, "b": 6} and len(tr.t) == 16  # 6 ticks of a (t = 0 … 0.01), 10 of b
    np.testing.assert_allclose(ticks, np.arange(6) * 0.002)
