"""The collision rows' candidate passes, compiled: every monitored pair the broad phase lets
through, its distance appended to one candidate buffer.

The buffer (:class:`~wmm_qp.limits.pair_search.Candidates`): per entry the signed distance d [m],
the closest points P on the body and Q on the other side, the unit normal N from the other side to
the body (base frame), ok (False: the compiled distances do not cover the pair, coal computes it),
the body's index, the other side (a body ≥ 0, the floor −1, obstacle k −2 − k) and the pair's
safety distance d_s [m]. Primitives come in arrays (:class:`~wmm_qp.limits.pair_search.Table`):
kind 0 a swept segment [a0, a1] of radius r, 1 a box (centre c, rotation R, half extents h),
3 a convex vertex set (a mesh's hull: ``verts[vs:vs + vc]`` in its frame, placed by c and R; its
distances, and a box's to a box, by GJK, :mod:`._gjk`), 2 anything else; ``centre`` and
``radii`` their bounding spheres.
"""

from __future__ import annotations

import math

import numpy as np

from .._jit import jit, jit_inline
from .._typing import BoolArray, FloatArray, IntArray
from ._distance import box_plane, segment_distance, swept_box, swept_plane, swept_swept, swept_swept_at
from ._gjk import WARM_WIDTH, Layout, convex_pair, convex_plane, gjk, on_the_shapes, uses_gjk

COHERENCE_MARGIN = 1e-9
"""[m] what :func:`self_pass` keeps in hand when it leaves out a pair by its last distance (that
distance's rounding, the travel's sum's)."""
TRAVEL_RESTART = 1.0
"""[m] a body's travel (:func:`body_travel`) past which every body's starts again from 0 (its sum's
rounding kept ~1e-16 m; every pair is computed that tick, a tick's travel being millimetres)."""


@jit
def place_kernel(
    Hj: FloatArray, joint: IntArray, kind: IntArray, a0: FloatArray, a1: FloatArray, c: FloatArray,
    R: FloatArray, centre: FloatArray, o_a0: FloatArray, o_a1: FloatArray, o_c: FloatArray, o_R: FloatArray,
    o_centre: FloatArray,
) -> None:
    """Every primitive k placed by its joint's homogeneous transform Hj[joint[k]] (the ``o_`` arrays):
    its bounding sphere's centre, and a swept segment's ends (kind 0) or another shape's frame, c
    and R (what the distances read of each kind; a segment's c and R, another's ends, are left as
    they are)."""
    for k in range(joint.shape[0]):
        j = joint[k]
        swept = kind[k] == 0
        for r in range(3):
            o_centre[k, r] = Hj[j, r, 3]
            if swept:
                o_a0[k, r] = Hj[j, r, 3]
                o_a1[k, r] = Hj[j, r, 3]
            else:
                o_c[k, r] = Hj[j, r, 3]
            for m in range(3):
                o_centre[k, r] += Hj[j, r, m] * centre[k, m]
                if swept:
                    o_a0[k, r] += Hj[j, r, m] * a0[k, m]
                    o_a1[k, r] += Hj[j, r, m] * a1[k, m]
                else:
                    o_c[k, r] += Hj[j, r, m] * c[k, m]
                    acc = 0.0
                    for q in range(3):
                        acc += Hj[j, r, q] * R[k, q, m]
                    o_R[k, r, m] = acc


@jit_inline
def _row3(F: FloatArray, o: int, i: int) -> FloatArray:
    """Entry i of a table's (n, 3) array at offset o of the arena F (:data:`._gjk.Layout`), a view."""
    return F[o + 3 * i : o + 3 * i + 3]


