"""The sim's parallel gripper: a width that moves at a commanded speed towards its target.

A kinematic model, as the rest of the sim: ``open`` and ``close`` move to the full and zero
width, ``move`` to a width, ``grasp`` closes to a width and holds (no object: the fingers stop at
the width). Speed and force are clamped to the robot file's ``[gripper]`` limits, the width to
[0, ``width_max``].
"""

from __future__ import annotations

from wmm_qp.config import GripperConfig

ACTIONS = ("open", "close", "move", "grasp")


class Gripper:
    """A parallel gripper's width [m], stepped by :meth:`step`.

    Args:
        cfg: the robot file's gripper limits.
    """

    def __init__(self, cfg: GripperConfig) -> None:
        self.cfg = cfg
        self.width = cfg.width_max  # [m] starts open
        self.target = cfg.width_max  # [m]
        self.speed = 0.0  # [m/s] of the running command
        self.force = 0.0  # [N] of the running grasp (0: none)

    def command(self, action: str, width: float = 0.0, speed: float = 0.05, force: float = 0.0) -> bool:
        """Start a gripper command (replacing the running one); False: an unknown action."""
        if action not in ACTIONS:
            return False
        c = self.cfg
        target = {"open": c.width_max, "close": 0.0}.get(action, width)
        self.target = min(max(float(target), 0.0), c.width_max)
        self.speed = min(max(float(speed), 0.0), c.speed_max)
        self.force = min(max(float(force), 0.0), c.force_max) if action == "grasp" else 0.0
        return True

    def step(self, dt: float) -> float:
        """Move the fingers for ``dt`` [s]; the new width [m]."""
        d = self.target - self.width
        s = self.speed * dt
        self.width = self.target if abs(d) <= s else self.width + (s if d > 0 else -s)
        return self.width
