"""The sim process (``wmm-qp sim``): the pure :class:`~wmm_qp_sim.robot.SimRobot` behind Zenoh.

The simulated robot's driver: like :mod:`.franka` for a real robot, it lives in the service layer
(it speaks the daemon's protocol over Zenoh), while the robot it drives (``wmm_qp_sim``) imports
nothing of the service.


Runs the sim at its own rate (1 kHz) on the wall clock: step k is the robot at ``t0 + k·dt``, and
a wake-up that finds the process behind (a loaded host, or the process frozen) runs every step it
missed before publishing, so the simulated robot lives through the time its process did not: it
kept executing its last command, and past ``stale_timeout`` braked by itself, as a real robot
would have (:class:`CommandInbox`, :meth:`SimNode.advance`). Commands are stamped when they reach
the process (a callback on Zenoh's thread) and applied at the step their arrival falls in, each
validated and judged by the referee as received (the latest of a step is executed). The state is
published once per wake-up (odometry, torques, the firmware's reports: only what a real robot
reports), and with it the evaluation data on ``sim/truth`` (ground truth, the box, the referee's
violation counts; ``truth=False``: none); the node holds a liveliness token.
When commands go stale the pure model brakes the robot to rest by itself. A client may place
a box in the scene at run time (``sim/box``, :class:`~wmm_qp_service.protocol.BoxMsg`, FIFO,
validated on receipt); it is applied between two steps with :meth:`SimRobot.place_box`. The live
obstacles (``obstacles``, :class:`~wmm_qp_service.protocol.ObstaclesMsg`, latest wins) go to the
collision referee, which also checks the scene's obstacles (``--scene``) and the pushed box.

One robot, one controller:

- **instance**: the node draws a random id at start; every state carries it and a continuous
  ``seq`` (the step counter) and ``t``, so a daemon can tell two sims on one key apart.
- **lease**: the sim watches the control-lease tokens ``<robot>/lease/<id>`` (liveliness) and
  applies commands only from the holder — the earliest token still alive — and only those
  addressed to its own instance; every other command is counted in ``state.refused`` and
  dropped. The holder is reported in ``state.lease``.

Drive model: like a real joint or wheel drive, the pure model ramps the executed rate towards
the commanded one at the acceleration limit (``ramp``, on by default here); the referee judges
every command as it was received, before the ramp and before the firmware's protective stop
(:mod:`wmm_qp_sim.robot`, :mod:`wmm_qp_robot.referee`). ``ramp=False`` executes each command at once.

Fault injection (reliability tests, docs/reliability.md): ``state_loss`` drops each state
publication with that probability (seeded), ``state_delay`` holds every state back for a
fixed time before publishing it (a slow link).
"""

from __future__ import annotations

import contextlib
import math
import sys
import threading
import time
from collections import deque
from collections.abc import Callable, Mapping
from typing import Any, Generic, TypeVar

import numpy as np
import zenoh
from wmm_qp_robot.lease_gate import LeaseGate
from wmm_qp_sim.config import BoxConfig, SimConfig
from wmm_qp_sim.robot import SimCommand, SimRobot, SimState

import wmm_qp as w
from wmm_qp.scene import Scene, load_scene

from .. import robot_side
from ..config import ServiceConfig
from ..keys import Keys
from ..protocol import BoxMsg, CommandMsg, GripperMsg, ObstaclesMsg, StateMsg, TruthMsg, encode
from ..rate_loop import RateLoop, realtime_priority
from ..transport import ROLE_SIM, io_priority, open_session
from ..validation import Validator

P = TypeVar("P")

COMMAND_QUEUE = 1024
"""Commands kept between two wake-ups of the step loop (the oldest dropped beyond): every one is
judged as received, so none may be lost between the transport and the referee. 1024 holds a
second of commands at 1 kHz: a longer stall of the sim's process drops the oldest (counted in
:attr:`CommandInbox.dropped`)."""


