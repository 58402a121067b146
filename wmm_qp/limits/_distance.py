"""Compiled distances between primitives, for the collision rows' hot path (checked against coal
in ``tests/core/test_collision.py``).

A primitive is a segment [a, b] swept by a radius r (a sphere: a = b; a capsule), a box (centre c,
rotation R, half extents h), or a plane (unit normal n, offset o: the half-space n·p ≤ o is free).
Each function returns the signed distance d (negative in penetration) and the closest points p on
the first shape and q on the second and the unit normal from the second to the first: p = q + d·n
for separated shapes. Everything is in one frame (the base frame). Pairs these do not cover (box
against box, convex meshes, cylinders) stay with coal.
"""

from __future__ import annotations

import math

import numpy as np

from .._jit import jit, jit_inline
from .._typing import FloatArray


@jit
def _closest_params(
    ax: float, ay: float, az: float, ux: float, uy: float, uz: float,
    bx: float, by: float, bz: float, vx: float, vy: float, vz: float,
) -> tuple[float, float]:
    """Parameters (s, t) ∈ [0, 1]² of the closest points a + s·u, b + t·v of two segments
    (Ericson, Real-Time Collision Detection, 5.1.9), in scalars (no temporaries)."""
    rx, ry, rz = ax - bx, ay - by, az - bz
    a = ux * ux + uy * uy + uz * uz
    e = vx * vx + vy * vy + vz * vz
    f = vx * rx + vy * ry + vz * rz
    eps = 1e-18
    if a <= eps and e <= eps:
        return 0.0, 0.0
    if a <= eps:
        return 0.0, min(max(f / e, 0.0), 1.0)
    c = ux * rx + uy * ry + uz * rz
    if e <= eps:
        return min(max(-c / a, 0.0), 1.0), 0.0
    b = ux * vx + uy * vy + uz * vz
    denom = a * e - b * b
    s = min(max((b * f - c * e) / denom, 0.0), 1.0) if denom > eps else 0.0
    t = (b * s + f) / e
    if t < 0.0:
        t = 0.0
        s = min(max(-c / a, 0.0), 1.0)
    elif t > 1.0:
        t = 1.0
        s = min(max((b - c) / a, 0.0), 1.0)
    return s, t


@jit
def segment_distance(
    a0x: float, a0y: float, a0z: float, a1x: float, a1y: float, a1z: float,
    b0x: float, b0y: float, b0z: float, b1x: float, b1y: float, b1z: float,
) -> tuple[float, float, float, float, float, float, float, float, float, float]:
    """The centre-line distance of two segments, in scalars: (dist, the unit normal from the
    second to the first (0, 0, 1) where they touch, the closest point on the first, on the second)."""
    s, t = _closest_params(a0x, a0y, a0z, a1x - a0x, a1y - a0y, a1z - a0z,
                           b0x, b0y, b0z, b1x - b0x, b1y - b0y, b1z - b0z)
    cax, cay, caz = a0x + s * (a1x - a0x), a0y + s * (a1y - a0y), a0z + s * (a1z - a0z)
    cbx, cby, cbz = b0x + t * (b1x - b0x), b0y + t * (b1y - b0y), b0z + t * (b1z - b0z)
    vx, vy, vz = cax - cbx, cay - cby, caz - cbz
    dist = math.sqrt(vx * vx + vy * vy + vz * vz)
    if dist > 1e-12:
        return dist, vx / dist, vy / dist, vz / dist, cax, cay, caz, cbx, cby, cbz
    return dist, 0.0, 0.0, 1.0, cax, cay, caz, cbx, cby, cbz


@jit
def swept_swept(
    a0: FloatArray, a1: FloatArray, ra: float, b0: FloatArray, b1: FloatArray, rb: float,
    p: FloatArray, q: FloatArray, n: FloatArray,
) -> float:
    """Two swept segments (spheres, capsules)."""
    dist, n[0], n[1], n[2], cax, cay, caz, cbx, cby, cbz = segment_distance(
        a0[0], a0[1], a0[2], a1[0], a1[1], a1[2], b0[0], b0[1], b0[2], b1[0], b1[1], b1[2])
    for i, (ca, cb) in enumerate(((cax, cbx), (cay, cby), (caz, cbz))):
        p[i] = ca - ra * n[i]
        q[i] = cb + rb * n[i]
    return dist - ra - rb


@jit_inline
def swept_swept_at(
    a0: FloatArray, a1: FloatArray, r: FloatArray, i: int, j: int,
    d: FloatArray, P: FloatArray, Q: FloatArray, N: FloatArray, k: int,
) -> None:
    """:func:`swept_swept` of rows i and j of one table of segments into entry k of the
    candidates, by index: no array view made (each costs a reference count), and inlined into its
    caller (no call passing arrays); the Panda's ~105 capsule pairs a tick
    (``benchmarks/collision/passes_tick.py``, docs/benchmarks.md §12)."""
    dist, nx, ny, nz, cax, cay, caz, cbx, cby, cbz = segment_distance(
        a0[i, 0], a0[i, 1], a0[i, 2], a1[i, 0], a1[i, 1], a1[i, 2],
        a0[j, 0], a0[j, 1], a0[j, 2], a1[j, 0], a1[j, 1], a1[j, 2])
    ra, rb = r[i], r[j]
    N[k, 0], N[k, 1], N[k, 2] = nx, ny, nz
    P[k, 0], P[k, 1], P[k, 2] = cax - ra * nx, cay - ra * ny, caz - ra * nz
    Q[k, 0], Q[k, 1], Q[k, 2] = cbx + rb * nx, cby + rb * ny, cbz + rb * nz
    d[k] = dist - ra - rb


