"""The referee of ``wmm-qp verify`` (wmm_qp/verify.py) must be able to fail."""

from __future__ import annotations

import numpy as np
import pytest
from core_fixtures import Q0, config, model

import wmm_qp as w
from wmm_qp.verify import check_command, verify_controller

ARM = model().config.arm
DT = config().dt


def cmd(arm: np.ndarray) -> w.Command:
    return w.Command(wheel_speeds=np.zeros(4), arm_rates=arm)


def test_a_command_that_cannot_brake_before_the_limit_is_a_position_violation() -> None:
    q = Q0.copy()
    q[1] = ARM.position_upper[1] - 0.01  # 10 mrad before joint 2's limit
    v0 = np.zeros(7)
    v0[1] = 0.5
    state = w.RobotState(np.zeros(3), q, v_arm=v0)
    fast = v0.copy()  # one step stays inside (5 mrad/s·dt ≪ 10 mrad) but braking needs 24 mrad
    assert check_command(model().config, DT, state, cmd(fast))["position"] == 1
    brake = v0 - ARM.acceleration_max * DT  # braking now: always legal
    assert check_command(model().config, DT, state, cmd(brake))["position"] == 0


def test_verify_catches_a_controller_without_the_braking_bound(monkeypatch: pytest.MonkeyPatch) -> None:
    """Drop the braking-distance part of bounds (13): the referee must notice."""
    from wmm_qp.config import N_WHEELS
    from wmm_qp.limits import intersect_by_priority

    ctl = w.QpController(model(), config().with_(qp={"solver": "daqp"}))
    arm, wheels = model().config.arm, ctl.bounds

    def one_step_only(q, v_prev):  # type: ignore[no-untyped-def]
        lo, hi = wheels(q, v_prev)  # the wheels' bounds as they are; the arm's without braking
        a, qa, va = arm.acceleration_max * DT, q[N_WHEELS:], v_prev[N_WHEELS:]
        alo, ahi = intersect_by_priority(va - a, va + a, -arm.velocity_max, arm.velocity_max)
        lo[N_WHEELS:], hi[N_WHEELS:] = intersect_by_priority(
            alo, ahi, np.minimum((arm.position_lower - qa) / DT, 0), np.maximum((arm.position_upper - qa) / DT, 0)
        )
        return lo, hi

    monkeypatch.setattr(ctl, "bounds", one_step_only)
    assert verify_controller(ctl, model(), 150, 0).by_kind["position"] > 0
