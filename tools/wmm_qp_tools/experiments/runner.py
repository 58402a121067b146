"""The in-process driver of a scenario: the controller stepped directly against the simulated
robot, deterministic.

Every tick (``ctl_cfg.rate_hz``, 500 Hz by default) the controller sees what a real
controller would see — the sim's :meth:`~wmm_qp_sim.SimRobot.robot_state` (odometry base pose),
its rates anchored on the last command (:func:`anchored`) — and its command is held by the sim
for ``round(sim_rate / control_rate)`` sim steps (two at 1 kHz). A phase starts at the first
tick at or after its start time (the durations before it summed; :func:`phase_ticks`) and ends
there or earlier, when its ``done`` says so. Metrics use the sim's ground truth. Nothing here
depends on wall-clock time.
"""

from __future__ import annotations

import math
import re
import time
from collections.abc import Callable, Mapping

import numpy as np
from wmm_qp_sim import BoxConfig, SimCommand, SimRobot, SimState

import wmm_qp
from wmm_qp.config import FloatArray
from wmm_qp.manipulability import directional_manipulability
from wmm_qp.tasks import rotation_to_quat
from wmm_qp_tools.experiments.progress_bar import Progress
from wmm_qp_tools.experiments.scenario import Anchor, Scenario
from wmm_qp_tools.experiments.setup import Setup
from wmm_qp_tools.experiments.trace import Trace

ObserveFn = Callable[[SimRobot], None]
"""Called with the sim after every tick (e.g. to render its plant); must not change it."""

BOX_MOVED = 1e-3  # [m] / [rad]: the controller is told where the box is when it moved this much


class SimProbe:
    """A phase's questions answered from the sim (:class:`~.scenario.Probe`); a placed box is
    also an obstacle for the controller, for every body but the EE's, updated when it moves.

    Args:
        setup: the run's setup (its controller is told about the box; the scene's obstacles stay).
        sim: the simulated robot.
    """

    def __init__(self, setup: Setup, sim: SimRobot) -> None:
        self.setup = setup
        self.sim = sim
        self.state: SimState = sim.state()  # the newest state (the driver sets it after each tick)
        self._placed = [math.nan, 0.0]  # face x [m], tilt [rad] of the box the controller last saw
        self._tracking = False

    def ee_true(self) -> FloatArray:
        return self.state.ee_true

    def place_box(self, box: BoxConfig) -> None:
        self.sim.place_box(box)
        self.state = self.sim.state()
        self._tracking = True
        self.track_box()

    def box_moved(self) -> float:
        return float(self.state.box_displacement)

    def track_box(self) -> None:
        """Tell the controller the box's place when it moved since it was last told."""
        box = self.sim.box
        if not self._tracking or box is None:
            return
        if abs(box.face_x - self._placed[0]) > BOX_MOVED or abs(box.tilt - self._placed[1]) > BOX_MOVED:
            self._placed = [box.face_x, box.tilt]
            shape = self.sim.box_obstacle()
            scene = self.setup.scene.obstacles if self.setup.scene is not None else ()
            self.setup.controller.set_obstacles(scene + ((shape,) if shape is not None else ()))


def anchor_of(setup: Setup, st: SimState) -> Anchor:
    """The EE pose the controller estimates from the sim's state (odometry base pose, measured
    joints; the orientation with the pose task)."""
    m = setup.model
    quat = rotation_to_quat(m.ee_pose(st.base_odom, st.q_arm)[1]) if setup.controller.pose else None
    return Anchor(x=m.ee_position(st.base_odom, st.q_arm), quat=quat)


def phase_ticks(scenario: Scenario, dt: float) -> list[int]:
    """Ticks of each phase at the control period ``dt`` [s]: a phase starts at the first tick at
    or after its start time (the durations before it summed), the run has
    ``round(scenario.duration / dt)`` ticks."""
    n_ticks = round(scenario.duration / dt)
    firsts, start = [], 0.0
    for p in scenario.phases:
        firsts.append(min(_first_tick_at(start, dt), n_ticks))
        start += p.duration
    return [b - a for a, b in zip(firsts, [*firsts[1:], n_ticks], strict=True)]


def _first_tick_at(t: float, dt: float) -> int:
    """The first k with k·dt ≥ t (to 1 ns)."""
    k = max(0, math.ceil((t - 1e-9) / dt))
    while k > 0 and (k - 1) * dt >= t - 1e-9:
        k -= 1
    while k * dt < t - 1e-9:
        k += 1
    return k


