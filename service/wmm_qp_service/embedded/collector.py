"""Python's cyclic garbage collector kept off the command's path (:class:`SlackCollector`)."""

from __future__ import annotations

import gc
import time
from typing import Any


class SlackCollector:
    """Python's cyclic garbage collector kept off the command's path.

    At :meth:`start` everything allocated so far (the model, the compiled kernels, the configs)
    is collected once and frozen (``gc.freeze``: never scanned again) and automatic collection is
    disabled, for every thread of the process; :meth:`slack` then collects the young generation
    after the command, when its allocations passed the interpreter's threshold (generation 1
    every 10th time, generation 2 every 100th), so a collection never lands inside a tick.

    Args:
        enabled: False: the interpreter's own collection, anywhere.

    Attributes:
        collections: per generation, the collections run in the slack.
        max_us, total_us: [µs] the longest one and their sum.
    """

    def __init__(self, enabled: bool = True) -> None:
        self.enabled = enabled
        self.threshold = max(1, gc.get_threshold()[0])
        self.collections = [0, 0, 0]
        self.max_us = 0.0
        self.total_us = 0.0
        self._n = 0
        self._was_enabled = True

    def start(self) -> None:
        if not self.enabled:
            return
        self._was_enabled = gc.isenabled()
        gc.collect()
        gc.freeze()
        gc.disable()

    def slack(self) -> None:
        """Collect now if the young generation is due (never raises)."""
        if not self.enabled or gc.get_count()[0] < self.threshold:
            return
        self._n += 1
        gen = 2 if self._n % 100 == 0 else 1 if self._n % 10 == 0 else 0
        t = time.perf_counter_ns()
        gc.collect(gen)
        us = (time.perf_counter_ns() - t) * 1e-3
        self.collections[gen] += 1
        self.total_us += us
        self.max_us = max(self.max_us, us)

    def stop(self) -> None:
        if not self.enabled:
            return
        gc.unfreeze()
        if self._was_enabled:
            gc.enable()

    def report(self) -> dict[str, Any]:
        """What the collector did (the cycle report's ``gc``)."""
        return {"enabled": self.enabled, "collections": list(self.collections),
                "max_us": round(self.max_us, 1), "total_us": round(self.total_us, 1)}
