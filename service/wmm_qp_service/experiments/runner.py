"""The shared in-process experiment loop: controller and simulated robot, deterministic.

Every tick (``ctl_cfg.rate_hz``, 500 Hz by default) the controller sees what a real
controller would see — the sim's :meth:`~wmm_qp_sim.SimRobot.robot_state` (odometry base pose)
— and its command is held by the sim for ``round(sim_rate / control_rate)`` sim steps (two at
1 kHz). Metrics use the sim's ground truth. Nothing here depends on wall-clock time.
"""

from __future__ import annotations

import re
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from wmm_qp_sim import BoxConfig, SimCommand, SimConfig, SimRobot, SimState

import wmm_qp
from wmm_qp.config import FloatArray
from wmm_qp.manipulability import directional_manipulability
from wmm_qp.scene import Scene

from ..progress import ProgressLine

ReferenceFn = Callable[[float, SimState, wmm_qp.Command | None], wmm_qp.Reference]
"""(t [s], true sim state, previous command) → the reference of this tick."""

StopFn = Callable[[float, SimState], bool]
"""(t, state) → True to end the run early."""

ObserveFn = Callable[[SimRobot], None]
"""Called with the sim after every tick (e.g. to render its plant); must not change it."""


@dataclass
class Trace:
    """Per-tick record of a run (arrays with one row per control tick).

    Attributes:
        t: [s] tick times.
        mode: the reference's mode per tick.
        status: the command's status per tick.
        q: [rad] (n, n_arm) true joint angles at the tick (m for a prismatic joint).
        qd_cmd: [rad/s] (n, n_arm) commanded joint rates.
        wheel_cmd: [rad/s] (n, n_wheels) commanded wheel speeds (n_wheels = 0: a fixed base).
        base_twist_cmd: (n, 3) commanded body twist M·wheel_cmd [m/s, m/s, rad/s].
        base_odom, base_true: (n, 3) base poses [m, m, rad].
        ee_des, ee_true: [m] (n, 3) desired and true EE positions.
        dm: H2 along the run's DM direction at the true joint angles.
        tau: [N·m] (n, n_arm) joint torques from contact.
        box_displacement: [m] how far the box has moved (nan without a box).
        stalled_joint: per tick, the joint stalling the push or -1.
        violations: the referee's counts at the end.
        wall_time: [s] wall-clock time of the run (informative only).
        sim: the sim at the end of the run (to continue it).
    """

    t: FloatArray
    mode: list[str]
    status: list[str]
    q: FloatArray
    qd_cmd: FloatArray
    wheel_cmd: FloatArray
    base_twist_cmd: FloatArray
    base_odom: FloatArray
    base_true: FloatArray
    ee_des: FloatArray
    ee_true: FloatArray
    dm: FloatArray
    tau: FloatArray
    box_displacement: FloatArray
    stalled_joint: np.ndarray
    violations: dict[str, int] = field(default_factory=dict)
    reasons: dict[str, int] = field(default_factory=dict)
    wall_time: float = 0.0
    sim: SimRobot | None = None
    last_command: wmm_qp.Command | None = None

    def at(self, t: float) -> int:
        """Index of the last tick at or before time t [s]."""
        return max(0, int(np.searchsorted(self.t, t + 1e-9)) - 1)