@jit
def pair_one(
    FA: FloatArray, IA: IntArray, LA: Layout, i: int, FB: FloatArray, IB: IntArray, LB: Layout, j: int,
    d: FloatArray, P: FloatArray, Q: FloatArray, N: FloatArray, ok: BoolArray, k: int, ow: int, ws: int, wi: int,
) -> None:
    """Entry k ← the distance of A[i] to B[j] (ok False where coal must compute it); the tables in
    their arenas (:data:`._gjk.Layout`); ``ow``, ``ws``, ``wi``: GJK's start for the pair (−1: none)
    and its workspace, in A's arenas (:func:`._gjk.gjk`)."""
    ok[k] = True
    ka, kb = IA[LA[0] + i], IB[LB[0] + j]
    if uses_gjk(ka, kb):
        # a hull, or two boxes: GJK (touching cores: coal)
        dd, got = convex_pair(FA, IA, LA, i, FB, IB, LB, j, P[k], Q[k], N[k], ow, ws, wi)
        d[k], ok[k] = dd, got
    elif ka == 0 and kb == 0:
        d[k] = swept_swept(_row3(FA, LA[1], i), _row3(FA, LA[2], i), FA[LA[3] + i], _row3(FB, LB[1], j),
                           _row3(FB, LB[2], j), FB[LB[3] + j], P[k], Q[k], N[k])
    elif ka == 0 and kb == 1:
        ra = FA[LA[3] + i]
        d[k] = swept_box(_row3(FA, LA[1], i), _row3(FA, LA[2], i), ra, _row3(FB, LB[4], j),
                         FB[LB[5] + 9 * j : LB[5] + 9 * j + 9].reshape((3, 3)), _row3(FB, LB[6], j), P[k], Q[k], N[k])
        ok[k] = d[k] + ra >= 0.0  # the segment itself inside the box: see swept_box
    elif ka == 1 and kb == 0:
        rb = FB[LB[3] + j]
        d[k] = swept_box(_row3(FB, LB[1], j), _row3(FB, LB[2], j), rb, _row3(FA, LA[4], i),
                         FA[LA[5] + 9 * i : LA[5] + 9 * i + 9].reshape((3, 3)), _row3(FA, LA[6], i), Q[k], P[k], N[k])
        N[k] = -N[k]
        ok[k] = d[k] + rb >= 0.0
    else:
        ok[k] = False


@jit
def plane_one(
    kind: IntArray, a0: FloatArray, a1: FloatArray, r: FloatArray, c: FloatArray, R: FloatArray, h: FloatArray,
    verts: FloatArray, vs: IntArray, vc: IntArray,
    i: int, normal: FloatArray, offset: float, d: FloatArray, P: FloatArray, Q: FloatArray, N: FloatArray,
    ok: BoolArray, k: int,
) -> None:
    """Entry k ← the distance of A[i] to the plane (ok False where coal must compute it)."""
    ok[k] = True
    if kind[i] == 0:
        d[k] = swept_plane(a0[i], a1[i], r[i], normal, offset, P[k], Q[k], N[k])
    elif kind[i] == 1:
        d[k] = box_plane(c[i], R[i], h[i], normal, offset, P[k], Q[k], N[k])
    elif kind[i] == 3:
        d[k] = convex_plane(c, R, verts, vs, vc, i, normal, offset, P[k], Q[k], N[k])
    else:
        ok[k] = False


