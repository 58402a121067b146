"""An experiment written once: its phases, what each one commands, what the run records.

A :class:`Scenario` is a sequence of :class:`Phase` s; each phase has a mode (and its DM
direction), a duration and, when it streams one, a target: a function of the time since the
phase's first tick and of the phase's :class:`Anchor`, the EE pose the controller estimates at
that tick. A phase may place a box before its first tick and end early (``done``).

Two drivers run a scenario and record the same per-tick :class:`~.trace.Trace`:

- in process (:func:`.runner.run`): the controller stepped directly against the simulated
  robot, deterministic; a phase starts at the first control tick at or after its start time;
- in real time (:func:`.realtime.run_realtime`): the daemon and the sim as processes over
  Zenoh; the client switches the daemon's mode and streams the phase's targets for d seconds.

What a phase needs from the robot it asks a :class:`Probe`, which each driver answers from its
own source (the sim's state in process, the sim's ``sim/truth`` in real time).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from wmm_qp_sim import BoxConfig

import wmm_qp
from wmm_qp.config import FloatArray


@dataclass(frozen=True)
class Anchor:
    """What a phase starts from: the EE pose the controller estimates at the phase's first tick
    (the model's kinematics at the measured joints and the odometry base pose: what a real
    controller knows).

    Attributes:
        x: [m] EE position (world).
        quat: EE orientation, a quaternion [x, y, z, w] (world), with the pose task; None
            without it, or where the driver does not know it (real time).
    """

    x: FloatArray
    quat: FloatArray | None = None


@dataclass(frozen=True)
class Target:
    """A phase's setpoint at one instant.

    Attributes:
        x_d: [m] desired EE position (world).
        xd_d: [m/s] its feed-forward velocity.
        quat_d: desired EE orientation [x, y, z, w] (pose task); None: none.
    """

    x_d: FloatArray
    xd_d: FloatArray
    quat_d: FloatArray | None = None


class Probe(Protocol):
    """What a phase may ask of the robot it runs on (each driver answers from its own source)."""

    def ee_true(self) -> FloatArray:
        """[m] the true EE position now (ground truth, world)."""
        ...

    def place_box(self, box: BoxConfig) -> None:
        """Put ``box`` in the scene now, and return once the robot has it."""
        ...

    def box_moved(self) -> float:
        """[m] how far the placed box has moved along its push axis (nan: no box)."""
        ...


TargetFn = Callable[[float, Anchor], Target]
"""(t [s] since the phase's first tick, the phase's anchor) → the setpoint."""

BoxFn = Callable[[FloatArray], BoxConfig]
"""(the true EE position [m] at the phase's start) → the box to place before its first tick."""

DoneFn = Callable[[float, Probe], bool]
"""(t [s] since the phase's first tick, the robot after that tick) → True to end the phase now."""


@dataclass(frozen=True)
class Phase:
    """One phase of a scenario.

    Attributes:
        name: the phase's name (unique in its scenario; :attr:`.trace.Trace.phase_starts`).
        mode: the controller's mode.
        duration: [s] how long it lasts (unless ``done`` ends it earlier).
        direction: DM direction u (base frame) handed with the mode; None: the config's.
        target: the setpoint; None: none (the controller moves the EE by itself, as in
            DM_CARTESIAN, or holds it).
        box: the box to place at the phase's start; None: none.
        done: an early end; None: the phase lasts ``duration``.
    """

    name: str
    mode: wmm_qp.Mode
    duration: float
    direction: FloatArray | None = None
    target: TargetFn | None = None
    box: BoxFn | None = None
    done: DoneFn | None = None

    def reference(self, t: float, anchor: Anchor) -> wmm_qp.Reference:
        """The controller's reference at ``t`` [s] since the phase's first tick (no target: x_d None)."""
        if self.target is None:
            return wmm_qp.Reference(mode=self.mode, direction=self.direction)
        g = self.target(t, anchor)
        return wmm_qp.Reference(mode=self.mode, x_d=g.x_d, xd_d=g.xd_d, direction=self.direction, quat_d=g.quat_d)

    def mode_message(self) -> tuple[str, list[float] | None]:
        """The mode and direction a client sends to the daemon for this phase."""
        return str(self.mode), None if self.direction is None else [float(v) for v in self.direction]


@dataclass(frozen=True)
class Scenario:
    """An experiment's run: its phases in order.

    Attributes:
        name: its label (progress lines).
        phases: the phases, in order.
        dm_direction: u (base frame) of the DM the trace records.
    """

    name: str
    phases: tuple[Phase, ...]
    dm_direction: FloatArray

    def __post_init__(self) -> None:
        names = [p.name for p in self.phases]
        if not names or len(set(names)) != len(names):
            raise ValueError(f"scenario {self.name!r}: phases need unique names, got {names}")
        u = np.asarray(self.dm_direction, dtype=float)
        object.__setattr__(self, "dm_direction", u / np.linalg.norm(u))

    @property
    def duration(self) -> float:
        """[s] the phases' durations together."""
        return float(sum(p.duration for p in self.phases))
