"""Compiled GJK distances for the collision rows: convex vertex sets (the hulls of a URDF's
collision meshes) against each other, against swept segments (spheres, capsules) and boxes,
boxes against boxes, and vertex sets against planes, in one compiled pass with the other
primitives (checked against coal in ``tests/core/test_gjk.py``).

A shape is given by its support point (the farthest point along a direction): a segment's end
(its radius is added after), a box's corner, a hull's vertex. GJK (Gilbert, Johnson, Keerthi
1988; in the form of van den Bergen, *Collision Detection in Interactive 3D Environments*, 4.3)
walks a simplex of the Minkowski difference A − B towards the origin; the closest point on each
simplex is the affine projection of the origin on the one face whose barycentric coordinates
are all positive and which lies nearest (the faces that hold the newest point tried: at most 8
for a tetrahedron; every face, 15, only where rounding leaves none of those). The
distance between the cores is then exact up to the termination tolerance, and the closest points
come from the barycentric coordinates of the support points. Where the cores touch or overlap
(the origin in the simplex, or a core distance under :data:`TOUCH`) GJK gives no distance: the
caller leaves the pair to coal (EPA), as it does for any pair GJK does not finish.

Kinds as in :mod:`._pair_passes`: 0 a swept segment [a0, a1] of radius r, 1 a box (centre c,
rotation R, half extents h), 3 a convex vertex set (vertices ``verts[vs:vs + vc]`` in the shape's
own frame, placed by c, R).
"""

from __future__ import annotations

import math

from .._jit import jit, jit_inline
from .._typing import FloatArray, IntArray

TOUCH = 1e-6
"""[m] core distances below this are left to coal (touching or overlapping cores: no GJK distance)."""
ABS_TOL = 1e-15
"""[m²] added to GJK's stopping test: ‖v‖ then exceeds the distance by at most 1e-15 / ‖v‖ more
(≤ 1e-9 m above :data:`TOUCH`), where rounding keeps the relative test from ever passing."""
STALL_TOL = 1e-9
"""[m] a step of GJK that does not get nearer (rounding, parallel faces) ends it with the distance
it has if that is within this of the lower bound the step's support point gives; else coal."""
MAX_ITERATIONS = 64
"""GJK's iterations before it gives the pair up to coal (polytopes of ~100 vertices take ~5–15)."""
REL_TOL = 1e-12
"""GJK stops when ‖v‖² − v·w ≤ REL_TOL ‖v‖² (v the closest point so far, w the new support
point): ‖v‖ then exceeds the cores' distance by at most REL_TOL ‖v‖."""

_SA, _SB = 4, 8
"""GJK's scratch rows (and numbers) of the simplex's support points on A and on B, after its points
of A − B [0:4]."""
_NEW_A, _NEW_B = 12, 13
"""GJK's scratch rows of a new pair of support points (on A, on B)."""
WORK_FLOATS, WORK_INTS = 56, 12
"""GJK's workspace in its caller's arenas (:func:`gjk`'s ``ws``, ``wi``): the simplex and its support
points (14 × 3), the barycentric coordinates (8), the closest points on the cores p, q (3 + 3);
a face's points and the simplex's numbers on each shape (12 ints)."""
_LAM, _P, _Q = 42, 50, 53
"""The barycentric coordinates' and the closest points' offsets in the workspace (the simplex's
14 × 3 first)."""

Layout = tuple[int, int, int, int, int, int, int, int, int, int]
"""Where a table of shapes lies in a float arena F and an int arena I: the offsets of its arrays in
the order of :meth:`~wmm_qp.limits.pair_search.Table.shapes` (kind, a0, a1, r, c, R, h, verts, vs,
vc; kind, vs and vc in I, the rest in F, each row-major): shape i's kind is ``I[L[0] + i]``, its
rotation's entry (r, m) ``F[L[5] + 9 i + 3 r + m]``, its vertices from ``F[L[7] + 3 vs]``.
Compiled code takes a shape table so, as two arrays and a tuple of ints, instead of ten arrays:
each array a compiled call is handed has its reference count taken and released, two atomic
operations (``perf``: a third of GJK's warm calls' time, docs/benchmarks.md §12)."""


