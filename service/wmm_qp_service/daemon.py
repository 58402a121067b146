"""The control daemon: one thread, a fixed-rate loop, all I/O polled inside it.

Each tick: poll the latest state (ring channel, depth 1), the mode changes (FIFO, none
lost), the latest setpoint (ring, depth 1), the ``info`` queries and the sim's liveliness;
validate everything on receipt; run the watchdogs; smooth the setpoint (Ruckig); call the
controller ``ctl.step(state, ref)``; publish the command; publish status and telemetry.
Nothing in the loop raises: failures become a safe stop and a reason in the status.
"""

from __future__ import annotations

import contextlib
import gc
import math
import os
import sys
import threading
import time
from collections import Counter
from dataclasses import asdict
from typing import Any

import numpy as np
import zenoh

import wmm_qp as w

from .config import ServiceConfig
from .keys import Keys
from .protocol import (
    CommandMsg,
    InfoMsg,
    ModeMsg,
    SetpointMsg,
    StateMsg,
    StatusMsg,
    TelemetryMsg,
    encode,
)
from .rate_loop import RateLoop
from .smoother import SetpointSmoother, VelocityEstimator
from .transport import ROLE_DAEMON, open_session
from .validation import Validator

_NAN3 = [math.nan] * 3


def realtime_priority(priority: int) -> str:
    """Put the calling thread under SCHED_FIFO at ``priority`` (Linux); say what happened.

    A real-time thread is not preempted by ordinary processes, so a loaded machine delays its
    ticks far less. The loop sleeps most of each period, so it does not starve the others.
    """
    if priority <= 0:
        return "normal scheduling"
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))  # 0 = this thread
    except (AttributeError, OSError) as e:  # not Linux, or not permitted
        return f"normal scheduling (SCHED_FIFO {priority} refused: {getattr(e, 'strerror', e)})"
    return f"SCHED_FIFO {priority}"


def _xd(ref: w.Reference) -> list[float]:
    """The reference's target for messages (NaN when it means "where the EE is")."""
    return list(_NAN3) if ref.x_d is None else ref.x_d.tolist()


