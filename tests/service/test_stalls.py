"""Stalls of the sim's or the daemon's process: the sequences behind the referee counts that
loaded hosts and SIGSTOP drills produced, replayed with fake clocks (no timing).

1. The sim frozen ~80 ms: commands that reached it before the freeze were stamped when the step
   loop took them (after the freeze), and the sim's clock did not count the frozen time. Two
   commands sent 82 ms apart (41 lost between them) were judged over 26 ms.
2. The daemon frozen past the robot's command timeout: a command of the old stream, left in the
   frozen daemon's transmit queue, reached the robot after it had braked to rest in its stale stop
   and restarted it; the daemon, having seen the stop, started a new stream from rest: the robot's
   executed rates and the new stream's first command met as a jump (2.50 A·Δt).
3. The daemon's own stall while its stream's commands were still on the way (the UR5's physics
   demo at 1 kHz: 8 counts, one command): it went silent and started a new stream on a state of
   the robot at rest in an older stream's stop, which had applied none of the broken stream's
   commands; those reached the robot afterwards and moved it, and the new stream's first command,
   computed from rest, met it moving. The daemon now keeps the stream and brakes it.
4. Two whole stacks at real-time priority on the 2 cores (a starved transmit thread drops
   commands): a new stream's first 12 commands, ramping from rest, were lost on the wire; its
   13th reached the robot at rest 9 A·Δt from it ("changed by 9.00 A·Δt over Δt = 2.00 ms from
   the executed rates (a new stream)"). The daemon now repeats a new stream's first command until
   a state shows the robot applied one of the stream's.
"""

from __future__ import annotations

from collections import deque

import numpy as np
import pytest
from support.daemon_drive import max_step_ratio
from wmm_qp_service.config import ServiceConfig
from wmm_qp_service.daemon import ControlCore
from wmm_qp_service.drivers.sim_node import CommandInbox, SimNode, state_refused
from wmm_qp_service.protocol import CommandMsg, ModeMsg, SetpointMsg, StateMsg, encode
from wmm_qp_sim import load_sim_config
from wmm_qp_sim.robot import SimCommand, SimRobot

import wmm_qp as w
from wmm_qp.config.shapes import ShapeConfig

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
        assert node.sim.ended == 1  # the stopped stream's late command cannot restart it
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
            assert sim.ended == 1
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
    assert st.stale_stop and node.sim.ended == 2
    counted = st.violations["acceleration"]
    assert counted == (0 if sender_stamps else 1), node.sim.referee.last_event


# ---------------------------------------------------------------- 3. the daemon's own stall
class Wire:
    """The daemon's core and a simulated robot joined in memory on one fake clock: each daemon
    tick (``PERIOD``) is two robot steps (``DT``). A command goes into the wire and reaches the
    robot at the next step, one per step, oldest first; ``hold`` keeps them in the wire (a
    congested link, a starved transmit thread) and ``drop`` loses them. States reach the daemon
    at once. Commands are numbered, stamped and given their stream as the daemon's cycle does."""

    def __init__(self, robot: w.RobotConfig) -> None:
        self.core = ControlCore(ServiceConfig(), w.load_controller_config(), robot)
        self.robot = robot
        self.sim = SimRobot(self.core.model, load_sim_config(), ramp=True)
        self.sim.reset()
        self.t = 0.0
        self.queue: deque[SimCommand] = deque()
        self.hold = self.drop = False
        self.sent: list[tuple[int, int, w.Command]] = []  # (seq, stream, command) as sent
        self.cmd_seq = -1  # the last command the robot received
        self.n = 0
        self.target: np.ndarray | None = None  # the setpoint streamed each tick (None: none)

    def msg(self) -> StateMsg:
        st = self.sim.state()
        self.n += 1
        return StateMsg(robot="wmm", seq=self.n, stamp=0.0, t=st.t, q_base=st.base_odom.tolist(),
                        q_arm=st.q_arm.tolist(), v_arm=st.v_arm.tolist(), wheel_speeds=st.wheel_speeds.tolist(),
                        tau=st.tau.tolist(), stale_stop=st.stale_stop, cmd_seq=self.cmd_seq, instance="sim-A",
                        lease=self.core.lease, protective_stop=st.protective_stop,
                        protective_stops=st.protective_stops, protective_reason=st.protective_reason,
                        refused=state_refused({}, st))

    def mode(self, name: str) -> None:
        self.core.on_mode(ModeMsg(robot="wmm", seq=1, stamp=0.0, mode=name))

    def tick(self, state: StateMsg | None = None) -> w.Command | None:
        """One daemon tick at the robot's current state (or ``state``), then the robot's steps."""
        core = self.core
        core.on_state(state if state is not None else self.msg(), self.t)
        if self.target is not None:
            core.on_setpoint(SetpointMsg(robot="wmm", seq=1, stamp=self.t, x=self.target.tolist(), source="op"),
                             self.t)
        cmd = core.tick(self.t)
        if cmd is not None:
            core.stream.numbered()
            core.stream.sent(core.stream.seq, self.t)
            self.sent.append((core.stream.seq, core.stream.start, cmd))
            if not self.drop:
                self.queue.append(SimCommand(cmd.wheel_speeds.copy(), cmd.arm_rates.copy(), period=PERIOD,
                                             seq=core.stream.seq, stream=core.stream.start, sent=self.t,
                                             sender=core.lease))
        self.run(PERIOD)
        return cmd

    def run(self, seconds: float) -> None:
        """The robot lives ``seconds`` [s] on (the daemon does not tick: it is stalled)."""
        for _ in range(round(seconds / DT)):
            c = self.queue.popleft() if self.queue and not self.hold else None
            if c is not None:
                c.received = self.sim.t
                self.cmd_seq = c.seq  # type: ignore[assignment]
            self.sim.step(c, DT)
        self.t += seconds

    def counts(self) -> int:
        return sum(self.sim.state().violations.values())