@jit_inline
def support(F: FloatArray, I: IntArray, L: Layout, i: int, dx: float, dy: float, dz: float, out: FloatArray,
            row: int) -> int:
    """``out[row]`` ← the point of shape i's core farthest along (dx, dy, dz); returns which point of
    the shape it is (:func:`point`: a segment's end 0 or 1, a box's corner as three sign bits, a vertex
    set's vertex index). The shapes are read in the arenas F, I at the offsets L (:data:`Layout`)."""
    k = I[L[0] + i]
    if k == 0:
        o0, o1 = L[1] + 3 * i, L[2] + 3 * i
        e0 = F[o0] * dx + F[o0 + 1] * dy + F[o0 + 2] * dz
        e1 = F[o1] * dx + F[o1 + 1] * dy + F[o1 + 2] * dz
        s = o0 if e0 >= e1 else o1
        out[row, 0], out[row, 1], out[row, 2] = F[s], F[s + 1], F[s + 2]
        return 0 if e0 >= e1 else 1
    oR = L[5] + 9 * i  # R[i, r, m] = F[oR + 3 r + m]
    # the direction in the shape's frame: Rᵀ d
    lx = F[oR] * dx + F[oR + 3] * dy + F[oR + 6] * dz
    ly = F[oR + 1] * dx + F[oR + 4] * dy + F[oR + 7] * dz
    lz = F[oR + 2] * dx + F[oR + 5] * dy + F[oR + 8] * dz
    if k == 1:
        oh = L[6] + 3 * i
        px = F[oh] if lx >= 0.0 else -F[oh]
        py = F[oh + 1] if ly >= 0.0 else -F[oh + 1]
        pz = F[oh + 2] if lz >= 0.0 else -F[oh + 2]
        which = (lx >= 0.0) + 2 * (ly >= 0.0) + 4 * (lz >= 0.0)
    else:
        vs, ov = I[L[8] + i], L[7]
        best, m = -math.inf, vs
        for t in range(vs, vs + I[L[9] + i]):
            e = F[ov + 3 * t] * lx + F[ov + 3 * t + 1] * ly + F[ov + 3 * t + 2] * lz
            if e > best:
                best, m = e, t
        px, py, pz = F[ov + 3 * m], F[ov + 3 * m + 1], F[ov + 3 * m + 2]
        which = m - vs
    oc = L[4] + 3 * i
    for r in range(3):
        out[row, r] = F[oc + r] + F[oR + 3 * r] * px + F[oR + 3 * r + 1] * py + F[oR + 3 * r + 2] * pz
    return which


@jit_inline
def point(F: FloatArray, I: IntArray, L: Layout, i: int, which: int, out: FloatArray, row: int) -> None:
    """``out[row]`` ← point ``which`` of shape i's core, as :func:`support` numbers them, where the
    shape is now."""
    k = I[L[0] + i]
    if k == 0:
        s = (L[1] if which == 0 else L[2]) + 3 * i
        out[row, 0], out[row, 1], out[row, 2] = F[s], F[s + 1], F[s + 2]
        return
    oR = L[5] + 9 * i
    if k == 1:
        oh = L[6] + 3 * i
        px = F[oh] if which & 1 else -F[oh]
        py = F[oh + 1] if which & 2 else -F[oh + 1]
        pz = F[oh + 2] if which & 4 else -F[oh + 2]
    else:
        t = L[7] + 3 * (I[L[8] + i] + which)
        px, py, pz = F[t], F[t + 1], F[t + 2]
    oc = L[4] + 3 * i
    for r in range(3):
        out[row, r] = F[oc + r] + F[oR + 3 * r] * px + F[oR + 3 * r + 1] * py + F[oR + 3 * r + 2] * pz


@jit_inline
def _origin(F: FloatArray, I: IntArray, L: Layout, i: int) -> tuple[float, float, float]:
    """A point inside shape i's core: a segment's middle, a box's or vertex set's frame origin."""
    if I[L[0] + i] == 0:
        o0, o1 = L[1] + 3 * i, L[2] + 3 * i
        return 0.5 * (F[o0] + F[o1]), 0.5 * (F[o0 + 1] + F[o1 + 1]), 0.5 * (F[o0 + 2] + F[o1 + 2])
    oc = L[4] + 3 * i
    return F[oc], F[oc + 1], F[oc + 2]


