"""The velocity damper: the bound every collision and fence row asks of the robot (the safety rule).

For a monitored pair (a, b) at distance d, ḋ = n̂ᵀ(J_{p_a} − J_{p_b}) v = C v (:mod:`.collision`
builds C; :mod:`.fence` the fence's). While d < d_i (the influence distance), Faverjon &
Tournassoud's damper in NEO's form:

    C v ≥ −ξ (d' − d_s)/(d_i − d_s)                                              (damper)

with d_s the safety distance (``collision.floor_margin`` for the floor, 0 for the fence), ξ the
gain [m/s], raised to the braking profile −√(2 β a_n (d' − d_s)) where that is larger: a_n =
Σ_j |C_j| A_j is the fastest the pair's approach can be slowed (every column of v braking for it
at its acceleration limit A_j), of which β is counted on — a slow arm cannot follow the linear
damper's deceleration ξ²(d − d_s)/(d_i − d_s)² near d_i. d' = d − τ·max(0, −ḋ_prev) is the
distance left after the state's age τ at the approach speed the robot already has (ḋ_prev from
the bounds' centre, the last command): like bounds (13), the rows account for the state's
latency. A moving obstacle (velocity v_b, world frame) closes the distance by n̂ᵀv_b on its own:
its rows ask that much more of the robot, ḋ = C v − n̂ᵀv_b (the robot gives way at the obstacle's
approach speed, as far as the bounds allow). Inside d_s the bound is positive: the pair is pushed
apart. A pair inside d_s also has a row on its bodies linearised where full braking ends
(:mod:`.inside_pairs`): its bound carries an offset, (d − d̃)/Δt.

Priority: the acceleration bounds (13) win. Each row is relaxed, where the bounds cannot meet it,
to the most separating rate they admit, l ← min(l, max_{lb ≤ v ≤ ub} C_k v): the robot then
separates (or stops approaching) as hard as (13) allows, and each row alone is feasible. Rows that
exclude each other are relaxed together (:meth:`~wmm_qp.limits.rows.Rows.relax_together`): every
damper source (:class:`DamperRows`: the collision pairs, the fence) is pooled, relaxed and
reported with the others. The influence distance must exceed the distance the robot needs to stop
(docs/model.md "Collisions").
"""

from __future__ import annotations

import math

import numpy as np

from .._jit import jit, jit_inline
from .._typing import FloatArray
from .rows import RELAX_MARGIN, Retry, Rows, RowSource


@jit_inline
def _row_bounds(
    C: FloatArray, k: int, v_prev: FloatArray, v0: FloatArray, lb: FloatArray, ub: FloatArray,
    d: float, d_s: float, d_i: float, gain: float, latency: float, shift: float, accel: FloatArray,
    braking: float, offset: float,
) -> tuple[float, float, float]:
    """Of row ``k`` of C (read by index: a row view costs a reference count): (the damper's
    bound, the most separating rate in lb ≤ v ≤ ub, the braking command's rate).

    The damper's bound is the larger of the linear damper and the braking profile
    −√(2 β a_n (d' − d_s)), a_n = Σ_j |C_j| A_j the fastest the pair's approach can be slowed
    (every joint braking for it at its A)."""
    prev = best = brake = a_n = 0.0
    for i in range(C.shape[1]):
        c = C[k, i]
        prev += c * v_prev[i]
        brake += c * v0[i]
        best += c * ub[i] if c > 0.0 else c * lb[i]
        a_n += abs(c) * accel[i]
    d_eff = d - latency * max(0.0, shift - prev)  # the approach during the state's age (ḋ = prev − shift)
    linear = -gain * (d_eff - d_s) / (d_i - d_s)
    profile = -math.sqrt(2.0 * braking * a_n * max(d_eff - d_s, 0.0))
    return max(linear, profile) + shift + offset, best, brake


