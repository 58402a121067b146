"""In-process fuzzing of the validators and the daemon core (fast; the wire run is in test_fuzz_wire).

Whatever bytes arrive: the validator never raises, anything it accepts is well formed (sizes,
finite numbers, ranges), and the controller fed with the accepted ones keeps commanding
finite rates inside the velocity limits.
"""

from __future__ import annotations

import math
from collections import Counter
from typing import Any

import msgspec
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from support.daemon_drive import send
from wmm_qp_service.config import ServiceConfig
from wmm_qp_service.daemon import ControlCore
from wmm_qp_service.protocol import PROTOCOL_VERSION, CommandMsg, ModeMsg, SetpointMsg, StateMsg
from wmm_qp_service.validation import Reject, Validator
from wmm_qp_tools.fuzz import KEYS, KINDS, Mutator, templates

import wmm_qp as w

ROBOT = "wmm"
CONFIG = w.load_robot_config()
N_ARM, N_WHEELS = CONFIG.n_arm, CONFIG.n_wheels
TYPES: dict[str, type[msgspec.Struct]] = {"state": StateMsg, "setpoint": SetpointMsg, "mode": ModeMsg,
                                          "cmd": CommandMsg}


def validators() -> dict[str, Validator[Any]]:
    lim = ServiceConfig().validation
    return {k: Validator(t, ROBOT, lim, n_arm=N_ARM, n_wheels=N_WHEELS) for k, t in TYPES.items()}


def well_formed(msg: msgspec.Struct) -> None:
    """What every accepted message guarantees."""
    assert msg.robot == ROBOT and msg.v == PROTOCOL_VERSION  # type: ignore[attr-defined]
    assert math.isfinite(msg.stamp)  # type: ignore[attr-defined]
    sizes = {"q_base": 3, "q_arm": N_ARM, "v_arm": N_ARM, "wheel_speeds": N_WHEELS, "x": 3, "xd": 3,
             "direction": 3, "arm_rates": N_ARM, "q": 4, "w": 3}
    for name, n in sizes.items():
        v = getattr(msg, name, None)
        if v is not None:
            assert len(v) == n and all(math.isfinite(e) for e in v), (name, v)
    for name, n in {"tau": N_ARM}.items():  # may hold nan
        v = getattr(msg, name, None)
        assert v is None or len(v) == n, (name, v)


hostile = st.recursive(
    st.none() | st.booleans() | st.integers(-(2**63), 2**64 - 1) | st.floats(allow_nan=True, allow_infinity=True)
    | st.text(max_size=20) | st.binary(max_size=20),
    lambda inner: st.lists(inner, max_size=12) | st.dictionaries(st.text(max_size=8), inner, max_size=5),
    max_leaves=30)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.binary(max_size=600), key=st.sampled_from(list(TYPES)))
def test_random_bytes_never_raise(data: bytes, key: str) -> None:
    v = validators()[key]
    msg = v(data)
    if msg is not None:
        well_formed(msg)
    else:
        assert sum(v.rejected.values()) == 1


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(key=st.sampled_from(list(TYPES)), field=st.text(max_size=12), value=hostile,
       drop=st.booleans())
def test_mutated_fields_are_rejected_or_well_formed(key: str, field: str, value: Any, drop: bool) -> None:
    msg = dict(templates(ROBOT)[key])
    name = field if field and not drop else list(msg)[len(field) % len(msg)]
    if drop:
        del msg[name]
    else:
        msg[name] = value
    v = validators()[key]
    out = v(msgspec.msgpack.encode(msg))
    if out is not None:
        well_formed(out)
    else:
        assert set(v.rejected) <= {r.value for r in Reject}


def test_mutator_covers_every_kind_and_key() -> None:
    mut = Mutator(ROBOT, seed=1)
    seen: Counter[tuple[str, str]] = Counter()
    for key in KEYS:
        for kind in KINDS:
            payload, k = mut.payload(key, kind)
            assert k == kind and isinstance(payload, bytes)
            seen[key, kind] += 1
    assert len(seen) == len(KEYS) * len(KINDS)