@jit
def self_pass(
    kind: IntArray, a0: FloatArray, a1: FloatArray, r: FloatArray, F: FloatArray, I: IntArray, L: Layout,
    centre: FloatArray, pairs: IntArray, pair_r: FloatArray, d_i: float, d_s: float,
    d: FloatArray, P: FloatArray, Q: FloatArray, N: FloatArray, ok: BoolArray, body: IntArray, other: IntArray,
    safety: FloatArray, n: int, warm: int, ws: int, wi: int, cap: FloatArray, cap_r: FloatArray,
    moved: FloatArray, slack: FloatArray, cover: IntArray, pair_d: FloatArray, cover_within: float,
) -> int:
    """The robot's own pairs whose bounding spheres are within d_i (the broad phase), their
    distances appended to the candidates from entry n; returns the new count. The bodies' table is
    in the arenas F, I (:data:`._gjk.Layout`; ``kind``, ``a0``, ``a1``, ``r``: its views, read by the
    pairs of swept segments); ``F[warm + WARM_WIDTH k:]``: GJK's start for pair k, ``ws``, ``wi``: its
    workspace (:func:`._gjk.gjk`). A pair that is not two swept segments (whose distance
    is as cheap) is left out, too, where the bounding capsules of its shapes (``cap[i]``: the
    segment's ends, placed; ``cap_r[i]``: the radius) are further apart than d_i: its distance is
    no less than theirs (a capsule distance instead of GJK's iterations).

    Two swept segments are left out, too, while the last lower bound d₀ of their distance (their
    distance, or their bounding spheres' gap where the spheres were beyond d_i) still keeps them
    beyond d_i: no point of body i has moved further than ``moved[i, 3]`` − (its value then) since
    (:func:`body_travel`), so d ≥ d₀ − (how far both moved) > d_i (``slack[k]``: d₀ − d_i − 1e-9 m,
    −inf where the pair has no such bound, and both bodies' travel then). Their candidates are
    those of a pass without it, bit for bit (a pair of swept segments keeps no state between
    ticks; GJK's pairs, which keep their warm start, are not left out so).

    A pair of a body inside another (``cover[k]``: its containers' pair, which comes before it;
    −1: none) is left out, too, while that pair's distance this tick (``pair_d``: inf where it was
    not computed, beyond d_i; −inf where it was left to coal, unknown here) is beyond
    ``cover_within`` (d_s + ``COVER_REACH``): it is no nearer
    (:attr:`~wmm_qp.model.collision.RobotGeometry.covered_pairs`)."""
    for k in range(pairs.shape[0]):
        i, j = pairs[k, 0], pairs[k, 1]
        pair_d[k] = math.inf
        if cover[k] >= 0 and not pair_d[cover[k]] < cover_within:
            continue
        swept = kind[i] == 0 and kind[j] == 0  # two capsules or spheres (most pairs)
        travel = 0.0
        if swept:
            travel = moved[i, 3] + moved[j, 3]
            if travel - slack[k, 1] < slack[k, 0]:  # still beyond d_i (the last bound, less the travel)
                continue
        x, y, z = centre[i, 0] - centre[j, 0], centre[i, 1] - centre[j, 1], centre[i, 2] - centre[j, 2]
        gap = math.sqrt(x * x + y * y + z * z) - pair_r[k]
        if not gap <= d_i:
            if swept:  # the spheres' gap: a lower bound of the distance
                slack[k, 0], slack[k, 1] = gap - d_i - COHERENCE_MARGIN, travel
            continue
        if swept:  # by index
            swept_swept_at(a0, a1, r, i, j, d, P, Q, N, n)
            ok[n] = True
            slack[k, 0], slack[k, 1] = d[n] - d_i - COHERENCE_MARGIN, travel
            pair_d[k] = d[n]
        else:
            lower = segment_distance(cap[i, 0, 0], cap[i, 0, 1], cap[i, 0, 2], cap[i, 1, 0], cap[i, 1, 1], cap[i, 1, 2],
                                     cap[j, 0, 0], cap[j, 0, 1], cap[j, 0, 2], cap[j, 1, 0], cap[j, 1, 1],
                                     cap[j, 1, 2])[0] - cap_r[i] - cap_r[j]
            if lower > d_i:
                continue
            if uses_gjk(kind[i], kind[j]):  # GJK called directly, convex_pair's work inline (a call
                # between compiled functions takes and releases each array's reference: those saved)
                dist = gjk(F, I, L, i, F, I, L, j, warm + WARM_WIDTH * k, ws, wi)
                d[n], ok[n] = on_the_shapes(dist, r[i] if kind[i] == 0 else 0.0, r[j] if kind[j] == 0 else 0.0, F, ws,
                                            P[n], Q[n], N[n])
            else:
                pair_one(F, I, L, i, F, I, L, j, d, P, Q, N, ok, n, warm + WARM_WIDTH * k, ws, wi)
        if not swept:
            pair_d[k] = d[n] if ok[n] else -math.inf  # (left to coal: unknown here, the pairs it covers computed)
        body[n], other[n], safety[n] = i, j, d_s
        n += 1
    return n


