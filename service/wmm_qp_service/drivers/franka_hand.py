"""The Franka Hand behind the driver: pylibfranka's ``Gripper`` in a process of its own.

pylibfranka holds the GIL through a whole gripper command (``Gripper.move`` for 0.5 s held a
thread of the same process off for all of it) and through each ``read_once``: in the driver's
process it would stall the 1 kHz joint loop, so the hand lives in a child process. The driver
hands it commands through a queue (:meth:`FrankaHand.command`, never blocks) and reads the
width it last measured from shared memory (:attr:`FrankaHand.width`, [m]; nan until the first
reading). Between commands the child reads the width every ``READ_PERIOD``; during a command
(libfranka's blocking move or grasp) the width is the one measured before it, and is read again
when it ends.
"""

from __future__ import annotations

import contextlib
import math
import multiprocessing as mp
import queue
import signal
import sys
from typing import Any

READ_PERIOD = 0.01
"""[s] how often the child reads the hand's width while no command runs."""


def _serve(robot_ip: str, commands: Any, width: Any, stop: Any) -> None:
    """The child: connect, then execute commands and read the width until ``stop``.

    Ctrl-C in a terminal reaches the whole foreground process group: the child ignores it (no
    ``KeyboardInterrupt`` traceback of its own) and ends when the driver, which stops on it, sets
    ``stop``."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        import pylibfranka as fr

        g = fr.Gripper(robot_ip)
    except Exception as e:  # no hand at that address: say so once, report nan
        print(f"wmm-qp driver franka: no gripper at {robot_ip}: {type(e).__name__}: {e}", file=sys.stderr, flush=True)
        return
    while not stop.is_set():
        try:
            width.value = float(g.read_once().width)
        except Exception as e:
            print(f"wmm-qp driver franka: gripper: {type(e).__name__}: {e}", file=sys.stderr, flush=True)
            return
        try:
            action, w, speed, force = commands.get(timeout=READ_PERIOD)
        except queue.Empty:
            continue
        try:
            if action == "grasp":
                g.grasp(w, speed, force, 0.08, 0.08)  # epsilon: hold at any width the object stops the fingers
            else:
                g.move(w, speed)
        except Exception as e:  # a refused or failed command: said, the hand stays usable
            print(f"wmm-qp driver franka: gripper {action} failed: {type(e).__name__}: {e}", file=sys.stderr,
                  flush=True)


class FrankaHand:
    """The hand's child process and its channels.

    Args:
        width_max: [m] the hand's full opening (``open``'s target).
        speed_max: [m/s] commands' speeds are clamped to it.
        force_max: [N] grasp forces are clamped to it.
    """

    def __init__(self, width_max: float, speed_max: float, force_max: float) -> None:
        self.width_max, self.speed_max, self.force_max = width_max, speed_max, force_max
        ctx = mp.get_context("spawn")
        self._commands = ctx.Queue(16)
        self._width = ctx.Value("d", math.nan, lock=False)
        self._stop = ctx.Event()
        self._ctx = ctx
        self._proc: Any = None

    def start(self, robot_ip: str) -> None:
        """Start the child process that connects to the hand at ``robot_ip``."""
        self._proc = self._ctx.Process(target=_serve, args=(robot_ip, self._commands, self._width, self._stop),
                                       daemon=True)
        self._proc.start()

    @property
    def width(self) -> float:
        """[m] the last measured opening (nan: none yet, or no hand)."""
        return float(self._width.value)

    def command(self, action: str, width: float, speed: float, force: float) -> bool:
        """Queue a validated gripper command, clamped to the hand's limits; False: the queue is full."""
        target = {"open": self.width_max, "close": 0.0}.get(action, width)
        cmd = (action, min(max(target, 0.0), self.width_max), min(max(speed, 1e-3), self.speed_max),
               min(max(force, 0.0), self.force_max))
        try:
            self._commands.put_nowait(cmd)
        except queue.Full:
            return False
        return True

    def close(self) -> None:
        """Stop the child (a running command ends first, up to 5 s; then it is killed)."""
        self._stop.set()
        if self._proc is not None:
            self._proc.join(5.0)
            if self._proc.is_alive():
                self._proc.kill()
                self._proc.join(1.0)
        with contextlib.suppress(Exception):
            self._commands.close()