@pytest.fixture(scope="module")
def robot() -> w.RobotConfig:
    return w.load_robot_config()


def _tracking(robot: w.RobotConfig) -> tuple[Wire, np.ndarray]:
    """A daemon tracking a target 20 cm away for 0.2 s, the robot following (moving)."""
    wire = Wire(robot)
    x0 = wire.core.model.ee_position(wire.sim.base_odom, wire.sim.q_arm)
    wire.mode("track")
    wire.target = x0 + np.array([0.2, 0.0, 0.0])
    for _ in range(100):
        assert wire.tick() is not None
    assert np.abs(wire.sim.v_arm).max() > 0.05 and not wire.core.fault_active
    return wire, x0


def test_after_its_own_stall_the_daemon_brakes_its_stream_while_its_commands_may_be_on_the_way(
        robot: w.RobotConfig) -> None:
    """The defect, replayed: the robot rests in the stop of an older stream A; the daemon's
    stream B (40 commands, tracking) sits in the wire; the daemon stalls 50 ms; the next state
    still shows A's stop at rest. Before, the daemon started a new stream C from rest on it; B's
    commands, reaching the robot afterwards, moved it, and C's first met it moving (a jump, "from
    the executed rates (a new stream)"). Now it keeps B and brakes it to rest: whenever B reaches
    the robot it runs from rest to rest, 0 counts; once a state shows B's zero applied at rest,
    the daemon goes on within B (in hold until a mode message). (B no longer moves before the
    robot applies one of its commands: its commands in the wire are its first, repeated.)"""
    wire = Wire(robot)
    core = wire.core
    for _ in range(20):  # stream A, in hold, followed
        assert wire.tick() is not None
    a_start = core.stream.start
    wire.drop = True  # A's commands are lost: the robot stops A by itself, at rest
    while not (wire.sim.stale and not wire.sim.v_arm.any()):
        wire.tick()
    wire.drop, wire.hold = False, True  # the next stream's commands wait in the wire
    assert wire.tick() is not None  # the state shows A's stop at rest: A breaks, B starts from rest
    assert "its command timeout" in core.fault_record.last and core.stream.start > a_start
    b = core.stream.start
    x0 = core.model.ee_position(wire.sim.base_odom, wire.sim.q_arm)
    wire.mode("track")
    wire.target = x0 + np.array([0.2, 0.0, 0.0])
    for _ in range(40):
        wire.tick()
    assert core.stream.start == b and len(wire.queue) == 41 and wire.sim.stale  # none of B applied
    # B's first command, again and again: the robot applied none of B yet. (Before, B went on from
    # it and moved, 40 commands of a moving stream in the wire: the defect below needed that; the
    # repeat now keeps B at its first command until the robot follows, see the test of lost
    # commands. What this test still holds: the stall keeps B, brakes it, starts no new stream.)
    b_cmds = [cmd for _, stream, cmd in wire.sent if stream == b]
    assert len(b_cmds) == 41 and all(cmd is b_cmds[0] for cmd in b_cmds)
    wire.run(0.050)  # the daemon stalls 50 ms
    wire.tick()  # on a state of the robot at rest in A's stop: B's commands may still be on the way
    wire.hold = False  # they are: the wire delivers them, and what the daemon sent after them
    for _ in range(150):
        wire.tick()
    assert wire.counts() == 0, wire.sim.referee.last_event
    after = [(seq, stream, cmd) for seq, stream, cmd in wire.sent if stream == b]
    assert [stream for _, stream, _ in wire.sent[-150:]] == [b] * 150  # no new stream
    assert max_step_ratio(robot, [cmd for _, _, cmd in after]) <= 1.0 + 1e-9  # each inside A·Δt
    assert core.fault_record.counts["stall_braking"] == 1
    # the robot followed B from A's stop and braked with it to rest; the daemon goes on within B
    assert not wire.sim.stale and not wire.sim.v_arm.any() and not wire.sim.wheels.any()
    assert not core.safe and core.mode == w.Mode.HOLD and core.resume_needed
    wire.mode("track")  # resume: the task goes on in B, anchored on its last command
    for _ in range(100):
        wire.tick()
    assert core.stream.start == b and not core.fault_active and wire.counts() == 0
    assert np.abs(wire.sim.v_arm).max() > 0.01  # moving again


