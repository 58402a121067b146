"""Stalls of the sim's or the daemon's process: the sequences behind the referee counts that
loaded hosts and SIGSTOP drills produced, replayed with fake clocks (no timing).

1. The sim frozen ~80 ms: commands that reached it before the freeze were stamped when the step
   loop took them (after the freeze), and the sim's clock did not count the frozen time. Two
   commands sent 82 ms apart (41 lost between them) were judged over 26 ms.
2. The daemon frozen past the robot's command timeout: a command of the old stream, left in the
   frozen daemon's transmit queue, reached the robot after it had braked to rest in its stale stop
   and restarted it; the daemon, having seen the stop, started a new stream from rest: the robot's
   executed rates and the new stream's first command met as a jump (2.50 A·Δt).
"""

from __future__ import annotations

import numpy as np
import pytest
from wmm_qp_service.config import ServiceConfig
from wmm_qp_service.drivers.sim_node import CommandInbox, SimNode
from wmm_qp_service.protocol import CommandMsg, encode
from wmm_qp_sim import load_sim_config
from wmm_qp_sim.robot import SimCommand, SimRobot

import wmm_qp as w

DT = 0.001  # the sim's step
PERIOD = 0.002  # the daemon's (500 Hz)


class FakeClock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def _node() -> tuple[SimNode, w.RobotConfig]:
    robot = w.load_robot_config()
    node = SimNode(ServiceConfig(), load_sim_config(), robot)
    node.on_lease("d", True)
    node.t0 = 0.0
    return node, robot


def _payload(node: SimNode, robot: w.RobotConfig, seq: int, arm: np.ndarray, sent: float,
             stream: int = 1) -> bytes:
    return encode(CommandMsg(robot=node.svc.robot, seq=seq, stamp=sent, wheel_speeds=[0.0] * robot.n_wheels,
                             arm_rates=arm.tolist(), lease="d", instance=node.instance, period=PERIOD,
                             stream=stream))


@pytest.mark.parametrize("stamped_on_arrival", [True, False])
def test_a_frozen_sim_judges_commands_over_the_time_between_their_arrivals(stamped_on_arrival: bool) -> None:
    """Command 41 seqs after the last one before an 82 ms freeze (those between lost on the way),
    changed by 1.23·A·26 ms: legal over the 82 ms it really took. Stamped on arrival and with the
    sim's clock following the wall, 0 counts; stamped when the step loop took them (the sim
    before), 1 count, "changed by 1.23 A·Δt over Δt = 26 ms"."""
    node, robot = _node()
    clock = FakeClock()
    inbox = CommandInbox(clock=clock)
    a = robot.arm.acceleration_max[0]
    arm = np.zeros(robot.n_arm)
    seq = 0
    for k in range(50):  # 100 ms of a stream ramping joint 1 at 0.5 A, one command per 2 ms
        clock.t = k * PERIOD
        seq += 1
        arm[0] = 0.5 * a * clock.t
        inbox.put(_payload(node, robot, seq, arm, clock.t))
        node.advance(clock.t, inbox)
        clock.t += DT
        node.advance(clock.t, inbox)
    clock.t += 0.0005
    seq += 1
    arm[0] += 0.5 * a * PERIOD
    inbox.put(_payload(node, robot, seq, arm, clock.t))  # reached the process, then it froze: 82 ms
    before = node.sim.t
    clock.t += 0.082
    seq += 41
    arm[0] += 1.23 * a * 0.026  # 41 seqs later: what the referee's old 26 ms window called too much
    late = _payload(node, robot, seq, arm, clock.t)
    if stamped_on_arrival:
        inbox.put(late)
        st = node.advance(clock.t, inbox)
        assert st.t - before >= 0.082 - 2 * DT  # the sim lived through the freeze
        assert st.stale_stop  # and braked by itself past its command timeout
        assert node.sim.refused == 1  # the stopped stream's late command cannot restart it
        assert sum(st.violations.values()) == 0, node.sim.referee.last_event
    else:  # the sim before: both taken after the freeze, stamped then, its clock one step on
        first = node.accept(inbox.take_until(np.inf)[0][1], clock.t)
        second = node.accept(late, clock.t)
        assert first is not None and second is not None
        node.sim.step(node.take([first, second], DT), DT)
        assert node.sim.state().violations["acceleration"] == 1
        assert "over Δt = 26" in node.sim.referee.last_event


def test_the_sim_steps_through_a_freeze_executing_then_braking() -> None:
    """After a freeze of 300 ms the sim has run every step: the held command for the command
    timeout, then braking at the acceleration limits to rest (the state is at rest, stale)."""
    node, robot = _node()
    clock = FakeClock()
    inbox = CommandInbox(clock=clock)
    arm = np.zeros(robot.n_arm)
    arm[1] = 0.3
    for k in range(1, 400):  # ramp up to 0.3 rad/s (the drives' ramp), one command per 2 ms
        clock.t = k * DT
        if k % 2:
            inbox.put(_payload(node, robot, k, arm, clock.t))
        node.advance(clock.t, inbox)
    assert node.sim.v_arm[1] == pytest.approx(0.3)
    q1 = node.sim.q_arm[1]
    steps = node.steps
    clock.t += 0.300
    st = node.advance(clock.t, inbox)
    assert node.steps - steps == 300
    assert st.stale_stop and not st.v_arm.any()
    cfg = load_sim_config()
    a = robot.arm.acceleration_max[1]
    moved = st.q_arm[1] - q1
    # held for the timeout, then braked: 0.3·T + 0.3²/(2A), within a step's worth
    expect = 0.3 * cfg.stale_timeout + 0.3**2 / (2 * a)
    assert moved == pytest.approx(expect, abs=0.3 * 2 * DT)


