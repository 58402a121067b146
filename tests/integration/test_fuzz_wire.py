"""A short wire fuzzing run against the real daemon and sim (the ≥100k run: benchmarks/reliability/fuzz.py).

Asserts behaviour only: nothing crashes, everything hostile is rejected and counted, the
loop keeps ticking, the sim's referee sees no violation. Timing figures are printed.
"""

from __future__ import annotations

import time
from typing import Any

import pytest
from wmm_qp_service.client import Client
from wmm_qp_tools.fuzz import fuzz_wire

pytestmark = pytest.mark.integration


def test_wire_fuzz_short(service_stack: Any) -> None:
    stack = service_stack(500.0)
    with Client(stack.svc, name="fuzzer") as c:
        assert c.wait_for_daemon(90.0) is not None
        end = time.monotonic() + 30.0
        while time.monotonic() < end and not ((i := c.info()) and i.status.state_ok):
            time.sleep(0.1)
        c.set_mode("track")
        rep = fuzz_wire(c, 3000, rate_hz=3000.0, seed=11,
                        alive=lambda: sum(p.poll() is None for p in stack.procs.values()))
        print("\nwire fuzz (short):", rep.as_dict())
        assert rep.sent == 3000 and set(rep.sent_by_key) == {"state", "setpoint", "mode", "cmd", "info"}
        assert rep.crashes == 0 and rep.daemon_answering
        assert sum(rep.rejected.values()) > 300  # counted under their reasons ...
        assert {"decode", "schema", "size"} <= set(rep.rejected)
        assert rep.ticks > 0  # ... while the loop keeps running
        assert sum(rep.violations.values()) == 0, rep.violations
        info = c.info()
        assert info is not None and info.status.state_ok
    codes = stack.stop()
    assert codes == {"sim": 0, "daemon": 0}
