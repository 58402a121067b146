"""``wmm-qp record FILE.mcap``: record what goes over a robot's keys, as a client.

Anyone on the robot's Zenoh network can record it, without touching the daemon: the robot's
states and the daemon's commands become the ROS 2 channels of a recording
(``/arm/joint_states``, ``/base/wheel_states``, ``/arm/joint_commands``, ``/base/wheel_commands``,
``/odom``, ``/tf``, ``/ee/pose``; ``/ee/target`` from the telemetry's target), and the status,
telemetry, setpoints, mode requests and obstacle sets its JSON channels (docs/recording.md). It
holds no controller inputs: ``wmm-qp replay`` needs the daemon's own recording
(``wmm-qp serve --record``); ``wmm-qp plot`` draws both.
"""

from __future__ import annotations

import argparse
import math
import sys
import threading
import time
import uuid
from collections import deque
from pathlib import Path
from typing import Any

HELP = "record a robot's keys to MCAP (ROS 2 message types) as a client"
KEYS = ("state", "cmd", "status", "telemetry", "setpoint", "mode", "obstacles")
RING = 8192  # messages of one key held until written (the oldest dropped beyond)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from wmm_qp_service.cli_common import add_service_arguments
    from wmm_qp_service.commands.common import add_robot_argument

    parser.add_argument("file", metavar="FILE.mcap", help="the recording to write")
    add_service_arguments(parser)
    add_robot_argument(parser)
    parser.add_argument("--duration", type=float, metavar="S",
                        help="stop after this many seconds (default: at Ctrl-C)")


