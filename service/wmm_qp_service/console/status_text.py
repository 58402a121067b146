"""The console's status panel as Markdown: what the daemon's status and the sim's truth say."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..protocol import StatusMsg, TruthMsg


def status_markdown(st: StatusMsg | None, truth: TruthMsg | None, source: str,
                    gripper_width: float = math.nan) -> str:
    """The panel's status text: rate, deadline misses, safe stop, last fault, rejected and clamped
    counts (``clamped`` where the daemon reports it), the sim's violations, who holds the stream,
    the gripper's measured opening (``gripper_width`` [m] from the robot's state; nan: no
    gripper, no line), and with the sim's ground truth (``truth``; None: a robot without one) the
    EE's error."""
    if st is None:
        return "**daemon**: no status yet"
    lp = st.loop
    rej = sum(st.rejected.values())
    viol = sum(st.robot_violations.values())
    clamped: Any = getattr(st, "clamped", None)
    if isinstance(clamped, dict):
        clamped = sum(int(v) for v in clamped.values())
    if st.operator == "":
        stream = "free"
    elif st.operator == source:
        stream = "**this console**"
    else:
        stream = f"`{st.operator}`"
    lines = [
        f"**mode** `{st.mode}`" + ("  **SAFE STOP**" if st.safe_stop else "")
        + ("  (resume: pick a mode)" if st.resume_needed else ""),
        f"**rate** {lp.measured_hz:.0f} / {lp.rate_hz:.0f} Hz · tick p50 {lp.tick_p50_us:.0f} µs"
        f" · p99 {lp.tick_p99_us:.0f} µs",
        f"**deadline misses** {lp.deadline_misses} of {lp.ticks}",
        f"**last fault** {st.last_fault or '—'}",
        f"**rejected** {rej}" + (f" {dict(st.rejected)}" if rej else "")
        + (f" · **clamped** {clamped}" if clamped is not None else "")
        + (f" (last: {last})" if (last := getattr(st, "last_clamp", "")) else ""),
        f"**robot violations** {viol}" + (f" {dict(st.robot_violations)}" if viol else "")
        + (" · **protective stop**" if st.protective_stop else ""),
        f"**DM** {st.dm:.3f} · **stream** {stream}",
    ]
    if math.isfinite(gripper_width):
        lines.append(f"**gripper** {1000 * gripper_width:.1f} mm open")
    if truth is not None and st.x_d:
        err = float(np.linalg.norm(np.asarray(truth.ee_true) - np.asarray(st.x_d)))
        lines.append(f"**EE** {_fmt(truth.ee_true)} · **target** {_fmt(st.x_d)} · error {1000 * err:.1f} mm")
    return "  \n".join(lines)


def _fmt(v: Any) -> str:
    return "(" + ", ".join(f"{float(x):.3f}" for x in v) + ")"
