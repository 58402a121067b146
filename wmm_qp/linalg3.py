"""Compiled small linear algebra shared by the hot path's kernels: 3×3 in closed form (the
position task, r = 3), r×r by Cholesky (the pose task, r = 6)."""

from __future__ import annotations

import math

import numpy as np

from ._jit import jit
from ._typing import FloatArray


@jit
def gram3(J: FloatArray) -> tuple[float, float, float, float, float, float]:
    """The entries (a, b, c, d, e, f) of J Jᵀ = [[a, b, c], [b, d, e], [c, e, f]] for a 3×n J."""
    a = b = c = d = e = f = 0.0
    for i in range(J.shape[1]):
        x, y, z = J[0, i], J[1, i], J[2, i]
        a += x * x
        b += x * y
        c += x * z
        d += y * y
        e += y * z
        f += z * z
    return a, b, c, d, e, f


@jit
def solve_sym3(
    a: float, b: float, c: float, d: float, e: float, f: float, r0: float, r1: float, r2: float
) -> tuple[float, float, float, float]:
    """(det, y) with [[a, b, c], [b, d, e], [c, e, f]] y = r, by the adjugate; the caller checks
    det (y is inf/NaN when it is 0)."""
    A0, A1, A2 = d * f - e * e, c * e - b * f, b * e - c * d
    B1, B2, C2 = a * f - c * c, b * c - a * e, a * d - b * b
    det = a * A0 + b * A1 + c * A2
    return (
        det,
        (A0 * r0 + A1 * r1 + A2 * r2) / det,
        (A1 * r0 + B1 * r1 + B2 * r2) / det,
        (A2 * r0 + B2 * r1 + C2 * r2) / det,
    )


@jit
def solve_spd(G: FloatArray, r: FloatArray, y: FloatArray) -> bool:
    """y = G⁻¹ r for a symmetric positive definite G (m×m) by Cholesky; False (y undefined) when
    G is not numerically positive definite (a pivot ≤ 1e-300 or NaN)."""
    m = G.shape[0]
    L = np.zeros((m, m))
    for i in range(m):
        for j in range(i + 1):
            acc = G[i, j]
            for k in range(j):
                acc -= L[i, k] * L[j, k]
            if i == j:
                if not acc > 1e-300:
                    return False
                L[i, i] = math.sqrt(acc)
            else:
                L[i, j] = acc / L[j, j]
    for i in range(m):  # L w = r
        acc = r[i]
        for k in range(i):
            acc -= L[i, k] * y[k]
        y[i] = acc / L[i, i]
    for i in range(m - 1, -1, -1):  # Lᵀ y = w
        acc = y[i]
        for k in range(i + 1, m):
            acc -= L[k, i] * y[k]
        y[i] = acc / L[i, i]
    return True
