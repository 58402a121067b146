"""A robot's side of the wire, declared once for every robot node.

The sim (``wmm-qp sim``), the FR3 driver and an embedded process (the robot and the controller in
one) all are robots to the daemon and to clients: the same keys, the same QoS, the same
liveliness token. This module is the one list of them (docs/protocol.md "Key expressions"); a
node declares what it serves through it, so a change of QoS is one line for every robot.

- ``state`` (robot → daemon): express, congestion DROP, priority REAL_TIME — the newest state
  matters, an old one is worse than none, never batched behind other traffic;
- ``sim/truth`` (robot → observers): congestion DROP — evaluation data, off the control path;
- ``cmd`` (daemon → robot): the node's own handler (a callback that stamps arrival, or a FIFO its
  cycle drains) — every command is judged by the referee, in order;
- ``sim/box``, ``gripper`` (clients → robot): a FIFO of 16 — each one acts once;
- ``obstacles`` (clients → robot): a ring of one — the latest set wins;
- ``alive/robot``: the liveliness token, held while the node runs — its disappearance is a safe
  stop at once;
- ``lease/*``: liveliness, watched with history (a FIFO of 64) — the lease holder is the earliest
  token alive.
"""

from __future__ import annotations

from typing import Any

import zenoh

from .keys import Keys


def state_publisher(session: zenoh.Session, keys: Keys) -> zenoh.Publisher:
    """The robot's ``state``: express, dropped under congestion, real-time priority."""
    return session.declare_publisher(keys.state, express=True, congestion_control=zenoh.CongestionControl.DROP,
                                     priority=zenoh.Priority.REAL_TIME)


def truth_publisher(session: zenoh.Session, keys: Keys) -> zenoh.Publisher:
    """The evaluation data on ``sim/truth`` (off the control path), dropped under congestion."""
    return session.declare_publisher(keys.sim_truth, congestion_control=zenoh.CongestionControl.DROP)


def command_subscriber(session: zenoh.Session, keys: Keys, handler: Any) -> zenoh.Subscriber[Any]:
    """The daemon's commands (``cmd``), into the node's own handler."""
    return session.declare_subscriber(keys.cmd, handler)


def input_subscriber(session: zenoh.Session, keys: Keys, kind: str) -> zenoh.Subscriber[Any]:
    """A client's input to the robot: ``box`` and ``gripper`` (each acts once: a FIFO), or
    ``obstacles`` (the latest set wins: a ring of one)."""
    key = {"box": keys.sim_box, "gripper": keys.gripper, "obstacles": keys.obstacles}[kind]
    if kind == "obstacles":
        return session.declare_subscriber(key, zenoh.handlers.RingChannel(1))
    return session.declare_subscriber(key, zenoh.handlers.FifoChannel(16))


def alive_token(session: zenoh.Session, keys: Keys) -> zenoh.LivelinessToken:
    """The robot's liveliness token (``alive/robot``): held while the node runs."""
    return session.liveliness().declare_token(keys.alive("robot"))


def lease_watch(session: zenoh.Session, keys: Keys) -> zenoh.Subscriber[Any]:
    """The lease tokens (``lease/*``), with history: the holder is the earliest one alive."""
    return session.liveliness().declare_subscriber(keys.lease_all, zenoh.handlers.FifoChannel(64), history=True)