@jit
def plane_pass(
    kind: IntArray, a0: FloatArray, a1: FloatArray, r: FloatArray, c: FloatArray, R: FloatArray, h: FloatArray,
    verts: FloatArray, vs: IntArray, vc: IntArray,
    centre: FloatArray, radii: FloatArray, idx: IntArray, cull: bool, normal: FloatArray, offset: float,
    d_i: float, code: int, d_s: float,
    d: FloatArray, P: FloatArray, Q: FloatArray, N: FloatArray, ok: BoolArray, body: IntArray, other: IntArray,
    safety: FloatArray, n: int,
) -> int:
    """The bodies ``idx`` against the plane normal·x = offset (free side ≤), appended from entry n
    (the other side coded ``code``); with ``cull`` only those whose bounding sphere is within d_i."""
    for t in range(idx.shape[0]):
        i = idx[t]
        if cull:
            gap = offset - (normal[0] * centre[i, 0] + normal[1] * centre[i, 1] + normal[2] * centre[i, 2]) - radii[i]
            if not gap <= d_i:
                continue
        plane_one(kind, a0, a1, r, c, R, h, verts, vs, vc, i, normal, offset, d, P, Q, N, ok, n)
        body[n], other[n], safety[n] = i, code, d_s
        n += 1
    return n


@jit_inline
def _view1(A: np.ndarray, L: IntArray, k: int) -> np.ndarray:
    """Array k of the arena A (either of :func:`robot_passes`'s, float or int): ``L[k]`` =
    (offset, size), 1-D."""
    return A[L[k, 0] : L[k, 0] + L[k, 1]]


@jit_inline
def _view2(A: np.ndarray, L: IntArray, k: int) -> np.ndarray:
    """Array k of A, 2-D: ``L[k]`` = (offset, size, rows, columns)."""
    return A[L[k, 0] : L[k, 0] + L[k, 1]].reshape((L[k, 2], L[k, 3]))


@jit_inline
def _view3(A: np.ndarray, L: IntArray, k: int) -> np.ndarray:
    """Array k of A, 3-D: ``L[k]`` = (offset, size, d0, d1, d2)."""
    return A[L[k, 0] : L[k, 0] + L[k, 1]].reshape((L[k, 2], L[k, 3], L[k, 4]))


