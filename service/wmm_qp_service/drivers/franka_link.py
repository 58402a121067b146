"""libfranka's side of ``wmm-qp driver franka``: the robot, its joint velocity control, the loss
of that control on a reflex and its recovery.

While a control runs, each cycle is libfranka's ``readOnce`` / ``writeOnce`` on it. When libfranka
ends the motion with a ``ControlException`` (a reflex of the robot: a collision, a limit, a
discontinuity), :meth:`FrankaLink.lose` gives the control back — dropping it sends libfranka's
``StopMove``, as libfranka's own control loop does after an error; a control still held would make
``automatic_error_recovery`` and a new control fail with libfranka's "another control or read
operation is running". Until :meth:`FrankaLink.recover` succeeds the robot is only read
(``Robot.read_once``: its states keep coming at 1 kHz, the robot in its ``Reflex`` mode) and
nothing is written. :meth:`FrankaLink.recover` runs libfranka's ``automatic_error_recovery`` and
starts a new control; the driver (:mod:`.franka`) asks for it on the first command of a new
stream once the arm is at rest.

Only this module and :mod:`.franka_hand` call ``pylibfranka``.
"""

from __future__ import annotations

import sys
import threading
from collections.abc import Callable
from typing import Any, Protocol

import numpy as np
from wmm_qp_robot.shaper import CommandShaper


class FrankaLink:
    """A connected robot and its joint velocity control (or none, after libfranka ended it).

    Args:
        fr: the ``pylibfranka`` module.
        robot: a connected ``pylibfranka.Robot``.
    """

    def __init__(self, fr: Any, robot: Any) -> None:
        self.fr = fr
        self.robot = robot
        self.ctl: Any = None  # the active control (None: libfranka ended it, not yet recovered)
        self._read_by_ctl = False  # this cycle's state came from the active control (write answers it)
        self._t: float | None = None  # [s] the robot's time of the last state read

    @property
    def controlling(self) -> bool:
        """A joint velocity control runs: the cycle's velocities are written."""
        return self.ctl is not None

    def start(self) -> None:
        """Start libfranka's joint velocity control (joint impedance controller)."""
        self.ctl = self.robot.start_joint_velocity_control(self.fr.ControllerMode.JointImpedance)
        self._read_by_ctl = False

    def read(self) -> tuple[Any, float]:
        """The next robot state and the robot's time since the previous one [s] (0.001 at 1 kHz;
        0 for the first state). Raises libfranka's exceptions (a reflex: ``ControlException``)."""
        self._read_by_ctl = self.ctl is not None
        st = self.ctl.readOnce()[0] if self.ctl is not None else self.robot.read_once()
        t = float(st.time.to_sec())
        elapsed = 0.0 if self._t is None else max(t - self._t, 0.0)
        self._t = t
        return st, elapsed

    def write(self, v: np.ndarray, finished: bool = False) -> None:
        """Write this cycle's joint velocities [rad/s] (nothing while no control runs, nor in the
        cycle a new control started: its first command answers its first state);
        ``finished``: the last command of the motion."""
        if self.ctl is None or not self._read_by_ctl:
            return
        cmd = self.fr.JointVelocities(v.tolist())
        if finished:
            cmd.motion_finished = True
        self.ctl.writeOnce(cmd)
        if finished:
            self.ctl = None

    def lose(self) -> None:
        """libfranka ended the motion: give the control back (its release sends ``StopMove``)."""
        self.ctl = None

    def recover(self) -> str | None:
        """libfranka's automatic error recovery, then a new joint velocity control.

        Returns:
            None on success; why not otherwise (the robot refused: e.g. a manual recovery is
            required). A lost connection raises ``NetworkException``.
        """
        fr = self.fr
        try:
            self.robot.automatic_error_recovery()
            self.start()
        except fr.NetworkException:
            raise
        except (fr.FrankaException, RuntimeError) as e:
            return f"{type(e).__name__}: {str(e).strip() or 'no reason given'}"
        return None


class Driven(Protocol):
    """What :func:`drive` needs of the driver: its shaper and its reflex handler."""

    shaper: CommandShaper

    def reflex(self, e: Exception, link: FrankaLink) -> None: ...


def drive(fr: Any, link: FrankaLink, driver: Driven, stop: threading.Event, max_cycles: int | None, robot_ip: str,
          step: Callable[[bool], tuple[np.ndarray, int]], after: Callable[[bool], None]) -> int:
    """libfranka's cycle until ``stop`` (or ``max_cycles``), then brake to rest and finish the
    motion; a reflex is a protective stop (:meth:`FrankaDriver.reflex`) and the cycle goes on.

    Args:
        fr: pylibfranka (its exception types).
        link: the robot.
        driver: whose shaper halts when finishing, and who takes a reflex.
        stop, max_cycles: when to brake and finish.
        robot_ip: for the message when the connection is lost.
        step: one cycle up to the write — read the robot, take the inputs (none once
            finishing, its argument), shape the command — giving the velocities to write and
            the cycles so far.
        after: the cycle's slack after the write (its argument: the motion finished).

    Returns:
        0 after a clean stop; 1 when the connection was lost.
    """
    finishing = False
    while True:
        try:
            v, cycles = step(finishing)
            if not finishing and (stop.is_set() or (max_cycles is not None and cycles >= max_cycles)):
                finishing = True  # brake to rest, then finish the motion
                driver.shaper.halt()
            done = finishing and driver.shaper.at_rest
            link.write(v, finished=done)
            after(done)
            if done:
                return 0
        except fr.NetworkException as e:
            print(f"wmm-qp driver franka: error: lost the connection to the robot at {robot_ip}: {e}",
                  file=sys.stderr, flush=True)
            return 1
        except fr.ControlException as e:
            driver.reflex(e, link)
            if finishing:
                return 0
