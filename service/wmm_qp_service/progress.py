"""Progress of a long command on stderr (never stdout: ``--json`` output stays parseable).

The first update is shown at once, then at most one per ``every`` seconds, and :meth:`done`
always: a run of a few seconds shows two lines, a long one about one a second. On a terminal
the line is rewritten in place; on a pipe or into a log file each update is its own line.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from typing import TextIO


class ProgressLine:
    """``<label>: <text>, <elapsed> s`` on stderr.

    Args:
        label: the command, e.g. ``verify``.
        every: [s] the shortest time between two updates shown.
        stream: where to write (default: ``sys.stderr`` at the time of each write).
        clock: [s] a monotonic clock (tests pass a fake one).
    """

    def __init__(self, label: str, every: float = 1.0, stream: TextIO | None = None,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.label = label
        self.every = every
        self._stream = stream
        self._clock = clock
        self._t0 = clock()
        self._last: float | None = None
        self._open = False  # a terminal line not yet ended

    @property
    def stream(self) -> TextIO:
        return self._stream if self._stream is not None else sys.stderr

    def elapsed(self) -> float:
        """[s] since the line was created."""
        return self._clock() - self._t0

    def due(self) -> bool:
        """An update now would be shown (the first, or ``every`` seconds after the last shown)."""
        return self._last is None or self._clock() - self._last >= self.every

    def update(self, text: str | Callable[[], str]) -> None:
        """Show ``text`` if due; a callable is only called when it is (for costly texts)."""
        if not self.due():
            return
        self._last = self._clock()
        self._write(text() if callable(text) else text, end=False)

    def done(self, text: str) -> None:
        """Show the final ``text`` (always) and end the line."""
        self._last = self._clock()
        self._write(text, end=True)

    def _write(self, text: str, end: bool) -> None:
        s = self.stream
        line = f"{self.label}: {text}, {self.elapsed():.0f} s"
        try:
            tty = s.isatty()
        except (AttributeError, ValueError):
            tty = False
        try:
            if tty:
                s.write(f"\r\x1b[K{line}" + ("\n" if end else ""))
                self._open = not end
            else:
                s.write(line + "\n")
            s.flush()
        except (OSError, ValueError):  # a closed stderr: progress is never worth a failure
            pass

    def close(self) -> None:
        """End a terminal line left open by :meth:`update` (before other output)."""
        if self._open:
            try:
                self.stream.write("\n")
                self.stream.flush()
            except (OSError, ValueError):
                pass
            self._open = False
