"""The 1 kHz command shaper of a robot that aborts a discontinuous velocity stream (Franka's FCI).

The daemon sends joint rates at its own rate (500 Hz or 1 kHz), over a network that may delay or
lose some; Franka's joint velocity interface wants one command every millisecond, each within the
joint's velocity, acceleration and jerk limits from the previous one, or it aborts the motion.
:class:`CommandShaper` sits between the two: it holds the latest accepted command as the
**target** and moves its output towards it, one cycle at a time, at most ``jerk_max·dt`` of
acceleration change and ``acceleration_max·dt`` of velocity change per cycle (a jerk-limited
velocity tracker, below). Pure: no libfranka, no clock, no transport — the driver
(``wmm_qp_service.drivers.franka``) feeds it commands and the robot's cycles.

A cycle's change is bounded by the robot time elapsed since the previous cycle, not by the
nominal period: the tracker below runs with ``h``, that time (a period at most), in place of
``dt``. However close a driver's cycles come (a loop whose cycles bunched under load) the output
changes by at most ``acceleration_max·h`` and stays within the velocity limits; its acceleration
changes by at most ``jerk_max·max(h, h_prev)``, ``h_prev`` the cycle before's (a cycle shorter
than the one that landed the output on its target stops accelerating as fast as that one started:
the landing's acceleration is at most ``jerk_max·h_prev``). A cycle at the same robot time as the
last changes nothing; a late one (h > dt) moves the output by one period's worth at most. A robot
whose every cycle is a whole period of its time (Franka's: 1 ms) gets the fixed-period tracker.

Firmware duties: the stream rules every robot keeps (:class:`~.stream_rules.StreamRules`, the
simulated robot's too): an illegal command (past a velocity limit, non-finite) is refused with a
protective stop; a stop ends its stream; after a protective stop only a new stream, the arm at
rest, resumes. Besides them, the shaper's own: **stale commands** (none for ``stale_timeout``: the
target becomes 0, the arm brakes jerk-limited to rest, ``stale``); a command from which a joint
could not brake before its position limit is refused, and so is going on when the next cycle's
state could not stop before one (protective stops, ``cannot_stop_before_limit``).

The tracker: with e = v_target − v, the acceleration that makes the most progress yet can still
be ramped back to 0 at the jerk limit without overshooting the target solves
a·dt + a²/(2·j_max) = |e| (continuous braking of the acceleration, conservative for the discrete
ramp), clipped to ±acceleration_max, to a previous acceleration ± jerk_max·dt, and to the
velocity limits. Since a target is never beyond ±velocity_max and every state keeps
v + a·|a|/(2·j_max) between the targets it tracked, the output stays within the velocity limits
too (the property tests check all three on random command sequences).
"""

from __future__ import annotations

from collections.abc import Hashable
from dataclasses import dataclass

import numpy as np

from wmm_qp.config import ArmConfig, FloatArray
from wmm_qp.fault_codes import FaultCode

from .stream_rules import StreamRules


@dataclass(frozen=True)
class StreamLimits:
    """The joint limits the stream keeps (symmetric velocity, acceleration, jerk).

    Attributes:
        q_lo, q_hi: [rad] position limits (±inf: none).
        v_max: [rad/s] velocity limits.
        a_max: [rad/s²] acceleration limits.
        j_max: [rad/s³] jerk limits.
    """

    q_lo: FloatArray
    q_hi: FloatArray
    v_max: FloatArray
    a_max: FloatArray
    j_max: FloatArray

    @classmethod
    def of(cls, arm: ArmConfig) -> StreamLimits:
        """The arm's limits; without the robot file's ``jerk_max``, 1000 s⁻¹ × ``acceleration_max``
        (the acceleration limit reached in 1 ms: a smooth stream still, for drives that ask none)."""
        a = np.asarray(arm.acceleration_max, dtype=float)
        j = np.asarray(arm.jerk_max, dtype=float) if arm.jerk_max is not None else 1000.0 * a
        return cls(np.asarray(arm.position_lower, dtype=float), np.asarray(arm.position_upper, dtype=float),
                   np.asarray(arm.velocity_max, dtype=float), a, j)