def test_a_stall_inside_the_robots_timeout_brakes_with_the_robot_following(robot: w.RobotConfig) -> None:
    """A 22 ms stall: past the daemon's own limit (20 ms, 0.8 × the robot's 25 ms timeout), not
    the robot's. The daemon goes on in the same stream with braking commands: the robot never
    stops by itself, brakes with the stream to rest, 0 counts, and the daemon goes on in it,
    holding until a mode message. (Before, it went silent: the robot's timeout stopped it.)"""
    wire, _ = _tracking(robot)
    core = wire.core
    b = core.stream.start
    last = wire.sent[-1][2]
    wire.run(0.020)  # and the tick's own period: 22 ms since the last command
    cmd = wire.tick()
    assert cmd is not None and core.stream.start == b  # braking, in the same stream
    assert core.fault_record.last.startswith("braking stream after a stall (22 ms without a command")
    assert cmd.status == w.Status.SAFE_STOP and cmd.reason == core.fault_record.last
    assert max_step_ratio(robot, [last, cmd]) <= 1.0 + 1e-9  # from the last command sent
    for _ in range(200):
        wire.tick()
        assert not wire.sim.stale  # the robot never stopped by itself
    assert wire.counts() == 0, wire.sim.referee.last_event
    assert {stream for _, stream, _ in wire.sent} == {b}
    assert not core.safe and core.mode == w.Mode.HOLD and core.resume_needed
    assert not wire.sim.v_arm.any()


def test_a_robot_that_stopped_the_stream_during_the_stall_refuses_its_braking(robot: w.RobotConfig) -> None:
    """A 200 ms stall: the robot stopped the stream (its timeout) and braked to rest. The first
    state after the stall is one from before (a late one): the daemon brakes the stream from its
    last command; the robot refuses those commands (its stop ended the stream); the next state
    shows its stop with one of them applied: the stream breaks, and (the robot at rest) a new
    stream starts from rest. 0 counts; the robot never moved again before the new stream."""
    wire, _ = _tracking(robot)
    core = wire.core
    b = core.stream.start
    old = wire.msg()  # a state from before the stall
    last = wire.sent[-1][2]
    wire.run(0.200)
    assert wire.sim.stale and not wire.sim.v_arm.any()  # stopped, at rest
    q_stop = wire.sim.q_arm.copy()
    cmd = wire.tick(old)
    assert cmd is not None and core.stream.start == b and max_step_ratio(robot, [last, cmd]) <= 1.0 + 1e-9
    assert wire.sim.ended == 1  # the robot refused it: its stop ended B
    cmd = wire.tick()  # its state shows the stop, with B's command applied: B breaks; at rest, a new stream
    assert core.fault_record.counts["stream_broken"] == 1
    assert cmd is not None and core.stream.start > b and np.allclose(wire.sim.q_arm, q_stop)  # from rest
    a = np.asarray(robot.arm.acceleration_max) * PERIOD
    assert np.all(np.abs(cmd.arm_rates) <= a * (1 + 1e-9))
    for _ in range(50):
        wire.tick()
    assert wire.counts() == 0, wire.sim.referee.last_event
    assert core.mode == w.Mode.HOLD and core.resume_needed


