"""The rows of one tick's stages: every row source's, stacked in the sources' order.

The stages never look inside one source: they ask this stack for the rows (relaxed for the arm
alone, or for the stage solved again), for the rows to re-check and how to name one, and for why
the task was cut. What differs between sources is what each declares (:class:`~wmm_qp.limits.rows.RowSource`):
its :class:`~wmm_qp.limits.rows.Retry`, whether it is re-checked, whether it yields to the task.
The dampers' rows (``Retry.TOGETHER``: the collision pairs, the fence) are pooled into one group,
at the first damper source's place: relaxed together, reported together.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from ..._jit import jit
from ..._typing import BoolArray, FloatArray
from ...limits.rows import Retry, Rows, RowSource
from ...solvers import INF
from ...types import Mode


class RowGroup(NamedTuple):
    """One source's rows this tick (the dampers': all damper sources' rows, pooled). (A named
    tuple: built several times a tick, ~0.4 µs cheaper than a frozen dataclass.)"""

    source: RowSource
    rows: Rows


class StageRows:
    """The rows of one tick's stages (see the module docstring).

    Args:
        parts: (source, its rows this tick) in the sources' order; None: none this tick.
        n_v: the length of v = [v_b; v_m].
    """

    def __init__(self, parts: Sequence[tuple[RowSource, Rows | None]], n_v: int) -> None:
        self.n_v = n_v
        groups: list[RowGroup] = []  # the sources with rows this tick, in order (one pass: every tick)
        dampers: list[Rows] = []
        first: RowSource | None = None
        pool_at = 0
        for source, rows in parts:
            if rows is None:
                continue
            if source.retry is Retry.TOGETHER:
                if first is None:
                    first, pool_at = source, len(groups)  # the pool's place
                dampers.append(rows)
            elif rows.l.shape[0]:
                groups.append(RowGroup(source, rows))
        self.dampers: Rows | None = None
        """The dampers' rows this tick, pooled (None: no damper source)."""
        if first is not None:
            self.dampers = dampers[0] if len(dampers) == 1 else Rows.stack(dampers, n_v)
            if self.dampers.l.shape[0]:
                groups.insert(pool_at, RowGroup(first, self.dampers))
        self.groups = groups
        n, mixed = 0, False
        for g in groups:
            n += g.rows.l.shape[0]
            mixed = mixed or not g.source.rechecked
        self.n = n
        self._mixed = mixed  # some rows are not re-checked (rechecked())

    def without_yielding(self, mode: Mode) -> StageRows | None:
        """These rows without the sources that yield to the task in ``mode``; None: none does."""
        kept = [g for g in self.groups if not g.source.yields_to_task(mode)]
        if len(kept) == len(self.groups):
            return None
        out = object.__new__(StageRows)
        out.n_v, out.dampers, out.groups, out.n = self.n_v, self.dampers, kept, sum(g.rows.n for g in kept)
        out._mixed = any(not g.source.rechecked for g in kept)
        return out

    # ------------------------------------------------------------------ the stacked rows
    def limits(self, brake: bool = False) -> tuple[FloatArray, FloatArray, FloatArray]:
        """(C, l, u) of every row, ±inf as the backends' ±INF; ``brake``: l relaxed as the stage
        solved again when the rows exclude each other has them (``l_brake``)."""
        if not self.groups:
            return np.zeros((0, self.n_v)), np.zeros(0), np.zeros(0)
        if len(self.groups) == 1:
            r = self.groups[0].rows
            C, l, u = r.C, r.l_brake if brake else r.l, r.upper()
        else:
            C = np.vstack([g.rows.C for g in self.groups])
            l = np.concatenate([g.rows.l_brake if brake else g.rows.l for g in self.groups])
            u = np.concatenate([g.rows.upper() for g in self.groups])
        return C, np.maximum(l, -INF), np.minimum(u, INF)

    def for_the_arm(self, n_wheels: int, held: FloatArray, lb: FloatArray, ub: FloatArray, C_out: FloatArray,
                    l_out: FloatArray, u_out: FloatArray) -> None:
        """(C_arm, l, u) of every row with the wheels held at ``held``, for the arm alone inside its
        bounds lb ≤ v_m ≤ ub (the first n_arm entries of ``lb``, ``ub``: the stage's own bounds may
        be passed whole, slack and all), into ``C_out`` (its first n_arm columns), ``l_out``, ``u_out``: each
        row's own bound (``damper``) relaxed to what the arm alone can do,
        l ← min(damper, max C_arm v_m + C_w w) − C_w w, the upper bound moved by the wheels' share,
        u ← u − C_w w (+INF stays). One compiled call (:func:`_rows_for_the_arm`)."""
        if len(self.groups) == 1:  # the common case (the dampers' pool alone): its arrays as they are
            r = self.groups[0].rows
            C, damper, u = r.C, r.damper, r.u
        else:
            C = np.vstack([g.rows.C for g in self.groups])
            damper = np.concatenate([g.rows.damper for g in self.groups])
            u = np.concatenate([g.rows.upper() for g in self.groups])
        _rows_for_the_arm(C, damper, NO_UPPER if u is None else u, n_wheels, held, lb, ub, C_out, l_out, u_out)

    # ------------------------------------------------------------------ when the rows exclude each other
    @property
    def relaxable(self) -> bool:
        """Some rows can be relaxed further when the stage has no solution (dampers, or rows that
        admit the braking command only once relaxed)."""
        return any(g.source.retry is not Retry.KEEP for g in self.groups)

    @property
    def has_dampers(self) -> bool:
        return any(g.source.retry is Retry.TOGETHER for g in self.groups)

    def relax_together(self, lb: FloatArray, ub: FloatArray) -> FloatArray:
        """The dampers relaxed together (:meth:`~wmm_qp.limits.rows.Rows.relax_together`, inside
        the KEEP rows), then every ADMIT row relaxed to admit their joint command v_r too.

        Returns:
            v_r, or an empty array (no dampers: the braking command is the stage's reference).
        """
        dampers = [g for g in self.groups if g.source.retry is Retry.TOGETHER]
        if not dampers:
            return np.zeros(0)
        keep = [g for g in self.groups if g.source.retry is Retry.KEEP]
        if keep:
            C_keep = np.vstack([g.rows.C for g in keep])
            l_keep = np.maximum(np.concatenate([g.rows.l for g in keep]), -INF)
            u_keep = np.minimum(np.concatenate([g.rows.upper() for g in keep]), INF)
            ref = dampers[0].rows.relax_together(lb, ub, C_keep, l_keep, u_keep)
        else:
            ref = dampers[0].rows.relax_together(lb, ub)
        for g in self.groups:
            if g.source.retry is Retry.ADMIT:
                r = g.rows
                r.l_brake = np.array([min(float(r.l_brake[k]), float(r.C[k] @ ref)) for k in range(r.n)])
        return ref

    # ------------------------------------------------------------------ after the solve
    def rechecked(self) -> BoolArray | None:
        """Which stacked rows are re-checked whatever solved the stage (None: all)."""
        if not self._mixed:
            return None
        return np.concatenate([np.full(g.rows.n, g.source.rechecked) for g in self.groups])

    def recheck_label(self, k: int) -> str:
        """The k-th re-checked row, as a reason names it."""
        for g in self.groups:
            if g.source.rechecked:
                if k < g.rows.n:
                    return g.source.row_label(g.rows, k)
                k -= g.rows.n
        return ""

    def cut_reason(self, v: FloatArray) -> str:
        """Why the task was cut at the command v: the first source (in order) whose rows v sits on
        says which, else the bounds cut it."""
        for g in self.groups:
            why = g.source.cut_reason(g.rows, v)
            if why:
                return why
        return "the bounds cut the task (best effort)"


NO_UPPER = np.zeros(0)  # _rows_for_the_arm's u of rows without an upper bound (read only)
NO_UPPER.setflags(write=False)


@jit
def _rows_for_the_arm(C: FloatArray, damper: FloatArray, u: FloatArray, n_w: int, held: FloatArray, lb: FloatArray,
                      ub: FloatArray, C_out: FloatArray, l_out: FloatArray, u_out: FloatArray) -> None:
    """:meth:`StageRows.for_the_arm` compiled (u empty: no row has an upper bound)."""
    m, n_v = C.shape
    for k in range(m):
        share = 0.0  # C_w w: the held wheels' share
        for j in range(n_w):
            share += C[k, j] * held[j]
        best = 0.0  # max C_arm v_m over lb ≤ v_m ≤ ub
        for i in range(n_v - n_w):
            c = C[k, n_w + i]
            C_out[k, i] = c
            best += c * ub[i] if c > 0.0 else c * lb[i]
        l_out[k] = min(damper[k], best + share) - share
        hi = min(u[k], INF) if u.shape[0] else INF
        u_out[k] = INF if hi >= INF else hi - share