@jit
def robot_passes(
    oMi: FloatArray, F: FloatArray, Lf: IntArray, I: IntArray, Li: IntArray, ok: BoolArray, d_i: float, d_s: float,
    floor_o: float, floor_margin: float, cover_within: float,
) -> tuple[int, int]:
    """A tick's robot-side passes in one call: the joints' placements Hj read from Pinocchio's
    ``oMi`` (row ``joint_id[k]``: rotation column-major, translation; empty: Hj is current), the
    bodies placed (:func:`place_kernel`, from the ``l_`` arrays, their frames', into the placed
    table's), how far each has moved (:func:`body_travel`), the robot's own pairs
    (:func:`self_pass`) and the floor (:func:`plane_pass`, code −1) from entry 0. Returns the
    number of candidates and how many of them the compiled distances left to coal.

    Its arrays come packed into two arenas, F and I (in the orders of ``ROBOT_FLOATS`` and
    ``ROBOT_INTS``; ``Lf``, ``Li``: each one's offset, size and shape, as
    :func:`~wmm_qp.limits.pair_search.pack` lays them out), unpacked here into views: a compiled
    call unboxes each array it is passed (~50 ns each), and one compiled function passing them on
    to another takes and releases each one's reference (~25 ns each). ``cap_local``: each body's
    bounding capsule's ends in its joint's frame, placed into ``cap`` (:func:`self_pass`);
    ``last_H``, ``moved``, ``slack``: :func:`body_travel`'s and :func:`self_pass`'s."""
    Hj, l_R, R, cap_local, cap, last_H = (_view3(F, Lf, 0), _view3(F, Lf, 4), _view3(F, Lf, 10), _view3(F, Lf, 23),
                                          _view3(F, Lf, 25), _view3(F, Lf, 26))
    l_a0, l_a1, l_c, l_centre = _view2(F, Lf, 1), _view2(F, Lf, 2), _view2(F, Lf, 3), _view2(F, Lf, 5)
    a0, a1, c, h, verts, centre = (_view2(F, Lf, 6), _view2(F, Lf, 7), _view2(F, Lf, 9), _view2(F, Lf, 11),
                                   _view2(F, Lf, 12), _view2(F, Lf, 13))
    P, Q, N, moved, slack = (_view2(F, Lf, 18), _view2(F, Lf, 19), _view2(F, Lf, 20), _view2(F, Lf, 27),
                             _view2(F, Lf, 28))
    r, radii, pair_r, floor_n, d, safety, cap_r = (_view1(F, Lf, 8), _view1(F, Lf, 14), _view1(F, Lf, 15),
                                                   _view1(F, Lf, 16), _view1(F, Lf, 17), _view1(F, Lf, 21),
                                                   _view1(F, Lf, 24))
    joint_id, joint, kind, vs, vc = (_view1(I, Li, 0), _view1(I, Li, 1), _view1(I, Li, 2), _view1(I, Li, 3),
                                     _view1(I, Li, 4))
    pairs, floor_idx, body, other = _view2(I, Li, 5), _view1(I, Li, 6), _view1(I, Li, 7), _view1(I, Li, 8)
    cover, pair_d = _view1(I, Li, 9), _view1(F, Lf, 29)
    if oMi.shape[0]:
        for k in range(joint_id.shape[0]):
            row = oMi[joint_id[k]]
            for a in range(3):  # (r and R are the shapes' radii and rotations here)
                for b in range(3):
                    Hj[k, a, b] = row[a + 3 * b]
                Hj[k, a, 3] = row[9 + a]
    place_kernel(Hj, joint, kind, l_a0, l_a1, l_c, l_R, l_centre, a0, a1, c, R, centre)
    for k in range(joint.shape[0]):  # the bounding capsules (cap_local: their ends, joint frames)
        H = Hj[joint[k]]
        for e in range(2):
            for a in range(3):
                cap[k, e, a] = (H[a, 3] + H[a, 0] * cap_local[k, e, 0] + H[a, 1] * cap_local[k, e, 1]
                                + H[a, 2] * cap_local[k, e, 2])
    body_travel(Hj, joint, centre, radii, last_H, moved, slack)
    n = self_pass(kind, a0, a1, r, F, I, robot_layout(Lf, Li), centre, pairs, pair_r, d_i, d_s,
                  d, P, Q, N, ok, body, other, safety, 0, Lf[_WARM, 0], Lf[_WORK, 0], Li[_WORK_IDS, 0], cap, cap_r,
                  moved, slack, cover, pair_d, cover_within)
    n = plane_pass(kind, a0, a1, r, c, R, h, verts, vs, vc, centre, radii, floor_idx, True, floor_n, floor_o,
                   d_i, -1, floor_margin, d, P, Q, N, ok, body, other, safety, n)
    return n, left_to_coal(ok, 0, n)


ROBOT_FLOATS = ("Hj", "l_a0", "l_a1", "l_c", "l_R", "l_centre", "a0", "a1", "r", "c", "R", "h", "verts", "centre",
                "radii", "pair_r", "floor_n", "d", "P", "Q", "N", "safety", "warm", "cap_local", "cap_r", "cap",
                "last_H", "moved", "slack", "pair_d", "warm_solid", "work")
