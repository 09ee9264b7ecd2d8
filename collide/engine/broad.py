"""Broad phase: a uniform cell grid, so that finding contacts follows the bodies, not the pairs;
union-find over bodies (clusters of contacts); and whether two bodies went through each other
unseen between two positions.
"""

from __future__ import annotations

import numpy as np

from collide.engine.jit import jit, jit_inline
from collide.engine.layout import G_R
from collide.engine.numerics import grow_int


@jit
def near_pairs(P, rad, margin, n, dim):
    """Pairs (i < j) with |s_i - s_j| <= r_i + r_j + margin_i + margin_j, shape (K, 2), from
    positions P (N, 3). A body whose reach is far above the rest's (a fast one) is checked
    against every body instead of setting the cell size for all."""
    out = np.empty((max(16, 4 * n), 2), np.int64)
    m = 0
    if n < 2:
        return out[:0]
    mean = 0.0
    for i in range(n):
        mean += rad[i] + margin[i]
    mean /= n
    size = 0.0
    for i in range(n):
        b = rad[i] + margin[i]
        if b <= 4.0 * mean:
            size = max(size, b)
    size *= 2.0
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    for i in range(n):
        for d in range(dim):
            lo[d] = min(lo[d], P[i, d])
            hi[d] = max(hi[d], P[i, d])
    cells = np.ones(3, np.int64)
    while True:
        total = 1
        for d in range(dim):
            cells[d] = min(int((hi[d] - lo[d]) / size) + 1, 1 << 20) if size > 0 else 1
            total *= cells[d]
        if total <= 4 * n + 64:
            break
        size *= 1.5
    head = np.full(cells[0] * cells[1] * cells[2], -1, np.int64)
    nxt = np.full(n, -1, np.int64)
    cell = np.zeros((n, 3), np.int64)
    for i in range(n):
        if rad[i] + margin[i] > 4.0 * mean:
            continue
        for d in range(dim):
            cell[i, d] = min(max(int((P[i, d] - lo[d]) / size) if size > 0 else 0, 0), cells[d] - 1)
        key = (cell[i, 0] * cells[1] + cell[i, 1]) * cells[2] + cell[i, 2]
        nxt[i] = head[key]
        head[key] = i
    for i in range(n):
        bi = rad[i] + margin[i]
        if bi > 4.0 * mean:
            # Against everyone (another outlier only once, from the lower index).
            for j in range(n):
                if j == i or (j < i and rad[j] + margin[j] > 4.0 * mean):
                    continue
                if _close(P, i, j, bi + rad[j] + margin[j]):
                    out = grow_int(out, m)
                    out[m, 0], out[m, 1] = min(i, j), max(i, j)
                    m += 1
            continue
        a0, a1 = max(cell[i, 0] - 1, 0), min(cell[i, 0] + 1, cells[0] - 1)
        b0, b1 = max(cell[i, 1] - 1, 0), min(cell[i, 1] + 1, cells[1] - 1)
        c0, c1 = max(cell[i, 2] - 1, 0), min(cell[i, 2] + 1, cells[2] - 1)
        for a in range(a0, a1 + 1):
            for b in range(b0, b1 + 1):
                for c in range(c0, c1 + 1):
                    j = head[(a * cells[1] + b) * cells[2] + c]
                    while j >= 0:
                        if j > i and _close(P, i, j, bi + rad[j] + margin[j]):
                            out = grow_int(out, m)
                            out[m, 0], out[m, 1] = i, j
                            m += 1
                        j = nxt[j]
    return out[:m]


@jit
def _close(P, i, j, reach):
    dx = P[j, 0] - P[i, 0]
    dy = P[j, 1] - P[i, 1]
    dz = P[j, 2] - P[i, 2]
    return dx * dx + dy * dy + dz * dz <= reach * reach


@jit
def root_of(parent, i):
    """Union-find root, with path halving."""
    while parent[i] != i:
        parent[i] = parent[parent[i]]
        i = parent[i]
    return i


@jit
def join(parent, i, j):
    a, b = root_of(parent, i), root_of(parent, j)
    if a != b:
        parent[max(a, b)] = min(a, b)


@jit
def crossed(P0, P, G, n, start, other, margin):
    """Whether two bodies, neither the other's candidate, went through each other between P0 and
    P. Only a body that moved past its margin can have (a speed bound that failed: a body at rest
    sent on by a candidate within the window, in a row of spheres, went through the next one
    whole, touching it at neither end). Their relative motion taken straight from P0 to P; in 1D
    exact: their order flipped."""
    for i in range(n):
        mx, my, mz = P[i, 0] - P0[i, 0], P[i, 1] - P0[i, 1], P[i, 2] - P0[i, 2]
        if mx * mx + my * my + mz * mz <= margin[i] * margin[i]:
            continue
        for j in range(n):
            if j == i or listed(start, other, i, j) or listed(start, other, j, i):
                continue
            ax, ay, az = P0[j, 0] - P0[i, 0], P0[j, 1] - P0[i, 1], P0[j, 2] - P0[i, 2]
            ux = P[j, 0] - P[i, 0] - ax
            uy = P[j, 1] - P[i, 1] - ay
            uz = P[j, 2] - P[i, 2] - az
            uu = ux * ux + uy * uy + uz * uz
            s = min(max(-(ax * ux + ay * uy + az * uz) / uu, 0.0), 1.0) if uu > 0.0 else 0.0
            cx, cy, cz = ax + ux * s, ay + uy * s, az + uz * s
            reach = G[i, G_R] + G[j, G_R]
            if cx * cx + cy * cy + cz * cz < reach * reach:
                return True
    return False


@jit_inline
def listed(start, other, i, j):
    """Whether j is among i's candidates (CSR)."""
    for k in range(start[i], start[i + 1]):
        if other[k] == j:
            return True
    return False


@jit
def largest_set(parent, n):
    size = np.zeros(n, np.int64)
    big = 0
    for i in range(n):
        r = root_of(parent, i)
        size[r] += 1
        big = max(big, size[r])
    return big
