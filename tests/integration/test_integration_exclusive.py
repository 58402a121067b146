"""One robot, one controller, over real Zenoh: the blind drill's attacks, replayed.

Each test starts a real sim and daemon on loopback and attacks them the way the drill did: a
second daemon for the same robot, a second sim under the same id dialling the daemon, a
client publishing ``cmd`` itself, a status query for a mistyped robot id. No timing asserts.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from support.live import TIMEOUT, cli, until
from wmm_qp_service.client import Client
from wmm_qp_service.processes import Stack, _service_args, free_port
from wmm_qp_service.protocol import CommandMsg, StateMsg, TruthMsg, encode

import wmm_qp as w

pytestmark = pytest.mark.integration

def ready(c: Client) -> Any:
    assert c.wait_for_daemon(3 * TIMEOUT) is not None, "daemon did not answer"  # a first start compiles
    return until(lambda: (i := c.info()) is not None and i.status.state_ok
                 and i.status.lease_holder == i.status.lease and i)


def test_a_second_daemon_refuses_to_start_or_waits_for_the_lease(service_stack: Any) -> None:
    stack: Stack = service_stack(500.0)
    with Client(stack.svc, name="test") as c:
        first = ready(c)
        other = stack.svc.with_(zenoh={"daemon_endpoint": f"tcp/127.0.0.1:{free_port()}"})
        r = cli("serve", *_service_args(other), timeout=120.0)
        assert r.returncode == 3, r.stderr
        assert f"is already controlled by daemon {first.status.lease}" in r.stderr
        assert "Traceback" not in r.stderr
        # with --wait-lease it waits, and takes over when the first one ends
        waiting = Stack(other, log_dir=stack.log_dir)
        waiting.extra_daemon_args = ["--wait-lease"]
        waiting.start_daemon()
        try:
            time.sleep(3.0)
            assert waiting.procs["daemon"].poll() is None  # still waiting, not commanding
            st = until(lambda: c.wait_state(2.0))
            assert st.lease == first.status.lease  # the sim still applies the first one's commands
            stack.kill("daemon")
            st2 = until(lambda: (s := c.wait_state(2.0)) is not None and s.lease
                        and s.lease != first.status.lease and s)
            # the second daemon answers with its own lease and, once its first states are in, state_ok
            # (asserted at the first answer, CI once saw its status of the tick before its first state);
            # asked where it listens: every link is an explicit connect (no gossip), so a client of
            # the first daemon's endpoint does not reach it
            with Client(other, name="test2") as c2:
                second = until(lambda: (i := c2.info()) is not None and i.status.lease == st2.lease
                               and i.status.state_ok and i)
            assert second.status.lease == st2.lease
        finally:
            waiting.stop()


def test_a_second_sim_under_the_same_id_is_a_fault_not_mixed(service_stack: Any, tmp_path: Path) -> None:
    stack: Stack = service_stack(500.0)
    with Client(stack.svc, name="test") as c:
        info = ready(c)
        latched = info.status.robot_instance
        # a second sim for the same robot, on another port, that dials the daemon itself (a robot
        # process configured with the daemon's endpoint; every link is an explicit connect)
        twin_svc = stack.svc.with_(zenoh={"sim_endpoint": f"tcp/127.0.0.1:{free_port()}"})
        dial = tmp_path / "twin_dials_the_daemon.json5"
        dial.write_text(f'{{ connect: {{ endpoints: ["{stack.svc.zenoh.daemon_endpoint}"] }} }}\n', encoding="utf-8")
        twin = Stack(twin_svc, log_dir=stack.log_dir, extra_sim_args=["--zenoh-config", str(dial)])
        twin.start_sim()
        try:
            # a peer watches it (the drill: wmm-qp status --sim-endpoint <the twin's port>)
            with Client(twin_svc, name="bridge") as bridge:
                twin_state = until(lambda: (s := bridge.wait_state(2.0)) is not None
                                   and s.instance != latched and s)
                st = until(lambda: (i := c.info()) is not None
                           and i.status.faults.get("second_state_source", 0) >= 1 and i)
                assert st.status.robot_instance == latched  # never switched to the twin
                assert "second state source" in st.status.last_fault
                assert st.status.rejected.get("instance", 0) >= 1
                # the twin applies none of the daemon's commands: they are for the other instance
                s2 = until(lambda: (s := bridge.wait_state(2.0)) is not None
                           and s.instance == twin_state.instance and s.refused.get("instance", 0) > 0 and s)
                t2 = until(lambda: (t := bridge.wait_truth(2.0)) is not None
                           and t.instance == twin_state.instance and t)
                assert s2.cmd_seq == -1 and sum(t2.violations.values()) == 0
        finally:
            twin.stop()
        t1 = until(lambda: (t := c.wait_truth(2.0)) is not None and t.instance == latched and t)
        assert sum(t1.violations.values()) == 0, t1.violations


def test_a_client_publishing_cmd_meets_the_robots_own_protection(service_stack: Any) -> None:
    """The drill published cmd at 2 kHz (joint 4 to 15.8 rad, the base 8.8 m). Even with a
    forged lease and instance read off the state, the firmware refuses the rates."""
    stack: Stack = service_stack(500.0)
    robot = w.load_robot_config()
    hi = np.asarray(robot.arm.position_upper)
    with Client(stack.svc, name="rogue") as c:
        ready(c)
        st: StateMsg = until(lambda: c.wait_state(2.0))
        tr0: TruthMsg = until(lambda: c.wait_truth(2.0))
        arm = [0.0] * robot.n_arm
        arm[3] = 100.0
        seq = 10**6
        end = time.monotonic() + 1.5
        while time.monotonic() < end:
            seq += 1
            c.put_raw("cmd", encode(CommandMsg(robot=stack.svc.robot, seq=seq, stamp=time.time(),
                                               wheel_speeds=[100.0] * robot.n_wheels, arm_rates=arm, lease=st.lease,
                                               instance=st.instance, period=0.0005, stream=1)))
            time.sleep(0.0005)
        after: StateMsg = until(lambda: c.wait_state(2.0))
        assert after.protective_stops >= 1 and "refused command" in after.protective_reason
        tr: TruthMsg = until(lambda: c.wait_truth(2.0))
        assert tr.violations["velocity"] > 0  # the referee counts what was commanded
        assert tr.violations["position"] == 0 and np.all(np.array(after.q_arm) <= hi + 1e-9)
        assert np.linalg.norm(np.subtract(tr.base_true[:2], tr0.base_true[:2])) < 0.05
        status = until(lambda: (i := c.info()) is not None and
                       (i.status.faults.get("robot_firmware", 0) or i.status.faults.get("robot_protective_stop", 0))
                       and i)
        assert status.status.faults


def test_status_names_a_mistyped_robot(service_stack: Any) -> None:
    stack: Stack = service_stack(500.0)
    with Client(stack.svc, name="test") as c:
        ready(c)
    svc = stack.svc
    r = cli("status", *_service_args(svc.with_(robot="wmmm")), "--timeout", "5")
    assert r.returncode == 1
    assert f"no daemon for robot {svc.prefix}/wmmm" in r.stderr
    assert f"daemons seen: {svc.prefix}/{svc.robot}" in r.stderr
