"""Every robot's limit referee (the sim's, a driver's): counts every limit violation, independently
of the controller.

It deliberately does not use :mod:`wmm_qp.limits`: the limits come straight from the robot
config and the checks are written out here. A value is legal when
``|v| <= limit·(1 + rtol) + atol`` (``configs/sim.toml`` [referee], default 1e-9 and 1e-9).

The referee judges each **command as it was received** — before the robot's own protections
(the firmware's refusal and protective stop, the drive's acceleration ramp, see
:class:`wmm_qp_sim.robot.SimRobot`, a driver) act on it — and the **executed joint positions** after
every step. Kinds and
what one count means:

- ``position``: a (sim step, joint) pair whose executed angle is outside
  [lower − tol, upper + tol]; continuous joints (±inf limits) are never counted.
- ``velocity``: a (received command, joint) pair with |q̇_cmd| above velocity_max.
- ``acceleration``: a (received command, joint) pair with |q̇_cmd,k − q̇_cmd,k−1| above
  acceleration_max·Δt. Δt is the command's own period times the number of periods since the
  previous command (``SimCommand.period`` × seq gap: a lost command widens the window), with
  the period taken as at most ``period_max`` (the robot's command timeout: a longer one is no
  stream at all) and the window never more than the time that really passed between the two
  receipts plus ``period_max`` and one sim step (``SimCommand.received``, the adapter's
  monotonic clock; ``period_max`` absorbs the transport's batching and jitter), so a sender
  cannot widen the window much by claiming a long period or skipping seq numbers; when the
  command gives no period (in-process experiments), the time since the previous command. In a
  stream that a stale or protective stop ended (its commands reach the robot late and the
  firmware refuses them: none is executed) the cap is the time between the two commands'
  sending stamps (``SimCommand.sent``, the sender's clock) instead: a sender's transmit queue
  that was starved and then flushed delivers commands sent 100 ms apart within a millisecond,
  and their arrival says nothing about how fast the controller changed them.
  A new stream — the first command, the first of a new ``SimCommand.stream`` id (the sender
  started again from the robot's measured rates), the first of a new lease holder, or, for
  commands without a stream id, the first after a stale or protective stop — is judged against
  the executed rates over one period: it must start from what the robot is doing. A stream
  that goes on after a stale stop (its commands were late on the way) is judged against its
  own previous command: the jump from the braked rates is the robot's to ramp.
- ``wheel_speed`` / ``wheel_acceleration``: the same for the wheels.
"""

from __future__ import annotations

import numpy as np

from wmm_qp.config import FloatArray, RobotConfig

from .config import RefereeConfig

VIOLATION_KINDS = ("position", "velocity", "acceleration", "wheel_speed", "wheel_acceleration", "collision")


