"""``wmm-qp driver franka`` against franky-sim (a MuJoCo FR3 speaking libfranka's protocol,
:mod:`support.franky_rig`): franky-sim runs in a child process of the test, the driver as ``wmm-qp
driver franka``; the test plays the daemon (it holds the control lease and publishes ``cmd`` at
500 Hz) or runs ``wmm-qp serve`` and talks to it as a client.
"""

from __future__ import annotations

import subprocess
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.importorskip("pylibfranka", reason="needs pylibfranka (pip install 'wmm-qp[franka]')")
pytest.importorskip("franky_sim", reason="needs franky-sim (pip install franky-sim)")

import zenoh
from support.franky_rig import FR3, RECOVERIES, REFLEXES, driver_stack, start_franky_sim
from wmm_qp_service.keys import Keys
from wmm_qp_service.processes import CLI, isolated_config
from wmm_qp_service.protocol import CommandMsg, GripperMsg, StateMsg, TruthMsg, decode, encode
from wmm_qp_service.transport import ROLE_DAEMON, open_session

import wmm_qp as w


class Daemon:
    """The test as the daemon: the lease, the latest state, commands at 500 Hz."""

    def __init__(self, session: zenoh.Session, keys: Keys, robot: str) -> None:
        self.keys, self.robot = keys, robot
        self.token = session.liveliness().declare_token(keys.lease("testlease"))
        self.sub = session.declare_subscriber(keys.state, zenoh.handlers.RingChannel(1))
        self.sub_truth = session.declare_subscriber(keys.sim_truth, zenoh.handlers.RingChannel(1))
        self.truth: TruthMsg | None = None
        self.pub = session.declare_publisher(keys.cmd, express=True)
        self.pub_gripper = session.declare_publisher(keys.gripper)
        self.seq = 0
        self.stream = 1
        self.state: StateMsg | None = None

    def poll(self) -> StateMsg | None:
        if (s := self.sub.try_recv()) is not None:
            self.state = decode(StateMsg, s.payload.to_bytes())
        if (s := self.sub_truth.try_recv()) is not None:
            self.truth = decode(TruthMsg, s.payload.to_bytes())
        return self.state

    def violations(self) -> dict[str, int]:
        """The driver's referee counts (``sim/truth``, published every 10 cycles)."""
        self.wait(0.05)
        assert self.truth is not None, "no sim/truth from the driver"
        return dict(self.truth.violations)

    def send_for(self, duration: float, rates: Any) -> None:
        """Send rates(t) [rad/s] every 2 ms for duration [s] of wall time; t is the commands' own
        time (k · period), as a daemon's bounds (13) see it, whatever the host's stalls."""
        t0 = time.monotonic()
        k = 0
        while time.monotonic() - t0 < duration:
            st = self.poll()
            if st is not None:
                self.seq += 1
                k += 1
                self.pub.put(encode(CommandMsg(robot=self.robot, seq=self.seq, stamp=time.time(), wheel_speeds=[],
                                               arm_rates=list(map(float, rates(k * 0.002))), lease="testlease",
                                               instance=st.instance, period=0.002, stream=self.stream)))
            time.sleep(0.002)

    def wait(self, duration: float) -> StateMsg:
        t0 = time.monotonic()
        while time.monotonic() - t0 < duration:
            self.poll()
            time.sleep(0.005)
        assert self.state is not None
        return self.state


@pytest.fixture(scope="module")
def rig(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Daemon, Any]]:
    robot = w.load_robot_config(FR3)
    sim = start_franky_sim(robot)
    svc = isolated_config(robot=robot)
    log = tmp_path_factory.mktemp("franka") / "driver.log"
    with open(log, "w") as err:
        drv = subprocess.Popen([*CLI, "driver", "franka", "--robot-ip",
                                sim.host, "--robot-config", str(FR3), "--prefix", svc.prefix,
                                "--daemon-endpoint", svc.zenoh.daemon_endpoint,
                                "--sim-endpoint", svc.zenoh.sim_endpoint], stderr=err)
    try:
        with open_session(svc, ROLE_DAEMON) as session:
            d = Daemon(session, Keys.of(svc.prefix, svc.robot), svc.robot)
            t0 = time.monotonic()
            while d.poll() is None and time.monotonic() - t0 < 60:
                assert drv.poll() is None, Path(log).read_text()
                time.sleep(0.05)
            assert d.state is not None, "no state from the driver: " + Path(log).read_text()
            d.wait(0.5)  # the lease reaches the driver
            yield d, sim.shared
    finally:
        drv.terminate()
        try:
            drv.wait(20)
        except subprocess.TimeoutExpired:
            drv.kill()
        sim.close()


