"""Controllers that wrap a real one to inject a fault at a chosen step."""

from __future__ import annotations

from typing import Any

import wmm_qp as w


class OverLimitOnce:
    """A controller whose ``n``-th command asks joint 1 for twice its velocity limit."""

    def __init__(self, ctl: w.Controller, n: int, v_max: float) -> None:
        self.ctl, self.n, self.v_max, self.steps = ctl, n, v_max, 0

    def step(self, state: w.RobotState, ref: w.Reference) -> w.Command:
        self.steps += 1
        cmd = self.ctl.step(state, ref)
        if self.steps == self.n:
            cmd.arm_rates = cmd.arm_rates.copy()
            cmd.arm_rates[0] = 2.0 * self.v_max
        return cmd

    def __getattr__(self, name: str) -> Any:
        return getattr(self.ctl, name)