@jit_inline
def _project(W: FloatArray, idx: IntArray, m: int, lam: FloatArray, at: int) -> float:
    """The affine projection of the origin on the points W[idx[:m]]: its barycentric coordinates
    into ``lam[at:at + m]``; returns its squared norm, or inf where the points are
    degenerate or a coordinate is not positive (the projection is outside their hull). Solves the
    normal equations G μ = b of the edges e_r = y_r − y_0 (scalars: no temporaries)."""
    i0 = idx[0]
    y0x, y0y, y0z = W[i0, 0], W[i0, 1], W[i0, 2]
    if m == 1:
        lam[at] = 1.0
        return y0x * y0x + y0y * y0y + y0z * y0z
    i1 = idx[1]
    e1x, e1y, e1z = W[i1, 0] - y0x, W[i1, 1] - y0y, W[i1, 2] - y0z
    g11 = e1x * e1x + e1y * e1y + e1z * e1z
    b1 = -(e1x * y0x + e1y * y0y + e1z * y0z)
    mu1 = mu2 = mu3 = 0.0
    if m == 2:
        if g11 <= 1e-24:
            return math.inf
        mu1 = b1 / g11
    else:
        i2 = idx[2]
        e2x, e2y, e2z = W[i2, 0] - y0x, W[i2, 1] - y0y, W[i2, 2] - y0z
        g12 = e1x * e2x + e1y * e2y + e1z * e2z
        g22 = e2x * e2x + e2y * e2y + e2z * e2z
        b2 = -(e2x * y0x + e2y * y0y + e2z * y0z)
        if m == 3:
            det = g11 * g22 - g12 * g12
            scale = g11 + g22
            if not abs(det) > 1e-14 * scale * scale:
                return math.inf
            mu1 = (b1 * g22 - g12 * b2) / det
            mu2 = (g11 * b2 - b1 * g12) / det
        else:
            i3 = idx[3]
            e3x, e3y, e3z = W[i3, 0] - y0x, W[i3, 1] - y0y, W[i3, 2] - y0z
            g13 = e1x * e3x + e1y * e3y + e1z * e3z
            g23 = e2x * e3x + e2y * e3y + e2z * e3z
            g33 = e3x * e3x + e3y * e3y + e3z * e3z
            b3 = -(e3x * y0x + e3y * y0y + e3z * y0z)
            c11 = g22 * g33 - g23 * g23  # the cofactors of the symmetric G
            c12 = g13 * g23 - g12 * g33
            c13 = g12 * g23 - g13 * g22
            det = g11 * c11 + g12 * c12 + g13 * c13
            scale = g11 + g22 + g33
            if not abs(det) > 1e-14 * scale * scale * scale:
                return math.inf
            c22 = g11 * g33 - g13 * g13
            c23 = g12 * g13 - g11 * g23
            c33 = g11 * g22 - g12 * g12
            mu1 = (c11 * b1 + c12 * b2 + c13 * b3) / det
            mu2 = (c12 * b1 + c22 * b2 + c23 * b3) / det
            mu3 = (c13 * b1 + c23 * b2 + c33 * b3) / det
    lam0 = 1.0 - mu1 - mu2 - mu3
    if not (lam0 > 0.0 and mu1 > 0.0 and (m < 3 or mu2 > 0.0) and (m < 4 or mu3 > 0.0)):
        return math.inf
    lam[at], lam[at + 1] = lam0, mu1
    x = lam0 * y0x + mu1 * W[i1, 0]
    y = lam0 * y0y + mu1 * W[i1, 1]
    z = lam0 * y0z + mu1 * W[i1, 2]
    if m >= 3:
        lam[at + 2] = mu2
        x += mu2 * W[idx[2], 0]
        y += mu2 * W[idx[2], 1]
        z += mu2 * W[idx[2], 2]
    if m == 4:
        lam[at + 3] = mu3
        x += mu3 * W[idx[3], 0]
        y += mu3 * W[idx[3], 1]
        z += mu3 * W[idx[3], 2]
    return x * x + y * y + z * z


@jit_inline
def _nearest_face(S: FloatArray, n: int, first: int, ids: IntArray, lam: FloatArray) -> tuple[float, int]:
    """The face of the simplex S[:n] nearest the origin among those whose mask is ``first`` or more
    (``first`` = 1 << (n − 1): the faces with the newest point; 1: every face): its squared
    distance and mask (0: none projects into its hull), its barycentric coordinates into lam[:4]
    (a trial face's into lam[4:8], its points into ids[:4])."""
    best, best_mask = math.inf, 0
    for mask in range(first, 1 << n):
        m = 0
        for t in range(n):
            if mask & (1 << t):
                ids[m] = t
                m += 1
        dd = _project(S, ids, m, lam, 4)
        if dd < best:
            best, best_mask = dd, mask
            for t in range(m):
                lam[t] = lam[4 + t]
    return best, best_mask