def run(
    setup: Setup,
    scenario: Scenario,
    *,
    progress: bool = False,
    observe: Mapping[str, ObserveFn] | None = None,
) -> Trace:
    """Run ``scenario`` in the closed loop, from a fresh sim at the origin and the robot's
    ``arm.start`` (the Gen3's is the paper's start configuration).

    Args:
        setup: model, controller and configs.
        scenario: the phases.
        progress: a progress bar on stderr, labelled with the scenario's name.
        observe: per phase name, called with the sim after every tick of that phase.
    """
    m = setup.model
    W = np.asarray(setup.W, dtype=float)
    u = scenario.dm_direction
    sim = SimRobot(m, setup.sim_cfg, seed=setup.seed, scene=setup.scene)
    sim.reset(q_base=np.zeros(3))
    probe = SimProbe(setup, sim)
    dt = setup.ctl_cfg.dt
    n_sub = max(1, round(setup.sim_cfg.rate_hz / setup.ctl_cfg.rate_hz))
    sim_dt = dt / n_sub
    ticks = phase_ticks(scenario, dt)
    n_ticks = sum(ticks)
    t0 = sim.state().t
    rows: dict[str, list] = {k: [] for k in ("t", "mode", "status", "q", "qd", "wh", "tw", "bo", "bt", "ed",
                                             "et", "dm", "tau", "box", "stall")}  # fmt: skip
    reasons: dict[str, int] = {}
    starts: dict[str, int] = {}
    bar = Progress(scenario.name) if progress else None
    observe = observe or {}
    last: wmm_qp.Command | None = None
    wall = time.perf_counter()
    st = probe.state
    k = 0
    for phase, n in zip(scenario.phases, ticks, strict=True):
        anchor = anchor_of(setup, st)
        if phase.box is not None:
            probe.place_box(phase.box(st.ee_true))
            st = probe.state
        starts[phase.name] = len(rows["t"])
        seen = observe.get(phase.name)
        for j in range(n):
            probe.track_box()  # where the box is now
            ref = phase.reference(j * dt, anchor)
            cmd = setup.controller.step(anchored(sim.robot_state(), last), ref)
            last = cmd
            if cmd.reason:
                key = re.sub(r"[-+]?\d[\d.e-]*", "#", cmd.reason)  # group by kind, not value
                reasons[key] = reasons.get(key, 0) + 1
            J_arm = m.arm.position_jacobian(st.q_arm)[1]
            rows["t"].append(k * dt)
            rows["mode"].append(str(ref.mode))
            rows["status"].append(str(cmd.status))
            rows["q"].append(st.q_arm)
            rows["qd"].append(cmd.arm_rates)
            rows["wh"].append(cmd.wheel_speeds)
            rows["tw"].append(m.base.body_twist(cmd.wheel_speeds))
            rows["bo"].append(st.base_odom)
            rows["bt"].append(st.base_true)
            rows["ed"].append(np.array(ref.x_d if ref.x_d is not None else cmd.x, dtype=float))
            rows["et"].append(st.ee_true)
            rows["dm"].append(directional_manipulability(J_arm, u, W))
            rows["tau"].append(st.tau)
            rows["box"].append(st.box_displacement)
            rows["stall"].append(-1 if st.stalled_joint is None else st.stalled_joint)
            st = sim.step(SimCommand(cmd.wheel_speeds, cmd.arm_rates, period=dt, seq=k), sim_dt)
            for _ in range(n_sub - 1):
                st = sim.step(None, sim_dt)
            probe.state = st
            if seen is not None:
                seen(sim)
            if bar is not None and k % 50 == 0:
                bar.update((k + 1) / n_ticks)
            k += 1
            if phase.done is not None and phase.done(j * dt, probe):
                break
    if bar is not None:
        bar.update(1.0)
        bar.close()
    arr = {k: np.array(v, dtype=float) for k, v in rows.items() if k not in ("mode", "status")}
    return Trace(
        t=arr["t"] + t0,
        mode=rows["mode"],
        status=rows["status"],
        q=arr["q"],
        qd_cmd=arr["qd"],
        wheel_cmd=arr["wh"],
        base_twist_cmd=arr["tw"],
        base_odom=arr["bo"],
        base_true=arr["bt"],
        ee_des=arr["ed"],
        ee_true=arr["et"],
        dm=arr["dm"],
        tau=arr["tau"],
        box_displacement=arr["box"],
        stalled_joint=arr["stall"].astype(int),
        violations=dict(st.violations),
        reasons=reasons,
        phase_starts=starts,
        box_displacement_end=float(st.box_displacement),
        box_tilt_end=sim.box.tilt if sim.box is not None else math.nan,
        wall_time=time.perf_counter() - wall,
        sim=sim,
    )


def anchored(state: wmm_qp.RobotState, last: wmm_qp.Command | None) -> wmm_qp.RobotState:
    """The state handed to the controller: its rates replaced by the last command, once there is one.

    The acceleration bounds of (13) are q̇_prev ± A·Δt around what the robot executes next: the
    last command (the referee judges each command against the previous one). A physics plant's
    measured rates lag the command (its servos have an error, its wheels slip), so bounds
    centred on them let two consecutive commands differ by more than A·Δt. The sim's state
    reports the executed rates (:meth:`~wmm_qp_sim.SimRobot.robot_state`), which in process
    (firmware off, no ramp) are the last command itself: the anchor makes that explicit rather
    than a property of the sim. The daemon does the same while the robot follows its stream
    (``ControlCore._anchored``); in process the firmware is off and the robot always follows.

    Args:
        state: what the sim measured (its pose is kept).
        last: the previous command sent to the sim, or None (the first tick: the measured rates).
    """
    if last is None:
        return state
    return wmm_qp.RobotState(q_base=state.q_base, q_arm=state.q_arm, v_arm=last.arm_rates.copy(),
                             wheel_speeds=last.wheel_speeds.copy())