def state_refused(gate: Mapping[str, int], st: SimState) -> dict[str, int]:
    """A state's ``refused``: the gate's counts (lease, instance, seq, invalid), the firmware's
    (``firmware``: past a limit, or while braking in a protective stop) and a stopped stream's
    (``ended``: docs/protocol.md), each key only once it counts."""
    out = dict(gate)
    if st.refused_commands:
        out["firmware"] = st.refused_commands
    if st.ended_commands:
        out["ended"] = st.ended_commands
    return out


class CommandInbox(Generic[P]):
    """Commands stamped on arrival (by Zenoh's callback thread), taken by the step loop in order.

    The stamp is the time the command reached this process: a command that arrived before the
    process froze keeps its time, one that arrived after is stamped after (the referee's window
    between two commands never spans less than the real time between their arrivals).

    Args:
        depth: commands kept (the oldest dropped beyond, counted).
        clock: monotonic clock [s] (the step loop's).
    """

    def __init__(self, depth: int = COMMAND_QUEUE, clock: Callable[[], float] = time.monotonic) -> None:
        self._q: deque[tuple[float, P]] = deque(maxlen=depth)  # append, popleft: atomic under the GIL
        self._clock = clock
        self.dropped = 0

    def put(self, data: P) -> None:
        """A command's payload (or, in memory, the message) arrived now (the producer's thread)."""
        if len(self._q) == self._q.maxlen:
            self.dropped += 1
        self._q.append((self._clock(), data))

    def next_arrival(self) -> float:
        """[s] the oldest pending command's arrival time (inf: none)."""
        try:
            return self._q[0][0]
        except IndexError:
            return math.inf

    def take_until(self, t: float) -> list[tuple[float, P]]:
        """The pending commands that arrived at or before ``t`` [s], oldest first."""
        out = []
        while self._q and self._q[0][0] <= t:
            out.append(self._q.popleft())
        return out