class ControlCore:
    """The daemon's logic without transport: modes, watchdogs, smoothing, the controller.

    The :class:`Daemon` feeds it validated messages and publishes what it returns; tests
    can drive it directly with a fake clock.

    Args:
        svc: service config.
        ctl_cfg: controller config (its rate is replaced by ``svc.loop.rate_hz``).
        robot: robot config.
        kind: controller kind (qp, paper, traditional); None = ``ctl_cfg.kind``.
    """

    def __init__(self, svc: ServiceConfig, ctl_cfg: w.ControllerConfig, robot: w.RobotConfig,
                 kind: str | None = None) -> None:
        self.svc = svc
        # Bounds (13) brake from where the joints can be when the next command (or the robot's
        # own command timeout) takes over: over a transport that is longer than in-process.
        hold = max(ctl_cfg.state_latency, svc.watchdog.command_hold)
        self.cfg = ctl_cfg.with_(rate_hz=svc.loop.rate_hz, state_latency=hold)
        self.robot = robot
        self.model = w.WmmModel(robot)
        self.kind = kind or self.cfg.kind
        self.ctl = w.make_controller(self.kind, self.model, self.cfg)
        self.ctl.warm_up()  # the compiled kernels are loaded before the loop, not in its first tick
        self.dt = self.cfg.dt
        sm = svc.smoothing
        self.smoother = SetpointSmoother(self.dt, sm.v_max, sm.a_max, sm.j_max)
        self.estimator = VelocityEstimator(v_max=sm.v_max)
        self.mode = w.Mode.HOLD
        self.direction: np.ndarray | None = None
        self.state: w.RobotState | None = None
        self.state_msg: StateMsg | None = None
        self.state_time = -math.inf
        self.setpoint_time = -math.inf
        self.need_latch = True
        self.safe = False
        self.last_fault = ""
        self.sim_alive = False
        self.cmd: w.Command | None = None
        self.ref = w.Reference(mode=w.Mode.HOLD)
        self.ref_valid = False  # self.ref was computed from the current latch
        self.ee_error = math.nan
        self.faults: Counter[str] = Counter()
        self.now = 0.0
        self.t0 = 0.0  # [s] clock value at the loop's start (fault messages say time since)
        self.state_fresh = False

    # ------------------------------------------------------------------ inputs
    def on_state(self, msg: StateMsg, now: float) -> None:
        """A validated state arrived at ``now`` [s]."""
        self.state_msg = msg
        self.state = w.RobotState(q_base=np.array(msg.q_base), q_arm=np.array(msg.q_arm),
                                  v_arm=np.array(msg.v_arm), wheel_speeds=np.array(msg.wheel_speeds))
        self.state_time = now
        self.state_fresh = True

    def on_mode(self, msg: ModeMsg) -> None:
        """A validated mode change: switch and re-latch the target from the current EE."""
        self.mode = w.Mode(msg.mode)
        self.direction = None if msg.direction is None else np.asarray(msg.direction, dtype=float)
        self.need_latch = True

    def on_setpoint(self, msg: SetpointMsg, now: float) -> None:
        """A validated setpoint: feed the smoother (track and null-space DM modes only)."""
        self.setpoint_time = now
        if self.mode not in (w.Mode.TRACK, w.Mode.DM_NULLSPACE) or self.need_latch:
            return
        x = np.asarray(msg.x, dtype=float)
        if msg.xd is not None:  # a scripted trajectory: its own feed-forward velocity
            self.smoother.set_target(x, np.asarray(msg.xd, dtype=float))
        else:
            xf, v = self.estimator.update(x, msg.stamp)
            self.smoother.set_target(xf, v)

    def on_sim_alive(self, alive: bool) -> None:
        """The sim's liveliness token appeared or vanished."""
        if self.sim_alive and not alive:
            self._fault("sim lost (liveliness)")
            self.state_time = -math.inf
            self.safe = self.state is not None  # the next ticks brake (see _safe_stop)
        self.sim_alive = alive

    def _fault(self, what: str) -> None:
        """Record a fault (and say it once on stderr when it is new)."""
        if what != self.last_fault:
            st = self.state
            where = (f" [t={self.now - self.t0:.3f} s, mode {self.mode.value}, q_base "
                     f"{np.round(st.q_base, 4).tolist()}, q_arm {np.round(st.q_arm, 4).tolist()}]"
                     if st is not None else "")
            print(f"wmm-qp serve: fault: {what}{where}", file=sys.stderr, flush=True)
        self.last_fault = what
        self.faults[what.split(" (")[0]] += 1

    def _latch(self) -> None:
        """Re-latch: the smoother restarts from the current EE position and velocity."""
        assert self.state is not None
        st = self.state
        kin = self.model.kinematics(st.q_base, st.q_arm)
        xdot = kin.J @ np.concatenate([st.wheel_speeds, st.v_arm])
        self.smoother.reset(kin.x, xdot)
        self.estimator.reset()
        self.ctl.reset()
        self.need_latch = False
        self.ref_valid = False

    # ------------------------------------------------------------------ one tick
    def tick(self, now: float) -> w.Command | None:
        """One control tick at ``now`` [s]; returns the command to publish (None: nothing)."""
        wd = self.svc.watchdog
        self.now = now
        if self.state is None:
            return None
        if now - self.state_time > wd.state_timeout:
            return self._safe_stop(f"state stale (none valid for > {wd.state_timeout * 1e3:.0f} ms)")
        if self.safe:  # the state is back: resume from the measured state
            self.safe = False
            self.need_latch = True
        if not self.state_fresh and self.cmd is not None:
            self._predict_state()
        self.state_fresh = False
        if self.need_latch:
            self._latch()
        if (not self.smoother.resting and self.mode in (w.Mode.TRACK, w.Mode.DM_NULLSPACE)
                and now - self.setpoint_time > wd.setpoint_timeout):
            self.smoother.bring_to_rest()
        if self.mode == w.Mode.HOLD and not self.smoother.resting:
            self.smoother.bring_to_rest()
        # ground-truth error of the state (the previous tick's command) against its target
        if self.ref_valid and self.state_msg is not None and self.mode != w.Mode.DM_CARTESIAN:
            self.ee_error = float(np.linalg.norm(np.asarray(self.state_msg.ee_true) - self.ref.x_d))
        else:
            self.ee_error = math.nan
        x_d, xd_d = self.smoother.step()
        self.ref = w.Reference(mode=self.mode, x_d=x_d, xd_d=xd_d, direction=self.direction)
        self.ref_valid = True
        cmd = self.ctl.step(self.state, self.ref)
        if cmd.status == w.Status.SAFE_STOP:
            self._fault(f"controller: {cmd.reason}")
            self.smoother.reset(cmd.x if np.isfinite(cmd.x).all() else x_d)
        self.cmd = cmd
        return cmd

    def _predict_state(self) -> None:
        """No new state this tick: assume the last command executed for one period.

        The controller's acceleration bounds start from the state's rates; starting them
        again from an old state would let two consecutive commands differ by 2·A·dt.
        """
        assert self.state is not None and self.cmd is not None
        st, cmd = self.state, self.cmd
        twist = self.model.base.P(float(st.q_base[2])) @ cmd.wheel_speeds
        self.state = w.RobotState(q_base=st.q_base + self.dt * twist,
                                  q_arm=st.q_arm + self.dt * cmd.arm_rates,
                                  v_arm=cmd.arm_rates.copy(), wheel_speeds=cmd.wheel_speeds.copy())

    def _safe_stop(self, why: str) -> w.Command:
        """Brake from the last command at the acceleration limits (the state is not trusted)."""
        if not self.safe:
            self._fault(why)
            self.safe = True
        assert self.state is not None
        last = self.cmd
        base = w.RobotState(
            q_base=self.state.q_base, q_arm=self.state.q_arm,
            v_arm=last.arm_rates if last is not None else self.state.v_arm,
            wheel_speeds=last.wheel_speeds if last is not None else self.state.wheel_speeds)
        cmd = self.ctl.safe_stop(base, why)
        self.cmd = cmd
        return cmd

    def status(self, loop: RateLoop, rejected: Counter[str], accepted: dict[str, int]) -> StatusMsg:
        """The status message."""
        cmd = self.cmd
        return StatusMsg(
            robot=self.svc.robot, stamp=time.time(), mode=self.mode.value,
            state_ok=self.state is not None and not self.safe, safe_stop=self.safe,
            controller_status=cmd.status.value if cmd else "", reason=cmd.reason if cmd else "",
            last_fault=self.last_fault, loop=loop.stats(), rejected=dict(rejected),
            accepted=accepted,
            sim_violations=dict(self.state_msg.violations) if self.state_msg else {},
            x=cmd.x.tolist() if cmd is not None else [], x_d=_xd(self.ref),
            dm=float(cmd.dm) if cmd is not None else math.nan, sim_alive=self.sim_alive)

    def config_dict(self) -> dict[str, Any]:
        """The running configuration as plain data (for the ``info`` queryable)."""
        c = self.cfg
        return {
            "service": _plain(asdict(self.svc)),
            "controller": {"kind": self.kind, "rate_hz": c.rate_hz, "K_x": c.K_x, "alpha": c.alpha,
                           "k_C": c.k_C, "k_N": c.k_N, "W": c.W.tolist(),
                           "direction": c.direction.tolist(), "solver": c.qp.solver},
        }