"""The float arrays of :func:`robot_passes`, in the order it unpacks them from its arena F
(``warm_solid``: GJK's starts of the (solid obstacle, body) pairs, :func:`solid_pass`'s; ``work``:
GJK's workspace, :data:`._gjk.WORK_FLOATS`)."""
ROBOT_INTS = ("joint_id", "joint", "kind", "vs", "vc", "pairs", "floor_idx", "body", "other", "cover", "work_ids")
"""Its int arrays, likewise (from I)."""
TABLE_FLOATS, TABLE_INTS = ("a0", "a1", "r", "c", "R", "h", "verts"), ("kind", "vs", "vc")
"""A shape table's arrays in its float and int arenas (:data:`._gjk.Layout`)."""
_WARM, _WORK, _WORK_IDS = ROBOT_FLOATS.index("warm"), ROBOT_FLOATS.index("work"), ROBOT_INTS.index("work_ids")
_RF = tuple(ROBOT_FLOATS.index(k) for k in TABLE_FLOATS)
_RI = tuple(ROBOT_INTS.index(k) for k in TABLE_INTS)


@jit_inline
def robot_layout(Lf: IntArray, Li: IntArray) -> Layout:
    """The placed bodies' table in :func:`robot_passes`'s arenas, as :data:`._gjk.Layout` gives it."""
    return (Li[_RI[0], 0], Lf[_RF[0], 0], Lf[_RF[1], 0], Lf[_RF[2], 0], Lf[_RF[3], 0], Lf[_RF[4], 0], Lf[_RF[5], 0],
            Lf[_RF[6], 0], Li[_RI[1], 0], Li[_RI[2], 0])


def layout(Lf: IntArray, Li: IntArray, floats: tuple[str, ...], ints: tuple[str, ...]) -> Layout:
    """A shape table's :data:`._gjk.Layout` in arenas packed in the orders ``floats``, ``ints``
    (:func:`~wmm_qp.limits.pair_search.pack`'s ``L``), as Python ints."""
    f = [int(Lf[floats.index(k), 0]) for k in TABLE_FLOATS]
    i = [int(Li[ints.index(k), 0]) for k in TABLE_INTS]
    return (i[0], f[0], f[1], f[2], f[3], f[4], f[5], f[6], i[1], i[2])


@jit_inline
def candidates_of(F: FloatArray, Lf: IntArray, I: IntArray, Li: IntArray) -> tuple[
        FloatArray, FloatArray, FloatArray, FloatArray, IntArray, IntArray, FloatArray]:
    """The candidate buffer's arrays in :func:`robot_passes`'s arenas: (d, P, Q, N, body, other,
    safety) (the obstacles' passes append to the same arrays)."""
    return (_view1(F, Lf, 17), _view2(F, Lf, 18), _view2(F, Lf, 19), _view2(F, Lf, 20), _view1(I, Li, 7),
            _view1(I, Li, 8), _view1(F, Lf, 21))


@jit
def body_travel(Hj: FloatArray, joint: IntArray, centre: FloatArray, radii: FloatArray, last_H: FloatArray,
                moved: FloatArray, slack: FloatArray) -> None:
    """How far each body has moved, at most, since its travel last started from 0: ``moved[k, 3]``
    += the largest displacement of any point of its bounding sphere (centre c, radius ρ) since the
    last call, |Δc| + ‖ΔR‖_F ρ (a point c + u, |u| ≤ ρ, moves by Δc + ΔR u, and ‖ΔR‖₂ ≤ ‖ΔR‖_F),
    from its joint's placement ``Hj`` against the last one (``last_H``) and its centre against the
    last one (``moved[k, :3]``); both then take this call's.

    The sum is compensated (Kahan's, ``moved[k, 4]``: what rounding left out), so its error stays
    ~1e-16 of it however many small steps it adds; and once a body's travel passes
    ``TRAVEL_RESTART`` every body's starts again from 0 and every pair's slack is forgotten
    (:func:`self_pass` computes every pair that tick), so the error stays far below
    ``COHERENCE_MARGIN``. The same where a displacement is not finite (a state that should
    never reach here)."""
    spin = np.empty(Hj.shape[0])
    for j in range(Hj.shape[0]):
        s = 0.0
        for a in range(3):
            for b in range(3):
                e = Hj[j, a, b] - last_H[j, a, b]
                s += e * e
                last_H[j, a, b] = Hj[j, a, b]
        spin[j] = math.sqrt(s)
    restart = False
    for k in range(joint.shape[0]):
        x, y, z = centre[k, 0] - moved[k, 0], centre[k, 1] - moved[k, 1], centre[k, 2] - moved[k, 2]
        step = math.sqrt(x * x + y * y + z * z) + spin[joint[k]] * radii[k]
        moved[k, 0], moved[k, 1], moved[k, 2] = centre[k, 0], centre[k, 1], centre[k, 2]
        if math.isfinite(step):
            y_k = step - moved[k, 4]  # Kahan: the step less what the last sum lost
            total = moved[k, 3] + y_k
            moved[k, 4] = (total - moved[k, 3]) - y_k
            moved[k, 3] = total
            restart = restart or total > TRAVEL_RESTART
        else:
            restart = True
    if restart:
        for k in range(joint.shape[0]):
            moved[k, 3] = moved[k, 4] = 0.0
        for k in range(slack.shape[0]):
            slack[k, 0] = -math.inf


