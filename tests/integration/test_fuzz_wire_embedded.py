"""A short wire fuzzing run against the embedded process (``wmm-qp sim --embedded``).

The same fuzz as ``tests/integration/test_fuzz_wire.py``'s against a split sim and daemon, on the keys the
embedded process listens on (``fuzz.EMBEDDED_KEYS``: setpoint, mode and ``info`` queries; its
state and command never cross the wire). Asserts behaviour only: the process stays up and exits
cleanly, everything hostile is rejected and counted, the cycle keeps ticking, the referee sees no
violation.
"""

from __future__ import annotations

from typing import Any

import pytest
from wmm_qp_service.client import Client
from wmm_qp_tools.fuzz import EMBEDDED_KEYS, fuzz_wire

pytestmark = pytest.mark.integration


def test_wire_fuzz_short_embedded(service_stack: Any) -> None:
    stack = service_stack(500.0, embedded=True)
    with Client(stack.svc, name="fuzzer") as c:
        c.wait_ready(90.0, 30.0, exited=stack.exited)
        c.set_mode("track")
        rep = fuzz_wire(c, 2000, rate_hz=3000.0, seed=11, keys=EMBEDDED_KEYS,
                        alive=lambda: sum(p.poll() is None for p in stack.procs.values()))
        print("\nwire fuzz (short, embedded):", rep.as_dict())
        assert rep.sent == 2000 and set(rep.sent_by_key) == {"setpoint", "mode", "info"}
        assert rep.crashes == 0 and rep.daemon_answering
        assert sum(rep.rejected.values()) > 300  # counted under their reasons ...
        assert {"decode", "schema", "size"} <= set(rep.rejected)
        assert rep.ticks > 0  # ... while the cycle keeps running
        assert sum(rep.violations.values()) == 0, rep.violations
        info = c.info()
        assert info is not None and info.status.state_ok and info.status.loop.trigger == "embedded"
    codes = stack.stop()
    assert codes == {"embedded": 0}