def test_mutation_fuzz_through_the_validators_and_the_controller() -> None:
    """20,000 mutated messages; the accepted ones drive a ControlCore against an exact plant."""
    robot = CONFIG
    core = ControlCore(ServiceConfig(), w.load_controller_config(), robot)
    vals = validators()
    mut = Mutator(ROBOT, seed=7)
    dt = core.dt
    q_arm = np.array(robot.arm.start)
    v_arm, wheels, q_base = np.zeros(robot.n_arm), np.zeros(robot.n_wheels), np.zeros(3)
    vmax = np.asarray(robot.arm.velocity_max)
    rejected = 0
    t = 0.0
    for i in range(20_000):
        key = ("state", "setpoint", "mode", "cmd")[i % 4]
        payload, _ = mut.payload(key)
        msg = vals[key](payload)
        if msg is None:
            rejected += 1
        else:
            well_formed(msg)
            if isinstance(msg, SetpointMsg):
                core.on_setpoint(msg, t)
            elif isinstance(msg, ModeMsg):
                core.on_mode(msg)
            # accepted forged states are not fed: the plant below is the truth
        if i % 4 == 3:  # one control tick per four messages, with the true state
            core.on_state(StateMsg(robot=ROBOT, seq=i + 1, stamp=t, t=t, q_base=q_base.tolist(),
                                   q_arm=q_arm.tolist(), v_arm=v_arm.tolist(), wheel_speeds=wheels.tolist(),
                                   tau=[0.0] * robot.n_arm, instance="sim", cmd_seq=core.stream.seq), t)
            cmd = core.tick(t)
            assert cmd is not None
            send(core, t)  # numbered and sent, as the daemon's cycle does; the next state names it applied
            assert np.isfinite(cmd.arm_rates).all() and np.isfinite(cmd.wheel_speeds).all()
            assert (np.abs(cmd.arm_rates) <= vmax + 1e-6).all()
            assert (np.abs(cmd.wheel_speeds) <= robot.base.wheel_speed_max + 1e-6).all()
            v_arm, wheels = cmd.arm_rates.copy(), cmd.wheel_speeds.copy()
            q_arm = q_arm + dt * v_arm
            q_base = q_base + dt * (core.model.base.P(float(q_base[2])) @ wheels)
            t += dt
    assert rejected > 15_000  # most of it is hostile
    assert core.stream.confirmed and not core.fault_record.counts["commands_not_applied"]  # it ran every tick
    assert all(np.isfinite(core.smoother.step()[0]))


def test_one_bogus_stamp_does_not_freeze_the_velocity_estimate() -> None:
    """Found by the fuzzer: a far-future stamp used to freeze the estimator until a mode change."""
    from wmm_qp_service.smoother import VelocityEstimator

    e = VelocityEstimator()
    e.update(np.array([0.6, 0.0, 0.5]), 100.0)
    e.update(np.array([0.6, 0.0, 0.5]), 1e12)  # finite, so it passes validation
    x, _ = e.update(np.array([0.7, 0.0, 0.5]), 100.1)
    assert x[0] == pytest.approx(0.7)
    for k in range(2, 20):
        x, v = e.update(np.array([0.7 + 0.001 * k, 0.0, 0.5]), 100.0 + 0.01 * k)
    assert v[0] > 0.0  # the stream is followed again


def test_non_finite_stamp_is_rejected() -> None:
    v = validators()["setpoint"]
    bad = msgspec.msgpack.encode(SetpointMsg(robot=ROBOT, seq=1, stamp=math.inf, x=[0.6, 0.0, 0.5], source="op"))
    assert v(bad) is None and v.rejected == Counter({"non_finite": 1})


def test_huge_payload_is_rejected_before_decoding() -> None:
    v = validators()["setpoint"]
    big = msgspec.msgpack.encode(SetpointMsg(robot=ROBOT, seq=1, stamp=0.0, x=[0.5] * 20_000, source="op"))
    assert v(big) is None and v.rejected == Counter({"size": 1})
    assert "bytes exceeds" in v.last_rejection


@pytest.mark.parametrize("base", ["diff_drive", "fixed"])
def test_mutations_for_another_robot(tmp_path, base: str) -> None:  # type: ignore[no-untyped-def]
    """The templates and validators take the robot's sizes: the valid templates of a Gen3 on
    another base pass its validators, and whatever else passes has its lengths."""
    from support.service_robots import gen3_file

    robot = w.load_robot_config(gen3_file(tmp_path, base))
    na, nw = robot.n_arm, robot.n_wheels
    lim = ServiceConfig().validation
    vals = {k: Validator(t, "r", lim, n_arm=na, n_wheels=nw) for k, t in TYPES.items()}
    mut = Mutator("r", seed=3, config=robot)
    for key, v in vals.items():
        assert v(msgspec.msgpack.encode(mut.templates[key])) is not None, (key, v.last_rejection)
    for i in range(4000):
        key = list(TYPES)[i % 4]
        msg = vals[key](mut.payload(key)[0])
        if msg is not None:
            for name, n in (("q_arm", na), ("v_arm", na), ("tau", na), ("arm_rates", na), ("wheel_speeds", nw)):
                if (vec := getattr(msg, name, None)) is not None:
                    assert len(vec) == n, (name, vec)
