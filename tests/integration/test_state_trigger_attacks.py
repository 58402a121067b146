"""The state-triggered daemon (``--trigger state``) under the attacks the fixed-rate one is tested
against, over the wire with the real processes: a state flood at 10 kHz (replays, another
instance's states, garbage), the wire fuzzer, and a frozen sim. The outcomes asserted are the
fixed-rate trigger's: everything hostile refused and counted, the loop never ticks faster than
its rate (a state flood cannot make commands land within one bound's Δt), a frozen sim is a safe
stop that resumes, and the sim's referee counts nothing."""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path

import msgspec
import numpy as np
import pytest
from wmm_qp_service.client import Client
from wmm_qp_service.processes import Stack, isolated_config
from wmm_qp_service.protocol import encode
from wmm_qp_tools.faults import Probe, sigstop
from wmm_qp_tools.fuzz import fuzz_wire

pytestmark = [pytest.mark.integration, pytest.mark.slow]

RATE = 1000.0  # the state trigger's rate is the robot's cycle: the sim's 1 kHz (configs/sim.toml)


@pytest.fixture(scope="module")
def probe(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Probe]:
    log_dir: Path = tmp_path_factory.mktemp("state_trigger")
    stack = Stack(isolated_config(), rate_hz=RATE, log_dir=log_dir, extra_daemon_args=["--trigger", "state"])
    p = None
    try:
        stack.start()
        p = Probe(stack)
        yield p
    finally:
        if p is not None:
            p.close()
        stack.stop()


def _flood(c: Client, payloads: list[bytes], hz: float, seconds: float) -> int:
    """Publish the payloads round-robin on the state key at ``hz`` for ``seconds``; returns the count."""
    n, period = 0, 1.0 / hz
    t0 = time.perf_counter()
    while (now := time.perf_counter()) - t0 < seconds:
        if now - t0 >= n * period:
            c.put_raw("state", payloads[n % len(payloads)])
            n += 1
    return n


def test_a_state_flood_at_ten_kilohertz_is_refused_and_cannot_speed_up_the_loop(probe: Probe) -> None:
    info = probe.ready()
    assert info.status.loop.trigger == "state"
    c = probe.client
    c.set_mode("track")
    probe.move(np.array(info.status.x), 0.5)
    real = c.latest_state() or c.wait_state(2.0)
    assert real is not None
    replay = encode(real)  # an old seq by the time it lands: refused
    twin = encode(msgspec.structs.replace(real, instance="f" * 16, seq=1))  # another robot on the key
    garbage = b"\x93\x01\x02\x03" * 8
    before = c.info()
    assert before is not None
    t0 = time.monotonic()
    sent = _flood(c, [replay, twin, garbage], 10_000.0, 3.0)
    elapsed = time.monotonic() - t0
    after = probe.until(lambda: (i := c.info()) is not None and i)
    rej = after.status.rejected
    assert sent > 3_000  # the flood happened (> 1 kHz whatever the machine)
    assert rej.get("state_seq", 0) > before.status.rejected.get("state_seq", 0)
    assert rej.get("instance", 0) > before.status.rejected.get("instance", 0)
    assert after.status.faults.get("second_state_source", 0) >= 1
    assert sum(rej.values()) - sum(before.status.rejected.values()) > 500
    # the loop's state ticks come at most at the robot's rate, however many states arrive (the
    # daemon's own stamps of the two statuses bracket the ticks counted between them). Watchdog
    # ticks (no state for 1.5 periods) are left out: a loaded host's late states add one each, a
    # timing matter, not the flood's (a tick per flooded state would be ten times the rate)
    ticks = after.status.loop.ticks - before.status.loop.ticks
    watchdog = after.status.loop.watchdog_ticks - before.status.loop.watchdog_ticks
    span = after.status.stamp - before.status.stamp
    assert span >= elapsed
    assert ticks - watchdog <= RATE * span * 1.02 + 5, (ticks, watchdog, span)
    # and it comes back: the twin's states stopped, the latched sim is followed again
    ok = probe.until(lambda: (i := c.info()) is not None and i.status.robot_instance == real.instance
                     and i.status.state_ok and i, timeout=30.0)
    assert ok.status.robot_instance == real.instance
    violations = probe.violations()
    assert sum(violations.values()) == 0, violations


def test_the_wire_fuzzer_against_the_state_trigger(probe: Probe) -> None:
    c = probe.client
    probe.ready()
    c.set_mode("track")
    rep = fuzz_wire(c, 3000, rate_hz=3000.0, seed=12,
                    alive=lambda: sum(p.poll() is None for p in probe.stack.procs.values()))
    assert rep.crashes == 0 and rep.daemon_answering
    assert {"decode", "schema", "size"} <= set(rep.rejected)
    assert rep.ticks > 0
    assert sum(rep.violations.values()) == 0, rep.violations


def test_a_frozen_sim_under_the_state_trigger_is_a_safe_stop_that_resumes(probe: Probe) -> None:
    r = sigstop(probe, "sim", hold_s=1.5)
    assert "safe_s" in r and "liveliness_s" in r and "resume_s" in r
    assert sum(r["violations"].values()) == 0
