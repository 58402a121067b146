"""Wire fuzzing: random and mutated payloads for every key the daemon (and the sim) listens on.

:class:`Mutator` turns a valid message of each key into hostile payloads — garbage bytes,
truncations, bit flips, type swaps, NaN/inf, huge numbers and huge vectors, wrong vector
lengths, missing and unknown fields, another robot's id or protocol version, another key's
message — plus a few valid ones. :func:`fuzz_wire` throws them at a running stack over Zenoh
(``benchmarks/reliability/fuzz.py``, ``tests/integration/test_fuzz_wire.py``; at the embedded process with
:data:`EMBEDDED_KEYS`, ``tests/integration/test_fuzz_wire_embedded.py``); the in-process tests feed them
straight to the validators and the :class:`~.daemon.ControlCore`.
"""

from __future__ import annotations

import contextlib
import functools
import math
import time
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import msgspec
import numpy as np
from wmm_qp_service.protocol import CommandMsg, ModeMsg, SetpointMsg, StateMsg

import wmm_qp as w

KEYS = ("state", "setpoint", "mode", "cmd", "info")
"""The keys fuzzed: the daemon's subscriptions (state, setpoint, mode), its ``info``
queryable (query payloads and parameters), and the sim's command subscription (cmd)."""

EMBEDDED_KEYS = ("setpoint", "mode", "info")
"""The keys of :data:`KEYS` an embedded process (``wmm-qp sim --embedded``) listens on: the
core's setpoint and mode subscriptions and its ``info`` queryable. Its state and command never
cross the wire (nothing subscribes ``state`` or ``cmd`` there)."""

KINDS = ("garbage", "truncated", "bitflip", "type_swap", "non_finite", "huge", "huge_vector",
         "wrong_length", "missing_field", "extra_field", "wrong_robot", "wrong_version",
         "other_message", "nested", "valid")
"""Mutation kinds, drawn uniformly (``valid``: a correct message with perturbed values)."""

_ENC = msgspec.msgpack.Encoder()


def templates(robot: str, config: w.RobotConfig | None = None) -> dict[str, dict[str, Any]]:
    """One valid message per key, as plain msgpack-able data.

    Args:
        robot: the robot id they carry.
        config: the robot description (sizes, start configuration); None: the default robot.
    """
    config = config if config is not None else _default_robot()
    model = w.WmmModel(config)
    q = config.arm.start.tolist()
    na, nw = config.n_arm, config.n_wheels
    x0 = model.ee_position(np.zeros(3), config.arm.start).tolist()
    msgs: dict[str, msgspec.Struct] = {
        "state": StateMsg(robot=robot, seq=1, stamp=time.time(), t=1.0, q_base=[0.0] * 3, q_arm=q,
                          v_arm=[0.0] * na, wheel_speeds=[0.0] * nw, tau=[0.0] * na,
                          gripper_width=0.04, instance="fuzz-sim"),
        "setpoint": SetpointMsg(robot=robot, seq=1, stamp=time.time(), x=[x0[0], x0[1] + 0.01, x0[2]],
                                xd=[0.0, 0.01, 0.0], source="fuzz", q=[0.0, 0.0, 0.0, 1.0],
                                w=[0.0, 0.0, 0.1]),
        "mode": ModeMsg(robot=robot, seq=1, stamp=time.time(), mode="hold", direction=[1.0, 0.0, 0.0]),
        "cmd": CommandMsg(robot=robot, seq=1, stamp=time.time(), wheel_speeds=[0.0] * nw,
                          arm_rates=[0.0] * na, lease="fuzz", instance="fuzz-sim", period=0.002, stream=1),
    }
    out = {k: msgspec.to_builtins(m) for k, m in msgs.items()}
    out["info"] = {"query": "status"}
    return out


@functools.cache
def _default_robot() -> w.RobotConfig:
    return w.load_robot_config()


