"""The FR3's 1 kHz command shaper: every output step within the velocity, acceleration and jerk
limits, whatever the daemon sends and however late; stale commands brake it to rest; a command
past the limits is refused with a protective stop that only a new stream releases."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from wmm_qp_robot.shaper import CommandShaper, StreamLimits

DT = 1e-3
# The FR3's published limits (configs/robots/fr3.toml), written out: the shaper is tested
# against the numbers, not against the file it reads them from.
LIM = StreamLimits(
    q_lo=np.array([-2.7437, -1.7837, -2.9007, -3.0421, -2.8065, 0.5445, -3.0159]),
    q_hi=np.array([2.7437, 1.7837, 2.9007, -0.1518, 2.8065, 4.5169, 3.0159]),
    v_max=np.array([2.62, 2.62, 2.62, 2.62, 5.26, 4.18, 5.26]),
    a_max=np.full(7, 10.0),
    j_max=np.full(7, 5000.0),
)
READY = np.array([0.0, -np.pi / 4, 0.0, -3 * np.pi / 4, 0.0, np.pi / 2, np.pi / 4])
TOL = 1e-9


def _check_bunched(v: np.ndarray, v_prev: np.ndarray, a_prev: np.ndarray, h: float, h_prev: float) -> np.ndarray:
    """Assert one cycle's limits, ``h`` [s] of robot time after the last (which came ``h_prev``
    after the one before): within the velocity limits, the change within A·h, the acceleration's
    within J·max(h, h_prev); return the acceleration (a_prev where h = 0, which changes nothing)."""
    dv = v - v_prev
    assert np.all(np.abs(v) <= LIM.v_max + TOL), f"velocity {v} beyond {LIM.v_max}"
    assert np.all(np.abs(dv) <= LIM.a_max * h + 1e-9), f"{np.abs(dv).max()} rad/s in {h} s of robot time"
    if h == 0.0:
        assert not dv.any()
        return a_prev
    a = dv / h
    assert np.all(np.abs(a - a_prev) <= LIM.j_max * max(h, h_prev) + 1e-6), f"jerk {(a - a_prev) / max(h, h_prev)}"
    return a


def _check_step(v: np.ndarray, v_prev: np.ndarray, a_prev: np.ndarray) -> np.ndarray:
    """Assert one whole-period output step's limits; return its acceleration."""
    return _check_bunched(v, v_prev, a_prev, DT, DT)


# a command: (cycles until it arrives [1, 40], fraction of each joint's velocity limit in [-1, 1])
COMMANDS = st.lists(
    st.tuples(st.integers(1, 40), st.lists(st.floats(-1.0, 1.0), min_size=7, max_size=7)),
    min_size=1, max_size=40,
)


@settings(max_examples=60, deadline=None)
@given(COMMANDS)
def test_every_output_step_is_within_velocity_acceleration_and_jerk_limits_and_braking_reaches_rest(
        commands: list[tuple[int, list[float]]]) -> None:
    sh = CommandShaper(LIM, DT, stale_timeout=0.02)
    q = np.zeros(7) + 0.5 * (LIM.q_lo + LIM.q_hi)  # mid-range: the position check stays out of the way
    v_prev, a_prev, t = np.zeros(7), np.zeros(7), 0.0
    for gap, frac in commands:
        for _ in range(gap):  # late, early, lost: the gap between two commands in cycles
            t += DT
            v = sh.step(t, q)
            a_prev, v_prev = _check_step(v, v_prev, a_prev), v
        sh.command(t, 0.3 * np.array(frac) * LIM.v_max, stream=1, q=q)  # 30 %: mid-range stays inside
    # the command source falls silent: stale within 20 ms, then at rest
    rest_by = 0.02 + float(np.max(LIM.v_max / LIM.a_max + 2 * LIM.a_max / LIM.j_max)) + 0.01
    for _ in range(int(rest_by / DT) + 1):
        t += DT
        v = sh.step(t, q)
        a_prev, v_prev = _check_step(v, v_prev, a_prev), v
    assert sh.stale and sh.at_rest, (sh.v, sh.a)


GAPS = [0.0, 0.05, 0.2, 0.3, 0.7, 1.0, 1.0, 1.0, 2.5]  # [periods] of robot time between two cycles