def test_a_late_command_of_a_stopped_stream_cannot_restart_the_robot() -> None:
    """The daemon frozen past the command timeout: the robot stops itself and brakes to rest; a
    command of the old stream arrives late (it sat in the frozen sender's queue), then the new
    stream's first command, within A·Δt of rest. The firmware refuses the old stream's command
    (the stop ended that stream), so the robot is at rest when the new stream starts: 0 counts.
    Without the rule the late command restarted the robot and the new stream's first command
    met its rates as a jump."""
    robot = w.load_robot_config()
    model = w.WmmModel(robot)
    for stream_rule in (True, False):
        sim = SimRobot(model, load_sim_config(), ramp=True)
        sim.reset()
        a = np.asarray(robot.arm.acceleration_max)
        arm = np.zeros(robot.n_arm)
        seq = 0
        for k in range(200):  # stream 1 ramps joint 2 up to 0.2 rad/s
            arm[1] = min(0.2, a[1] * PERIOD * (k // 2))
            if k % 2 == 0:
                seq += 1
                sim.step(SimCommand(np.zeros(robot.n_wheels), arm.copy(), period=PERIOD, seq=seq,
                                    received=k * DT, stream=1), DT)
            else:
                sim.step(None, DT)
        k = 200
        while not (sim.stale and not sim.v_arm.any()):  # silence: the stale stop brakes to rest
            sim.step(None, DT)
            k += 1
        late = SimCommand(np.zeros(robot.n_wheels), arm.copy(), period=PERIOD, seq=seq + 1,
                          received=k * DT, stream=1 if stream_rule else None)
        sim.step(late, DT)
        sim.step(None, DT)
        first = np.zeros(robot.n_arm)
        first[1] = -0.9 * a[1] * PERIOD  # the new stream's first command, from rest
        sim.step(SimCommand(np.zeros(robot.n_wheels), first, period=PERIOD, seq=seq + 2,
                            received=(k + 2) * DT, stream=seq + 2), DT)
        counted = sim.state().violations["acceleration"]
        if stream_rule:
            assert counted == 0, sim.referee.last_event
            assert sim.refused == 1
        else:  # commands without stream ids: the late one restarts the robot (the old behaviour),
            # and the new stream's first command jumps from its rates
            assert counted >= 1 and "(a new stream)" in sim.referee.last_event, sim.referee.last_event


@pytest.mark.parametrize("sender_stamps", [True, False])
def test_a_flushed_transmit_queue_is_judged_over_the_sender_s_clock(sender_stamps: bool) -> None:
    """The daemon's transmit thread starved for 122 ms while its control thread went on (the drill
    under load: "command seq 7562 changed by 1.88 A·Δt over Δt = 26.02 ms from command seq 7501;
    stale True"): 7501 and 7562 reached the robot together, the 60 between them dropped. The robot
    had stopped the stream (no command for its timeout) and refuses both; the referee judges their
    step over the 122 ms between their sending stamps: 0 counts. Over their arrivals (no stamps),
    it counted one."""
    node, robot = _node()
    clock = FakeClock()
    inbox = CommandInbox(clock=clock)
    a = robot.arm.acceleration_max[0]
    arm = np.zeros(robot.n_arm)

    def send(seq: int, sent: float) -> None:
        inbox.put(encode(CommandMsg(robot=node.svc.robot, seq=seq, stamp=sent if sender_stamps else 0.0,
                                    wheel_speeds=[0.0] * robot.n_wheels, arm_rates=arm.tolist(), lease="d",
                                    instance=node.instance, period=PERIOD, stream=1)))

    for k in range(1, 51):  # 100 ms of stream 1 at 500 Hz, delivered on time
        clock.t = k * PERIOD
        arm[0] = 0.2 * a * clock.t
        send(k, clock.t)
        node.advance(clock.t, inbox)
        node.advance(clock.t + DT, inbox)
    t_sent = clock.t + PERIOD
    arm[0] += 0.2 * a * PERIOD
    held = arm.copy()  # 51: sent on time, stuck in the sender's queue
    for k in range(52, 112):
        clock.t = k * PERIOD
        node.advance(clock.t, inbox)  # the robot hears nothing: stale after its timeout
    arm[:] = held
    send(51, t_sent)
    arm[0] += 1.88 * a * 0.026  # 61 periods (122 ms) later: well inside A over the real time
    send(112, t_sent + 0.122)
    clock.t += 0.0005
    st = node.advance(clock.t + DT, inbox)
    assert st.stale_stop and node.sim.refused == 2
    counted = st.violations["acceleration"]
    assert counted == (0 if sender_stamps else 1), node.sim.referee.last_event
