"""Small numerics the engine's kernels share: roots of quadratics and cubic Hermite curves, a
small dense factor and solve (a stuck island's hold forces), and buffers that grow.
"""

from __future__ import annotations

import math

import numpy as np

from collide.engine.jit import jit, jit_inline
from collide.engine.layout import DIP_SAMPLES


@jit_inline
def factor(A, piv, m, symmetric):
    """Factor A[:m, :m] in place: `symmetric` (and positive definite, as W is where it is
    symmetric) as L D L^T, L unit lower triangular below the diagonal and 1 / D on it, half the
    work of LU and no pivoting (Cholesky: 0.21 against 0.38 us at m = 10, 0.68 against 1.57 at
    16), and no square root, nor a division in the solves, whose chains wait on each; the upper
    triangle holds L D while factoring. Else LU with partial pivoting (row swaps in
    piv). False if singular."""
    if symmetric:
        for k in range(m):
            for p in range(k):
                s = A[k, p]
                for q in range(p):
                    s -= A[q, k] * A[p, q]
                A[p, k] = s  # L[k, p] D[p]
            d = A[k, k]
            for p in range(k):
                lkp = A[p, k] * A[p, p]
                A[k, p] = lkp
                d -= A[p, k] * lkp
            if not d > 0.0:
                return False
            A[k, k] = 1.0 / d
        return True
    for k in range(m):
        p = k
        for r in range(k + 1, m):
            if abs(A[r, k]) > abs(A[p, k]):
                p = r
        piv[k] = p
        if A[p, k] == 0.0:
            return False
        if p != k:
            for col in range(m):
                A[k, col], A[p, col] = A[p, col], A[k, col]
        for r in range(k + 1, m):
            A[r, k] /= A[k, k]
            f = A[r, k]
            if f != 0.0:
                for col in range(k + 1, m):
                    A[r, col] -= f * A[k, col]
    return True


@jit_inline
def solve_factored(A, piv, b, m, symmetric):
    """Solve with the factors from `factor`; b holds the solution."""
    if symmetric:
        for k in range(m):
            s = b[k]
            for col in range(k):
                s -= A[k, col] * b[col]
            b[k] = s
        for k in range(m - 1, -1, -1):
            s = b[k] * A[k, k]
            for r in range(k + 1, m):
                s -= A[r, k] * b[r]
            b[k] = s
        return
    for k in range(m):
        p = piv[k]
        if p != k:
            b[k], b[p] = b[p], b[k]
    for k in range(m):
        s = b[k]
        for col in range(k):
            s -= A[k, col] * b[col]
        b[k] = s
    for k in range(m - 1, -1, -1):
        s = b[k]
        for col in range(k + 1, m):
            s -= A[k, col] * b[col]
        b[k] = s / A[k, k]


@jit_inline
def hermite_root(d0, d1, r0, r1):
    """Root in (0, 1) of the cubic Hermite through (0, d0, r0) and (1, d1, r1) (r per step), by
    safeguarded Newton on the cubic, kept inside the bracket."""
    c2 = 3.0 * (d1 - d0) - 2.0 * r0 - r1
    c3 = 2.0 * (d0 - d1) + r0 + r1
    theta = min(max(d0 / (d0 - d1 if d0 != d1 else 1.0), 0.0), 1.0)
    if (d0 > 0) == (d1 > 0):
        return theta
    lo, hi = 0.0, 1.0
    positive = d0 > 0
    for _ in range(60):
        p = d0 + theta * (r0 + theta * (c2 + theta * c3))
        dp = r0 + theta * (2.0 * c2 + 3.0 * c3 * theta)
        if (p > 0) == positive:
            lo = theta
        else:
            hi = theta
        newton = theta - p / dp if dp != 0 else math.inf
        nxt = newton if lo <= newton <= hi else 0.5 * (lo + hi)
        done = abs(nxt - theta) <= 1e-15
        theta = nxt
        if done:
            break
    return theta