@jit_inline
def _keep_face(S: FloatArray, ids: IntArray, n: int, mask: int) -> int:
    """The simplex S[:n] (its support points and their numbers, :data:`_SA`, :data:`_SB`) cut down to
    the face ``mask``, in order; returns its size."""
    m = 0
    for t in range(n):
        if mask & (1 << t):  # t >= m: copying down never overwrites a vertex still to come
            for r in range(3):
                S[m, r], S[_SA + m, r], S[_SB + m, r] = S[t, r], S[_SA + t, r], S[_SB + t, r]
            ids[_SA + m], ids[_SB + m] = ids[_SA + t], ids[_SB + t]
            m += 1
    return m


@jit_inline
def _add(S: FloatArray, n: int) -> None:
    """The new pair of support points (rows :data:`_NEW_A`, :data:`_NEW_B`) as the simplex's point n."""
    for r in range(3):
        S[n, r], S[_SA + n, r], S[_SB + n, r] = S[_NEW_A, r] - S[_NEW_B, r], S[_NEW_A, r], S[_NEW_B, r]


WARM_WIDTH = 10
"""A pair's warm start (:func:`gjk`'s ``FA[ow:ow + WARM_WIDTH]``): the direction from A's closest
point to B's [0:3], the size of the last simplex [3] and its points' numbers on A [4:7] and on B
[7:10] (:func:`point`)."""