def test_the_driver_streams_within_the_fr3s_limits_and_brakes_when_the_commands_stop(rig: Any) -> None:
    d, shared = rig
    d.send_for(1.5, lambda t: [0.4 * np.sin(4.0 * t), 0.2 * np.sin(3.0 * t), 0, 0.2 * np.sin(2.0 * t), 0, 0,
                               0.5 * min(1.0, t / 0.3)])  # from rest, within 10 rad/s² between commands
    st = d.poll()
    assert st is not None and st.lease == "testlease" and st.cmd_seq > 0
    moved = abs(shared[13])  # joint 7 follows 0.5 rad/s
    assert moved > 0.3, f"joint 7 at {moved} rad/s"
    assert shared[15] == 0 and shared[16] == 0, "franky-sim saw a joint past a limit"
    assert not any((v := d.violations()).values()), v
    # the command source dies: stale after 0.025 s, at rest 0.5/10 s later (robot time; franky-sim's
    # clock runs slower than the wall's on a loaded host). At rest, franky-sim's joint 7 chatters
    # at about ±0.08 rad/s around a still position (its D controller on a light link): rest is
    # judged on positions.
    st = d.wait(0.3)
    assert st.stale_stop
    q0 = np.array(shared[0:7])
    st = d.wait(0.3)
    assert np.max(np.abs(np.array(shared[0:7]) - q0)) < 0.005, np.array(shared[0:7]) - q0  # 0.5 rad/s: 0.15 rad
    assert shared[15] == 0 and shared[16] == 0


def test_a_command_past_the_limits_is_refused_with_a_protective_stop(rig: Any) -> None:
    d, shared = rig
    d.stream = 100
    too_fast = [0, 0, 0, 0, 6.0, 0, 0]  # joint 5: 5.26 rad/s at most
    d.send_for(0.3, lambda t: too_fast)
    st = d.wait(0.3)
    assert st.protective_stop and "joint 5" in st.protective_reason and st.refused.get("firmware", 0) > 0
    assert d.violations().get("velocity", 0) > 0  # the referee judged the command as received
    q0 = np.array(shared[0:7])
    d.wait(0.3)
    assert abs(shared[4] - q0[4]) < 0.005 and shared[16] == 0  # joint 5 never moved off: refused


def _hold_until_moved(c: Any, target: np.ndarray, x0: np.ndarray, distance: float, seconds: float) -> Any:
    """Hold the setpoint ``target`` (resuming after a fault, as :func:`_follow`) until the EE is
    ``distance`` [m] from ``x0`` along y or ``seconds`` passed; the last info. A loaded host's
    faults (late states: the daemon's safe stop) slow the tracking, never end it."""
    t_end = time.monotonic() + seconds
    info = c.info()
    while time.monotonic() < t_end and (info is None or abs(info.status.x[1] - x0[1]) <= distance):
        if c.resume_needed():
            c.resume("track", timeout=20)
        c.send_setpoint(target)
        time.sleep(0.01)
        info = c.info()
    return info


def _follow(c: Any, x0: np.ndarray, seconds: float, k0: int, resume: bool = True) -> int:
    """Stream setpoints for ``seconds``: 5 cm along y in about 3 s and back (100 Hz); returns the
    setpoint count to go on from. ``resume``: after a fault (a loaded host delays states and
    commands: the daemon's safe stop) send the mode message again, as an operator would."""
    k = k0
    t_end = time.monotonic() + seconds
    while time.monotonic() < t_end:
        if resume and c.resume_needed():
            t0 = time.monotonic()
            c.resume("track", timeout=20)
            t_end += time.monotonic() - t0  # the time the resume took is not tracking time
        if c.send_setpoint(x0 + [0.0, 0.05 * np.sin(0.005 * k), 0.0]):
            k += 1
        time.sleep(0.01)
    return k