@settings(max_examples=80, deadline=None)
@given(st.lists(st.tuples(st.lists(st.sampled_from(GAPS), min_size=1, max_size=60),
                          st.lists(st.floats(-1.0, 1.0), min_size=7, max_size=7)), min_size=1, max_size=30))
def test_cycles_bunched_in_robot_time_change_the_output_by_the_time_elapsed_only(
        commands: list[tuple[list[float], list[float]]]) -> None:
    """A driver's cycles need not come a period apart in the robot's time (a loop whose cycles
    bunched under load): each cycle changes the output by at most the acceleration limit times the
    robot time since the previous one (a period at most), its acceleration by at most the jerk
    limit times the longer of that time and the previous cycle's, never past a velocity limit
    (commands up to the limits); the silence after the last command still brakes it to rest. The
    fixed-period shaper changed the rate by a period's worth every cycle, however close: 3.3 x the
    acceleration limit for a cycle 0.3 periods after the last."""
    sh = CommandShaper(LIM, DT, stale_timeout=0.02)
    q = 0.5 * (LIM.q_lo + LIM.q_hi)
    v_prev, a_prev, t, h_prev = np.zeros(7), np.zeros(7), 0.0, DT
    sh.step(t, q)
    for gaps, frac in commands:
        sh.command(t, np.array(frac) * LIM.v_max, stream=1, q=q)
        for g in gaps:
            t += g * DT
            h = min(g, 1.0) * DT
            v = sh.step(t, q)
            a_prev, v_prev = _check_bunched(v, v_prev, a_prev, h, h_prev), v
            h_prev = h or h_prev
    rest_by = 0.02 + float(np.max(LIM.v_max / LIM.a_max + 2 * LIM.a_max / LIM.j_max)) + 0.01
    for k in range(2 * int(rest_by / DT) + 1):  # silent: stale, then at rest (cycles 0.3 and 1.7 periods apart)
        g = 0.3 if k % 2 else 1.7
        t += g * DT
        h = min(g, 1.0) * DT
        v = sh.step(t, q)
        a_prev, v_prev = _check_bunched(v, v_prev, a_prev, h, h_prev), v
        h_prev = h
    assert sh.stale and sh.at_rest, (sh.v, sh.a)


@pytest.mark.parametrize("fraction", [1.0, 0.5])
def test_a_short_cycle_after_landing_on_the_target_stops_accelerating_within_the_last_cycles_jerk(
        fraction: float) -> None:
    """The output lands on its target (joint 1's velocity limit, or half of it) in a whole period,
    accelerating by J·dt at most; the next cycle comes 0.2 periods later and can only stop
    accelerating as fast as the last started: the acceleration's change within J·dt, never past
    the velocity limit, and back on the target within a few cycles."""
    sh = CommandShaper(LIM, DT, stale_timeout=1.0)
    q = 0.5 * (LIM.q_lo + LIM.q_hi)
    target = np.zeros(7)
    v_prev, a_prev, t, h_prev = np.zeros(7), np.zeros(7), 0.0, DT
    for value, gaps in ((fraction * LIM.v_max[0] - 0.004, [1.0] * 400), (fraction * LIM.v_max[0], [1.0, 0.2, 0.2])):
        target[0] = value
        sh.command(t, target, stream=1, q=q)
        for g in gaps:
            t += g * DT
            v = sh.step(t, q)
            a_prev, v_prev = _check_bunched(v, v_prev, a_prev, g * DT, h_prev), v
            h_prev = g * DT
    for _ in range(10):
        t += DT
        v = sh.step(t, q)
        a_prev, v_prev = _check_bunched(v, v_prev, a_prev, DT, h_prev), v
        h_prev = DT
    assert v[0] == target[0], (v[0], target[0])


@settings(max_examples=25, deadline=None)
@given(st.lists(st.tuples(st.integers(1, 5), st.lists(st.floats(-1.0, 1.0), min_size=7, max_size=7)),
                min_size=1, max_size=30), st.integers(0, 6), st.sampled_from([-1.0, 1.0]))