@jit
def gjk(FA: FloatArray, IA: IntArray, LA: Layout, i: int, FB: FloatArray, IB: IntArray, LB: Layout, j: int,
        ow: int, ws: int, wi: int) -> float:
    """The distance of shape i of A's core to shape j of B's (the tables A and B in their arenas,
    :data:`Layout`), its closest points into the workspace (``FA[ws + _P:]``, ``FA[ws + _Q:]``);
    −1 where GJK gives none (cores within :data:`TOUCH` or overlapping, or no convergence). The
    workspace: ``FA[ws:ws + WORK_FLOATS]`` and ``IA[wi:wi + WORK_INTS]`` (:data:`WORK_FLOATS`).

    ``FA[ow:ow + WARM_WIDTH]`` (ow ≥ 0): where the last call for this pair ended, the
    simplex it ended on (its points by their numbers on the shapes, :func:`point`) and the
    direction between the closest points. GJK starts from that simplex where the shapes are now (a
    pair moves little in a tick: it is the closest feature or next to it, and GJK ends after one
    support step instead of several), else from the direction, else (zero, or w < 0) on the line
    between the shapes' origins. Any start gives the same distance within GJK's tolerance: every
    start is points of A − B, and GJK only stops where a support step finds nothing nearer.
    Updated here.

    Scalar arithmetic (an iteration is ~100 ns), no allocation. Its helpers are inlined
    (:func:`~wmm_qp._jit.jit_inline`) and read the scratch at offsets (:data:`_SA`, ...) rather than
    through ten views, and its shapes in two arenas rather than ten arrays a side: an array that a
    compiled call passes or a view holds has its reference count taken and released, two atomic
    operations (``perf``: 40 % of the warm calls' samples with ten views and twenty arrays;
    docs/benchmarks.md §12)."""
    S = FA[ws : ws + _LAM].reshape((14, 3))  # the simplex (A − B) [0:4], its support points on A [_SA:] and
    # B [_SB:], a new pair
    lam = FA[ws + _LAM : ws + _P]  # barycentric coordinates: the best face's [0:4], a trial face's [4:8]
    ids = IA[wi : wi + WORK_INTS]  # a face's points [0:4]; the simplex's numbers on A [_SA:], B [_SB:]
    n = 0
    if ow >= 0 and FA[ow + 3] > 0.0:  # the last simplex, where the shapes are now
        for t in range(int(FA[ow + 3])):
            a, b = int(FA[ow + 4 + t]), int(FA[ow + 7 + t])
            point(FA, IA, LA, i, a, S, _NEW_A)
            point(FB, IB, LB, j, b, S, _NEW_B)
            dup = False
            for u in range(n):
                if ids[_SA + u] == a and ids[_SB + u] == b:
                    dup = True
            if dup:
                continue
            _add(S, n)
            ids[_SA + n], ids[_SB + n] = a, b
            n += 1
        best, mask = _nearest_face(S, n, 1, ids, lam)
        if mask == 0 or best < TOUCH * TOUCH:
            n = 0  # degenerate where the shapes are now: start afresh
        else:
            n = _keep_face(S, ids, n, mask)
            vv = best
    if n == 0:  # the first point: the supports facing each other along the last direction, or the
        # line between the shapes' origins
        if ow >= 0 and (FA[ow] != 0.0 or FA[ow + 1] != 0.0 or FA[ow + 2] != 0.0):
            dx, dy, dz = FA[ow], FA[ow + 1], FA[ow + 2]
        else:
            ax, ay, az = _origin(FA, IA, LA, i)
            bx, by, bz = _origin(FB, IB, LB, j)
            dx, dy, dz = bx - ax, by - ay, bz - az
        ids[_SA] = support(FA, IA, LA, i, dx, dy, dz, S, _NEW_A)
        ids[_SB] = support(FB, IB, LB, j, -dx, -dy, -dz, S, _NEW_B)
        _add(S, 0)
        n = 1
        lam[0] = 1.0
        vv = S[0, 0] * S[0, 0] + S[0, 1] * S[0, 1] + S[0, 2] * S[0, 2]
    vx = vy = vz = 0.0
    for r in range(n):
        vx += lam[r] * S[r, 0]
        vy += lam[r] * S[r, 1]
        vz += lam[r] * S[r, 2]
    done = False
    for _ in range(MAX_ITERATIONS):
        if vv < TOUCH * TOUCH:
            return -1.0
        ia = support(FA, IA, LA, i, -vx, -vy, -vz, S, _NEW_A)
        ib = support(FB, IB, LB, j, vx, vy, vz, S, _NEW_B)
        wx, wy, wz = S[_NEW_A, 0] - S[_NEW_B, 0], S[_NEW_A, 1] - S[_NEW_B, 1], S[_NEW_A, 2] - S[_NEW_B, 2]
        vw = vx * wx + vy * wy + vz * wz
        if vv - vw <= REL_TOL * vv + ABS_TOL:  # w no nearer than v: v is the closest
            done = True
            break
        lower = vw / math.sqrt(vv)  # the distance is at least this (A − B is beyond the plane of w ⊥ v)
        dup = False
        for t in range(n):
            if S[t, 0] == wx and S[t, 1] == wy and S[t, 2] == wz:
                dup = True
        if dup:  # w is a vertex already: v is the closest
            done = True
            break
        _add(S, n)  # (its point of A − B is w)
        ids[_SA + n], ids[_SB + n] = ia, ib
        n += 1
        # the nearest face of the simplex and the barycentric coordinates of v on it: first only
        # the faces with w (bit n − 1). v was the nearest point of the simplex without w and w lies
        # nearer along v (the test above), so moving from v towards w gets nearer: the nearest
        # point of the new simplex has a positive weight on w. Every face only where rounding
        # leaves none of those valid.
        best, best_mask = _nearest_face(S, n, 1 << (n - 1), ids, lam)
        if best_mask == 0:
            best, best_mask = _nearest_face(S, n, 1, ids, lam)
        if best_mask == 0 or (n == 4 and best_mask == 15):
            return -1.0  # no face projects into its hull (degenerate), or the origin is inside
        n = _keep_face(S, ids, n, best_mask)
        new_vv = best
        if not new_vv < vv:  # no progress (rounding in a flat simplex: parallel faces)
            if math.sqrt(new_vv) - lower <= STALL_TOL:  # the face's point is that close to the distance
                done = True
                break
            return -1.0  # else coal decides
        vv = new_vv
        vx = vy = vz = 0.0
        for r in range(n):
            vx += lam[r] * S[r, 0]
            vy += lam[r] * S[r, 1]
            vz += lam[r] * S[r, 2]
    if not done:
        return -1.0
    p, q = ws + _P, ws + _Q
    for c in range(3):
        pc = qc = 0.0
        for r in range(n):
            pc += lam[r] * S[_SA + r, c]
            qc += lam[r] * S[_SB + r, c]
        FA[p + c], FA[q + c] = pc, qc
    dist = math.sqrt((FA[p] - FA[q]) ** 2 + (FA[p + 1] - FA[q + 1]) ** 2 + (FA[p + 2] - FA[q + 2]) ** 2)
    if not dist >= TOUCH:
        return -1.0
    if ow >= 0:
        for c in range(3):
            FA[ow + c] = FA[q + c] - FA[p + c]
        FA[ow + 3] = float(n) if n < 4 else 0.0
        for t in range(min(n, 3)):
            FA[ow + 4 + t], FA[ow + 7 + t] = float(ids[_SA + t]), float(ids[_SB + t])
    return dist