def _follow_until_moved(c: Any, sim: Any, x0: np.ndarray, k: int, q0: np.ndarray, distance: float,
                        seconds: float) -> int:
    """:func:`_follow` in half seconds until a joint of franky-sim's arm is ``distance`` [rad] from
    ``q0`` or ``seconds`` passed; the setpoint count to go on from. A loaded host moves the arm
    slower (1.5 s of setpoints moved it 0.0024 rad once in CI): the tests judge the motion, not its speed."""
    t_end = time.monotonic() + seconds
    while np.max(np.abs(sim.q() - q0)) <= distance and time.monotonic() < t_end:
        k = _follow(c, x0, 0.5, k)
    return k


def _wait(what: str, fn: Any, timeout: float, logs: Path) -> Any:
    end = time.monotonic() + timeout
    while not (v := fn()):
        if time.monotonic() > end:
            tails = "\n".join(f"--- {f.name}:\n{f.read_text()[-1500:]}" for f in sorted(logs.glob("*.log")))
            raise AssertionError(f"timed out after {timeout:g} s waiting for {what}\n{tails}")
        time.sleep(0.02)
    return v


def test_serve_tracks_through_the_driver_and_resumes_after_the_robot_braked_in_its_own_stop(tmp_path: Path) -> None:
    """wmm-qp serve + the driver + franky-sim: a track phase within every limit; the daemon frozen
    for 0.3 s (the driver brakes: stale) resumes on the client's mode message, which needs the
    state's ``v_arm`` exactly 0 at rest."""
    import os
    import signal

    from wmm_qp_service.client import Client

    sim = start_franky_sim(w.load_robot_config(FR3))
    try:
        with driver_stack(sim, tmp_path) as (svc, procs), Client(svc, name="e2e") as c:
            info = c.wait_for_daemon(timeout=60)
            assert info is not None, (tmp_path / "serve.log").read_text()
            x0 = np.array(info.status.x)
            assert c.resume("track", timeout=20), (tmp_path / "serve.log").read_text()
            k = _follow(c, x0, 3.0, 0)
            st = _hold_until_moved(c, x0 + [0.0, 0.05 * np.sin(0.005 * k), 0.0], x0, 0.02, 60.0)
            assert st is not None and abs(st.status.x[1] - x0[1]) > 0.02, (st, x0)
            os.kill(procs["serve"].pid, signal.SIGSTOP)  # the daemon freezes: no command for 0.3 s
            time.sleep(0.3)
            os.kill(procs["serve"].pid, signal.SIGCONT)
            time.sleep(0.5)
            # the daemon saw its stream broken (asked until it answers: just thawed on a loaded host,
            # its first answer can come after the query's timeout, and info() is then None)
            mid = _wait("the thawed daemon's info", lambda: c.info(), 20.0, tmp_path)
            assert mid.status.faults, mid
            assert c.resume("track", timeout=20), "the daemon did not resume after the robot's stale stop"
            _follow(c, x0, 1.5, k)
            if c.resume_needed():  # a loaded host stalled a command past the timeout again: resume
                c.resume("track", timeout=20)
            state = _wait("a state of the robot streaming again", lambda: (st := c.wait_state(1.0)) is not None
                          and not st.stale_stop and not st.protective_stop and st, 20.0, tmp_path)
            truth = c.latest_truth() or c.wait_truth(1.0)
            info = c.info()
        assert state is not None and not state.stale_stop and not state.protective_stop, state
        assert truth is not None and not any(truth.violations.values()), truth.violations
        assert info is not None and not any(info.status.robot_violations.values())
        assert sim.shared[15] == 0 and sim.shared[16] == 0, "franky-sim saw a joint past a limit"
    finally:
        sim.close()


