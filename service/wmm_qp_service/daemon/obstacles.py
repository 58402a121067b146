"""Live obstacles: the latest set a client sent (``<robot>/obstacles``), beside the scene's own.

Each set replaces the previous one atomically (the controller sees it from the next tick on);
after ``watchdog.obstacles_timeout`` without a message the set is stale: kept, said once, and
shown by the status.
"""

from __future__ import annotations

import math

from wmm_qp.config import ShapeConfig


class LiveObstacles:
    """The live obstacle set and its freshness.

    Args:
        timeout: [s] the set goes stale after this long without a message.

    Attributes:
        shapes: the live set (the scene's obstacles are not in it).
        time: [s] when the last set arrived (-inf: none yet).
        stale: no set for longer than ``timeout``.
    """

    def __init__(self, timeout: float) -> None:
        self.timeout = timeout
        self.shapes: tuple[ShapeConfig, ...] = ()
        self.time = -math.inf
        self.stale = False

    def update(self, shapes: tuple[ShapeConfig, ...], now: float) -> bool:
        """A validated set arrived at ``now`` [s]; True: the set had gone stale until now."""
        was_stale = self.stale
        self.shapes, self.time, self.stale = shapes, now, False
        return was_stale

    def went_stale(self, now: float) -> bool:
        """True once, at the first ``now`` [s] more than ``timeout`` after the last set."""
        if not self.stale and self.time > -math.inf and now - self.time > self.timeout:
            self.stale = True
            return True
        return False