def _plain(d: Any) -> Any:
    if isinstance(d, dict):
        return {k: _plain(v) for k, v in d.items()}
    if isinstance(d, float) and not math.isfinite(d):
        return str(d)
    if isinstance(d, int | float | str | bool) or d is None:
        return d
    return str(d)


class Daemon:
    """The control daemon over Zenoh (``wmm-qp serve``).

    Args:
        svc: service config.
        ctl_cfg: controller config.
        robot: robot config.
        kind: controller kind; None = the controller config's.
    """

    def __init__(self, svc: ServiceConfig, ctl_cfg: w.ControllerConfig, robot: w.RobotConfig,
                 kind: str | None = None) -> None:
        self.svc = svc
        self.core = ControlCore(svc, ctl_cfg, robot, kind)
        self.keys = Keys.of(svc.prefix, svc.robot)
        lim = svc.validation
        self.v_state = Validator(StateMsg, svc.robot, lim)
        self.v_mode = Validator(ModeMsg, svc.robot, lim)
        self.v_setpoint = Validator(SetpointMsg, svc.robot, lim)
        self.loop = RateLoop(svc.loop.rate_hz, svc.loop.spin_us * 1e-6)
        self.scheduling = "not started"  # set by run(): the control thread's scheduling policy

    def rejected(self) -> Counter[str]:
        """Rejected messages by reason, all keys together."""
        return self.v_state.rejected + self.v_mode.rejected + self.v_setpoint.rejected

    def accepted(self) -> dict[str, int]:
        """Accepted messages by key."""
        return {"state": self.v_state.accepted, "mode": self.v_mode.accepted,
                "setpoint": self.v_setpoint.accepted}

    def run(self, stop: threading.Event, max_ticks: int | None = None) -> StatusMsg:
        """Run until ``stop`` is set (or ``max_ticks``); returns the final status."""
        with open_session(self.svc, ROLE_DAEMON) as session:
            return self._run(session, stop, max_ticks)

    def _run(self, session: zenoh.Session, stop: threading.Event, max_ticks: int | None) -> StatusMsg:
        k, core, svc = self.keys, self.core, self.svc
        # After the session opened: Zenoh's own threads keep normal priority, only this one is raised.
        self.scheduling = realtime_priority(svc.loop.rt_priority)
        print(f"wmm-qp serve: control thread: {self.scheduling}", file=sys.stderr, flush=True)
        ring = zenoh.handlers.RingChannel
        fifo = zenoh.handlers.FifoChannel
        sub_state = session.declare_subscriber(k.state, ring(1))
        sub_setpoint = session.declare_subscriber(k.setpoint, ring(1))
        sub_mode = session.declare_subscriber(k.mode, fifo(256))
        queryable = session.declare_queryable(k.info, fifo(64))
        alive_sub = session.liveliness().declare_subscriber(k.alive("sim"), fifo(64), history=True)
        token = session.liveliness().declare_token(k.alive("daemon"))
        pub_cmd = session.declare_publisher(k.cmd, express=True,
                                            congestion_control=zenoh.CongestionControl.DROP,
                                            priority=zenoh.Priority.REAL_TIME)
        pub_status = session.declare_publisher(k.status)
        pub_tel = session.declare_publisher(k.telemetry, congestion_control=zenoh.CongestionControl.DROP)
        status_every = max(1, round(svc.loop.rate_hz / svc.loop.status_hz))
        tel_every = svc.loop.telemetry_every
        seq = 0
        gc.collect()
        gc.freeze()
        loop = self.loop
        t0 = loop.start()
        core.t0 = now = t0
        try:
            while not stop.is_set() and (max_ticks is None or loop.ticks < max_ticks):
                # ---- inputs, all polled from this thread
                while (a := alive_sub.try_recv()) is not None:
                    core.on_sim_alive(a.kind == zenoh.SampleKind.PUT)
                s = sub_state.try_recv()
                if s is not None and (m := self.v_state(s.payload.to_bytes())) is not None:
                    core.on_state(m, now)
                while (s := sub_mode.try_recv()) is not None:
                    if (mm := self.v_mode(s.payload.to_bytes())) is not None:
                        core.on_mode(mm)
                s = sub_setpoint.try_recv()
                if s is not None and (sp := self.v_setpoint(s.payload.to_bytes())) is not None:
                    core.on_setpoint(sp, now)
                # ---- control
                cmd = core.tick(now)
                if cmd is not None:
                    seq += 1
                    pub_cmd.put(encode(CommandMsg(
                        robot=svc.robot, seq=seq, stamp=time.time(),
                        wheel_speeds=cmd.wheel_speeds.tolist(), arm_rates=cmd.arm_rates.tolist(),
                        status=cmd.status.value)))
                    if tel_every and loop.ticks % tel_every == 0:
                        ee = core.state_msg.ee_true if core.state_msg is not None else _NAN3
                        pub_tel.put(encode(TelemetryMsg(
                            robot=svc.robot, seq=seq, stamp=time.time(), t=now - t0,
                            mode=core.mode.value, x=cmd.x.tolist(), x_d=_xd(core.ref),
                            xd_d=core.ref.xd_d.tolist(), ee_true=list(ee), ee_error=core.ee_error,
                            wheel_speeds=cmd.wheel_speeds.tolist(), arm_rates=cmd.arm_rates.tolist(),
                            status=cmd.status.value, dm=float(cmd.dm), task_error=float(cmd.task_error),
                            tick_us=(time.perf_counter() - now) * 1e6)))
                # ---- status, queries
                if loop.ticks % status_every == 0:
                    pub_status.put(encode(core.status(loop, self.rejected(), self.accepted())))
                while (q := queryable.try_recv()) is not None:
                    info = InfoMsg(robot=svc.robot, stamp=time.time(),
                                   status=core.status(loop, self.rejected(), self.accepted()),
                                   config=core.config_dict())
                    try:
                        q.reply(k.info, encode(info))
                    except Exception as e:  # a vanished querier must not stop the loop
                        core.last_fault = f"info reply failed: {e}"
                now = loop.wait()
        finally:
            gc.unfreeze()
            final = core.status(loop, self.rejected(), self.accepted())
            for ent in (token, sub_state, sub_setpoint, sub_mode, queryable, alive_sub,
                        pub_cmd, pub_status, pub_tel):
                with contextlib.suppress(Exception):
                    ent.undeclare()
        return final