def run(args: argparse.Namespace) -> int:
    import msgspec
    import numpy as np
    from wmm_qp_service.cli_common import stop_on_signals
    from wmm_qp_service.commands.common import robot_service_config
    from wmm_qp_service.keys import Keys
    from wmm_qp_service.protocol import (
        CommandMsg,
        ModeMsg,
        ObstaclesMsg,
        SetpointMsg,
        StateMsg,
        StatusMsg,
        TelemetryMsg,
        decoder,
    )
    from wmm_qp_service.recording import require
    from wmm_qp_service.recording.layout import Layout
    from wmm_qp_service.recording.writer import McapSink
    from wmm_qp_service.transport import ROLE_CLIENT, open_session

    from wmm_qp.exceptions import WmmQpError

    require()
    if args.duration is not None and not args.duration > 0:
        raise WmmQpError(f"--duration must be > 0, got {args.duration:g}")
    robot, svc = robot_service_config(args)
    import wmm_qp as w

    model = w.WmmModel(robot)
    meta = {"format": "wmm-qp recording 1", "recording_id": uuid.uuid4().hex, "host": "record",
            "robot": svc.robot, "robot_name": robot.name, "robot_file": str(robot.path or ""),
            "arm_joints": msgspec.json.encode(list(robot.arm.joints)).decode(),
            "wheels": msgspec.json.encode(list(model.base.wheel_names)).decode(),
            "rate_hz": repr(svc.loop.rate_hz),
            "started": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
    path = Path(args.file)
    try:
        sink = McapSink(path, meta, Layout(robot.n_arm, robot.n_wheels), None, None,
                        extra_json={"/wmm/setpoint": {}})
        sink.open(0)
    except OSError as e:
        raise WmmQpError(f"cannot write {path}: {e.strerror or e}") from None
    decoders: dict[str, Any] = {"state": decoder(StateMsg), "cmd": decoder(CommandMsg), "status": decoder(StatusMsg),
                                "telemetry": decoder(TelemetryMsg), "setpoint": decoder(SetpointMsg),
                                "mode": decoder(ModeMsg), "obstacles": decoder(ObstaclesMsg)}
    keys = Keys.of(svc.prefix, svc.robot)
    stop = stop_on_signals()
    if args.duration is not None:
        timer = threading.Timer(args.duration, stop.set)
        timer.daemon = True  # a stop before it fires must not wait for it
        timer.start()
    counts = dict.fromkeys(KEYS, 0)
    bad = 0
    last_seq, lost = {"state": -1, "cmd": -1}, {"state": 0, "cmd": 0}
    mode = None
    nan4 = np.full(4, math.nan)
    with open_session(svc, ROLE_CLIENT) as session:
        # each message stamped when it arrives (zenoh's thread), not when this loop writes it: a
        # recorder that falls behind (a busy host) wrote seconds of statuses at one instant, and the
        # timeline showed a mode for a few milliseconds; rings of 8192 (the oldest dropped when it
        # falls further behind): a slow recorder never holds up a publisher, and the lost states and
        # commands show as gaps in their seq
        rings: dict[str, deque[tuple[int, bytes]]] = {k: deque(maxlen=RING) for k in KEYS}

        def arrival(ring: deque[tuple[int, bytes]]) -> Any:
            return lambda s: ring.append((time.time_ns(), s.payload.to_bytes()))

        subs = {k: session.declare_subscriber(getattr(keys, k), arrival(rings[k])) for k in KEYS}
        print(f"wmm-qp record: recording {keys.root}/{{{','.join(KEYS)}}} to {path}"
              + (f" for {args.duration:g} s" if args.duration else " (Ctrl-C stops)"), file=sys.stderr, flush=True)
        def handle(k: str, ns: int, payload: bytes) -> None:
            nonlocal bad, mode
            try:
                m = decoders[k].decode(payload)
            except msgspec.DecodeError:
                bad += 1
                return
            counts[k] += 1
            if k in last_seq:
                if 0 <= last_seq[k] < m.seq - 1:
                    lost[k] += m.seq - 1 - last_seq[k]
                last_seq[k] = m.seq
            if k == "state":
                sink.measured(ns, np.array(m.q_base), np.array(m.q_arm), np.array(m.v_arm), np.array(m.wheel_speeds))
            elif k == "cmd":
                sink.commanded(ns, np.array(m.arm_rates), np.array(m.wheel_speeds))
            elif k == "telemetry":
                sink.json("/wmm/telemetry", ns, msgspec.to_builtins(m))
                if all(math.isfinite(v) for v in m.x_d):
                    sink.target(ns, np.array(m.x_d), nan4)
            elif k == "status":
                if m.mode != mode:
                    sink.json("/wmm/mode", ns, {"tick": m.loop.ticks, "mode": m.mode, "previous": mode})
                    mode = m.mode
                sink.json("/wmm/status", ns, {"tick": m.loop.ticks, "status": msgspec.to_builtins(m)})
            elif k == "setpoint":
                sink.json("/wmm/setpoint", ns, msgspec.to_builtins(m))
            else:
                sink.json("/wmm/events", ns, {"tick": -1, "kind": f"{k}_message", "data": msgspec.to_builtins(m)})

        def drain(limit: int) -> bool:
            """At most ``limit`` messages of each key; whether any came."""
            got = False
            for k, ring in rings.items():
                for _ in range(min(limit, len(ring))):
                    got = True
                    handle(k, *ring.popleft())
            return got

        last_say = time.monotonic()
        try:
            while not stop.is_set():
                if not drain(256):  # then the stop flag and the progress line
                    sink.stream.flush()
                    time.sleep(0.005)
                if time.monotonic() - last_say > 5.0:
                    last_say = time.monotonic()
                    print(f"wmm-qp record: {counts['state']} states, {counts['cmd']} commands so far",
                          file=sys.stderr, flush=True)
            drain(8192)  # what had arrived when it was told to stop
        finally:
            for sub in subs.values():
                sub.undeclare()
            sink.close_file({"messages": str(sum(counts.values())), "undecodable": str(bad),
                             "states_lost": str(lost["state"]), "commands_lost": str(lost["cmd"]), "ended": "stopped"})
    print(f"wmm-qp record: {path}: " + ", ".join(f"{v} {k}" for k, v in counts.items())
          + f"; {lost['state']} states and {lost['cmd']} commands lost (seq gaps)"
          + (f"; {bad} undecodable" if bad else ""), file=sys.stderr, flush=True)
    if not counts["state"] and not counts["status"]:
        print(f"wmm-qp record: error: nothing arrived on {keys.root} (is a robot running with this prefix and id?)",
              file=sys.stderr)
        return 1
    return 0
