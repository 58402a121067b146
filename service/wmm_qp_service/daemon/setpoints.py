"""Setpoints: one operator per stream, stamps that increase, targets inside the fence.

One operator holds the stream: the first source, for as long as its setpoints keep coming
(``operator_timeout``); another source's setpoints are refused and counted (``operator``), and
so is a setpoint whose stamp does not increase (``stamp``: a frozen or replayed stream would
otherwise look alive and never move the EE). A stamp more than ``setpoint_timeout`` behind the
last one starts a new stream (a restarted client, or one bogus far-future stamp before it),
reported as a fault. An accepted target is clamped into the scene's fence and above the floor
margin (``clamped``) before the smoother sees it: never chased beyond it.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable

import numpy as np

from wmm_qp.fault_codes import FaultCode
from wmm_qp.scene import Scene

from ..config import WatchdogConfig
from ..protocol import SetpointMsg


class Setpoints:
    """The setpoint stream's gate and the fence clamp.

    Args:
        wd: the watchdog's timeouts (``operator_timeout``, ``setpoint_timeout``).
        scene: the scene whose fence clamps the targets.
        z_floor: [m] targets stay above this height (the floor plus its margin).
        pose: the pose task (r = 6): setpoints' orientations are followed, else ignored and counted.
        refused: where refusals are counted (shared with the daemon's other checks).
        fault: records a fault (``fault(code, what)``).

    Attributes:
        operator: the source that holds the stream ("" before the first setpoint).
        operator_conflicts: setpoints of another source refused while it held it.
        time: [s] when the last setpoint was accepted (-inf: never).
        orientation_ignored: setpoints whose orientation the position task ignored.
        clamped: targets clamped into the fence or above the floor margin; ``last_clamp`` says how.
    """

    def __init__(self, wd: WatchdogConfig, scene: Scene, z_floor: float, pose: bool, refused: Counter[str],
                 fault: Callable[[FaultCode, str], None]) -> None:
        self.wd = wd
        self.scene = scene
        self.z_floor = z_floor
        self.pose = pose
        self.refused = refused
        self.fault = fault
        self.operator = ""
        self.operator_time = -math.inf
        self.operator_stamp = -math.inf
        self.operator_conflicts = 0
        self.time = -math.inf
        self.orientation_ignored = 0
        self.clamped = 0
        self.last_clamp = ""

    def admit(self, msg: SetpointMsg, now: float) -> bool:
        """A validated setpoint arrived at ``now`` [s]: False when it is refused (another
        operator's, or a stamp that does not increase)."""
        wd = self.wd
        if msg.source != self.operator:
            if self.operator and now - self.operator_time < wd.operator_timeout:
                self.refused["operator"] += 1
                self.operator_conflicts += 1
                self.fault(FaultCode.SETPOINT_CONFLICT,
                           f"setpoint conflict (from {msg.source!r} refused: {self.operator!r} holds the stream)")
                return False
            self.operator, self.operator_stamp = msg.source, -math.inf
        if not msg.stamp > self.operator_stamp:
            if msg.stamp < self.operator_stamp - wd.setpoint_timeout:  # far behind: a new stream
                self.fault(FaultCode.SETPOINT_STAMP_BACK, f"setpoint stamp jumped back (from {msg.source!r}: "
                           f"{msg.stamp!r} after {self.operator_stamp!r}; taken as a restarted stream)")
            else:
                self.refused["stamp"] += 1
                self.fault(FaultCode.SETPOINT_STAMP_STALE, f"setpoint stamp not increasing (from {msg.source!r}: "
                           f"{msg.stamp!r} after {self.operator_stamp!r})")
                return False
        self.operator_time, self.operator_stamp = now, msg.stamp
        self.time = now
        if not self.pose and (msg.q is not None or msg.w is not None):
            self.orientation_ignored += 1  # the position task (r = 3) has no orientation target
        return True

    def target(self, msg: SetpointMsg) -> tuple[np.ndarray, np.ndarray | None]:
        """The accepted setpoint's target [m] inside the fence, and its feed-forward velocity
        [m/s] (None: the setpoint has none), zero along a clamped axis."""
        x_in = np.asarray(msg.x, dtype=float)
        x, moved = self.scene.clamp_target(x_in, self.z_floor)  # never beyond the fence
        if moved:
            self.clamped += 1
            self.last_clamp = f"setpoint clamped to the fence: {moved}"
        if msg.xd is None:
            return x, None
        xd = np.asarray(msg.xd, dtype=float)  # a scripted trajectory: its own feed-forward velocity
        if moved:
            xd = np.where(x != x_in, 0.0, xd)  # no feed-forward along a clamped axis
        return x, xd
