"""The compiled hot path's guards: shapes, caches, warm-up (wmm_qp/_jit.py and its callers)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from support.core_fixtures import Q0, config, model

import wmm_qp as w
from wmm_qp import _jit
from wmm_qp.limits import joint_motion_bounds


def test_a_state_whose_arrays_were_replaced_with_wrong_shapes_is_a_safe_stop() -> None:
    """The kernels do not bounds-check: a mutated RobotState must never reach them."""
    ctl = w.QpController(model(), config())
    state = w.RobotState(np.zeros(3), Q0)
    state.q_arm = np.zeros(8)  # RobotState is mutable
    cmd = ctl.step(state, w.Reference("hold"))
    assert cmd.status == w.Status.SAFE_STOP and "shape" in cmd.reason
    state.q_arm = Q0.astype(np.float32)  # right length, wrong type
    assert ctl.step(state, w.Reference("hold")).status == w.Status.SAFE_STOP


def test_public_entry_points_reject_wrong_lengths() -> None:
    arm = model().config.arm
    with pytest.raises(ValueError, match="entries"):
        lim = (arm.position_lower, arm.position_upper, arm.velocity_max, arm.acceleration_max)
        joint_motion_bounds(np.zeros(5), np.zeros(5), *lim, 0.002)
    with pytest.raises(ValueError, match="entries"):
        model().arm.pin_q(np.zeros(8))
    with pytest.raises(ValueError, match="entries"):
        model().kinematics(np.zeros(2), Q0)


def test_state_fields_are_own_contiguous_float_copies() -> None:
    q = np.array(Q0)
    q.setflags(write=False)
    s = w.RobotState(np.zeros(3), q[::1], v_arm=np.zeros(14)[::2])
    assert s.q_arm is not q and s.q_arm.flags.writeable and s.v_arm.flags.c_contiguous


def test_warm_up_raises_if_a_kernel_fails_and_clears_the_counters(monkeypatch: pytest.MonkeyPatch) -> None:
    ctl = w.QpController(model(), config())
    ctl.warm_up()
    assert ctl.closed_form_hits == 0 and ctl.task_checks == 0
    monkeypatch.setattr(ctl, "closed_form", lambda p: 1 / 0)
    with pytest.raises(RuntimeError, match="warm-up"):
        ctl.warm_up()


def test_a_source_change_drops_the_packages_kernel_caches(tmp_path: Path) -> None:
    pkg = tmp_path / "pkg"
    (pkg / "sub" / "__pycache__").mkdir(parents=True)
    (pkg / "a.py").write_text("x = 1\n")
    (pkg / "sub" / "b.py").write_text("y = 2\n")
    cached = pkg / "sub" / "__pycache__" / "b.f-1.py311.nbi"
    cached.write_text("index")
    assert _jit._drop_stale_caches(pkg)  # no stamp yet: dropped, stamp written
    assert not cached.exists()
    cached.write_text("index")
    assert not _jit._drop_stale_caches(pkg) and cached.exists()  # unchanged sources: kept
    (pkg / "a.py").write_text("x = 3\n")  # another file than the cached kernel's
    assert _jit._drop_stale_caches(pkg) and not cached.exists()


def test_without_a_writable_cache_the_kernels_compile_in_memory(monkeypatch: pytest.MonkeyPatch) -> None:
    calls: list[bool] = []

    def fake_njit(**kw: object):  # type: ignore[no-untyped-def]
        calls.append(bool(kw["cache"]))
        if kw["cache"]:
            raise RuntimeError("cannot cache function 'f': no locator available for file '<x>'")
        return lambda fn: fn

    monkeypatch.setattr(_jit, "njit", fake_njit)
    f = _jit.jit(lambda x: x + 1)
    assert f(1) == 2 and calls == [True, False]
