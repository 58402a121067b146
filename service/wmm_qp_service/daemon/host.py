"""The control host's inputs, once for every way the core is hosted: the daemon over Zenoh, the
embedded mode in a robot's own cycle, the ROS 2 face.

Every input is validated on receipt (:class:`~wmm_qp_service.validation.Validator`: one line of
reason counted per refusal, never raised) and kept: every mode change in order, the latest
setpoint, the latest obstacle set, the latest truth. :meth:`HostInputs.apply` hands what was kept
to the core at one point of each tick — after the tick's state, before its command — in the daemon
and in the embedded mode alike; the status's ``rejected`` and ``accepted`` come from here too.
"""

from __future__ import annotations

from collections import Counter, deque

from ..config import ServiceConfig
from ..protocol import ModeMsg, ObstaclesMsg, SetpointMsg, StateMsg, TruthMsg
from ..validation import Validator
from .core import ControlCore


class HostInputs:
    """The validators of a hosted core's inputs and what they accepted since the last tick.

    Args:
        svc: the service config (the robot id every message must name, the validation limits).
        n_arm, n_wheels: the robot's sizes (a state must match them).
    """

    def __init__(self, svc: ServiceConfig, n_arm: int, n_wheels: int) -> None:
        lim = svc.validation
        self.v_state = Validator(StateMsg, svc.robot, lim, n_arm=n_arm, n_wheels=n_wheels)
        self.v_truth = Validator(TruthMsg, svc.robot, lim)
        self.v_mode = Validator(ModeMsg, svc.robot, lim)
        self.v_setpoint = Validator(SetpointMsg, svc.robot, lim)
        self.v_obstacles = Validator(ObstaclesMsg, svc.robot, lim)
        self._modes: deque[ModeMsg] = deque(maxlen=256)
        self._setpoint: SetpointMsg | None = None
        self._obstacles = False  # a new set was accepted (its shapes: the validator's)
        self._truth: TruthMsg | None = None

    def take(self, kind: str, data: bytes) -> bool:
        """Validate one payload of ``kind`` (``mode``, ``setpoint``, ``obstacles``, ``truth``) and
        keep it for the next :meth:`apply`; False: refused (counted), or not an input of the core."""
        if kind == "mode":
            if (m := self.v_mode(data)) is None:
                return False
            self._modes.append(m)
        elif kind == "setpoint":
            if (sp := self.v_setpoint(data)) is None:
                return False
            self._setpoint = sp
        elif kind == "obstacles":
            if self.v_obstacles(data) is None:
                return False
            self._obstacles = True
        elif kind == "truth":
            if (tr := self.v_truth(data)) is None:
                return False
            self._truth = tr
        else:
            return False
        return True

    def apply(self, core: ControlCore, now: float) -> None:
        """Hand the core what was kept since the last tick, at ``now`` [s]: every mode change in
        order, then the latest setpoint, obstacle set and truth."""
        while self._modes:
            core.on_mode(self._modes.popleft())
        if self._setpoint is not None:
            core.on_setpoint(self._setpoint, now)
            self._setpoint = None
        if self._obstacles:
            core.on_obstacles(self.v_obstacles.shapes, now)
            self._obstacles = False
        if self._truth is not None:
            core.on_truth(self._truth)
            self._truth = None

    def rejected(self, core: ControlCore) -> Counter[str]:
        """Rejected and refused messages by reason, every key together (the status's ``rejected``)."""
        return (self.v_state.rejected + self.v_mode.rejected + self.v_setpoint.rejected
                + self.v_obstacles.rejected + self.v_truth.rejected + core.refused)

    def accepted(self) -> dict[str, int]:
        """Accepted messages by key (the status's ``accepted``)."""
        return {"state": self.v_state.accepted, "mode": self.v_mode.accepted,
                "setpoint": self.v_setpoint.accepted, "obstacles": self.v_obstacles.accepted}