@jit
def damper_bounds(
    C: FloatArray, v_prev: FloatArray, lb: FloatArray, ub: FloatArray, d: FloatArray, d_s: FloatArray,
    d_i: float, gain: float, latency: float, shift: FloatArray, accel: FloatArray, braking: float,
    offset: FloatArray,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(l, l_brake, damper) of every row: the module docstring's bound, relaxed.

    Args:
        C: (k, n_v) the rows, ḋ = C v (+ the other side's own approach).
        v_prev: the bounds' centre (the last command), for the latency term.
        lb, ub: the stage's box bounds on v (bounds (13) and the wheel bounds).
        d: [m] (k,) each row's distance; d_s: [m] (k,) its safety distance.
        d_i: [m] the influence distance; gain: [m/s] ξ; latency: [s] τ; braking: [-] β.
        shift: [m/s] (k,) n̂ᵀv_b of a row against a moving obstacle (0 otherwise).
        accel: A of each column of v [rad/s², rad/s² per wheel].
        offset: [m/s] (k,) added to each damper bound: (d − d̃)/Δt of a row linearised at the
            braking configuration (:mod:`.inside_pairs`: d̃ + Δt·C v is its distance after the
            tick, d its distance now), 0 for a row linearised at the state.

    Returns:
        l (the damper relaxed to the most separating rate the bounds admit), l_brake (relaxed to
        admit the braking command v₀ = clip(0, lb, ub)), damper (the bound itself), each (k,).
    """
    m = C.shape[0]
    l, l_brake, damper = np.empty(m), np.empty(m), np.empty(m)
    damper_bounds_into(C, v_prev, lb, ub, d, d_s, d_i, gain, latency, shift, accel, braking, offset,
                       np.empty(lb.shape[0]), l, l_brake, damper)
    return l, l_brake, damper


@jit_inline
def damper_bounds_into(
    C: FloatArray, v_prev: FloatArray, lb: FloatArray, ub: FloatArray, d: FloatArray, d_s: FloatArray,
    d_i: float, gain: float, latency: float, shift: FloatArray, accel: FloatArray, braking: float,
    offset: FloatArray, v0: FloatArray, l: FloatArray, l_brake: FloatArray, damper: FloatArray,
) -> None:
    """:func:`damper_bounds` into arrays of the caller's (``v0``: room for the braking command, n_v
    entries; the rows' kernel passes views of its scratch: no allocation a tick)."""
    for c in range(C.shape[1]):  # (v0's n_v entries: a longer lb is read only that far)
        v0[c] = np.minimum(np.maximum(0.0, lb[c]), ub[c])  # numpy's rule: a NaN bound gives a NaN v0
    for k in range(C.shape[0]):
        dk, best, brake = _row_bounds(C, k, v_prev, v0, lb, ub, d[k], d_s[k], d_i, gain, latency, shift[k],
                                      accel, braking, offset[k])
        damper[k] = dk
        # a relaxed row would pass through a vertex of the box exactly: 1e-9 m/s below it, so that
        # no solver's tolerance reads the degenerate (feasible) problem as infeasible
        l[k] = min(dk, best - RELAX_MARGIN)
        l_brake[k] = min(dk, brake - RELAX_MARGIN)


class DamperRows(RowSource):
    """A source of velocity dampers (the collision pairs, the fence): rows whose ``distances`` are
    metres to their safety distance, relaxed together with every other damper when they exclude
    each other, re-checked whatever solved the stage, and reported as "collision: <the nearest
    row the command sits on> ..." when they cut the task."""

    name = "collision"
    retry = Retry.TOGETHER
    rechecked = True

    def cut_reason(self, rows: Rows, v: FloatArray) -> str:
        """The active row (the command on its bound l, to 1e-9 relative) nearest its limit, and how
        many more are active."""
        slack = rows.C @ v - rows.l
        active = np.flatnonzero(slack <= 1e-9 * np.maximum(1.0, np.abs(rows.l)))
        if not active.size:
            return ""
        k = active[np.argmin(rows.distances[active])]
        more = f" (+{active.size - 1} more)" if active.size > 1 else ""
        return f"collision: {rows.names[k]} at {rows.distances[k]:.3f} m{more} (task cut)"

    def row_label(self, rows: Rows, k: int) -> str:
        return f"collision row {rows.names[k]}"