class Progress:
    """Progress on stderr: a one-line bar on a terminal; elsewhere (a pipe, a log) a line at most
    once a second (:class:`~wmm_qp_service.progress.ProgressLine`) and the last one."""

    def __init__(self, label: str, enabled: bool = True) -> None:
        self.label = label
        self.enabled = enabled
        self.tty = sys.stderr.isatty()
        self.last = -1
        self._line = ProgressLine(label)

    def update(self, fraction: float) -> None:
        pct = int(100 * fraction)
        if not self.enabled or pct == self.last:
            return
        self.last = pct
        if not self.tty:
            self._line.update(f"{pct}%")
            return
        bar = "#" * (pct // 4)
        sys.stderr.write(f"\r{self.label} [{bar:<25}] {pct:3d}%")
        sys.stderr.flush()

    def close(self) -> None:
        if not self.enabled:
            return
        if self.tty:
            sys.stderr.write("\n")
            sys.stderr.flush()
        else:
            self._line.done(f"{max(self.last, 0)}%")


@dataclass
class Setup:
    """Everything a run needs.

    Attributes:
        model: kinematic model (its ``config`` is the robot).
        controller: a controller made by :func:`wmm_qp.make_controller`.
        ctl_cfg: the controller's config (rate, gains).
        sim_cfg: the sim's config.
        seed: slip/drift seed.
        scene: obstacles and fence: the qp controller's collision rows keep the robot clear of
            them, the sim's collision referee checks them (None: no obstacles, no fence).
    """

    model: wmm_qp.WmmModel
    controller: wmm_qp.Controller
    ctl_cfg: wmm_qp.ControllerConfig
    sim_cfg: SimConfig
    seed: int | None = None
    scene: Scene | None = None

    @property
    def robot(self) -> wmm_qp.RobotConfig:
        """The robot description the run drives."""
        return self.model.config

    @property
    def W(self) -> FloatArray:
        """W of eq. (8) for this robot (the controller config's, else the robot's default)."""
        return self.ctl_cfg.weights_for(self.robot)


def run(
    setup: Setup,
    reference: ReferenceFn,
    duration: float,
    *,
    dm_direction: FloatArray,
    q_base: FloatArray | None = None,
    q_arm: FloatArray | None = None,
    box: BoxConfig | None = None,
    stop: StopFn | None = None,
    progress: str | None = None,
    sim: SimRobot | None = None,
    previous: wmm_qp.Command | None = None,
    observe: ObserveFn | None = None,
) -> Trace:
    """Run the closed loop for ``duration`` seconds (or until ``stop``).

    Args:
        setup: model, controller and configs.
        reference: the scenario, called once per tick.
        duration: [s] run length.
        dm_direction: u (base frame) for the logged DM.
        q_base, q_arm: start pose (default: origin, the robot's ``arm.start``; the Gen3's is the
            paper's start configuration).
        box: a box to push, or None.
        stop: optional early end.
        progress: label of the progress bar (None = no bar).
        sim: continue with this sim instead of a fresh one (then q_base/q_arm/box are ignored).
        previous: the last command the continued sim received (a run's ``last_command``): bounds
            (13) of the first tick start from it (:func:`anchored`); None: from the measured rates.
        observe: called with the sim after every tick (None: nothing).
    """
    m = setup.model
    W = np.asarray(setup.W, dtype=float)
    u = np.asarray(dm_direction, dtype=float)
    u = u / np.linalg.norm(u)
    if sim is None:
        sim = SimRobot(m, setup.sim_cfg, seed=setup.seed, scene=setup.scene)
        sim.reset(
            q_base=np.zeros(3) if q_base is None else q_base,
            q_arm=q_arm,  # None: the robot's arm.start
            box=box,
        )
    dt = setup.ctl_cfg.dt
    n_sub = max(1, round(setup.sim_cfg.rate_hz / setup.ctl_cfg.rate_hz))
    sim_dt = dt / n_sub
    n_ticks = round(duration / dt)
    t0 = sim.state().t
    rows: dict[str, list] = {
        k: []
        for k in (
            "t",
            "mode",
            "status",
            "q",
            "qd",
            "wh",
            "tw",
            "bo",
            "bt",
            "ed",
            "et",
            "dm",
            "tau",
            "box",
            "stall",
        )
    }
    reasons: dict[str, int] = {}
    bar = Progress(progress) if progress else None
    cmd: wmm_qp.Command | None = None
    wall = time.perf_counter()
    st = sim.state()
    last = previous
    for k in range(n_ticks):
        t = k * dt
        ref = reference(t, st, cmd)
        cmd = setup.controller.step(anchored(sim.robot_state(), last), ref)
        last = cmd
        if cmd.reason:
            key = re.sub(r"[-+]?\d[\d.e-]*", "#", cmd.reason)  # group by kind, not value
            reasons[key] = reasons.get(key, 0) + 1
        J_arm = m.arm.position_jacobian(st.q_arm)[1]
        x_des = ref.x_d if ref.mode != wmm_qp.Mode.DM_CARTESIAN else cmd.x
        rows["t"].append(t)
        rows["mode"].append(str(ref.mode))
        rows["status"].append(str(cmd.status))
        rows["q"].append(st.q_arm)
        rows["qd"].append(cmd.arm_rates)
        rows["wh"].append(cmd.wheel_speeds)
        rows["tw"].append(m.base.body_twist(cmd.wheel_speeds))
        rows["bo"].append(st.base_odom)
        rows["bt"].append(st.base_true)
        rows["ed"].append(np.array(x_des, dtype=float))
        rows["et"].append(st.ee_true)
        rows["dm"].append(directional_manipulability(J_arm, u, W))
        rows["tau"].append(st.tau)
        rows["box"].append(st.box_displacement)
        rows["stall"].append(-1 if st.stalled_joint is None else st.stalled_joint)
        st = sim.step(SimCommand(cmd.wheel_speeds, cmd.arm_rates, period=dt, seq=k), sim_dt)
        for _ in range(n_sub - 1):
            st = sim.step(None, sim_dt)
        if observe is not None:
            observe(sim)
        if bar is not None and k % 50 == 0:
            bar.update((k + 1) / n_ticks)
        if stop is not None and stop(t, st):
            break
    if bar is not None:
        bar.update(1.0)
        bar.close()
    arr = {k: np.array(v, dtype=float) for k, v in rows.items() if k not in ("mode", "status")}
    trace = Trace(
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
        wall_time=time.perf_counter() - wall,
        sim=sim,
        last_command=last,
    )
    return trace


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


def concat(a: Trace, b: Trace) -> Trace:
    """Two successive runs of one sim as one trace (b's violations are the cumulative ones)."""
    reasons = dict(a.reasons)
    for k, v in b.reasons.items():
        reasons[k] = reasons.get(k, 0) + v
    out = Trace(
        t=np.r_[a.t, b.t],
        mode=a.mode + b.mode,
        status=a.status + b.status,
        q=np.vstack([a.q, b.q]),
        qd_cmd=np.vstack([a.qd_cmd, b.qd_cmd]),
        wheel_cmd=np.vstack([a.wheel_cmd, b.wheel_cmd]),
        base_twist_cmd=np.vstack([a.base_twist_cmd, b.base_twist_cmd]),
        base_odom=np.vstack([a.base_odom, b.base_odom]),
        base_true=np.vstack([a.base_true, b.base_true]),
        ee_des=np.vstack([a.ee_des, b.ee_des]),
        ee_true=np.vstack([a.ee_true, b.ee_true]),
        dm=np.r_[a.dm, b.dm],
        tau=np.vstack([a.tau, b.tau]),
        box_displacement=np.r_[a.box_displacement, b.box_displacement],
        stalled_joint=np.r_[a.stalled_joint, b.stalled_joint],
        violations=dict(b.violations),
        reasons=reasons,
        wall_time=a.wall_time + b.wall_time,
        sim=b.sim,
        last_command=b.last_command,
    )
    return out


def make_setup(
    controller: str,
    solver: str | None = None,
    *,
    slip: bool = True,
    seed: int | None = None,
    robot: wmm_qp.RobotConfig | None = None,
    ctl_cfg: wmm_qp.ControllerConfig | None = None,
    wheel_units: str = "rad",
    scene: Scene | None = None,
    physics: str | None = None,
) -> Setup:
    """Load the configs and build the model, the controller and the sim config.

    Args:
        controller: "traditional", "paper" or "qp".
        solver: QP backend name (qp only); None = the config's.
        slip: base slip/drift on (the sim config's values) or off.
        seed: slip seed; None = the sim config's.
        robot: the robot description; None = the default robot file (the Gen3).
        ctl_cfg: the controller config; None = the default controller config.
        wheel_units: the traditional controller's J⁺ units, "rad" or "rim" (controllers/traditional.py).
        scene: obstacles and fence (``--scene``), given to the controller (its collision rows, when
            its config has them on) and to the sim's referee; None: none.
        physics: the sim's plant, "kinematic" or "mujoco"; None: the sim config's ``[physics] plant``.
    """
    from wmm_qp_sim import load_sim_config

    robot = wmm_qp.load_robot_config() if robot is None else robot
    model = wmm_qp.WmmModel(robot)
    cfg = wmm_qp.load_controller_config() if ctl_cfg is None else ctl_cfg
    cfg.weights_for(robot)  # a W of another length than the robot's: the config error, now
    if solver is not None:
        cfg = cfg.with_(qp={"solver": solver})
    if controller == "traditional":
        from wmm_qp.controllers.traditional import TraditionalController

        ctl: wmm_qp.Controller = TraditionalController(model, cfg, wheel_units=wheel_units)
    else:
        ctl = wmm_qp.make_controller(controller, model, cfg)
    # firmware off: the experiments measure the controllers, so the referee must see what a
    # controller commands without the robot's own protective stop masking it
    sim_cfg = load_sim_config().with_(firmware=False)
    if not slip:
        sim_cfg = sim_cfg.with_(slip={"enabled": False})
    if physics is not None:
        sim_cfg = sim_cfg.with_(physics={"plant": physics})
    if scene is not None:
        ctl.set_scene(scene)
    return Setup(model=model, controller=ctl, ctl_cfg=cfg, sim_cfg=sim_cfg, seed=seed, scene=scene)


def rms(a: FloatArray) -> float:
    """Root mean square (0 for an empty array)."""
    return float(np.sqrt(np.mean(np.square(a)))) if a.size else 0.0
