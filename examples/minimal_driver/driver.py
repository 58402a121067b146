"""A minimal robot driver written from docs/drivers.md and docs/protocol.md alone.

Its "hardware" is a kinematic robot of its own: the joints and wheels run exactly the rates the
drives execute, and the positions are their integral (no physics, no noise). Around it, every duty
of docs/drivers.md: a state every cycle (seq consecutive, one random instance), the liveliness token
``alive/robot``, the lease / instance / validation / seq gate with its refusal counts, commands held
until the next and ramped to at the acceleration limits, the stale stop, the protective stops of the
firmware (a rate past a velocity limit; a motion from which a joint could not brake before its
position limit), stops that end the stream they stopped, and a clean stop on SIGINT/SIGTERM.

    python examples/minimal_driver/driver.py [--robot-config F] [--prefix P] [--robot ID]
        [--sim-endpoint E] [--rate HZ] [--stale-timeout S] [--rt-priority N]

Check it with ``wmm-qp contract`` given the same robot file, prefix and endpoints.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import signal
import sys
import time
import uuid
from pathlib import Path
from typing import NoReturn

import numpy as np
import zenoh
from wmm_qp_service.config import ValidationConfig, load_service_config, resolve_robot_id
from wmm_qp_service.protocol import CommandMsg, StateMsg, encode
from wmm_qp_service.validation import Validator

import wmm_qp as w

REFUSALS = ("lease", "instance", "invalid", "seq", "firmware", "ended")


def say(line: str) -> None:
    print(f"minimal-driver: {line}", file=sys.stderr, flush=True)


class Robot:
    """The firmware and its kinematic hardware, stepped once per cycle (no transport in here)."""

    def __init__(self, robot: w.RobotConfig, robot_id: str, limits: ValidationConfig, rate_hz: float,
                 stale_timeout: float) -> None:
        self.cfg, self.id, self.dt, self.stale_timeout = robot, robot_id, 1.0 / rate_hz, stale_timeout
        self.n, self.m = robot.n_arm, robot.n_wheels
        self.base = w.WmmModel(robot).base                       # wheel speeds -> base velocity
        self.names = list(robot.arm.joints) + [f"wheel {nm}" for nm in self.base.wheel_names]
        self.v_max = np.concatenate([robot.arm.velocity_max, robot.base.wheel_speed_max])
        self.a_max = np.concatenate([robot.arm.acceleration_max, robot.base.wheel_acceleration_max])
        self.lower, self.upper = np.asarray(robot.arm.position_lower), np.asarray(robot.arm.position_upper)
        self.validator = Validator(CommandMsg, robot_id, limits, n_arm=self.n, n_wheels=self.m)
        self.instance = uuid.uuid4().hex                         # a new robot to the daemon per start
        # The hardware: positions, executed rates (arm then wheels), odometry.
        self.q = np.array(robot.arm.start, dtype=float)
        self.v = np.zeros(self.n + self.m)
        self.q_base = np.zeros(3)
        self.seq, self.t = 0, 0.0
        # The firmware.
        self.target = np.zeros(self.n + self.m)                  # the applied command, held until the next
        self.cmd_seq = -1
        self.last_applied: float | None = None                   # robot time of the last applied command
        self.leases: dict[str, None] = {}                        # alive lease tokens, oldest first
        self.last_seq: dict[str, int] = {}                       # per lease holder
        self.stream: tuple[str, int] | None = None               # (holder, stream) being followed
        self.ended: tuple[str, int] | None = None                # the stream the last stop ended
        self.stale_stop = self.protective_stop = self.stopping = False
        self.protective_stops, self.reason, self.code = 0, "", ""
        self.refused = dict.fromkeys(REFUSALS, 0)

    @property
    def holder(self) -> str:
        return next(iter(self.leases), "")

    def at_rest(self) -> bool:
        return not self.v.any()

    # -- the lease ---------------------------------------------------------------------------
    def lease_event(self, lease_id: str, alive: bool) -> None:
        if alive:
            self.leases.setdefault(lease_id, None)
        else:
            self.leases.pop(lease_id, None)

    # -- a command, judged as received -------------------------------------------------------
    def receive(self, data: bytes) -> None:
        msg = self.validator(data)
        if msg is None:
            self.refused["invalid"] += 1
            return
        if msg.lease != self.holder:
            self.refused["lease"] += 1
            return
        if msg.instance != self.instance:
            self.refused["instance"] += 1
            return
        if msg.seq <= self.last_seq.get(msg.lease, -math.inf):
            self.refused["seq"] += 1
            return
        self.last_seq[msg.lease] = msg.seq
        self.cmd_seq = msg.seq                  # applied or refused by the firmware: the sender sees which
        key = (msg.lease, msg.stream)
        rates = np.concatenate([msg.arm_rates, msg.wheel_speeds])
        over = np.flatnonzero(np.abs(rates) > self.v_max)
        if over.size:                           # past a limit, whatever the stream
            i = int(over[0])
            self.protect(key, "refused_command", f"{self.joint(i)} commanded at {rates[i]:.4g}, "
                         f"beyond its limit {self.v_max[i]:.4g}", refused=True)
            return
        if key == self.ended:                   # a stop ended this stream: late, not a new fault
            self.refused["ended"] += 1
            return
        if self.stopping or (self.protective_stop and not self.at_rest()):
            self.refused["firmware"] += 1       # a new stream while braking (or shutting down)
            return
        joint = self.cannot_brake(self.ramp(rates))
        if joint is not None:
            self.protect(key, "cannot_stop_before_limit", self.limit_reason(joint), refused=True)
            return
        self.target, self.stream, self.last_applied = rates, key, self.t
        self.stale_stop = self.protective_stop = False

    def joint(self, i: int) -> str:
        return f"joint {i + 1} ({self.names[i]})" if i < self.n else self.names[i]

    def limit_reason(self, i: int) -> str:
        return (f"{self.joint(i)} at {self.q[i]:.4g} moving {self.v[i]:.3g} could not brake "
                f"before its position limit [{self.lower[i]:.4g}, {self.upper[i]:.4g}]")

    def protect(self, key: tuple[str, int] | None, code: str, reason: str, refused: bool) -> None:
        """A protective stop: brake at the acceleration limits; the stream it stopped has ended."""
        if refused:
            self.refused["firmware"] += 1
        if not self.protective_stop:
            self.protective_stops += 1
            say(f"protective stop {self.protective_stops}: {reason}")
        if not self.protective_stop or (self.at_rest() and key != self.ended):
            self.ended, self.stale_stop = key, False    # the stop is this stream's (else it stays the first's)
        self.protective_stop, self.reason, self.code = True, reason, code
        self.stream, self.target = None, np.zeros_like(self.target)

    # -- the hardware ------------------------------------------------------------------------
    def ramp(self, target: np.ndarray) -> np.ndarray:
        """The executed rates one cycle on: towards ``target`` at most A·dt per joint and wheel."""
        step = self.a_max * self.dt
        return np.asarray(self.v + np.clip(target - self.v, -step, step))

    def cannot_brake(self, v_next: np.ndarray) -> int | None:
        """The first joint that, moving at ``v_next`` for a cycle, could no longer brake to rest
        at its acceleration limit before its position limit (None: every one can)."""
        v = v_next[: self.n]
        q = self.q + v * self.dt
        stop = q + v * np.abs(v) / (2.0 * self.a_max[: self.n])
        bad = np.flatnonzero((stop > self.upper) | (stop < self.lower))
        return int(bad[0]) if bad.size else None

    def step(self, commands: list[bytes]) -> StateMsg:
        """One robot cycle: the commands received since the last, the firmware, the drives."""
        for data in commands:
            self.receive(data)
        braking = self.stale_stop or self.protective_stop or self.stopping
        if not braking and self.last_applied is not None and self.t - self.last_applied >= self.stale_timeout - 1e-9:
            self.stale_stop, self.ended, self.stream = True, self.stream, None
            say(f"stale stop at t = {self.t:.3f} s: no command for {self.stale_timeout * 1e3:.0f} ms")
            braking = True
        v = self.ramp(np.zeros_like(self.v) if braking else self.target)
        if not braking and (joint := self.cannot_brake(v)) is not None:   # the held command, a cycle on
            self.protect(self.stream, "cannot_stop_before_limit", self.limit_reason(joint), refused=False)
            v = self.ramp(np.zeros_like(self.v))
        self.v = v
        self.q += v[: self.n] * self.dt
        self.q_base += self.base.P(float(self.q_base[2])) @ v[self.n:] * self.dt   # odometry
        self.seq += 1
        self.t = self.seq * self.dt                             # the robot's clock: its cycles
        return StateMsg(
            robot=self.id, seq=self.seq, stamp=time.time(), t=self.t, q_base=self.q_base.tolist(),
            q_arm=self.q.tolist(), v_arm=v[: self.n].tolist(), wheel_speeds=v[self.n:].tolist(),
            tau=[0.0] * self.n, gripper_width=math.nan, stale_stop=self.stale_stop, cmd_seq=self.cmd_seq,
            instance=self.instance, lease=self.holder, protective_stop=self.protective_stop,
            protective_stops=self.protective_stops, protective_reason=self.reason,
            protective_code=self.code, refused=dict(self.refused))


class Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:          # bad arguments: one line, exit 2
        print(f"{self.prog}: error: {message}", file=sys.stderr)
        sys.exit(2)


def parse(argv: list[str] | None) -> argparse.Namespace:
    p = Parser(description="a minimal kinematic robot driver (docs/drivers.md)")
    p.add_argument("--robot-config", type=Path, default=None, metavar="FILE",
                   help="robot file (default: configs/robots/gen3_mecanum.toml)")
    p.add_argument("--service-config", type=Path, default=None, metavar="TOML",
                   help="service config (default: configs/service.toml)")
    p.add_argument("--robot", default=None, help="robot id (default: the robot file's name)")
    p.add_argument("--prefix", default=None, help="key prefix (default: the service config's)")
    p.add_argument("--sim-endpoint", default=None, metavar="EP",
                   help="where the driver listens, as the sim does (default: the service config's)")
    p.add_argument("--daemon-endpoint", default=None, metavar="EP",
                   help="accepted with the other service flags; unused: the daemon connects to the driver")
    p.add_argument("--zenoh-config", type=Path, default=None, metavar="JSON5",
                   help="base Zenoh session config (default: the service config's)")
    p.add_argument("--rate", type=float, default=1000.0, metavar="HZ", help="cycle rate (default 1000)")
    p.add_argument("--stale-timeout", type=float, default=None, metavar="S",
                   help="command timeout (default: watchdog.command_hold - watchdog.state_age_max)")
    p.add_argument("--rt-priority", type=int, default=50, metavar="N",
                   help="SCHED_FIFO priority of the cycle, 0 = normal scheduling (default 50)")
    args = p.parse_args(argv)
    if not 0 < args.rate <= 10_000:
        p.error(f"--rate: must be in (0, 10000] Hz, got {args.rate:g}")
    if args.stale_timeout is not None and not 0 < args.stale_timeout <= 1:
        p.error(f"--stale-timeout: must be in (0, 1] s, got {args.stale_timeout:g}")
    if not 0 <= args.rt_priority <= 99:
        p.error(f"--rt-priority: must be in [0, 99], got {args.rt_priority}")
    return args


def open_session(config: Path | None, endpoint: str) -> zenoh.Session:
    """Peer mode, no scouting (the service's base config), listening on the sim's endpoint."""
    bare = '{mode: "peer", scouting: {multicast: {enabled: false}, gossip: {enabled: false}}}'
    conf = zenoh.Config.from_file(str(config)) if config else zenoh.Config.from_json5(bare)
    conf.insert_json5("listen/endpoints", json.dumps([endpoint]))
    return zenoh.open(conf)


def main(argv: list[str] | None = None) -> int:
    args = parse(argv)
    try:
        svc = load_service_config(args.service_config)
        robot = w.load_robot_config(args.robot_config)
        robot_id = resolve_robot_id(svc, args.robot, args.robot_config)
    except w.ConfigError as e:
        print(f"driver.py: error: {e}", file=sys.stderr)
        return 2
    prefix = args.prefix or svc.prefix
    stale = args.stale_timeout or svc.watchdog.command_hold - svc.watchdog.state_age_max
    bot = Robot(robot, robot_id, svc.validation, args.rate, stale)
    keys = f"{prefix}/{robot_id}"
    stop: list[int] = []
    signal.signal(signal.SIGINT, lambda s, f: stop.append(s))
    signal.signal(signal.SIGTERM, lambda s, f: stop.append(s))
    try:
        session = open_session(args.zenoh_config or svc.zenoh.config, args.sim_endpoint or svc.zenoh.sim_endpoint)
    except zenoh.ZError as e:
        print(f"driver.py: error: cannot open the Zenoh session: {e}", file=sys.stderr)
        return 1
    with session:
        state_pub = session.declare_publisher(f"{keys}/state", express=True, priority=zenoh.Priority.REAL_TIME,
                                              congestion_control=zenoh.CongestionControl.DROP)
        cmds = session.declare_subscriber(f"{keys}/cmd", zenoh.handlers.RingChannel(1024))
        leases = session.liveliness().declare_subscriber(f"{keys}/lease/*", zenoh.handlers.FifoChannel(64),
                                                         history=True)
        grips = session.declare_subscriber(f"{keys}/gripper", zenoh.handlers.FifoChannel(16))
        token = session.liveliness().declare_token(f"{keys}/alive/robot")
        if args.rt_priority:
            try:
                os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(args.rt_priority))
            except (PermissionError, OSError) as e:
                say(f"no SCHED_FIFO {args.rt_priority} ({e}): normal scheduling")
        say(f"robot {keys}, instance {bot.instance}, {args.rate:g} Hz, command timeout {stale * 1e3:g} ms")
        deadline = time.monotonic()
        while not (bot.stopping and bot.at_rest()):
            if stop and not bot.stopping:
                bot.stopping = True                     # brake to rest, then exit 0
            now = time.monotonic()
            if now < deadline:
                time.sleep(deadline - now)
                continue
            while (ev := leases.try_recv()) is not None:
                bot.lease_event(str(ev.key_expr).rsplit("/", 1)[-1], ev.kind == zenoh.SampleKind.PUT)
            while grips.try_recv() is not None:         # no gripper: counted, not applied
                bot.refused["gripper"] = bot.refused.get("gripper", 0) + 1
            received = []
            while (s := cmds.try_recv()) is not None:
                received.append(s.payload.to_bytes())
            state_pub.put(encode(bot.step(received)))
            deadline += bot.dt                          # late: run every step that was due
        token.undeclare()
    say(f"stopped at t = {bot.t:.3f} s: {bot.protective_stops} protective stops"
        f"{' (last: ' + bot.reason + ')' if bot.reason else ''}, refused {bot.refused}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