@jit
def swept_plane(
    a0: FloatArray, a1: FloatArray, ra: float, normal: FloatArray, offset: float,
    p: FloatArray, q: FloatArray, n: FloatArray,
) -> float:
    """A swept segment against the plane n·x = offset, the solid side n·x > offset (n from the
    solid towards the free side is −normal)."""
    h0 = offset - normal @ a0  # how far inside the free side each end is
    h1 = offset - normal @ a1
    c = a0 if h0 <= h1 else a1
    if abs(h0 - h1) < 1e-12:
        c = 0.5 * (a0 + a1)
    h = min(h0, h1)
    n[:] = -normal
    p[:] = c - ra * n
    q[:] = c + h * normal
    return float(h - ra)


@jit
def _point_box_d(x0: float, x1: float, x2: float, c: FloatArray, R: FloatArray, h: FloatArray) -> float:
    """Signed distance of the point (x0, x1, x2) to the box (scalars, no temporaries)."""
    d0, d1, d2 = x0 - c[0], x1 - c[1], x2 - c[2]
    out2, inside = 0.0, -1e300
    for k in range(3):
        lk = R[0, k] * d0 + R[1, k] * d1 + R[2, k] * d2  # Rᵀ (x − c)
        e = abs(lk) - h[k]
        if e > 0.0:
            out2 += e * e
        inside = max(inside, e)
    return math.sqrt(out2) if out2 > 0.0 else inside


@jit
def _point_box(x: FloatArray, c: FloatArray, R: FloatArray, h: FloatArray, q: FloatArray, n: FloatArray) -> float:
    """Signed distance of point x to the box; q ← its closest point on the box's surface, n ← the
    unit normal from q to x (outwards)."""
    local = R.T @ (x - c)
    clamped = np.minimum(np.maximum(local, -h), h)
    out = local - clamped
    d_out = math.sqrt(out @ out)
    if d_out > 0.0:
        q[:] = c + R @ clamped
        n[:] = R @ (out / d_out)
        return d_out
    # inside: the nearest face
    gaps = h - np.abs(local)
    k = int(np.argmin(gaps))
    sign = 1.0 if local[k] >= 0.0 else -1.0
    face = local.copy()
    face[k] = sign * h[k]
    q[:] = c + R @ face
    e = np.zeros(3)
    e[k] = sign
    n[:] = R @ e
    return -gaps[k]


@jit
def swept_box(
    a0: FloatArray, a1: FloatArray, ra: float, c: FloatArray, R: FloatArray, h: FloatArray,
    p: FloatArray, q: FloatArray, n: FloatArray,
) -> float:
    """A swept segment against a box: the signed distance of the segment's points to the box is
    convex along the segment, so a golden-section search over its parameter finds the closest.

    Exact while the segment itself is outside the box (d + ra ≥ 0). Once part of the segment is
    inside, the deepest point's depth is less than the segment's penetration depth (which must
    push every point out through one face; a Gen3 forearm 11 cm in a wall read −0.095 m here), and
    rows built on it let the pair go deeper (``wmm-qp verify``, 2,000 samples): the callers then
    take coal's instead."""
    u0, u1, u2 = a1[0] - a0[0], a1[1] - a0[1], a1[2] - a0[2]
    lo, hi = 0.0, 1.0
    g = 0.5 * (math.sqrt(5.0) - 1.0)
    x1 = hi - g * (hi - lo)
    x2 = lo + g * (hi - lo)
    f1 = _point_box_d(a0[0] + x1 * u0, a0[1] + x1 * u1, a0[2] + x1 * u2, c, R, h)
    f2 = _point_box_d(a0[0] + x2 * u0, a0[1] + x2 * u1, a0[2] + x2 * u2, c, R, h)
    if u0 * u0 + u1 * u1 + u2 * u2 > 1e-18:
        for _ in range(60):
            if f1 <= f2:
                hi, x2, f2 = x2, x1, f1
                x1 = hi - g * (hi - lo)
                f1 = _point_box_d(a0[0] + x1 * u0, a0[1] + x1 * u1, a0[2] + x1 * u2, c, R, h)
            else:
                lo, x1, f1 = x1, x2, f2
                x2 = lo + g * (hi - lo)
                f2 = _point_box_d(a0[0] + x2 * u0, a0[1] + x2 * u1, a0[2] + x2 * u2, c, R, h)
            if hi - lo < 1e-10:
                break
    best_t, best = 0.5 * (lo + hi), 1e300
    for t in (0.0, 1.0, 0.5 * (lo + hi)):  # the ends, where the minimum of a clamped search may sit
        dt = _point_box_d(a0[0] + t * u0, a0[1] + t * u1, a0[2] + t * u2, c, R, h)
        if dt < best:
            best, best_t = dt, t
    x = np.empty(3)
    x[0], x[1], x[2] = a0[0] + best_t * u0, a0[1] + best_t * u1, a0[2] + best_t * u2
    d = _point_box(x, c, R, h, q, n)
    for i in range(3):
        p[i] = x[i] - ra * n[i]
    return d - ra


@jit
def box_plane(
    c: FloatArray, R: FloatArray, h: FloatArray, normal: FloatArray, offset: float,
    p: FloatArray, q: FloatArray, n: FloatArray,
) -> float:
    """A box against the plane n·x = offset (solid where n·x > offset): its deepest corner."""
    best = 1e300
    corner = np.empty(3)
    for i in range(8):
        s = np.array([1.0 if i & 1 else -1.0, 1.0 if i & 2 else -1.0, 1.0 if i & 4 else -1.0])
        x = c + R @ (s * h)
        gap = float(offset - normal @ x)
        if gap < best:
            best = gap
            corner[:] = x
    n[:] = -normal
    p[:] = corner
    q[:] = corner + best * normal
    return best
