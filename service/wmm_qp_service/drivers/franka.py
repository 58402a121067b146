"""``wmm-qp driver franka``: a Franka FR3 behind the daemon's protocol, through libfranka.

One process, one loop: libfranka's joint velocity control (``readOnce`` / ``writeOnce``, the
robot's 1 kHz cycle is the clock: :func:`.franka_link.drive`) and the wmm-qp protocol as the simulated robot speaks it
(``service/wmm_qp_service/drivers/sim_node.py``, docs/protocol.md): it publishes ``state`` every cycle with
its ``instance``, a consecutive ``seq``, the ``lease`` holder and the ``cmd_seq`` it follows,
holds the liveliness token ``alive/robot``, and obeys ``cmd`` from the lease holder only, addressed
to its instance, with increasing seq. Between the daemon's commands (500 Hz or 1 kHz, some late
or lost) and the robot, the :class:`~wmm_qp_robot.shaper.CommandShaper` makes the continuous,
jerk-limited stream Franka's controller demands, brakes on stale commands and refuses commands
past the limits (protective stop). The sim's referee (:mod:`wmm_qp_robot.referee`) judges every
command as received and the measured joint positions each cycle; its counts go out on
``sim/truth`` (:class:`~..protocol.TruthMsg`, every ``TRUTH_EVERY`` cycles), so ``violations``
means what it means for the sim, and nothing on the control path depends on them.

``v_arm`` is the velocity the robot executes as its motion generator's output: the stream this
driver writes (libfranka's commanded ``dq_c``), exactly 0 at rest — as the sim's executed rates.
The daemon takes it as the baseline a new stream starts from and waits for it to be 0 after a
stale or protective stop; the measured ``dq`` (encoder noise, the joint controllers' tracking
error) is never exactly 0 and would hold the daemon in that wait for ever.

The state is what the robot reports: ``tau`` is the robot's estimate of the external joint
torques (``tau_ext_hat_filtered``); the base is fixed (``q_base`` zeros, no wheels). In the
truth, what a real robot cannot give is NaN: ``base_true`` and ``ee_true`` (no motion capture),
``box_position``; ``stalled_joint`` is −1 and ``contact_force`` the robot's estimate of the
external force at the EE (``O_F_ext_hat_K``, its first three entries).

The Franka Hand (a robot file with ``[gripper]``, as ``fr3.toml``): ``gripper`` commands
(:class:`~..protocol.GripperMsg`) are validated and handed to pylibfranka's ``Gripper`` in a
child process (:mod:`.franka_hand`: it holds the GIL through a whole gripper motion); the
state's ``gripper_width`` is the width it last measured (nan without a hand).

libfranka's errors: a ``ControlException`` (a reflex of the robot: a collision, a limit, a
discontinuity) is a protective stop (``protective_reason`` ``robot: `` and libfranka's message);
libfranka has ended the motion and the robot stays in its ``Reflex`` mode, its states still
published (:mod:`.franka_link`). The first command of a new stream, the arm at rest, asks the
robot to recover (libfranka's ``automatic_error_recovery``, then a new control) and, once it has,
is followed; a refused recovery is reported in ``protective_reason``, ends the stream that asked
(its state names that command: the daemon starts another) and is tried again by a new stream
no sooner than :data:`RECOVERY_RETRY` later. A ``NetworkException`` (the connection is lost) ends the
driver: it says so and exits 1.

``pylibfranka`` is imported at run time (``pip install 'wmm-qp[franka]'``) and called only by
:mod:`.franka_link` and :mod:`.franka_hand`.
"""

from __future__ import annotations

import contextlib
import math
import sys
import threading
import time
from collections.abc import Callable, Hashable
from typing import Any

import numpy as np
import zenoh
from wmm_qp_robot.config import RefereeConfig
from wmm_qp_robot.lease_gate import LeaseGate
from wmm_qp_robot.referee import Referee
from wmm_qp_robot.shaper import CommandShaper, StreamLimits

import wmm_qp as w
from wmm_qp.fault_codes import FaultCode

from .. import robot_side
from ..config import ServiceConfig
from ..keys import Keys
from ..protocol import CommandMsg, GripperMsg, StateMsg, TruthMsg, encode
from ..rate_loop import realtime_priority
from ..transport import ROLE_SIM, io_priority, open_session
from ..validation import Validator
from .franka_hand import FrankaHand
from .franka_link import FrankaLink, drive

DT = 1e-3
"""[s] Franka's control cycle."""

RECOVERY_RETRY = 1.0
"""[s] of robot time: after a refused recovery the robot is asked again no sooner (by a command
of a new stream, at rest: the stream that waited asks with its next one): a daemon starts a new
stream on each refusal, and would otherwise have libfranka's recovery called at its tick rate."""

