"""Client-side streaming of setpoints (used by ``wmm-qp teleop`` and ``wmm-qp demo``)."""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from .client import Client
from .devices import InputDevice, KeyboardDevice, TargetIntegrator
from .streams import HapticStream, circle


def stream_haptic(client: Client, x0: np.ndarray, duration: float, rate_hz: float = 100.0,
                  seed: int = 0, on_tick: Callable[[], None] | None = None) -> int:
    """Stream a haptic-like target (jitter in value and in send time, jumps) for ``duration`` [s].

    The daemon estimates the target's velocity from the stream. Returns the number sent.
    """
    hs = HapticStream(x0, seed=seed)
    rng = np.random.default_rng(seed + 1)
    t0 = time.monotonic()
    n = 0
    while (t := time.monotonic() - t0) < duration:
        client.send_setpoint(hs.sample(t))
        n += 1
        if on_tick is not None:
            on_tick()
        time.sleep(max(0.0, rng.normal(1.0 / rate_hz, 0.25 / rate_hz)))
    return n


def stream_circle(client: Client, x0: np.ndarray, duration: float, rate_hz: float = 100.0,
                  on_tick: Callable[[], None] | None = None) -> int:
    """Stream the paper's circle from x0 with its feed-forward velocity. Returns the number sent."""
    t0 = time.monotonic()
    n = 0
    next_t = t0
    while (t := time.monotonic() - t0) < duration:
        x, xd = circle(x0, t)
        client.send_setpoint(x, xd)
        n += 1
        if on_tick is not None:
            on_tick()
        next_t += 1.0 / rate_hz
        time.sleep(max(0.0, next_t - time.monotonic()))
    return n


def hold_stream(client: Client, x: np.ndarray, duration: float, rate_hz: float = 50.0,
                on_tick: Callable[[], None] | None = None) -> None:
    """Stream a standing target x [m] for ``duration`` [s]."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < duration:
        client.send_setpoint(x, [0.0, 0.0, 0.0])
        if on_tick is not None:
            on_tick()
        time.sleep(1.0 / rate_hz)


def wait(duration: float, on_tick: Callable[[], None] | None = None, period: float = 0.02) -> None:
    """Sleep ``duration`` [s], calling on_tick every ``period``."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < duration:
        if on_tick is not None:
            on_tick()
        time.sleep(period)


class DeviceTeleop:
    """An input device drives the daemon's EE target (``wmm-qp teleop keyboard|gamepad``).

    Each :meth:`tick` reads the device, moves the target at the set speed while the device is
    deflected and streams it (``stream_s`` [s] more after it stops, so the daemon sees one steady
    stream); the hold button sends mode ``hold`` (the daemon latches its target where the EE is)
    and ignores motion until the resume button sends ``track`` again from where the EE is.

    Args:
        client: an open client whose daemon answered.
        device: the input device.
        integrator: the target it moves (started at the EE).
        pose: send the orientation too (the daemon runs the pose task).
    """

    def __init__(self, client: Client, device: InputDevice, integrator: TargetIntegrator, pose: bool = False,
                 stream_s: float = 0.3) -> None:
        self.client, self.device, self.integ, self.pose = client, device, integrator, pose
        self.stream_s = stream_s
        self.holding = False
        self.quit = False
        self.sent = 0
        self._moved_at = -float("inf")
        self._last = time.monotonic()

    def tick(self, now: float | None = None) -> None:
        """One step: read, integrate, send."""
        now = time.monotonic() if now is None else now
        dt, self._last = now - self._last, now
        s = self.device.read(now)
        if s.quit:
            self.quit = True
            return
        if s.gripper:
            self.client.gripper(s.gripper)
        if s.hold:
            self.client.set_mode("hold")
            self.holding = True
        if s.resume:
            self.client.set_mode("track")
            self.holding = False
            self._restart_from_ee()
        if self.holding:
            return
        if self.integ.step(s, dt):
            self._moved_at = now
        if now - self._moved_at < self.stream_s:
            self.client.send_setpoint(self.integ.x, q=self.integ.quaternion() if self.pose else None)
            self.sent += 1

    def _restart_from_ee(self) -> None:
        st = self.client.latest_status()
        if st is not None and st.x:
            R = None
            if self.integ.R is not None and st.quat_d:
                from .console.geometry import quat_to_matrix, xyzw_to_wxyz

                R = quat_to_matrix(xyzw_to_wxyz(st.quat_d))
            self.integ.reset(np.asarray(st.x, float), R if R is not None else self.integ.R)


def keyboard_screen(t: DeviceTeleop, robot: str, task: str) -> list[str]:
    """The lines the keyboard teleop shows: the target, the mode, the daemon's status, the keys."""
    st = t.client.latest_status()
    x = t.integ.x
    lines = [f"wmm-qp teleop keyboard - robot {robot} ({task} task)",
             f"target  x {x[0]:+.3f}  y {x[1]:+.3f}  z {x[2]:+.3f} m"
             + (f"   quat {[round(v, 3) for v in q]}" if (q := t.integ.quaternion()) else ""),
             f"state   {'HOLDING (t resumes)' if t.holding else 'driving'}   setpoints sent {t.sent}"]
    if st is None:
        lines.append("daemon  no status yet")
    else:
        lp = st.loop
        lines += [f"mode    {st.mode}" + ("   SAFE STOP" if st.safe_stop else "")
                  + ("   resume needed (t)" if st.resume_needed else ""),
                  f"daemon  {lp.measured_hz:.0f}/{lp.rate_hz:.0f} Hz  misses {lp.deadline_misses}  "
                  f"rejected {sum(st.rejected.values())}  robot violations {sum(st.robot_violations.values())}",
                  f"fault   {st.last_fault or 'none'}",
                  f"EE      {' '.join(f'{v:+.3f}' for v in st.x)}   operator {st.operator or 'none'}"]
    rot = "  u/o yaw  i/k pitch  j/l roll" if t.integ.R is not None else ""
    lines.append(f"keys    w/s x  a/d y  r/f z{rot}  space hold  t track  c/v gripper close/open  q quit")
    return lines


def run_keyboard(t: DeviceTeleop, keyboard: KeyboardDevice, robot: str, task: str, rate_hz: float = 50.0) -> None:
    """The terminal UI of ``wmm-qp teleop keyboard`` (curses) until the quit key."""
    import curses

    def main(scr: curses.window) -> None:
        curses.curs_set(0)
        scr.nodelay(True)
        period = 1.0 / rate_hz
        k = 0
        while not t.quit:
            now = time.monotonic()
            while (c := scr.getch()) != -1:
                if 0 <= c < 256:
                    keyboard.press(chr(c).lower() if chr(c) != "Q" else "q", now)
            t.tick(now)
            if k % max(1, int(rate_hz / 10)) == 0:
                scr.erase()
                h, w_ = scr.getmaxyx()
                for i, line in enumerate(keyboard_screen(t, robot, task)[: h - 1]):
                    scr.addnstr(i, 0, line, w_ - 1)
                scr.refresh()
            k += 1
            time.sleep(max(0.0, period - (time.monotonic() - now)))

    curses.wrapper(main)
