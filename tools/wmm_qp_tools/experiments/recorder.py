"""What a real-time run records from the client's side: every state the sim publishes, its
evaluation data (``sim/truth``) and every tick's telemetry of the daemon."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import msgspec
import numpy as np
import zenoh
from wmm_qp_service.client import Client
from wmm_qp_service.protocol import StateMsg, TelemetryMsg, TruthMsg


@dataclass
class Recorder:
    """Collects the raw states and the telemetry from a client's session.

    Attributes:
        client: an open client with ``telemetry=True``.
        states: raw StateMsg payloads, in arrival order (decoded at the end).
        truths: raw TruthMsg payloads (``sim/truth``), in arrival order.
        telemetry: decoded telemetry messages, in arrival order.
    """

    client: Client
    states: list[bytes] = field(default_factory=list)
    truths: list[bytes] = field(default_factory=list)
    telemetry: list[TelemetryMsg] = field(default_factory=list)
    not_truths: int = 0  # messages on the truth key that were no truth (skipped, counted)
    _sub: Any = None
    _sub_truth: Any = None

    def open(self) -> Recorder:
        """Subscribe to every state and truth (FIFO: none dropped on the client's side)."""
        s = self.client.session
        assert s is not None
        self._sub = s.declare_subscriber(self.client.keys.state, zenoh.handlers.FifoChannel(200_000))
        self._sub_truth = s.declare_subscriber(self.client.keys.sim_truth, zenoh.handlers.FifoChannel(200_000))
        return self

    def drain(self) -> None:
        """Move what arrived into the lists (cheap: states stay raw bytes)."""
        while (s := self._sub.try_recv()) is not None:
            self.states.append(s.payload.to_bytes())
        while (s := self._sub_truth.try_recv()) is not None:
            self.truths.append(s.payload.to_bytes())
        self.telemetry.extend(self.client.telemetry())

    def truth_by_seq(self) -> dict[int, TruthMsg]:
        """The recorded truths, decoded, by the seq of their state."""
        dec = msgspec.msgpack.Decoder(TruthMsg)
        out: dict[int, TruthMsg] = {}
        for b in self.truths:
            try:
                t = dec.decode(b)
            except msgspec.ValidationError:  # not a truth (a bench once read a status here): skipped
                self.not_truths += 1
                continue
            out[t.state_seq] = t
        return out

    def last_x(self) -> np.ndarray | None:
        """[m] the model EE position of the newest telemetry (None: none yet)."""
        return np.array(self.telemetry[-1].x) if self.telemetry else None

    def close(self) -> None:
        if self._sub is not None:
            self._sub.undeclare()
            self._sub = None
        if self._sub_truth is not None:
            self._sub_truth.undeclare()
            self._sub_truth = None


def match_states(states: list[StateMsg], tel: list[TelemetryMsg]) -> list[int]:
    """For each telemetry message, the index of the state the daemon used: the telemetry's
    ``state_seq`` identifies it exactly among the recorded states; a predicted tick (``state_seq``
    -1) used the newest state stamped before the tick."""
    by_seq = {s.seq: i for i, s in enumerate(states)}
    stamps = np.array([s.stamp for s in states])
    out = []
    for m in tel:
        i = by_seq.get(m.state_seq) if m.state_seq >= 0 else None
        out.append(i if i is not None else max(0, int(np.searchsorted(stamps, m.stamp, side="right")) - 1))
    return out