NAN3 = [math.nan] * 3
TRUTH_EVERY = 10
"""The driver publishes its referee's counts on ``sim/truth`` every this many cycles (100 Hz)."""


class FrankaDriver(LeaseGate):
    """The protocol side of the driver: commands in, the shaper, the referee, states out.

    Pure of libfranka: :meth:`cycle` takes one robot state's measurements and returns the
    velocities to write; :meth:`run` binds it to libfranka and Zenoh.

    Args:
        svc: service config (keys, validation ranges).
        robot: the robot file (a fixed base; its ``jerk_max`` bounds the stream).
        stale_timeout: [s] commands older than this brake the arm to rest.
        referee: the referee's tolerances.
        rt_priority: SCHED_FIFO priority of libfranka's cycle (the calling thread, once the robot is
            connected), its Zenoh threads one below; 0: normal scheduling.
    """

    def __init__(self, svc: ServiceConfig, robot: w.RobotConfig, stale_timeout: float = 0.025,
                 referee: RefereeConfig | None = None, rt_priority: int = 0) -> None:
        svc = svc.with_robot(robot)
        self.svc = svc
        self.robot = robot
        self.rt_priority = rt_priority
        self.scheduling = "normal scheduling"
        self.keys = Keys.of(svc.prefix, svc.robot)
        LeaseGate.__init__(self, Validator(CommandMsg, svc.robot, svc.validation, n_arm=robot.n_arm,
                                           n_wheels=robot.n_wheels))
        self.shaper = CommandShaper(StreamLimits.of(robot.arm), DT, stale_timeout)
        self.referee = Referee(robot, referee if referee is not None else RefereeConfig(), period_max=stale_timeout)
        self.cmd_seq = -1
        self.t = 0.0  # [s] the robot's time: the sum of its cycles
        self.started_at = math.nan  # [s] monotonic time the motion started (robot time 0)
        self.seq = 0
        self._stopped = False  # the shaper was in a stale or protective stop at the last cycle
        self.robot_error: str | None = None  # libfranka ended the motion (its message); None: it runs
        self._recovery_refused_t = -math.inf  # [s] robot time of the last refused recovery
        self.validate_gripper = Validator(GripperMsg, svc.robot, svc.validation)
        g = robot.gripper
        self.hand = FrankaHand(g.width_max, g.speed_max, g.force_max) if g is not None else None

    def on_command(self, data: bytes, q: np.ndarray, received: float,
                   recover: Callable[[], str | None] | None = None) -> bool:
        """Validate a command, check its sender and hand it to the referee and the shaper.

        Args:
            data: the payload.
            q: [rad] the measured joint positions.
            received: [s] monotonic time of receipt.
            recover: asks the robot to recover after libfranka ended the motion (None on
                success, else why not); called by the first command of a new stream at rest.

        Returns:
            True when the shaper took it as its target.
        """
        return self._obey(self.admit(data, self.referee), q, received, recover)

    def on_command_msg(self, msg: CommandMsg, q: np.ndarray, received: float,
                       recover: Callable[[], str | None] | None = None) -> bool:
        """:meth:`on_command` for a command handed over in memory by a control core in this
        process (``--embedded``): the same checks on the message itself, nothing decoded."""
        checked = self.validate.checked(msg)
        if checked is None:
            self.refused["invalid"] += 1
            return False
        return self._obey(self.obey(checked, self.referee), q, received, recover)

    def _obey(self, msg: CommandMsg | None, q: np.ndarray, received: float,
              recover: Callable[[], str | None] | None) -> bool:
        """An obeyed command (None: refused) to the referee, as received, then to the shaper."""
        if msg is None:
            return False
        rates = np.array(msg.arm_rates, dtype=float)
        self.referee.on_command(self.t, rates, np.zeros(0), self.shaper.v, np.zeros(0), period=msg.period,
                                seq=msg.seq, received=received, step=DT, stream=msg.stream, sent=msg.stamp)
        stream = (msg.lease, msg.stream)
        sh = self.shaper
        if (self.robot_error is not None and sh.illegal(rates) is None  # (illegal: the shaper's fault, below)
                and (why := self._recover(stream, msg.seq, recover)) is not None):
            self.refused[why] += 1
            return False
        ended = sh.ended
        if not sh.command(self.t, rates, stream, q):
            self.refused["ended" if sh.ended > ended else "firmware"] += 1
            return False
        self.cmd_seq = msg.seq
        return True

    def _recover(self, stream: Hashable, seq: int, recover: Callable[[], str | None] | None) -> str | None:
        """After libfranka ended the motion: None when the robot runs again for this command (the
        first of a new stream at rest asks it to recover), else the ``refused`` key.

        ``ended``: the stream the reflex ended, or a refused recovery did; ``recovering``: a new
        stream within :data:`RECOVERY_RETRY` of a refused recovery (asked by a later command of
        it); ``firmware``: a new stream while the arm still moves, or the refused recovery itself
        (the fault: the refusing command's stream is then ended, and the state names it, so its
        sender sees its stream stopped and starts another)."""
        sh = self.shaper
        if stream == sh.stopped_stream:
            return "ended"
        if not sh.would_release(stream):
            return "firmware"
        if self.t - self._recovery_refused_t < RECOVERY_RETRY:
            return "recovering"
        why = recover() if recover is not None else "no robot to recover"
        if why is not None:
            sh.restop(stream, FaultCode.RECOVERY_REFUSED, f"robot: {self.robot_error}; recovery refused: {why}")
            self.cmd_seq = seq
            self._recovery_refused_t = self.t
            return "firmware"
        self.robot_error = None
        return None

    def cycle(self, elapsed: float, q: np.ndarray) -> np.ndarray:
        """One robot cycle: advance the robot's time, judge its positions, shape the next command.

        Args:
            elapsed: [s] the time since the previous cycle (libfranka's duration; 0.001 normally).
            q: [rad] the measured joint positions.

        Returns:
            [rad/s] the joint velocities to write.
        """
        self.t += elapsed
        return self.shape(q)

    def shape(self, q: np.ndarray) -> np.ndarray:
        """The second half of :meth:`cycle`, at the robot's time already advanced: judge the
        positions, shape the next command.

        Args:
            q: [rad] the measured joint positions.

        Returns:
            [rad/s] the joint velocities to write.
        """
        self.referee.check_positions(q)
        v = self.shaper.step(self.t, q)
        stopped = self.shaper.stale or self.shaper.protective
        if stopped and not self._stopped:
            self.referee.break_stream(hard=False)  # the robot stopped following the stream
        self._stopped = stopped
        return v

    def on_gripper(self, data: bytes) -> bool:
        """A gripper command: validated, then queued to the hand (False: rejected, or no hand:
        ``refused.gripper``)."""
        msg = self.validate_gripper(data)
        if msg is None:
            return False
        if self.hand is None or not self.hand.command(msg.action, msg.width, msg.speed, msg.force):
            self.refused["gripper"] += 1
            return False
        return True

    def fault(self, reason: str) -> None:
        """libfranka ended the motion (a reflex): a protective stop from rest until the robot
        recovers on a new stream (:meth:`on_command`)."""
        self.shaper.reset(FaultCode.ROBOT_REFLEX, f"robot: {reason}")
        self.referee.break_stream(hard=False)  # the stopped stream's late commands: judged among themselves
        self.robot_error = reason

    def state_msg(self, q: np.ndarray, tau: np.ndarray, gripper_width: float = math.nan) -> StateMsg:
        """The wire message of this cycle's state (``v_arm``: the stream written, see the module docstring).

        Args:
            q: [rad] measured joint positions.
            tau: [N·m] the robot's external joint torque estimate.
            gripper_width: [m] the hand's opening (nan: no hand).
        """
        self.seq += 1
        sh = self.shaper
        refused = {**self.refused}
        return StateMsg(
            robot=self.svc.robot, seq=self.seq, stamp=time.time(), t=self.t,
            q_base=[0.0, 0.0, 0.0], q_arm=q.tolist(), v_arm=sh.v.tolist(), wheel_speeds=[],
            tau=tau.tolist(), gripper_width=gripper_width, stale_stop=sh.stale,
            cmd_seq=self.cmd_seq, instance=self.instance, lease=self.holder,
            protective_stop=sh.protective, protective_stops=sh.protective_stops,
            protective_reason=sh.protective_reason, protective_code=sh.protective_code, refused=refused)

    def truth_msg(self, force: np.ndarray) -> TruthMsg:
        """The referee's counts as ``sim/truth`` for the last state (no ground truth: NaN).

        Args:
            force: [N] the robot's estimate of the external force at the EE (base frame).
        """
        return TruthMsg(
            robot=self.svc.robot, seq=self.seq, stamp=time.time(), t=self.t, instance=self.instance,
            state_seq=self.seq, base_true=NAN3, ee_true=NAN3, contact_force=force.tolist(),
            violations={k: n for k, n in self.referee.counts.items() if n})

    def run(self, robot_ip: str, stop: threading.Event, max_cycles: int | None = None) -> int:
        """Connect to the robot at ``robot_ip`` and drive it until ``stop`` (or ``max_cycles``).

        Returns:
            0 after a clean stop (the arm braked to rest, the motion finished); 1 when the
            connection to the robot could not be made or was lost (said on stderr).
        """
        try:
            import pylibfranka as fr
        except ImportError:
            print("wmm-qp driver franka: error: needs pylibfranka (pip install 'wmm-qp[franka]')",
                  file=sys.stderr, flush=True)
            return 2
        with open_session(self.svc, ROLE_SIM, io_priority(self.rt_priority)) as session:
            k = self.keys
            sub = robot_side.command_subscriber(session, k, zenoh.handlers.FifoChannel(1024))
            sub_gripper = robot_side.input_subscriber(session, k, "gripper")
            pub, pub_truth = robot_side.state_publisher(session, k), robot_side.truth_publisher(session, k)
            lease_sub = robot_side.lease_watch(session, k)
            token = None
            try:
                try:
                    link = FrankaLink(fr, fr.Robot(robot_ip, fr.RealtimeConfig.kIgnore))
                    link.start()
                    self.started_at = time.monotonic()
                except (fr.NetworkException, fr.FrankaException, RuntimeError) as e:
                    print(f"wmm-qp driver franka: error: cannot connect to the robot at {robot_ip}: {e}",
                          file=sys.stderr, flush=True)
                    return 1
                if self.hand is not None:
                    self.hand.start(robot_ip)
                token = robot_side.alive_token(session, k)
                self.scheduling = realtime_priority(self.rt_priority)  # after the hand's child started
                print(f"wmm-qp driver franka: {k.state.rsplit('/', 1)[0]} driving the robot at {robot_ip} "
                      f"(instance {self.instance}; cycle: {self.scheduling})", file=sys.stderr, flush=True)
                return self._loop(fr, link, (sub, sub_gripper), lease_sub, (pub, pub_truth), stop, max_cycles,
                                  robot_ip)
            finally:
                if self.hand is not None:
                    self.hand.close()
                for ent in (token, lease_sub, sub, sub_gripper, pub, pub_truth):
                    if ent is not None:
                        with contextlib.suppress(Exception):
                            ent.undeclare()

    def reflex(self, e: Exception, link: FrankaLink) -> None:
        """libfranka ended the motion (a ``ControlException``: a reflex of the robot): a protective
        stop, said on stderr, and the aborted control given back (libfranka runs one control at a
        time); the robot recovers on the first command of a new stream at rest (:meth:`recover`)."""
        reason = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        print(f"wmm-qp driver franka: protective stop: {reason}", file=sys.stderr, flush=True)
        self.fault(reason)
        link.lose()

    @staticmethod
    def recover(link: FrankaLink) -> str | None:
        """libfranka's automatic error recovery and a new control (None), or why not; said on stderr."""
        why = link.recover()
        print("wmm-qp driver franka: the robot recovered (automatic error recovery, a new control)"
              if why is None else f"wmm-qp driver franka: the robot did not recover: {why}",
              file=sys.stderr, flush=True)
        return why

    def _loop(self, fr: Any, link: FrankaLink, subs: tuple[Any, Any], lease_sub: Any, pubs: tuple[Any, Any],
              stop: threading.Event, max_cycles: int | None, robot_ip: str) -> int:
        sub, sub_gripper = subs
        pub, pub_truth = pubs
        n = 0
        st: Any = None
        q = np.zeros(0)

        def recover() -> str | None:
            return self.recover(link)

        def step(finishing: bool) -> tuple[np.ndarray, int]:
            nonlocal n, st, q
            st, elapsed = link.read()
            q = np.array(st.q, dtype=float)
            while (a := lease_sub.try_recv()) is not None:
                self.on_lease(str(a.key_expr).rsplit("/", 1)[-1], a.kind == zenoh.SampleKind.PUT)
            if not finishing:
                while (c := sub.try_recv()) is not None:
                    try:
                        self.on_command(c.payload.to_bytes(), q, time.monotonic(), recover)
                    except fr.NetworkException:
                        raise
                    except Exception as e:  # never out of the control loop: the command is dropped
                        self.refused["error"] += 1
                        if self.refused["error"] <= 10:
                            print(f"wmm-qp driver franka: a command dropped: {type(e).__name__}: {e}",
                                  file=sys.stderr, flush=True)
            v = self.cycle(elapsed, q)
            n += 1
            return v, n

        def after(done: bool) -> None:
            if (g := sub_gripper.try_recv()) is not None:
                self.on_gripper(g.payload.to_bytes())
            width = self.hand.width if self.hand is not None else math.nan
            pub.put(encode(self.state_msg(q, np.array(st.tau_ext_hat_filtered, dtype=float), width)))
            if n % TRUTH_EVERY == 1 or done:
                pub_truth.put(encode(self.truth_msg(np.array(st.O_F_ext_hat_K, dtype=float)[:3])))

        return drive(fr, link, self, stop, max_cycles, robot_ip, step, after)
