"""Faults against the real processes (integration) and the watchdogs' documented behaviour.

The integration tests share one stack (module fixture) and run the scenarios of
``wmm_qp_tools.faults`` in order; they assert behaviour only. The figures (latencies) are
printed here and recorded by ``benchmarks/reliability/faults.py`` in docs/reliability.md.
The watchdog tests drive the ControlCore with a fake clock (deterministic).
"""

from __future__ import annotations

import itertools
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from support.daemon_drive import send
from wmm_qp_service.config import ServiceConfig
from wmm_qp_service.daemon import ControlCore
from wmm_qp_service.protocol import ModeMsg, SetpointMsg, StateMsg

import wmm_qp as w

RATE = 500.0


# ---------------------------------------------------------------- the sim after its own stall
@pytest.mark.parametrize("keep_all", [True, False])
def test_a_burst_of_commands_after_a_sim_stall_is_judged_command_by_command(keep_all: bool) -> None:
    """A sim starved by a loaded machine receives the daemon's commands in a burst: each is
    judged as received, against the one before it (SimNode.take). Judging only the burst's last
    against the one before the stall (a ring of one, before) counted a legal ramp (the TIAGo and
    UR5 demos at 1 kHz: "changed by 1.17 A·Δt over Δt = 27.33 ms")."""
    from wmm_qp_service.drivers.sim_node import SimNode
    from wmm_qp_service.protocol import CommandMsg, encode
    from wmm_qp_sim import load_sim_config

    robot = w.load_robot_config()
    node = SimNode(ServiceConfig(), load_sim_config().with_(firmware=False), robot)
    node.on_lease("d", True)
    dt = 0.001
    step = np.zeros(robot.n_arm)
    step[0] = robot.arm.acceleration_max[0] * dt  # joint 1 ramps at its limit, A·Δt per command

    def cmd(seq: int, received: float):  # type: ignore[no-untyped-def]
        c = node.accept(encode(CommandMsg(robot=node.svc.robot, seq=seq, stamp=0.0,
                                          wheel_speeds=[0.0] * robot.n_wheels, arm_rates=(seq * step).tolist(),
                                          lease="d", instance=node.instance, period=dt, stream=1)))
        assert c is not None
        c.received = received
        return c

    for k in range(1, 11):  # one command a step
        node.sim.step(node.take([cmd(k, k * dt)], dt), dt)
    burst = [cmd(k, 11 * dt) for k in range(11, 51)]  # 40 ms of commands, received at once
    node.sim.step(node.take(burst, dt) if keep_all else burst[-1], dt)
    counted = node.sim.state().violations["acceleration"]
    assert (counted == 0) if keep_all else (counted == 1), node.sim.referee.last_event
    assert node.sim.n_commands == (50 if keep_all else 11)


# ---------------------------------------------------------------- watchdogs, fake clock
def _core_run(loss: float, burst: tuple[int, int] | None, n: int = 1500) -> tuple[ControlCore, list[w.Command]]:
    """Track a circle for n ticks; each state is lost with probability ``loss``, and all
    states in the tick range ``burst`` are lost. The plant executes commands exactly (each
    state names the last command as applied)."""
    robot = w.load_robot_config()
    core = ControlCore(ServiceConfig(), w.load_controller_config(), robot)
    dt = core.dt
    rng = np.random.default_rng(3)
    q_base, q_arm = np.zeros(3), np.array(robot.arm.start)
    v_arm, wheels = np.zeros(robot.n_arm), np.zeros(robot.n_wheels)
    x0 = core.model.ee_position(q_base, q_arm)
    cmds = []
    for k in range(n):
        t = k * dt
        lost = rng.random() < loss or (burst is not None and burst[0] <= k < burst[1])
        if k == 0 or not lost:
            core.on_state(StateMsg(robot="wmm", seq=k + 1, stamp=t, t=t, q_base=q_base.tolist(),
                                   q_arm=q_arm.tolist(), v_arm=v_arm.tolist(), wheel_speeds=wheels.tolist(),
                                   tau=[0.0] * robot.n_arm, instance="sim", cmd_seq=core.stream.seq), t)
        if k == 1:
            core.on_mode(ModeMsg(robot="wmm", seq=1, stamp=t, mode="track"))
        x = x0 + 0.05 * np.array([np.sin(2 * t), 1 - np.cos(2 * t), 0.0])
        core.on_setpoint(SetpointMsg(robot="wmm", seq=k, stamp=t, x=x.tolist(), source="op"), t)
        cmd = core.tick(t)
        assert cmd is not None
        send(core, t)  # numbered and sent, as the daemon's cycle does; the next state names it applied
        cmds.append(cmd)
        v_arm, wheels = cmd.arm_rates.copy(), cmd.wheel_speeds.copy()
        q_arm = q_arm + dt * v_arm
        q_base = q_base + dt * (core.model.base.P(float(q_base[2])) @ wheels)
    return core, cmds