@jit_inline
def bracketed_root(lo, f_lo, hi, f_hi, a, fa, b, fb, c, fc):
    """Next estimate of a root bracketed in [lo, hi] (f_lo >= 0 > f_hi) from the latest three
    trials (c the latest): inverse quadratic interpolation through them, else the secant through
    the latest two; where that leaves the bracket, false position nudged off its ends."""
    est = math.nan
    if fa == fa and fa != fb and fa != fc and fb != fc:
        est = (a * fb * fc / ((fa - fb) * (fa - fc)) + b * fa * fc / ((fb - fa) * (fb - fc))
               + c * fa * fb / ((fc - fa) * (fc - fb)))
    if not (lo < est < hi) and fb == fb and fc != fb:
        est = c - fc * (c - b) / (fc - fb)
    if lo < est < hi:
        return est
    width = hi - lo
    if f_lo != f_hi:
        return min(max(lo + width * f_lo / (f_lo - f_hi), lo + 0.01 * width), hi - 0.01 * width)
    return 0.5 * (lo + hi)


@jit
def smallest_positive_root(a, b, c):
    """Smallest t > 0 with a t^2 + b t + c = 0 (inf if none); c >= 0 (not yet touching)."""
    disc = b * b - 4.0 * a * c
    if disc < 0:
        return math.inf
    q = -0.5 * (b + math.copysign(math.sqrt(disc), b))
    r1 = c / q if q != 0 else math.inf
    r2 = q / a if a != 0 else math.inf
    best = math.inf
    if r1 > 0:
        best = r1
    if 0 < r2 < best:
        best = r2
    return best


@jit
def grow(buf, n):
    """`buf` with room for row n (doubled when full)."""
    if n < buf.shape[0]:
        return buf
    # At least row n: a caller may ask for many rows at once (an island's new contacts).
    out = np.empty((max(2 * buf.shape[0] + 16, n + 1), buf.shape[1]))
    out[:buf.shape[0]] = buf
    return out


@jit
def grow_int(buf, n):
    if n < buf.shape[0]:
        return buf
    out = np.empty((max(2 * buf.shape[0] + 16, n + 1), buf.shape[1]), np.int64)
    out[:buf.shape[0]] = buf
    return out


@jit_inline
def hermite_dip(e0, e1, r0, r1, floor):
    """The first of DIP_SAMPLES points in (0, 1) where the cubic Hermite through (0, e0, r0) and
    (1, e1, r1) (r per step) is below `floor`: a value above it at both ends that dips between.
    inf if none (or if the rates make it a hump)."""
    if r0 >= 0.0 and r1 <= 0.0:
        return math.inf
    # The cubic is e0, e1's blend plus r0 u (1 - u)^2 - r1 u^2 (1 - u), each term at most 4/27 of
    # its rate: no sample can dip below this bound (0.15 over 4/27 and the 1e-12 cover the
    # samples' rounding), and most values of a trial stay above it (their 15 samples skipped).
    reach = max(-r0, 0.0) + max(r1, 0.0)
    if min(e0, e1) - 0.15 * reach - 1e-12 * (abs(e0) + abs(e1) + reach) > floor:
        return math.inf
    for i in range(1, DIP_SAMPLES):
        u = i / DIP_SAMPLES
        u2, u3 = u * u, u * u * u
        p = (2 * u3 - 3 * u2 + 1) * e0 + (u3 - 2 * u2 + u) * r0 + (3 * u2 - 2 * u3) * e1 + (u3 - u2) * r1
        if p < floor:
            return u
    return math.inf


@jit_inline
def first_root(e0, r0, curve):
    """The first positive root of e0 + r0 t + curve t^2 / 2 (e0 > 0), in the form without
    cancellation; inf if none."""
    disc = r0 * r0 - 2.0 * curve * e0
    if disc >= 0.0:
        denominator = -r0 + math.sqrt(disc)
        if denominator > 0.0:
            return 2.0 * e0 / denominator
    return math.inf


@jit_inline
def dot3(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@jit_inline
def illinois(lo, hi, glo, ghi, side, m, g):
    """One Illinois update of a bracket [lo, hi] (values glo, ghi of opposite signs) with the
    value g at its secant point m: the side g shares with glo moves to m, and the other side's
    value is halved when the same side moved last. Returns (lo, hi, glo, ghi, side)."""
    if (g > 0.0) == (glo > 0.0):
        if side == -1:
            ghi *= 0.5
        return m, hi, g, ghi, -1
    if side == 1:
        glo *= 0.5
    return lo, m, glo, g, 1