def test_a_libfranka_reflex_is_a_protective_stop_the_arm_brakes_and_a_mode_message_resumes(tmp_path: Path) -> None:
    """wmm-qp serve + the driver + franky-sim with a reflex model (:class:`support.franky_rig.ReflexModel`):
    while the arm tracks, the robot aborts the motion with a Cartesian reflex, reported over
    libfranka's protocol; libfranka raises its own ``ControlException`` in the driver. The driver
    reports a protective stop naming it, the daemon faults and holds, the arm stands still in
    franky-sim's physics; the robot is recovered (libfranka's ``automatic_error_recovery``) and
    moves again after a mode message. Safety (no violation, no joint past a limit) whatever the
    timing."""
    from wmm_qp_service.client import Client

    sim = start_franky_sim(w.load_robot_config(FR3), reflex=True)
    try:
        with driver_stack(sim, tmp_path) as (svc, _), Client(svc, name="e2e") as c:
            info = c.wait_for_daemon(timeout=60)
            assert info is not None, (tmp_path / "serve.log").read_text()
            x0 = np.array(info.status.x)
            assert c.resume("track", timeout=20), (tmp_path / "serve.log").read_text()
            q_start = sim.q()
            k = _follow_until_moved(c, sim, x0, 0, q_start, 0.005, 30.0)
            assert np.max(np.abs(sim.q() - q_start)) > 0.005, "the arm did not move before the reflex"
            stops = c.latest_state().protective_stops  # type: ignore[union-attr]
            sim.trip.set()  # the reflex, while the arm moves
            st = _wait("the driver's protective stop", lambda: (s := c.latest_state()) is not None
                       and s.protective_stops > stops and s, 20.0, tmp_path)
            assert st.protective_reason.startswith("robot: libfranka") and "cartesian_reflex" in st.protective_reason, \
                st.protective_reason
            assert sim.shared[REFLEXES] == 1
            status = _wait("the daemon's fault", lambda: (s := c.latest_status()) is not None
                           and "robot_firmware" in s.faults and s, 20.0, tmp_path)
            assert status.faults["robot_firmware"] >= 1, status.faults
            # the arm brakes: franky-sim holds the joints; their positions stand still (its joint 7
            # chatters at about ±0.08 rad/s around a still position: rest is judged on positions)
            time.sleep(0.2)
            q_stopped = sim.q()
            st = _wait("the daemon holding, to be resumed", lambda: (s := c.latest_status()) is not None
                       and s.resume_needed and s, 20.0, tmp_path)
            assert st.mode == "hold"
            # the daemon's safe-stop stream has had the robot recover; the daemon holds it still
            assert sim.shared[RECOVERIES] == 1, "the robot was not recovered"
            _follow(c, x0, 0.5, k, resume=False)  # setpoints without a mode message move nothing
            assert np.max(np.abs(sim.q() - q_stopped)) < 0.005, sim.q() - q_stopped
            # the mode message: the daemon resumes, the arm follows again
            assert c.resume("track", timeout=20), f"the daemon did not resume: {c.latest_status()}"
            q_resumed = sim.q()
            k = _follow_until_moved(c, sim, x0, k, q_resumed, 0.005, 30.0)
            assert np.max(np.abs(sim.q() - q_resumed)) > 0.005, "the arm did not move after the mode message"
            state, truth = c.latest_state(), c.latest_truth() or c.wait_truth(1.0)
        # out of the reflex's protective stop (a stale stop at that instant is the daemon stalled on a
        # loaded host: safe, and no verdict on the reflex)
        assert state is not None and not state.protective_stop, state
        assert truth is not None and not any(truth.violations.values()), truth.violations
        assert sim.shared[15] == 0 and sim.shared[16] == 0, "franky-sim saw a joint past a limit"
        log = (tmp_path / "driver.log").read_text()
        assert "protective stop: libfranka: Move command aborted: motion aborted by reflex!" in log, log
        assert "the robot recovered" in log, log
    finally:
        sim.close()


def test_the_franka_hand_closes_and_opens_through_gripper_commands(rig: Any) -> None:
    """franky-sim serves the Franka Hand (libfranka's gripper port): a GripperMsg on
    ``<robot>/gripper`` moves its fingers, and the state reports the measured width."""
    d, _ = rig

    def grip(action: str, **kw: float) -> None:
        d.seq += 1
        d.pub_gripper.put(encode(GripperMsg(robot=d.robot, seq=d.seq, stamp=time.time(), action=action,
                                            speed=0.1, source="test", **kw)))

    def width_until(pred: Any, timeout: float = 20.0) -> float:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            st = d.wait(0.05)
            if pred(st.gripper_width):
                return float(st.gripper_width)
        raise AssertionError(f"gripper width {d.state.gripper_width if d.state else None}")

    width_until(lambda x: np.isfinite(x))  # the hand's child process has read it
    grip("close")
    assert width_until(lambda x: x < 0.005) < 0.005
    grip("move", width=0.05)
    assert abs(width_until(lambda x: abs(x - 0.05) < 0.003) - 0.05) < 0.003
    grip("open")
    assert width_until(lambda x: x > 0.075) > 0.075