class Referee:
    """Counts limit violations by kind.

    Args:
        robot: the robot config (its limits are the referee's rules).
        config: tolerances.
        period_max: [s] the longest command period the referee accepts as a window.
    """

    def __init__(self, robot: RobotConfig, config: RefereeConfig, period_max: float = float("inf")) -> None:
        self.period_max = period_max
        a, b = robot.arm, robot.base
        self.q_lo = np.array(a.position_lower, dtype=float)
        self.q_hi = np.array(a.position_upper, dtype=float)
        self.v_max = np.array(a.velocity_max, dtype=float)
        self.a_max = np.array(a.acceleration_max, dtype=float)
        self.w_max = np.array(b.wheel_speed_max, dtype=float)
        self.wa_max = np.array(b.wheel_acceleration_max, dtype=float)
        self.rtol, self.atol = config.rtol, config.atol
        self.counts: dict[str, int] = dict.fromkeys(VIOLATION_KINDS, 0)
        self.last_event = ""  # what the last counted violation was (for the sim's log)
        self._soft_break = False
        self._stream: int | None = None
        self._stopped: int | None = None  # the stream the last stale or protective stop ended
        self._prev: tuple[FloatArray, FloatArray, float, int | None, float | None, float | None] | None = None

    def reset(self) -> None:
        """Zero every count and forget the previous command."""
        self.counts = dict.fromkeys(VIOLATION_KINDS, 0)
        self._prev = None
        self._soft_break = False
        self._stream = None
        self._stopped = None

    def break_stream(self, hard: bool = True) -> None:
        """The robot stopped following the command stream.

        Args:
            hard: the next command is judged against the executed rates (a new lease holder);
                False (a stale or protective stop): only if it carries no stream id.
        """
        if hard:
            self._prev = None
        else:
            self._soft_break = True
            self._stopped = self._stream

    def _exceeds(self, value: FloatArray, limit: FloatArray | float) -> int:
        return int(
            np.count_nonzero(np.abs(value) > np.asarray(limit) * (1.0 + self.rtol) + self.atol)
        )

    def check_positions(self, q_arm: FloatArray) -> None:
        """Count joints outside their position limits (continuous joints have none)."""
        tol_lo = np.abs(self.q_lo) * self.rtol + self.atol
        tol_hi = np.abs(self.q_hi) * self.rtol + self.atol
        with np.errstate(invalid="ignore"):
            bad = (q_arm < self.q_lo - tol_lo) | (q_arm > self.q_hi + tol_hi)
        self.counts["position"] += int(np.count_nonzero(bad))

    def on_command(
        self,
        t: float,
        v_cmd: FloatArray,
        w_cmd: FloatArray,
        v_exec: FloatArray,
        w_exec: FloatArray,
        period: float | None = None,
        seq: int | None = None,
        received: float | None = None,
        step: float = 0.0,
        stream: int | None = None,
        sent: float | None = None,
    ) -> None:
        """Judge a command as received at sim time t [s].

        Args:
            t: [s] sim time of receipt.
            v_cmd, w_cmd: [rad/s] the commanded joint rates and wheel speeds.
            v_exec, w_exec: [rad/s] the rates the robot executes at receipt (the baseline
                after a break in the stream).
            period: [s] the command's own period (the Δt its sender's bounds assume), or None.
            seq: the command's sequence number (with ``period``: lost commands widen Δt).
            received: [s] monotonic time of receipt (caps Δt at the real time between receipts).
            step: [s] the sim's step (added to that cap: receipts are quantised to steps).
            stream: the sender's stream id (see the module docstring), or None.
            sent: [s] the sender's stamp of the command (its own clock: only differences are
                used), or None.
        """
        self.counts["velocity"] += self._exceeds(v_cmd, self.v_max)
        self.counts["wheel_speed"] += self._exceeds(w_cmd, self.w_max)
        prev = self._prev
        if prev is not None and (stream != self._stream if stream is not None else self._soft_break):
            prev = None
        self._soft_break = False
        self._stream = stream
        if prev is None:  # a new stream: it must start from what the robot executes
            base_v, base_w = v_exec, w_exec
            held = None if period is None else min(period, self.period_max)
        else:
            base_v, base_w, t_prev, seq_prev, rx_prev, sent_prev = prev
            if period is not None:
                period = min(period, self.period_max)
                gap = seq - seq_prev if (seq is not None and seq_prev is not None) else 1
                held = period * max(gap, 1)
                stopped = stream is not None and stream == self._stopped  # not executed: the sender's clock
                if stopped and sent is not None and sent_prev is not None:
                    held = min(held, sent - sent_prev + self.period_max + step)
                elif received is not None and rx_prev is not None:
                    held = min(held, received - rx_prev + self.period_max + step)
            else:
                held = t - t_prev
        if held is not None and held > 0.0:
            na = self._exceeds(v_cmd - base_v, self.a_max * held)
            nw = self._exceeds(w_cmd - base_w, self.wa_max * held)
            self.counts["acceleration"] += na
            self.counts["wheel_acceleration"] += nw
            if na or nw:
                ratio = max(float(np.max(np.abs(v_cmd - base_v) / (self.a_max * held), initial=0.0)),
                            float(np.max(np.abs(w_cmd - base_w) / (self.wa_max * held), initial=0.0)))
                since = "the executed rates (a new stream)" if prev is None else f"command seq {prev[3]}"
                self.last_event = (f"acceleration: command seq {seq} changed by {ratio:.2f} A·Δt "
                                   f"over Δt = {held * 1e3:.2f} ms from {since}")
        self._prev = (v_cmd.copy(), w_cmd.copy(), t, seq, received, sent)