class Mutator:
    """Seeded generator of hostile payloads.

    Args:
        robot: the robot id the valid templates carry.
        seed: random seed.
        config: the robot description of the templates (None: the default robot).
    """

    def __init__(self, robot: str, seed: int = 0, config: w.RobotConfig | None = None) -> None:
        self.rng = np.random.default_rng(seed)
        self.robot = robot
        self.templates = templates(robot, config)

    def _choice(self, seq: Any) -> Any:
        return seq[int(self.rng.integers(len(seq)))]

    def _odd_value(self) -> Any:
        r = self.rng
        return self._choice([
            None, True, "x" * int(r.integers(0, 64)), int(r.integers(-(2**63), 2**63 - 1)), 2**64 - 1,
            -(2**63), b"\x00\xff", [], {}, {"a": 1}, [None], ["1.0"], float(r.normal()), math.nan,
            [[1.0, 2.0]], "hold", -1,
        ])

    def _floatish(self, msg: dict[str, Any]) -> list[str]:
        return [k for k, v in msg.items()
                if isinstance(v, float) or (isinstance(v, list) and v and isinstance(v[0], float))]

    def _set_number(self, msg: dict[str, Any], value: float) -> None:
        keys = self._floatish(msg)
        if not keys:
            msg["stamp"] = value
            return
        k = self._choice(keys)
        if isinstance(msg[k], list):
            vec = list(msg[k])
            vec[int(self.rng.integers(len(vec)))] = value
            msg[k] = vec
        else:
            msg[k] = value

    def payload(self, key: str, kind: str | None = None) -> tuple[bytes, str]:
        """A payload for ``key`` and the mutation kind used."""
        r = self.rng
        kind = kind or self._choice(KINDS)
        msg = dict(self.templates[key])
        msg["seq"] = int(r.integers(0, 2**31))
        msg["stamp"] = time.time()
        if kind == "garbage":
            return r.bytes(int(r.integers(0, 512))), kind
        if kind == "truncated":
            b = _ENC.encode(msg)
            return b[: int(r.integers(0, len(b)))], kind
        if kind == "bitflip":
            flipped = bytearray(_ENC.encode(msg))
            for _ in range(int(r.integers(1, 9))):
                flipped[int(r.integers(len(flipped)))] = int(r.integers(256))
            return bytes(flipped), kind
        if kind == "type_swap":
            msg[self._choice(list(msg))] = self._odd_value()
        elif kind == "non_finite":
            self._set_number(msg, self._choice([math.nan, math.inf, -math.inf]))
        elif kind == "huge":
            self._set_number(msg, float(self._choice([1e308, -1e308, 1e30, -3e12, 5e5])))
        elif kind == "huge_vector":
            keys = [k for k, v in msg.items() if isinstance(v, list)] or ["x"]
            msg[self._choice(keys)] = [1.0] * int(r.integers(1000, 20_000))
        elif kind == "wrong_length":
            keys = [k for k, v in msg.items() if isinstance(v, list)] or ["x"]
            msg[self._choice(keys)] = [0.5] * int(self._choice([0, 1, 2, 4, 5, 6, 8, 11]))
        elif kind == "missing_field":
            del msg[self._choice(list(msg))]
        elif kind == "extra_field":
            msg[self._choice(["extra", "x2", "cmd", "mode_", "__proto__"])] = self._odd_value()
        elif kind == "wrong_robot":
            msg["robot"] = self._choice(["", "other", self.robot + "x", self.robot.upper(), "wmm/../x"])
        elif kind == "wrong_version":
            msg["v"] = self._choice([0, 2, -1, 255, 2**40])
        elif kind == "other_message":
            msg = dict(self.templates[self._choice([k for k in KEYS if k not in (key, "info")])])
        elif kind == "nested":
            depth = int(r.integers(10, 200))
            v: Any = 1.0
            for _ in range(depth):
                v = [v]
            msg[self._choice(list(msg))] = v
        elif kind == "valid":
            self._perturb_valid(key, msg)
        return _ENC.encode(msg), kind

    def _perturb_valid(self, key: str, msg: dict[str, Any]) -> None:
        r = self.rng
        if key == "setpoint":
            msg["x"] = (np.array(msg["x"]) + r.normal(0, 0.01, 3)).tolist()
            msg["xd"] = None if r.random() < 0.5 else r.normal(0, 0.05, 3).tolist()
            msg["q"] = None if r.random() < 0.5 else r.normal(0, 1, 4).tolist()
            msg["w"] = None if r.random() < 0.5 else r.normal(0, 0.2, 3).tolist()
        elif key == "mode":
            msg["mode"] = self._choice(["hold", "track", "dm_cartesian", "dm_nullspace"])
            msg["direction"] = None if r.random() < 0.5 else r.normal(0, 1, 3).tolist()