def _max_step(cmds: list[w.Command], dt: float) -> float:
    robot = w.load_robot_config()
    a = np.asarray(robot.arm.acceleration_max) * dt
    wa = robot.base.wheel_acceleration_max * dt
    return max(max(float(np.max(np.abs(q.arm_rates - p.arm_rates) / a)),
                   float(np.max(np.abs(q.wheel_speeds - p.wheel_speeds) / wa)))
               for p, q in itertools.pairwise(cmds))


def test_five_percent_state_loss_never_trips_the_state_watchdog() -> None:
    core, cmds = _core_run(loss=0.05, burst=None)
    assert not any(c.status == w.Status.SAFE_STOP for c in cmds)
    assert core.fault_record.counts == {}
    assert _max_step(cmds, core.dt) <= 1.0 + 1e-6  # the predicted state keeps the bounds exact
    assert np.abs(cmds[-1].v).max() > 1e-3  # still tracking the circle


def test_a_state_outage_longer_than_the_timeout_is_a_safe_stop_then_resumes() -> None:
    timeout_ticks = int(ServiceConfig().watchdog.state_timeout * RATE)
    core, cmds = _core_run(loss=0.0, burst=(600, 600 + 3 * timeout_ticks))
    safe = [k for k, c in enumerate(cmds) if c.status == w.Status.SAFE_STOP]
    assert safe and 600 + timeout_ticks - 1 <= safe[0] <= 600 + timeout_ticks + 1
    assert safe[-1] < 600 + 3 * timeout_ticks + 2  # resumes as soon as states are back
    assert core.fault_record.counts["state_stale"] == 1
    assert _max_step(cmds, core.dt) <= 1.0 + 1e-6


# ---------------------------------------------------------------- the real processes
@pytest.fixture(scope="module")
def probe(tmp_path_factory: pytest.TempPathFactory) -> Iterator[object]:
    from wmm_qp_service.processes import Stack, isolated_config
    from wmm_qp_tools.faults import Probe

    log_dir: Path = tmp_path_factory.mktemp("faults")
    stack = Stack(isolated_config(), rate_hz=RATE, log_dir=log_dir)
    p = None
    try:
        stack.start()
        p = Probe(stack)
        yield p
    finally:
        if p is not None:
            p.close()
        stack.stop()


@pytest.mark.integration
def test_sim_killed_mid_motion_then_restarted(probe: object) -> None:
    from wmm_qp_tools.faults import sim_kill_and_restart

    r = sim_kill_and_restart(probe, RATE)  # type: ignore[arg-type]
    print("\nsim kill/restart:", r)
    assert r["fault_code"] in ("robot_lost", "state_stale"), r["fault"]
    assert r["detect_s"] <= r["zero_s"]  # a safe stop first, braking to zero after
    assert r["first_cmd_ratio"] <= 1.0 + 1e-6  # inside the acceleration bounds of the measured rates
    # consecutive commands may differ by more than A·dt when the measured rates lag the
    # commands (transport jitter, a sim warming up): the bound is around the *measured* rates,
    # and the sim's referee checks what was executed
    assert np.isfinite(r["max_step_ratio"]) and r["resumed_ticks"] > 0
    assert sum(r["violations"].values()) == 0