@jit
def left_to_coal(ok: BoolArray, start: int, n: int) -> int:
    """How many of the candidates start..n−1 the compiled distances left to coal."""
    left = 0
    for k in range(start, n):
        if not ok[k]:
            left += 1
    return left


@jit
def solid_pass(
    FA: FloatArray, IA: IntArray, LA: Layout, centre: FloatArray, radii: FloatArray,
    FB: FloatArray, IB: IntArray, LB: Layout, okind: IntArray, oc: FloatArray, oR: FloatArray, oh: FloatArray,
    ocentre: FloatArray, oradii: FloatArray, checked: BoolArray, solid: IntArray,
    d_i: float, d_s: float,
    d: FloatArray, P: FloatArray, Q: FloatArray, N: FloatArray, ok: BoolArray, body: IntArray, other: IntArray,
    safety: FloatArray, n: int, warm: int, ws: int, wi: int,
) -> int:
    """Every checked body (the table A, in its arenas: :data:`._gjk.Layout`) against every solid
    obstacle (B, placed in the base frame; ``okind``, ``oc``, ``oR``, ``oh``: its views) within d_i:
    the broad phase on the bodies' bounding spheres (against a box: the sphere's distance to the box
    itself), appended from entry n (the other side coded −2 − the obstacle's index).
    ``FA[warm + WARM_WIDTH (o × bodies + b):]``: GJK's start for the pair, ``ws``, ``wi``: its
    workspace (:func:`._gjk.gjk`)."""
    bodies = centre.shape[0]
    for o in range(okind.shape[0]):
        for b in range(bodies):
            if not checked[o, b]:
                continue
            if okind[o] == 1:  # in the box's frame: the sphere's centre outside each slab
                s2 = 0.0
                for a in range(3):
                    rel = (oR[o, 0, a] * (centre[b, 0] - oc[o, 0]) + oR[o, 1, a] * (centre[b, 1] - oc[o, 1])
                           + oR[o, 2, a] * (centre[b, 2] - oc[o, 2]))
                    e = max(abs(rel) - oh[o, a], 0.0)
                    s2 += e * e
                gap = math.sqrt(s2) - radii[b]
            else:
                x, y, z = centre[b, 0] - ocentre[o, 0], centre[b, 1] - ocentre[o, 1], centre[b, 2] - ocentre[o, 2]
                gap = math.sqrt(x * x + y * y + z * z) - radii[b] - oradii[o]
            if not gap <= d_i:
                continue
            pair_one(FA, IA, LA, b, FB, IB, LB, o, d, P, Q, N, ok, n, warm + WARM_WIDTH * (o * bodies + b), ws, wi)
            body[n], other[n], safety[n] = b, -2 - solid[o], d_s
            n += 1
    return n