@dataclass
class FuzzReport:
    """What a wire fuzzing run did.

    Attributes:
        sent: messages sent (puts and queries).
        sent_by_key, sent_by_kind: the same by key and by mutation kind.
        duration_s: [s] wall time of the flood.
        rejected: the daemon's rejections during the flood, by reason.
        accepted: the daemon's accepted messages during the flood, by key.
        deadline_misses, ticks: the daemon loop's during the flood.
        tick_max_us: [µs] the daemon's largest tick work time so far.
        measured_hz: [Hz] the daemon's loop rate at the end.
        crashes: processes that died during the flood (must be 0).
        daemon_answering: the daemon answered its ``info`` query after the flood.
        violations: the sim's referee counts at the end.
    """

    sent: int = 0
    sent_by_key: Counter[str] = field(default_factory=Counter)
    sent_by_kind: Counter[str] = field(default_factory=Counter)
    duration_s: float = 0.0
    rejected: dict[str, int] = field(default_factory=dict)
    accepted: dict[str, int] = field(default_factory=dict)
    deadline_misses: int = 0
    ticks: int = 0
    tick_max_us: float = 0.0
    measured_hz: float = 0.0
    crashes: int = 0
    daemon_answering: bool = False
    violations: dict[str, int] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        """Plain data (JSON)."""
        return {"sent": self.sent, "sent_by_key": dict(self.sent_by_key),
                "sent_by_kind": dict(self.sent_by_kind), "duration_s": self.duration_s,
                "rejected": self.rejected, "accepted": self.accepted,
                "deadline_misses": self.deadline_misses, "ticks": self.ticks,
                "tick_max_us": self.tick_max_us, "measured_hz": self.measured_hz,
                "crashes": self.crashes, "daemon_answering": self.daemon_answering,
                "violations": self.violations}


def _delta(a: dict[str, int], b: dict[str, int]) -> dict[str, int]:
    return {k: b.get(k, 0) - a.get(k, 0) for k in sorted(set(a) | set(b)) if b.get(k, 0) != a.get(k, 0)}


def fuzz_wire(client: Any, n: int, rate_hz: float = 4000.0, seed: int = 0,
              alive: Callable[[], int] | None = None, query_share: float = 0.01,
              progress: Callable[[int], None] | None = None,
              robot: w.RobotConfig | None = None, keys: Sequence[str] = KEYS) -> FuzzReport:
    """Throw ``n`` hostile payloads at a running stack through ``client`` (a :class:`~.client.Client`).

    Keys are drawn uniformly from ``keys`` (``info``: a query with a hostile payload and
    parameters, drawn with probability ``query_share`` instead, if ``keys`` holds it). Paced at
    ``rate_hz`` so the daemon's depth-1 ring channels see most messages instead of overwriting
    them.

    Args:
        client: an open client of the stack.
        n: messages to send.
        rate_hz: [1/s] send rate.
        seed: mutation seed.
        alive: returns how many of the stack's processes are running (None: not checked).
        query_share: share of the messages that are ``info`` queries.
        progress: called every 10,000 messages with the count sent.
        robot: the stack's robot description (the valid templates' sizes); None: the default.
        keys: the keys fuzzed, of :data:`KEYS`, one besides ``info`` at least (an embedded
            process: :data:`EMBEDDED_KEYS`).
    """
    puts = [k for k in keys if k != "info"]
    queries = query_share if "info" in keys else 0.0
    mut = Mutator(client.svc.robot, seed, robot)
    rep = FuzzReport()
    before = client.wait_for_daemon(10.0)
    n_alive = alive() if alive is not None else 0
    session = client.session
    period = 1.0 / rate_hz
    t0 = time.perf_counter()
    for i in range(n):
        if mut.rng.random() < queries:
            payload, kind = mut.payload("info")
            params = mut.rng.bytes(int(mut.rng.integers(0, 40))).decode("latin-1")
            # a hostile selector may be refused by zenoh itself: that is not a crash
            with contextlib.suppress(Exception):
                session.get(f"{client.keys.info}?{params}", payload=payload, timeout=0.001)
            key = "info"
        else:
            key = puts[int(mut.rng.integers(len(puts)))]
            payload, kind = mut.payload(key)
            client.put_raw(key, payload)
        rep.sent += 1
        rep.sent_by_key[key] += 1
        rep.sent_by_kind[kind] += 1
        if progress is not None and (i + 1) % 10_000 == 0:
            progress(i + 1)
        delay = t0 + (i + 1) * period - time.perf_counter()
        if delay > 0:
            time.sleep(delay)
    rep.duration_s = time.perf_counter() - t0
    time.sleep(0.5)
    after = client.wait_for_daemon(10.0)
    rep.daemon_answering = after is not None
    if alive is not None:
        rep.crashes = n_alive - alive()
    if before is not None and after is not None:
        b, a = before.status, after.status
        rep.rejected = _delta(b.rejected, a.rejected)
        rep.accepted = _delta(b.accepted, a.accepted)
        rep.deadline_misses = a.loop.deadline_misses - b.loop.deadline_misses
        rep.ticks = a.loop.ticks - b.loop.ticks
        rep.tick_max_us = a.loop.tick_max_us
        rep.measured_hz = a.loop.measured_hz
    tr = client.wait_truth(5.0)
    rep.violations = dict(tr.violations) if tr is not None else {}
    return rep