class SimNode(LeaseGate):
    """The simulated robot as a Zenoh node.

    Args:
        svc: service config (keys, endpoints, validation ranges; an open robot id is the
            robot's name).
        sim_cfg: the sim's config (rate, noise, stale timeout).
        robot: robot config (commands must carry its number of wheels and joints).
        seed: noise seed; None = the sim config's.
        ramp: ramp executed rates at the acceleration limits (see module docstring).
        spin_s: [s] spin before each deadline. Default 0 (sleep only): the sim integrates
            with a fixed dt whatever the wake-up jitter, and on a small machine a spinning
            sim would take CPU from the daemon.
        state_loss: fault injection: probability in [0, 1) that a state is not published.
        state_delay: [s] fault injection: publish each state this long after it was computed.
        fault_seed: seed of the state-loss draws.
        rt_priority: SCHED_FIFO priority of the step loop's thread (0: normal scheduling), set
            in :meth:`run` after the session opened (Zenoh's own threads keep theirs).
        scene: the obstacles the referee checks (None: ``load_scene()``'s default).
        sim: the robot to drive, built by the caller (its model must be ``robot``'s; e.g. with
            a physics plant); None: a :class:`SimRobot` on its kinematic plant from ``sim_cfg``,
            ``seed``, ``ramp`` and ``scene``.
        truth: publish the evaluation data on ``sim/truth`` with each state (False: a robot
            that reports only what a real one does; the daemon runs the same).
    """

    def __init__(self, svc: ServiceConfig, sim_cfg: SimConfig, robot: w.RobotConfig,
                 seed: int | None = None, ramp: bool = True, spin_s: float = 0.0,
                 state_loss: float = 0.0, state_delay: float = 0.0, fault_seed: int = 0,
                 rt_priority: int = 0, scene: Scene | None = None, sim: SimRobot | None = None,
                 truth: bool = True) -> None:
        svc = svc.with_robot(robot)
        self.svc = svc
        self.cfg = sim_cfg
        self.robot = robot
        self.scene = scene if scene is not None else load_scene()
        if sim is None:
            sim = SimRobot(w.WmmModel(robot), sim_cfg, seed=seed, ramp=ramp, scene=self.scene)
        self.sim = sim
        self.model = sim.model
        self.keys = Keys.of(svc.prefix, svc.robot)
        LeaseGate.__init__(self, Validator(CommandMsg, svc.robot, svc.validation, n_arm=robot.n_arm,
                                           n_wheels=robot.n_wheels))
        self.validate_box = Validator(BoxMsg, svc.robot, svc.validation)
        self.validate_obstacles = Validator(ObstaclesMsg, svc.robot, svc.validation)
        self.validate_gripper = Validator(GripperMsg, svc.robot, svc.validation)
        self.loop = RateLoop(sim_cfg.rate_hz, spin_s, clock=time.monotonic)  # the inbox's clock
        self.t0 = 0.0  # [s] monotonic time of step 0 (run() sets it)
        self.steps = 0  # steps run since t0
        self.publications = 0  # states published (their seq)
        self.caught_up = 0  # steps run to catch up with the wall clock (beyond one per wake-up)
        self.cmd_seq = -1
        if not (0.0 <= state_loss < 1.0 and 0.0 <= state_delay < 10.0):
            raise ValueError("state_loss must be in [0, 1) and state_delay in [0, 10) s")
        self.state_loss = state_loss
        self.state_delay = state_delay
        self._fault_rng = np.random.default_rng(fault_seed)
        self._delayed: deque[tuple[float, bytes]] = deque()
        self.states_dropped = 0
        self.rt_priority = rt_priority
        self.truth = truth
        self.scheduling = "not started"  # set by run(): the step loop's scheduling policy

    def accept(self, data: bytes, received: float | None = None) -> SimCommand | None:
        """Validate a command and check that it comes from the lease holder for this instance.

        Args:
            data: the payload.
            received: [s] monotonic time it reached this process (None: now).

        Returns the command for the pure model, or None (rejected or refused, counted).
        """
        return self._command(self.admit(data, self.sim.referee), received)

    def accept_msg(self, msg: CommandMsg, received: float | None = None) -> SimCommand | None:
        """:meth:`accept` for a command handed over in memory (a control core in this process,
        ``wmm-qp sim --embedded``): the same checks on the message itself, nothing decoded.

        Args:
            msg: the command as its sender made it.
            received: [s] monotonic time it was handed over (None: now).
        """
        checked = self.validate.checked(msg)
        if checked is None:
            self.refused["invalid"] += 1
            return None
        return self._command(self.obey(checked, self.sim.referee), received)

    def _command(self, msg: CommandMsg | None, received: float | None) -> SimCommand | None:
        """The pure model's command of an obeyed message (None: refused)."""
        if msg is None:
            return None
        self.cmd_seq = msg.seq
        return SimCommand(wheel_speeds=np.array(msg.wheel_speeds), arm_rates=np.array(msg.arm_rates),
                          period=msg.period, seq=msg.seq,
                          received=time.monotonic() if received is None else received, stream=msg.stream,
                          sent=msg.stamp, sender=msg.lease)

    def take(self, commands: list[SimCommand], dt: float) -> SimCommand | None:
        """The commands received since the last step, oldest first: every one but the latest is
        received by the robot now (the referee judges it, the firmware checks it, the next
        supersedes it); the latest is returned for :meth:`SimRobot.step` to receive and execute.

        Args:
            commands: accepted commands, in arrival order.
            dt: [s] the sim step.
        """
        if not commands:
            return None
        for c in commands[:-1]:
            self.sim.receive_superseded(c, dt)
        return commands[-1]

    def advance(self, now: float, inbox: CommandInbox[Any],
                accept: Callable[[Any, float], SimCommand | None] | None = None) -> SimState:
        """Run every step due by ``now`` [s] (step k is due at ``t0 + k·dt``; at least one), each
        receiving the commands that arrived before its end; returns the state after the last.

        Normally one step is due per wake-up. After a stall of this process the missed steps run
        now, in order: the robot executed its held command in them, went stale past
        ``stale_timeout`` and braked, as a real robot's firmware would have. Steps in which the
        robot rests in its own stop and no command arrives are skipped in one go
        (:meth:`SimRobot.coast`).

        Args:
            now: [s] monotonic time (the inbox's clock).
            inbox: the arrival-stamped commands.
            accept: turns an inbox entry and its arrival time into the model's command (None:
                :meth:`accept`, payloads; in memory: :meth:`accept_msg`).
        """
        accept = accept or self.accept
        dt = self.cfg.dt
        due = max(1, int((now - self.t0) / dt + 1e-9) + 1 - self.steps)
        st: SimState | None = None
        while due > 0:
            end = self.t0 + (self.steps + 1) * dt  # this step's end: commands that arrived by then
            if due > 1 and (arrival := inbox.next_arrival()) > end:
                quiet = due - 1 if math.isinf(arrival) else int((arrival - self.t0) / dt) - self.steps
                idle = min(due - 1, max(1, quiet))
                if self.sim.coast(idle, dt):
                    self.steps += idle
                    self.caught_up += idle
                    due -= idle
                    continue
            arrivals = inbox.take_until(math.inf if due == 1 else end)
            commands = [c for t, data in arrivals if (c := accept(data, t)) is not None]
            st = self.sim.step(self.take(commands, dt), dt)
            self.steps += 1
            self.caught_up += due > 1
            due -= 1
        return st if st is not None else self.sim.state()

    def place_box(self, data: bytes) -> bool:
        """Validate a box request and put the box in the scene (False: rejected, counted)."""
        msg = self.validate_box(data)
        if msg is None:
            return False
        self.sim.place_box(BoxConfig(mass=msg.mass, mu=msg.mu, face_x=msg.face_x,
                                     center_y=msg.center_y, width=msg.width, height=msg.height))
        return True

    def command_gripper(self, data: bytes) -> bool:
        """Validate a gripper command and start it (False: rejected, or no gripper: ``refused.gripper``)."""
        msg = self.validate_gripper(data)
        if msg is None:
            return False
        if not self.sim.command_gripper(msg.action, msg.width, msg.speed, msg.force):
            self.refused["gripper"] += 1
            return False
        return True

    def set_obstacles(self, data: bytes) -> bool:
        """Validate a live obstacles message and hand its set to the referee (False: rejected)."""
        if self.validate_obstacles(data) is None:
            return False
        self.sim.set_obstacles(self.validate_obstacles.shapes)
        return True

    def state_msg(self, st: SimState, seq: int) -> StateMsg:
        """The wire message of a sim state."""
        return StateMsg(
            robot=self.svc.robot, seq=seq, stamp=time.time(), t=st.t,
            q_base=st.base_odom.tolist(), q_arm=st.q_arm.tolist(), v_arm=st.v_arm.tolist(),
            wheel_speeds=st.wheel_speeds.tolist(), tau=st.tau.tolist(), gripper_width=st.gripper_width,
            stale_stop=st.stale_stop, cmd_seq=self.cmd_seq,
            instance=self.instance, lease=self.holder, protective_stop=st.protective_stop,
            protective_stops=st.protective_stops, protective_reason=st.protective_reason,
            protective_code=st.protective_code,
            refused=state_refused(self.refused, st))

    def truth_msg(self, st: SimState, seq: int) -> TruthMsg:
        """The evaluation data of a sim state (``sim/truth``), for the state of seq ``seq``."""
        return TruthMsg(
            robot=self.svc.robot, seq=seq, stamp=time.time(), t=st.t, instance=self.instance, state_seq=seq,
            base_true=st.base_true.tolist(), ee_true=st.ee_true.tolist(),
            contact_force=st.contact_force.tolist(), box_position=st.box_position,
            stalled_joint=-1 if st.stalled_joint is None else st.stalled_joint, violations=dict(st.violations))

    def outgoing(self, payload: bytes, now: float) -> list[bytes]:
        """The state payloads to publish now, after the injected loss and delay (if any).

        Args:
            payload: this step's encoded state.
            now: [s] monotonic time.
        """
        if self.state_loss > 0.0 and self._fault_rng.random() < self.state_loss:
            self.states_dropped += 1
            payload = b""
        if self.state_delay <= 0.0:
            return [payload] if payload else []
        if payload:
            self._delayed.append((now + self.state_delay, payload))
        out = []
        while self._delayed and self._delayed[0][0] <= now:
            out.append(self._delayed.popleft()[1])
        return out

    def run(self, stop: threading.Event, max_ticks: int | None = None) -> SimState:
        """Run until ``stop`` is set (or ``max_ticks``); returns the final state."""
        with open_session(self.svc, ROLE_SIM, io_priority(self.rt_priority)) as session:
            k = self.keys
            inbox: CommandInbox[bytes] = CommandInbox(clock=time.monotonic)

            def on_command(sample: zenoh.Sample) -> None:  # Zenoh's thread: stamp and store only
                inbox.put(sample.payload.to_bytes())

            sub = robot_side.command_subscriber(session, k, zenoh.handlers.Callback(on_command, indirect=False))
            sub_box, sub_obstacles, sub_gripper = (robot_side.input_subscriber(session, k, kind)
                                                   for kind in ("box", "obstacles", "gripper"))
            pub = robot_side.state_publisher(session, k)
            pub_truth = robot_side.truth_publisher(session, k) if self.truth else None
            token = robot_side.alive_token(session, k)
            lease_sub = robot_side.lease_watch(session, k)
            self.scheduling = realtime_priority(self.rt_priority)
            print(f"wmm-qp sim: step loop: {self.scheduling}", file=sys.stderr, flush=True)
            st = self.sim.state()
            counted, said = 0, 0
            now = self.t0 = self.loop.start()
            self.steps = 0
            try:
                while not stop.is_set() and (max_ticks is None or self.loop.ticks < max_ticks):
                    while (a := lease_sub.try_recv()) is not None:
                        self.on_lease(str(a.key_expr).rsplit("/", 1)[-1], a.kind == zenoh.SampleKind.PUT)
                    while (b := sub_box.try_recv()) is not None:
                        self.place_box(b.payload.to_bytes())
                    while (g := sub_gripper.try_recv()) is not None:
                        self.command_gripper(g.payload.to_bytes())
                    if (o := sub_obstacles.try_recv()) is not None:  # the referee checks the live set too
                        self.set_obstacles(o.payload.to_bytes())
                    st = self.advance(now, inbox)
                    if (total := sum(st.violations.values())) != counted and said < 50:
                        counted, said = total, said + 1  # the first 50 events, for the log
                        print(f"wmm-qp sim: referee: {st.violations} at t = {st.t:.3f} s; last: "
                              f"{self.sim.referee.last_event}; stale {st.stale_stop}, protective "
                              f"{st.protective_stop}", file=sys.stderr, flush=True)
                    self.publications += 1
                    for payload in self.outgoing(encode(self.state_msg(st, self.publications)),
                                                 time.monotonic()):
                        pub.put(payload)
                    if pub_truth is not None:  # evaluation data: published as it is, never delayed
                        pub_truth.put(encode(self.truth_msg(st, self.publications)))
                    now = self.loop.wait()
            finally:
                for ent in (token, lease_sub, sub, sub_box, sub_obstacles, sub_gripper, pub, pub_truth):
                    with contextlib.suppress(Exception):
                        if ent is not None:
                            ent.undeclare()
            return st