@jit
def convex_pair(FA: FloatArray, IA: IntArray, LA: Layout, i: int, FB: FloatArray, IB: IntArray, LB: Layout, j: int,
                p: FloatArray, q: FloatArray, n: FloatArray, ow: int, ws: int, wi: int) -> tuple[float, bool]:
    """Shape i of A against shape j of B (either a vertex set, segment or box; the tables in their
    arenas, :data:`Layout`): the signed distance (the cores' less both radii), the closest points on
    the shapes into p and q, the unit normal from B to A into n; and whether GJK gave it (False:
    leave the pair to coal). ``ow``: GJK's start for this pair, ``ws``, ``wi``: its workspace
    (:func:`gjk`)."""
    dist = gjk(FA, IA, LA, i, FB, IB, LB, j, ow, ws, wi)
    ra = FA[LA[3] + i] if IA[LA[0] + i] == 0 else 0.0
    rb = FB[LB[3] + j] if IB[LB[0] + j] == 0 else 0.0
    return on_the_shapes(dist, ra, rb, FA, ws, p, q, n)


@jit_inline
def uses_gjk(ka: int, kb: int) -> bool:
    """Whether :func:`convex_pair` computes a pair of these kinds: a hull and anything but kind 2,
    or two boxes."""
    return (ka == 3 and kb != 2) or (kb == 3 and ka != 2) or (ka == 1 and kb == 1)


@jit_inline
def on_the_shapes(dist: float, ra: float, rb: float, W: FloatArray, ws: int, p: FloatArray, q: FloatArray,
                  n: FloatArray) -> tuple[float, bool]:
    """:func:`gjk`'s core distance and closest points (in its workspace ``W[ws:]``) moved onto the
    shapes of radii ra and rb (a swept segment's; 0 otherwise), into p and q: (the signed distance,
    whether GJK gave one), the unit normal from B to A into n."""
    if dist < 0.0:
        return 0.0, False
    for r in range(3):
        pr, qr = W[ws + _P + r], W[ws + _Q + r]
        n[r] = (pr - qr) / dist
        p[r] = pr - ra * n[r]
        q[r] = qr + rb * n[r]
    return dist - ra - rb, True


@jit
def convex_plane(c: FloatArray, R: FloatArray, verts: FloatArray, vs: IntArray, vc: IntArray, i: int,
                 normal: FloatArray, offset: float, p: FloatArray, q: FloatArray, n: FloatArray) -> float:
    """A vertex set against the plane normal·x = offset (solid where normal·x > offset): its
    deepest vertex."""
    lx = R[i, 0, 0] * normal[0] + R[i, 1, 0] * normal[1] + R[i, 2, 0] * normal[2]
    ly = R[i, 0, 1] * normal[0] + R[i, 1, 1] * normal[1] + R[i, 2, 1] * normal[2]
    lz = R[i, 0, 2] * normal[0] + R[i, 1, 2] * normal[1] + R[i, 2, 2] * normal[2]
    best, m = -math.inf, vs[i]
    for t in range(vs[i], vs[i] + vc[i]):
        e = verts[t, 0] * lx + verts[t, 1] * ly + verts[t, 2] * lz
        if e > best:
            best, m = e, t
    for r in range(3):
        p[r] = c[i, r] + R[i, r, 0] * verts[m, 0] + R[i, r, 1] * verts[m, 1] + R[i, r, 2] * verts[m, 2]
    gap = offset - (normal[0] * p[0] + normal[1] * p[1] + normal[2] * p[2])
    for r in range(3):
        n[r] = -normal[r]
        q[r] = p[r] + gap * normal[r]
    return gap