class CommandShaper(StreamRules):
    """Turns the daemon's commands into a continuous jerk-limited joint velocity stream.

    Args:
        limits: the joint limits.
        dt: [s] the robot's cycle (Franka: 0.001).
        stale_timeout: [s] commands older than this are stale: the arm brakes to rest.
        rtol, atol: a command's rate is legal when |v| ≤ v_max·(1 + rtol) + atol.
    """

    def __init__(self, limits: StreamLimits, dt: float = 1e-3, stale_timeout: float = 0.1,
                 rtol: float = 1e-9, atol: float = 1e-9) -> None:
        self.lim = limits
        self.dt = dt
        self.stale_timeout = stale_timeout
        self.rtol, self.atol = rtol, atol
        n = len(limits.v_max)
        self.v = np.zeros(n)  # [rad/s] the last output
        self.a = np.zeros(n)  # [rad/s²] (v_k − v_{k−1})/h of the last output (h: its cycle's time step)
        self.target = np.zeros(n)  # [rad/s] the latest accepted command (0: none, stale, stopped)
        self.t_cmd = -np.inf  # [s] receipt time of the latest accepted command
        self.t_step: float | None = None  # [s] the robot's time of the last cycle (None: none yet)
        self.reset_rules()
        self.halted = False  # halt(): braking to rest for good, every command refused

    @property
    def at_rest(self) -> bool:
        """The output is exactly 0 and not accelerating."""
        return not (self.v.any() or self.a.any())

    def stop_distance(self, v: FloatArray, a: FloatArray) -> FloatArray:
        """[rad] an upper bound of each joint's travel while the shaper brakes it to rest.

        Args:
            v: [rad/s] velocity; a: [rad/s²] acceleration (the sign of v is the direction).
        """
        lim = self.lim
        sv = np.sign(v)
        a_on = np.maximum(a * sv, 0.0)  # acceleration still pushing along v
        v1 = np.abs(v) + a_on**2 / (2.0 * lim.j_max)  # the speed reached while a ramps to 0
        ramps = a_on / lim.j_max + 2.0 * lim.a_max / lim.j_max + 2.0 * self.dt  # ramps of a, and a cycle
        return v1 * ramps + v1**2 / (2.0 * lim.a_max)

    def _cannot_stop(self, q: FloatArray, v: FloatArray, a: FloatArray) -> int:
        """The first joint that braking from (q, v, a) would carry past its position limit (−1: none)."""
        d = self.stop_distance(v, a)
        with np.errstate(invalid="ignore"):
            bad = ((v > 0) & (q + d > self.lim.q_hi)) | ((v < 0) & (q - d < self.lim.q_lo))
        idx = np.flatnonzero(bad)
        return int(idx[0]) if idx.size else -1

    def illegal(self, rates: FloatArray) -> str | None:
        """Why a command's rates are illegal whatever the state (non-finite, past a velocity
        limit), or None."""
        if not np.isfinite(rates).all():
            return "a command with a non-finite rate"
        over = np.flatnonzero(np.abs(rates) > self.lim.v_max * (1.0 + self.rtol) + self.atol)
        if over.size:
            i = int(over[0])
            return f"joint {i + 1} commanded at {rates[i]:.4g} rad/s, beyond its limit {self.lim.v_max[i]:.4g}"
        return None

    def protect(self, code: FaultCode, why: str) -> None:
        """A protective stop (:meth:`StreamRules.protect`): the target becomes rest."""
        super().protect(code, why)
        self.target = np.zeros_like(self.target)

    def reset(self, code: FaultCode, reason: str) -> None:
        """The robot stopped the motion itself (a reflex): a new stream starts from rest, and
        the stop is reported as a protective stop (released by a new stream)."""
        self.v = np.zeros_like(self.v)
        self.a = np.zeros_like(self.a)
        self.protect(code, reason)

    def halt(self) -> None:
        """Brake to rest and refuse every command from now on (the driver is stopping)."""
        self.halted = True
        self.target = np.zeros_like(self.target)

    def would_release(self, stream: Hashable) -> bool:
        """Whether a legal command of ``stream`` would end the protective stop now: a new stream,
        the output at rest (False outside a protective stop, and once halted)."""
        return not self.halted and self.releases(stream, self.at_rest)

    def command(self, t: float, rates: FloatArray, stream: Hashable, q: FloatArray) -> bool:
        """A command of the daemon, received at robot time ``t`` [s].

        Args:
            t: [s] the robot's time at receipt.
            rates: [rad/s] the commanded joint rates (already of the arm's length).
            stream: the stream it belongs to (e.g. (lease, stream id)): a new key after a
                protective stop is what releases it.
            q: [rad] the measured joint positions.

        Returns:
            True when it became the target; False when refused or ended (counted in ``refused``
            or ``ended``).
        """
        rates = np.asarray(rates, dtype=float)
        if self.halted:
            self.refused += 1
            return False
        if not self.receive(stream, self.illegal(rates), self.at_rest).followed:
            return False
        i = self._cannot_stop(np.asarray(q, dtype=float), rates, np.zeros_like(rates))
        if i >= 0:
            self.refused += 1
            self.protect(FaultCode.CANNOT_STOP_BEFORE_LIMIT, f"joint {i + 1} commanded at {rates[i]:.4g} rad/s "
                         f"from {q[i]:.4g} rad could not stop before its limit "
                         f"[{self.lim.q_lo[i]:.4g}, {self.lim.q_hi[i]:.4g}]")
            return False
        self.target = rates.copy()
        self.t_cmd = t
        return True

    def _track(self, target: FloatArray, h: float) -> tuple[FloatArray, FloatArray]:
        """One cycle of the jerk-limited tracker towards ``target``, ``h`` [s] of robot time after
        the previous one (0 < h ≤ dt; h = 0: no time passed, the output unchanged): the next (v, a)."""
        if h <= 0.0:
            return self.v.copy(), self.a.copy()
        lim = self.lim
        jh = lim.j_max * h
        e = target - self.v
        a_prog = np.sign(e) * lim.j_max * (np.sqrt(h * h + 2.0 * np.abs(e) / lim.j_max) - h)
        a_prog = np.clip(a_prog, -lim.a_max, lim.a_max)
        land = e / h  # land on the target this cycle when the next cycle may then stop accelerating
        a_prog = np.where((np.abs(land - self.a) <= jh) & (np.abs(land) <= np.minimum(jh, lim.a_max)), land, a_prog)
        a_new = np.clip(a_prog, self.a - jh, self.a + jh)
        a_new = np.clip(a_new, -lim.a_max, lim.a_max)
        v_new = self.v + a_new * h
        v_clip = np.clip(v_new, -lim.v_max, lim.v_max)
        a_new = np.where(v_clip != v_new, (v_clip - self.v) / h, a_new)
        return self.v + a_new * h, a_new

    def _elapsed(self, t: float) -> float:
        """Mark this cycle's robot time ``t``; [s] the time the cycle may move the output by: the
        time since the previous cycle, at most ``dt`` (the first cycle: ``dt``; within a millionth
        of ``dt``: ``dt``, so that a clock that adds periods in floating point steps whole periods)."""
        last, self.t_step = self.t_step, t
        if last is None:
            return self.dt
        h = t - last
        return self.dt if h >= self.dt * (1.0 - 1e-6) else max(h, 0.0)

    def step(self, t: float, q: FloatArray) -> FloatArray:
        """The joint velocities to send this cycle.

        Args:
            t: [s] the robot's time of this cycle.
            q: [rad] the measured joint positions.

        Returns:
            [rad/s] the command (a fresh array).
        """
        q = np.asarray(q, dtype=float)
        late = np.isfinite(self.t_cmd) and t - self.t_cmd > self.stale_timeout
        if late and not self.protective and self.go_stale():
            self.target = np.zeros_like(self.target)
        h = self._elapsed(t)
        v, a = self._track(self.target, h)
        if not self.protective and (i := self._cannot_stop(q + v * self.dt, v, a)) >= 0:
            self.protect(FaultCode.CANNOT_STOP_BEFORE_LIMIT, f"joint {i + 1} at {q[i]:.4g} rad moving at "
                         f"{v[i]:.4g} rad/s could no longer stop before its limit "
                         f"[{self.lim.q_lo[i]:.4g}, {self.lim.q_hi[i]:.4g}]")
            v, a = self._track(self.target, h)
        self.v, self.a = v, a
        return v.copy()