def test_a_new_stream_whose_first_commands_are_lost_starts_from_rest_whichever_arrives_first(
        robot: w.RobotConfig) -> None:
    """The defect, replayed: the robot stopped the stream by itself (its timeout) and braked to
    rest; a ball then came at the arm, and the daemon's new stream, started from rest, gave way
    at the acceleration limits; its first commands were lost on the wire, and a later one reached
    the robot at rest. Before, that one was 2 A·Δt (here) to 9 A·Δt (the drill) from the robot's
    rates: a jump "from the executed rates (a new stream)". Now, until a state shows the robot
    applied one of the new stream's commands, the daemon sends the stream's first command again
    (within A·Δt of rest): whichever arrives first is a legal start, and the stream goes on from
    it once the robot follows."""
    wire, _ = _tracking(robot)
    core = wire.core
    wire.drop = True  # the robot hears nothing: it stops the stream by itself, at rest
    while not (wire.sim.stale and not wire.sim.v_arm.any()):
        wire.tick()
    b = core.stream.start
    x = core.model.ee_position(wire.sim.base_odom, wire.sim.q_arm)
    ball = ShapeConfig(name="ball", link="", kind="sphere", size=np.array([0.08, 0.0, 0.0]),
                         xyz=x + [0.0, 0.2, 0.0], rpy=np.zeros(3), velocity=np.array([0.0, -0.2, 0.0]))
    core.on_obstacles((ball,), wire.t)  # coming at the arm: its row makes the robot give way
    for _ in range(6):  # the new stream's first commands are lost
        wire.tick()
    assert core.stream.start > b and wire.sim.stale and not wire.sim.v_arm.any()  # none of it applied
    new = [cmd for _, stream, cmd in wire.sent if stream == core.stream.start]
    assert len(new) == 6
    a = np.asarray(robot.arm.acceleration_max) * PERIOD
    wa = np.asarray(robot.base.wheel_acceleration_max) * PERIOD
    for cmd in new:  # every one of them a legal first command from rest
        assert np.all(np.abs(cmd.arm_rates) <= a * (1 + 1e-9)), np.max(np.abs(cmd.arm_rates) / a)
        assert np.all(np.abs(cmd.wheel_speeds) <= wa * (1 + 1e-9))
    wire.drop = False
    for _ in range(100):
        wire.tick()
    assert wire.counts() == 0, wire.sim.referee.last_event
    after = [cmd for _, stream, cmd in wire.sent if stream == core.stream.start]
    assert max_step_ratio(robot, after) <= 1.0 + 1e-9
    assert not wire.sim.stale and np.abs(wire.sim.v_arm).max() > a.max()  # past its first command: following


# ---------------------------------------------------------------- 5. a stopped stream's commands in flight
def test_a_stopped_stream_s_commands_in_flight_are_one_stop_not_a_fault_each(robot: w.RobotConfig) -> None:
    """Two whole stacks on the 2 cores: a starved link held the daemon's commands past the
    robot's command timeout; the robot stopped the stream and then refused them as they arrived,
    each counted as a firmware refusal, each a new "robot firmware" fault of the daemon's with a
    safe stop of its own: the robot stood for most of the run. Now the stop ends the stream once
    (``refused.ended`` counts its late commands, the daemon faults on ``refused.firmware`` and
    protective stops only): one break, and a new stream once the robot rests."""
    wire, _ = _tracking(robot)
    core = wire.core
    b = core.stream.start
    wire.hold = True  # the link holds the commands: the robot hears nothing for 40 ms
    for _ in range(20):
        wire.tick()
    assert wire.sim.stale and len(wire.queue) > 10  # it stopped the stream by itself, braking
    wire.hold = False  # the held commands arrive, one per step, after the stop
    for _ in range(150):
        wire.tick()
        if core.stream.start > b and core.stream.confirmed:
            break
    assert core.fault_record.counts["robot_firmware"] == 0, core.fault_record.last
    assert core.fault_record.counts["stream_broken"] == 1
    assert wire.sim.ended > 10 and wire.sim.refused == 0  # each refused as the stopped stream's
    assert core.stream.start > b and core.stream.confirmed  # a new stream, followed
    assert wire.counts() == 0, wire.sim.referee.last_event


# ---------------------------------------------------------------- 6. a restarted daemon, the robot still moving
def test_a_restarted_daemon_waits_for_a_moving_robot_to_rest_in_its_own_stop(robot: w.RobotConfig) -> None:
    """A daemon that starts (or restarts) while the robot still moves under another one's
    commands cannot know what the robot will execute when its first command arrives: the robot
    holds the last command until its timeout, then brakes at its acceleration limits. A first
    command computed from a state 6 ms older (a loaded link) met the robot braking 4 A·Δt further
    on ("from the executed rates (a new stream)"). The new daemon now sends nothing until a state
    shows the robot at rest in its own stop, then starts from rest."""
    wire, _ = _tracking(robot)
    wire.drop = True  # the first daemon dies: nothing more reaches the robot
    while not wire.sim.stale:
        wire.run(PERIOD)
    wire.run(0.004)  # braking by itself
    assert np.abs(wire.sim.v_arm).max() > 0.05
    wire.drop = False
    wire.core = core = ControlCore(ServiceConfig(), w.load_controller_config(), robot)  # a new daemon
    wire.sim.referee.break_stream()  # (the sim's lease gate does this on a new holder's first command)
    wire.hold = True  # its first commands take 6 ms on the way
    sent = [wire.tick() for _ in range(3)]
    wire.hold = False
    for _ in range(300):
        wire.tick()
    assert wire.counts() == 0, wire.sim.referee.last_event
    assert sent == [None, None, None]  # nothing while the robot moves
    assert core.fault_record.counts["foreign_commands"] == 1
    assert core.stream.confirmed and not wire.sim.stale and not core.fault_active
