"""What the service side hands the control core between two cycles: mode changes, setpoints,
live obstacles, the sim's evaluation data, the robot's liveliness.

These are the core's inputs that do not come with the robot's state: over Zenoh they are
polled on the control thread before each tick (:class:`~.zenoh_service.ZenohService`); a host
that runs the cycle on its own thread must hand them over to that thread the same way (the core
is not thread-safe). Each takes a validated message.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

import wmm_qp as w
from wmm_qp.config import ShapeConfig
from wmm_qp.fault_codes import FaultCode
from wmm_qp.scene import Scene

from ..protocol import ModeMsg, SetpointMsg, TruthMsg
from ..smoother import OrientationTarget, SetpointSmoother, VelocityEstimator
from .obstacles import LiveObstacles
from .setpoints import Setpoints
from .state_gate import StateGate


class CoreInputs:
    """The input half of :class:`~.core.ControlCore` (which sets every attribute below)."""

    ctl: w.Controller
    scene: Scene
    gate: StateGate
    setpoints: Setpoints
    obstacles: LiveObstacles
    smoother: SetpointSmoother
    estimator: VelocityEstimator
    orient: OrientationTarget
    pose: bool
    mode: w.Mode
    direction: np.ndarray | None
    need_latch: bool
    safe: bool
    resume_needed: bool
    robot_alive: bool
    state: w.RobotState | None
    state_time: float
    truth: TruthMsg | None
    say: Callable[[str], None]
    who: str = "wmm-qp serve"
    """The process the fault lines name (the embedded mode names its own)."""

    def _fault(self, code: FaultCode, what: str) -> None:
        raise NotImplementedError  # ControlCore records it

    def on_truth(self, msg: TruthMsg) -> None:
        """A validated ``sim/truth`` message: kept for telemetry's ``ee_error`` and the status's
        ``robot_violations`` when it is the latched instance's; the control path never reads it."""
        if msg.instance == self.gate.instance:
            self.truth = msg

    def on_mode(self, msg: ModeMsg) -> None:
        """A validated mode change: switch and re-latch the target from the current EE.

        It is also the explicit act that resumes after a safe stop (``resume = "manual"``):
        one sent during the safe stop itself is overruled by the hold that follows the fault,
        so resuming takes a mode message after the fault has cleared.
        """
        self.mode = w.Mode(msg.mode)
        self.direction = None if msg.direction is None else np.asarray(msg.direction, dtype=float)
        self.need_latch = True
        if not self.safe:
            self.resume_needed = False

    def on_setpoint(self, msg: SetpointMsg, now: float) -> bool:
        """A validated setpoint: feed the smoother (track and null-space DM modes only).

        Refused when another operator holds the stream or its stamp does not increase; its
        target is clamped into the fence (:class:`~.setpoints.Setpoints`).

        Returns:
            False when the setpoint was refused.
        """
        if not self.setpoints.admit(msg, now):
            return False
        if self.mode not in (w.Mode.TRACK, w.Mode.DM_NULLSPACE) or self.need_latch:
            return True
        if self.pose:
            self.orient.set_target(msg.q, msg.w)
        x, xd = self.setpoints.target(msg)
        if xd is not None:  # a scripted trajectory: its own feed-forward velocity
            self.smoother.set_target(x, xd)
        else:
            xf, v = self.estimator.update(x, msg.stamp)
            self.smoother.set_target(xf, v)
        return True

    def on_obstacles(self, shapes: tuple[ShapeConfig, ...], now: float) -> None:
        """A validated live obstacle set arrived: it replaces the previous live set, atomically
        (the controller sees it from the next tick on); the scene's obstacles stay."""
        if self.obstacles.update(shapes, now):
            self.say(f"{self.who}: live obstacles fresh again ({len(shapes)})")
        self.ctl.set_obstacles(self.scene.obstacles + shapes)

    def check_obstacles(self, now: float) -> None:
        """The live set goes stale after ``watchdog.obstacles_timeout`` without a message: it is
        kept (said once, and shown by the status)."""
        if self.obstacles.went_stale(now):
            self.say(f"{self.who}: live obstacles stale (none for {now - self.obstacles.time:.2f} s); "
                     f"the last set ({len(self.obstacles.shapes)}) is kept")

    def on_robot_alive(self, alive: bool) -> None:
        """The sim's liveliness token appeared or vanished."""
        if self.robot_alive and not alive:
            self._fault(FaultCode.ROBOT_LOST, "robot lost (liveliness)")
            self.state_time = -math.inf
            self.safe = self.state is not None  # the next ticks brake (see _safe_stop)
        self.robot_alive = alive