def test_a_joint_driven_towards_its_limit_stops_before_it(commands: list[tuple[int, list[float]]], joint: int,
                                                          side: float) -> None:
    """Integrating the output from near a limit: no joint ever passes one; the shaper stops the arm
    itself (protective stop) when the commands would carry it past."""
    sh = CommandShaper(LIM, DT, stale_timeout=1.0)
    q = 0.5 * (LIM.q_lo + LIM.q_hi)
    q[joint] = (LIM.q_hi if side > 0 else LIM.q_lo)[joint] - side * 0.05  # 5 cm of an angle from the limit
    v_prev, a_prev, t = np.zeros(7), np.zeros(7), 0.0
    for gap, frac in commands:
        f = np.array(frac)
        f[joint] = side * abs(f[joint])  # this joint always towards its limit
        sh.command(t, f * LIM.v_max, stream=1, q=q)
        for _ in range(gap * 100):  # up to 0.5 s between commands: the joint goes on alone
            t += DT
            v = sh.step(t, q)
            a_prev, v_prev = _check_step(v, v_prev, a_prev), v
            q = q + v * DT
            assert np.all(q >= LIM.q_lo - TOL) and np.all(q <= LIM.q_hi + TOL), (q, sh.protective_reason)


def test_a_command_that_could_not_stop_before_a_limit_is_refused_with_a_protective_stop() -> None:
    sh = CommandShaper(LIM, DT)
    q = READY.copy()
    q[0] = LIM.q_hi[0] - 0.01
    v = np.zeros(7)
    v[0] = 2.0  # 2 rad/s needs 0.2 rad to stop at 10 rad/s²: 0.01 rad is not enough
    assert not sh.command(0.0, v, stream=1, q=q)
    why = sh.protective_reason
    assert sh.protective and sh.protective_stops == 1 and "joint 1" in why and "could not stop" in why
    assert not sh.step(DT, q).any()  # the target is rest: nothing moves


def test_a_command_past_a_velocity_limit_is_refused_and_only_a_new_stream_at_rest_recovers() -> None:
    sh = CommandShaper(LIM, DT)
    ok = np.full(7, 0.1)
    assert sh.command(0.0, ok, stream=1, q=READY)
    t = 0.0
    for _ in range(50):
        t += DT
        sh.step(t, READY)
    bad = ok.copy()
    bad[4] = 5.3  # joint 5's limit is 5.26 rad/s
    assert not sh.command(t, bad, stream=1, q=READY)
    assert sh.protective and "joint 5" in sh.protective_reason and "5.26" in sh.protective_reason
    for _ in range(200):  # brakes to rest
        t += DT
        sh.step(t, READY)
        assert not sh.command(t, ok, stream=1, q=READY)  # the same stream: refused, even at rest
    assert sh.at_rest and sh.protective and sh.refused == 1  # the illegal one; the rest ended
    assert sh.ended == 200  # the stop ended stream 1: its commands are not new faults (the first one was)
    assert sh.command(t, ok, stream=2, q=READY)  # a new stream, at rest: resumes
    assert not sh.protective and sh.protective_stops == 1


def test_a_new_stream_while_still_braking_is_refused() -> None:
    sh = CommandShaper(LIM, DT)
    sh.command(0.0, np.full(7, 1.0), stream=1, q=READY)
    for k in range(100):
        sh.step((k + 1) * DT, READY)
    sh.command(0.1, np.full(7, 9.0), stream=1, q=READY)
    sh.step(0.101, READY)
    assert not sh.at_rest and not sh.command(0.101, np.zeros(7), stream=2, q=READY)


def test_stale_commands_brake_to_rest_and_only_a_new_stream_resumes() -> None:
    sh = CommandShaper(LIM, DT, stale_timeout=0.05)
    sh.command(0.0, np.full(7, 0.2), stream=1, q=READY)
    for k in range(1, 51):
        sh.step(k * DT, READY)
    assert not sh.stale and np.all(sh.v == 0.2)  # reached the target (in 22 ms), held it
    sh.step(51 * DT, READY)
    assert sh.stale  # 51 ms after the last command
    assert not sh.command(0.052, np.full(7, 0.2), stream=1, q=READY)  # the stopped stream, late: refused
    for k in range(52, 300):
        sh.step(k * DT, READY)
        assert not sh.command(k * DT, np.full(7, 0.2), stream=1, q=READY)
    assert sh.at_rest and sh.stale and sh.refused == 0 and not sh.protective  # ended, not refused
    assert sh.ended == 249  # each the stopped stream's: none a fault of the sender's
    assert sh.command(0.3, np.full(7, 0.2), stream=2, q=READY) and not sh.stale  # a new stream