@pytest.mark.integration
def test_daemon_killed_mid_motion_then_restarted(probe: object) -> None:
    from wmm_qp_tools.faults import daemon_kill_and_restart

    r = daemon_kill_and_restart(probe)  # type: ignore[arg-type]
    print("\ndaemon kill/restart:", r)
    assert r["speed_at_kill"] > 1e-3 and r["detect_s"] <= r["stop_s"]
    assert r["tracking_error"] < 0.01  # the restarted daemon drives the robot again
    assert sum(r["violations"].values()) == 0


@pytest.mark.integration
def test_setpoint_flood_at_ten_times_the_loop_rate(probe: object) -> None:
    from wmm_qp_tools.faults import setpoint_flood

    r = setpoint_flood(probe, factor=10.0, seconds=4.0)  # type: ignore[arg-type]
    print("\nsetpoint flood:", r)
    assert r["flood_rate"] > 2 * RATE  # the flood happened
    assert r["flood_hz"] > 0 and r["setpoints_accepted"] > 0  # the loop ran and took setpoints


@pytest.mark.integration
def test_five_percent_state_loss_on_the_wire(probe: object) -> None:
    from wmm_qp_tools.faults import state_faults

    r = state_faults(probe, ["--state-loss", "0.05"], seconds=2.0)  # type: ignore[arg-type]
    print("\nstate loss 5 %:", r)
    assert r["ticks"] > 0 and r["state_ok"]
    assert sum(r["violations"].values()) == 0


@pytest.mark.integration
@pytest.mark.parametrize("peer", ["sim", "daemon"])
def test_a_hung_peer_is_noticed_and_the_stack_resumes(probe: object, peer: str) -> None:
    from wmm_qp_tools.faults import sigstop

    r = sigstop(probe, peer, hold_s=1.5)  # type: ignore[arg-type]
    print(f"\nSIGSTOP {peer}:", r)
    assert "liveliness_s" in r and "resume_s" in r  # the lease expired, and it came back
    assert ("safe_s" in r) if peer == "sim" else ("sim_stop_s" in r)
    assert sum(r["violations"].values()) == 0


@pytest.mark.integration
@pytest.mark.slow
def test_a_daemon_stalled_past_the_command_timeout_resumes_on_the_physics_plant(tmp_path: Path) -> None:
    """The stall is noticed (the stream is braked; the robot, having stopped it, refuses it and the
    stream breaks); the daemon resumes once a state shows the robot at rest in its stale stop, rates
    exactly 0: the sim reports its executed rates, not the physics' measured ones (never exactly 0:
    the daemon waited for ever, and `demo` said the stack did not come up)."""
    pytest.importorskip("mujoco", reason="the physics plant needs mujoco: pip install 'wmm-qp[physics]'")
    import signal
    import time

    from wmm_qp_service.processes import Stack, isolated_config
    from wmm_qp_tools.faults import Probe

    stack = Stack(isolated_config(), rate_hz=RATE, log_dir=tmp_path, extra_sim_args=["--physics", "mujoco"])
    p = None
    try:
        stack.start()
        p = Probe(stack)
        info = p.ready(timeout=90.0)
        p.client.set_mode("track")
        p.move(np.array(info.status.x), 1.0)
        t0 = time.time()
        stack.procs["daemon"].send_signal(signal.SIGSTOP)
        p.until(lambda: p.first_state(lambda s: s.stale_stop, t0), timeout=10.0)  # the robot stopped itself
        stack.procs["daemon"].send_signal(signal.SIGCONT)
        i = p.until(lambda: (i := p.client.info()) is not None and i.status.state_ok and i.status.faults.get(
            "stall_braking", 0) > 0 and i, timeout=20.0)
        assert not i.status.safe_stop
        assert sum(p.violations().values()) == 0
    finally:
        if p is not None:
            p.close()
        codes = stack.stop()
    assert codes == {"sim": 0, "daemon": 0}
