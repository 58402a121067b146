"""The experiments' progress on stderr."""

from __future__ import annotations

import sys

from wmm_qp_service.progress import ProgressLine


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