def test_a_new_stream_resumes_a_stale_stop_while_still_braking() -> None:
    sh = CommandShaper(LIM, DT, stale_timeout=0.02)
    sh.command(0.0, np.full(7, 0.5), stream=1, q=READY)
    k = 0
    while not sh.stale:
        k += 1
        sh.step(k * DT, READY)
    sh.step((k + 1) * DT, READY)
    assert not sh.at_rest  # braking
    assert sh.command((k + 1) * DT, np.full(7, 0.1), stream=2, q=READY) and not sh.stale


@pytest.mark.parametrize("period_ms", [1, 2])
def test_the_daemons_bounds_drive_a_joint_into_its_limit_without_a_protective_stop(period_ms: int) -> None:
    """Commands at the daemon's bounds (13) with its latency margin (the robot's command timeout,
    25 ms, or more) bring a joint up to its limit at full speed: the shaper follows them, stops
    short of the limit and raises no protective stop (its own braking, jerk-limited, needs more
    room than (13)'s, which the margin covers; with a margin of 5 ms it would stop the arm)."""
    from wmm_qp.limits.joint_motion_bounds import joint_motion_bounds

    sh = CommandShaper(LIM, DT, stale_timeout=0.025)
    q = 0.5 * (LIM.q_lo + LIM.q_hi)
    q[0] = LIM.q_hi[0] - 0.5
    v_cmd = np.zeros(7)
    want = np.zeros(7)
    want[0] = LIM.v_max[0]
    for k in range(2000):
        if k % period_ms == 0:
            lo, hi = joint_motion_bounds(q, v_cmd, LIM.q_lo, LIM.q_hi, LIM.v_max, LIM.a_max, period_ms * 1e-3, 0.025)
            v_cmd = np.clip(want, lo, hi)
            assert sh.command(k * DT, v_cmd, stream=1, q=q), sh.protective_reason
        q = q + sh.step(k * DT, q) * DT
        assert not sh.protective, sh.protective_reason
    assert LIM.q_hi[0] - 0.01 < q[0] <= LIM.q_hi[0] and sh.at_rest


def test_an_illegal_command_of_a_stopped_stream_is_a_fault_not_an_ended_one() -> None:
    """After a stale stop, the stopped stream's legal commands count in ``ended``; an illegal one
    (past a velocity limit, or non-finite) is still refused as a fault: a protective stop."""
    sh = CommandShaper(LIM, DT, stale_timeout=0.05)
    sh.command(0.0, np.full(7, 0.2), stream=1, q=READY)
    for k in range(1, 200):
        sh.step(k * DT, READY)
    assert sh.stale and sh.at_rest
    assert not sh.command(0.2, np.full(7, 0.2), stream=1, q=READY) and sh.ended == 1
    bad = np.full(7, 0.2)
    bad[4] = 5.3  # joint 5's limit is 5.26 rad/s
    assert not sh.command(0.2, bad, stream=1, q=READY)
    assert sh.ended == 1 and sh.refused == 1 and sh.protective and "joint 5" in sh.protective_reason
    assert not sh.command(0.2, np.full(7, 0.2), stream=1, q=READY) and sh.ended == 2  # still ended
    assert sh.command(0.2, np.zeros(7), stream=2, q=READY)  # a new stream at rest resumes


def test_an_illegal_command_of_a_new_stream_in_a_stop_at_rest_ends_that_stream() -> None:
    """The first command of a new stream at rest releases a protective stop; an illegal one is
    refused and the stop becomes its stream's: that stream's next, legal command stays refused
    (ended), another new stream's resumes."""
    sh = CommandShaper(LIM, DT)
    bad = np.full(7, 0.1)
    bad[4] = 5.3
    assert not sh.command(0.0, bad, stream=1, q=READY) and sh.protective and sh.at_rest
    assert not sh.command(0.0, bad, stream=2, q=READY)  # a new stream, illegal
    assert not sh.command(0.0, np.zeros(7), stream=2, q=READY) and sh.ended == 1 and sh.protective
    assert sh.command(0.0, np.zeros(7), stream=3, q=READY) and not sh.protective
