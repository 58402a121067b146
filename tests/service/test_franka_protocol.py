"""The Franka driver's protocol side, without libfranka or a network: it obeys the lease holder
for its instance with increasing seq, reports a robot's reflex as a protective stop that a new
stream releases, and fills the state's sim-only fields as a real robot can."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
from wmm_qp_service.config import load_service_config
from wmm_qp_service.drivers.franka import FrankaDriver
from wmm_qp_service.protocol import CommandMsg, encode

import wmm_qp as w
from wmm_qp.config import default_config_dir

pytest.importorskip("franky_sim", reason="configs/robots/fr3.toml's URDF ships with franky-sim")

READY = np.array([0.0, -np.pi / 4, 0.0, -3 * np.pi / 4, 0.0, np.pi / 2, np.pi / 4])


@pytest.fixture
def drv() -> FrankaDriver:
    d = FrankaDriver(load_service_config(), w.load_robot_config(default_config_dir() / "robots" / "fr3.toml"))
    d.on_lease("L1", True)
    return d


def cmd(d: FrankaDriver, seq: int, rates: list[float], lease: str = "L1", instance: str | None = None,
        stream: int = 1) -> bytes:
    return encode(CommandMsg(robot=d.svc.robot, seq=seq, stamp=time.time(), wheel_speeds=[], arm_rates=rates,
                             lease=lease, instance=d.instance if instance is None else instance, period=0.002,
                             stream=stream))


def test_only_the_lease_holders_commands_for_this_instance_with_increasing_seq_are_followed(drv: FrankaDriver) -> None:
    d = drv
    d.on_lease("L2", True)  # a later token: not the holder
    small = [0.01] * 7
    assert not d.on_command(cmd(d, 1, small, lease="L2"), READY, 0.0)
    assert not d.on_command(cmd(d, 1, small, instance="another"), READY, 0.0)
    assert not d.on_command(b"\x80junk", READY, 0.0)
    assert d.on_command(cmd(d, 5, small), READY, 0.0) and d.cmd_seq == 5
    assert not d.on_command(cmd(d, 5, small), READY, 0.001)  # replayed
    assert d.refused == {"lease": 1, "instance": 1, "invalid": 1, "seq": 1}
    st = d.state_msg(READY, np.zeros(7))
    assert st.lease == "L1" and st.cmd_seq == 5 and st.instance == d.instance and st.refused == d.refused
    d.on_lease("L1", False)  # the holder's token vanished: L2 holds
    assert d.holder == "L2" and d.on_command(cmd(d, 1, small, lease="L2"), READY, 0.002)


def test_a_robot_reflex_is_a_protective_stop_that_only_a_new_stream_releases(drv: FrankaDriver) -> None:
    d = drv
    asked: list[int] = []
    assert d.on_command(cmd(d, 1, [0.01] * 7), READY, 0.0)
    for _ in range(5):
        d.cycle(1e-3, READY)
    d.fault("joint_velocity_violation")
    st = d.state_msg(READY, np.zeros(7))
    assert st.protective_stop and st.protective_stops == 1 and st.protective_reason == "robot: joint_velocity_violation"
    assert st.v_arm == [0.0] * 7  # the robot stopped: the next stream starts from rest
    assert not d.on_command(cmd(d, 2, [0.0] * 7), READY, 0.001, lambda: asked.append(2))  # the same stream
    assert d.refused["ended"] == 1 and asked == []  # refused, and the robot not asked to recover
    assert d.refused["firmware"] == 0  # the reflex ended the stream: its late commands are no new fault
    assert d.on_command(cmd(d, 3, [0.0] * 7, stream=3), READY, 0.002, lambda: asked.append(3))  # a new stream
    assert asked == [3] and d.robot_error is None  # it recovered the robot first, then resumed
    assert not d.state_msg(READY, np.zeros(7)).protective_stop


def test_a_refused_recovery_ends_its_stream_and_is_asked_again_by_a_new_one_a_second_later(
        drv: FrankaDriver) -> None:
    d = drv
    answers = ["CommandException: libfranka: Automatic Error Recovery command rejected: manual error recovery "
               "required!", None]
    asked: list[int] = []

    def recover() -> str | None:
        asked.append(1)
        return answers.pop(0)

    d.fault('libfranka: Move command aborted: motion aborted by reflex! ["cartesian_reflex"]')
    assert not d.on_command(cmd(d, 1, [0.0] * 7, stream=1), READY, 0.0, recover)
    st = d.state_msg(READY, np.zeros(7))
    assert len(asked) == 1 and st.protective_stop and st.refused["firmware"] == 1  # the refusal: one fault
    assert st.cmd_seq == 1  # and the state names the command: its sender sees its stream stopped
    assert st.protective_reason.startswith('robot: libfranka: Move command aborted: motion aborted by reflex! '
                                           '["cartesian_reflex"]; recovery refused: CommandException'), \
        st.protective_reason
    assert not d.on_command(cmd(d, 2, [0.0] * 7, stream=1), READY, 0.001, recover)  # the stream it ended
    assert not d.on_command(cmd(d, 3, [0.0] * 7, stream=3), READY, 0.002, recover)  # a new one, too soon
    st = d.state_msg(READY, np.zeros(7))
    assert len(asked) == 1 and st.refused == {"firmware": 1, "ended": 1, "recovering": 1}
    for _ in range(1000):  # a second of the robot's cycles
        d.cycle(1e-3, READY)
    assert d.on_command(cmd(d, 4, [0.0] * 7, stream=3), READY, 1.0, recover)  # that stream asks again
    assert len(asked) == 2 and not d.state_msg(READY, np.zeros(7)).protective_stop
    d.fault("another reflex")  # after a recovery (a second after the refusal at least): asked at once
    answers.append(None)
    assert d.on_command(cmd(d, 5, [0.0] * 7, stream=5), READY, 1.0, recover) and len(asked) == 3


def test_after_a_reflex_an_illegal_command_is_a_firmware_fault_and_asks_nothing(drv: FrankaDriver) -> None:
    """An illegal command (past a velocity limit) after a reflex: refused by the shaper as a
    fault (``firmware``), not as the reflex's stream (``ended``) nor as waiting (``recovering``),
    and the robot is not asked to recover; its stream is then the stopped one."""
    d = drv
    asked: list[int] = []
    d.fault("libfranka: reflex")
    bad = [0.0] * 7
    bad[4] = 5.3  # joint 5's limit is 5.26 rad/s
    assert not d.on_command(cmd(d, 1, bad, stream=1), READY, 0.0, lambda: asked.append(1))
    assert asked == [] and d.refused == {"firmware": 1}
    assert not d.on_command(cmd(d, 2, [0.0] * 7, stream=1), READY, 0.001, lambda: asked.append(2))
    assert asked == [] and d.refused == {"firmware": 1, "ended": 1}  # its stream: ended by the stop


def test_under_the_daemon_a_refused_recovery_is_retried_at_the_driver_s_pace(drv: FrankaDriver) -> None:
    """The attack (a review's): libfranka refuses the first recovery (the operator must clear the
    robot), later ones succeed. Before, the stream that asked was refused for good, a
    ``refused.firmware`` (a daemon fault) per command, 1,250 in 3 s, and the daemon never started
    another: its states named an older stream's command. Now the refusal ends that stream, the
    state names it, the daemon starts a new one, the driver asks again a second later (here
    refused twice): the robot runs, with a firmware fault per refusal."""
    from support.daemon_drive import send
    from wmm_qp_service.daemon import ControlCore
    from wmm_qp_service.protocol import StateMsg

    d = drv
    core = ControlCore(d.svc, w.load_controller_config(), d.robot)
    d.on_lease("L1", False)
    d.on_lease(core.lease, True)
    answers = ["manual error recovery required", "manual error recovery required"]
    asked: list[float] = []

    def recover() -> str | None:
        asked.append(d.t)
        return answers.pop(0) if answers else None

    q = READY.copy()
    t = 0.0
    for k in range(3000):  # 3 s at 1 kHz, the daemon at 500 Hz
        q = q + d.cycle(1e-3, q) * 1e-3
        if k == 500:
            d.fault("libfranka: reflex")
        if k % 2 == 0:
            st: StateMsg = d.state_msg(q, np.zeros(7))
            core.on_state(st, t)
            if (c := core.tick(t)) is not None:
                seq = send(core, t)
                d.on_command_msg(CommandMsg(robot=d.svc.robot, seq=seq, stamp=t, wheel_speeds=[],
                                            arm_rates=c.arm_rates.tolist(), lease=core.lease, instance=d.instance,
                                            period=0.002, stream=core.stream.start), q, t, recover)
        t += 1e-3
    assert d.robot_error is None and not answers  # asked again, and recovered
    assert len(asked) == 3 and min(np.diff(asked)) >= 1.0, asked  # at the driver's pace
    assert d.refused["firmware"] == 2, dict(d.refused)
    assert core.fault_record.counts["robot_firmware"] == 3, dict(core.fault_record.counts)  # reflex, 2 refusals
    assert core.stream.confirmed and not core.safe


def test_a_reflex_judges_the_stopped_streams_late_commands_against_each_other(drv: FrankaDriver) -> None:
    """The commands the daemon sent before it saw the reflex arrive after it: refused, and judged
    against the stream's own previous command, not against the stopped arm's 0 (they were not
    jumps of the controller)."""
    d = drv
    rates = np.zeros(7)
    t = 0.0
    for k in range(1, 200):  # joint 7 ramps to 0.3 rad/s at 5 rad/s², one command every 2 ms
        rates[6] = min(0.3, 5.0 * k * 0.002)
        assert d.on_command(cmd(d, k, rates.tolist()), READY, t)
        d.cycle(1e-3, READY)
        d.cycle(1e-3, READY)
        t += 0.002
    d.fault('libfranka: Move command aborted: motion aborted by reflex! ["cartesian_reflex"]')
    for k in range(200, 205):  # the stream goes on at 0.3 rad/s until the daemon sees the stop
        assert not d.on_command(cmd(d, k, rates.tolist()), READY, t)
        d.cycle(1e-3, READY)
        t += 0.002
    assert not any(d.truth_msg(np.zeros(3)).violations.values()), d.referee.counts


def test_the_truth_has_no_ground_truth_and_counts_the_referees_violations(drv: FrankaDriver) -> None:
    d = drv
    d.on_command(cmd(d, 1, [0.5] + [0.0] * 6), READY, 0.0)  # from rest: 0.5 rad/s in one 2 ms period
    st = d.state_msg(READY, np.zeros(7))
    assert st.wheel_speeds == [] and math.isnan(st.gripper_width)
    tr = d.truth_msg(np.zeros(3))
    assert all(math.isnan(x) for x in tr.base_true + tr.ee_true) and math.isnan(tr.box_position)
    assert tr.stalled_joint == -1 and tr.instance == st.instance and tr.state_seq == st.seq
    assert tr.violations == {"acceleration": 1}  # judged as received, before the shaper smooths it
