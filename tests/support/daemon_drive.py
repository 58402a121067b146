"""The daemon's core (ControlCore) driven by hand, without transport: a plant that integrates
commands exactly, the messages a test sends it, one tick, and the largest step between
consecutive commands relative to the acceleration bound of (13)."""

from __future__ import annotations

import itertools

import numpy as np
from wmm_qp_service.daemon import ControlCore
from wmm_qp_service.protocol import ModeMsg, SetpointMsg, StateMsg

import wmm_qp as w

DT = 0.002


class Plant:
    """Integrates commands exactly (executed = commanded) and makes StateMsgs."""

    def __init__(self, model: w.WmmModel) -> None:
        self.model = model
        self.q_base = np.zeros(3)
        self.q_arm = np.array(model.config.arm.start)
        self.v_arm = np.zeros(model.n_arm)
        self.wheels = np.zeros(model.n_wheels)
        self.seq = 0
        self.instance = "sim-A"
        self.protective_stops = 0
        self.refused: dict[str, int] = {}
        self.cmd_seq = -1

    def apply(self, cmd: w.Command) -> None:
        self.v_arm, self.wheels = cmd.arm_rates.copy(), cmd.wheel_speeds.copy()
        self.q_arm = self.q_arm + DT * self.v_arm
        self.q_base = self.q_base + DT * (self.model.base.P(float(self.q_base[2])) @ self.wheels)

    def msg(self, **kw: object) -> StateMsg:
        self.seq += 1
        d: dict[str, object] = dict(
            robot="wmm", seq=self.seq, stamp=0.0, t=0.0, q_base=self.q_base.tolist(),
            q_arm=self.q_arm.tolist(), v_arm=self.v_arm.tolist(), wheel_speeds=self.wheels.tolist(),
            tau=[0.0] * self.model.n_arm, instance=self.instance, lease="core", cmd_seq=self.cmd_seq,
            protective_stops=self.protective_stops, refused=dict(self.refused))
        d.update(kw)
        return StateMsg(**d)  # type: ignore[arg-type]


def max_step_ratio(robot: w.RobotConfig, cmds: list[w.Command]) -> float:
    a = np.asarray(robot.arm.acceleration_max) * DT
    wa = np.asarray(robot.base.wheel_acceleration_max) * DT
    worst = 0.0
    for p, q in itertools.pairwise(cmds):
        worst = max(worst, float(np.max(np.abs(q.arm_rates - p.arm_rates) / a)),
                    float(np.max(np.abs(q.wheel_speeds - p.wheel_speeds) / wa, initial=0.0)))
    return worst


def rotated(quat: np.ndarray, axis: list[float], angle: float) -> np.ndarray:
    from wmm_qp_service.smoother import quat_exp, quat_multiply

    return quat_multiply(quat_exp(angle * np.asarray(axis) / np.linalg.norm(axis)), quat)


def mode(core: ControlCore, name: str) -> None:
    core.on_mode(ModeMsg(robot="wmm", seq=1, stamp=0.0, mode=name))


def setpoint(x: np.ndarray, stamp: float, source: str = "op") -> SetpointMsg:
    return SetpointMsg(robot="wmm", seq=1, stamp=stamp, x=x.tolist(), source=source)


def send(core: ControlCore, t: float) -> int:
    """Number the tick's command and record it sent at ``t`` [s], as the daemon's cycle does
    (a state naming that seq as ``cmd_seq`` confirms the stream); returns its seq."""
    core.stream.numbered()
    core.stream.sent(core.stream.seq, t)
    return core.stream.seq


def tick(core: ControlCore, plant: Plant, t: float) -> w.Command:
    cmd = core.tick(t)
    assert cmd is not None
    send(core, t)
    plant.apply(cmd)
    plant.cmd_seq = core.stream.seq
    return cmd
