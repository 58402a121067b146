"""The heaviest box each arm configuration can push (``wmm-qp experiment push --max-mass``).

The paper's claim (Sec. IV-C): the DM enhancement along x lets the arm push a box it could not
push from its start configuration. Measured here as the heaviest box (friction μ of
:mod:`.push`) each configuration moves ``push.TARGET`` along x, found by bisection on the mass:
a mass counts as pushed when the run of :func:`.push.run_push` completes. Beside it the ratio
the DM values predict: the force along u a unit weighted torque norm buys is H2 (eq. (15)), so
the pushable masses should stand about as H2 after the enhancement to H2 at the start.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import Any

from wmm_qp_tools.experiments import push
from wmm_qp_tools.experiments.setup import Setup

LOWER = 5.0  # [kg] the bisection's bracket: a box this light is pushed (checked)
UPPER = 80.0  # [kg] and one this heavy is not (checked)
TOLERANCE = 2.5  # [kg] the bisection stops when the bracket is this narrow


def _pushed(setup_factory: Callable[[], Setup], run: str, mass: float, dm_duration: float) -> tuple[bool, float]:
    """(the box of ``mass`` [kg] moved the target distance, the DM at the push start)."""
    s, tr = push.run_push(setup_factory, dm_duration, progress=False, mass=mass, runs=(run,))[run]
    m = push.push_metrics(s, tr)
    return bool(m["completed"]), float(m["dm_at_push_start"])


def max_mass(setup_factory: Callable[[], Setup], dm_duration: float = push.DEFAULT_DM_DURATION,
             progress: bool = True) -> dict[str, Any]:
    """Bisect the heaviest pushable box with and without the DM enhancement.

    Returns:
        ``max_mass_kg`` {"with_dm", "without_dm"}: [kg] the heaviest mass pushed (the bracket's
        lower end; null if even ``LOWER`` was not), ``bracket_kg`` each run's final [pushed, not
        pushed], ``dm_at_push_start`` each run's H2 along x, ``measured_ratio`` with/without and
        ``dm_ratio`` the DMs' ratio (what the DM predicts), ``trials`` the number of runs.
    """
    out: dict[str, Any] = {"max_mass_kg": {}, "bracket_kg": {}, "dm_at_push_start": {}, "trials": 0}
    for run in ("with_dm", "without_dm"):
        lo, hi = LOWER, UPPER
        ok_lo, dm = _pushed(setup_factory, run, lo, dm_duration)
        ok_hi, _ = _pushed(setup_factory, run, hi, dm_duration)
        out["trials"] += 2
        out["dm_at_push_start"][run] = dm
        if progress:
            print(f"max-mass {run}: {lo:g} kg {'pushed' if ok_lo else 'not pushed'}, "
                  f"{hi:g} kg {'pushed' if ok_hi else 'not pushed'}", file=sys.stderr, flush=True)
        if not ok_lo or ok_hi:  # the bracket does not hold: say so, do not guess
            out["max_mass_kg"][run] = None if not ok_lo else hi
            out["bracket_kg"][run] = [lo if ok_lo else None, None if ok_hi else hi]
            continue
        while hi - lo > TOLERANCE:
            mid = 0.5 * (lo + hi)
            ok, _ = _pushed(setup_factory, run, mid, dm_duration)
            out["trials"] += 1
            lo, hi = (mid, hi) if ok else (lo, mid)
            if progress:
                print(f"max-mass {run}: {mid:.2f} kg {'pushed' if ok else 'not pushed'} -> [{lo:.2f}, {hi:.2f}] kg",
                      file=sys.stderr, flush=True)
        out["max_mass_kg"][run] = lo
        out["bracket_kg"][run] = [lo, hi]
    w, wo = out["max_mass_kg"]["with_dm"], out["max_mass_kg"]["without_dm"]
    out["measured_ratio"] = w / wo if w is not None and wo else None
    d = out["dm_at_push_start"]
    out["dm_ratio"] = d["with_dm"] / d["without_dm"]
    return out
